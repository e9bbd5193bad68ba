"""Print the last values of a COMA run's TensorBoard scalars: tbpeek.py RUN [RUN ...]."""
import glob
import sys

from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

KEYS = ("return_mean", "policy_entropy", "eval_entropy_final", "critic_loss", "advantage_std",
        "final_entropy_mean")
for run in sys.argv[1:]:
    ea = EventAccumulator(glob.glob(f"{run}/tb")[0])
    ea.Reload()
    out = {}
    for tag in ea.Tags()["scalars"]:
        key = tag.split("/")[-1]
        if key in KEYS:
            vals = ea.Scalars(tag)
            n = 4 if key != "eval_entropy_final" else 10
            out[key] = [(v.step, round(v.value, 3)) for v in vals[-n:]]
    print(run)
    for k, v in out.items():
        print("  ", k, v)
