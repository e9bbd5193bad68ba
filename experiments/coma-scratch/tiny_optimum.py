"""The best open-loop plan of a small mission, by exhaustive search.

On one fixed field every mission differs only in its sensor noise, so the best policy is (up
to reacting to the noise) the best fixed joint plan. This flies every joint plan of the
mission's budget (all valid joint actions at every step) on K validation missions, each plan
on the same K noise streams (the state is copied, streams and all, at every branch), and
prints the best plans' mean final entropy beside ig's, ig_paper's and random's.

    python experiments/coma-scratch/tiny_optimum.py experiments/coma-scratch/tiny.yaml -k 4
"""

from __future__ import annotations

import argparse
import copy
import itertools
import time

import numpy as np

from ipp_toolkit.config.files import load_config
from ipp_toolkit.runs.evaluation import evaluate
from ipp_toolkit.sim.mission import reset_mission, step_mission


def leaves(state, depth: int, plan: tuple, out: dict) -> None:
    """Fly every valid joint action from ``state``; ``out[plan] = final entropy``."""
    if state.done:
        out[plan] = state.history[-1].entropy
        return
    masks = state.masks().astype(bool)
    choices = [np.flatnonzero(m) for m in masks]
    for joint in itertools.product(*choices):
        child = copy.deepcopy(state)
        step_mission(child, np.array(joint))
        leaves(child, depth + 1, plan + (joint,), out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("config")
    parser.add_argument("-k", "--missions", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    config = load_config(args.config)
    tick = time.perf_counter()
    per_mission = []
    for k in range(args.missions):
        out: dict = {}
        leaves(reset_mission(config, args.seed, k, "validation"), 0, (), out)
        per_mission.append(out)
    plans = list(per_mission[0])
    scores = np.array([[m[p] for p in plans] for m in per_mission]).mean(axis=0)
    order = np.argsort(scores)
    print(f"{len(plans)} joint plans x {args.missions} missions in "
          f"{time.perf_counter() - tick:.0f} s")
    for i in order[:5]:
        print(f"  {scores[i]:.4f}  {plans[i]}")
    print(f"  median plan {np.median(scores):.4f}, worst {scores.max():.4f}")
    result = evaluate(config, ["ig", "ig_paper", "random"], missions=args.missions,
                      seed=args.seed, namespace="validation", progress=False)
    for label, curve in result.curves("entropy").items():
        print(f"  {label}: {curve[:, -1].mean():.4f}")


if __name__ == "__main__":
    main()
