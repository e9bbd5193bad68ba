"""Non-learning planners and PPO training built on :mod:`ipp_toolkit`."""
