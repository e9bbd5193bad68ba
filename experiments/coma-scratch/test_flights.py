"""Fly COMA policies beside ig and ig_paper and check the scratch recipe's bar.

Test missions of one team setting (default: 4 UAVs, D = 25 m, r_M = 0.1 m, split): each
policy's mean final entropy and F1, its paired difference to ig and ig_paper (mean +- SE),
and whether it is ahead of ig by two SE and at least 0.15 below ig_paper.

    python experiments/coma-scratch/test_flights.py s0:coma=RUN0/best.pt ... --missions 50
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.runs.evaluation import evaluate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("planners", nargs="+")
    parser.add_argument("--missions", type=int, default=50)
    parser.add_argument("--agents", type=int, default=4)
    parser.add_argument("--comm", type=float, default=25.0)
    parser.add_argument("--namespace", default="test")
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    config = EnvConfig().replace(team={"n_agents": args.agents, "comm_range": args.comm})
    if args.agents not in (2, 4, 8):
        config = config.replace(team={"start": "random"})
    result = evaluate(config, ["ig", "ig_paper", *args.planners], missions=args.missions,
                      seed=0, namespace=args.namespace, progress=False, workers=args.workers)
    entropy = {k: v[:, -1] for k, v in result.curves("entropy").items()}
    f1 = {k: v[:, -1] for k, v in result.curves("f1").items()}
    print(f"{args.namespace} missions: {args.missions}, {args.agents} UAVs, "
          f"D = {args.comm} m, r_M = {config.world.resolution} m")
    for label in result.labels:
        line = f"  {label:14s} H {entropy[label].mean():.4f}  F1 {f1[label].mean():.4f}"
        for ref in ("ig", "ig_paper"):
            if label != ref:
                diff = entropy[label] - entropy[ref]
                se = diff.std(ddof=1) / math.sqrt(len(diff))
                line += f"  vs {ref} {diff.mean():+.4f} +- {se:.4f}"
        if label not in ("ig", "ig_paper"):
            diff = entropy[label] - entropy["ig"]
            se = diff.std(ddof=1) / math.sqrt(len(diff))
            gap = np.mean(entropy["ig_paper"] - entropy[label])
            line += (f"  bar: ahead of ig by 2 SE {diff.mean() < -2 * se}, "
                     f"0.15 below ig_paper {gap >= 0.15}")
        print(line)


if __name__ == "__main__":
    main()
