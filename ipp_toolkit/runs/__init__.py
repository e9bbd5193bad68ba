"""Running many missions: the evaluation runner, its result store, the process pool and Ray
backends, and progress lines."""
