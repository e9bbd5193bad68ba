"""Fly COMA policies beside reference planners on validation or test missions.

One team setting (default: 4 UAVs, D = 25 m, r_M = 0.1 m, split). For each policy: its mean
final entropy and F1, its paired difference to each reference (mean +- standard error) and,
with ``--bar``, whether it is ahead of ig by two SE and at least 0.15 below ig_paper (the
scratch recipe's bar); with ``--differs-from NAME``, the share of missions where its final
entropy differs from NAME's (a policy that copies its prior differs on none).

    python experiments/coma-scratch/flights.py --namespace validation \
        --references ig,ig_learned --differs-from ig_learned coma=shipped:paper-actor ...
    python experiments/coma-scratch/flights.py --bar s0:coma=RUN0/best.pt ...
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.runs.evaluation import evaluate


def paired(entropy: dict[str, np.ndarray], label: str, ref: str) -> tuple[float, float]:
    """Mean and standard error of ``label``'s final entropy minus ``ref``'s, paired."""
    diff = entropy[label] - entropy[ref]
    return float(diff.mean()), float(diff.std(ddof=1) / math.sqrt(len(diff)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("planners", nargs="+")
    parser.add_argument("--missions", type=int, default=50)
    parser.add_argument("--agents", type=int, default=4)
    parser.add_argument("--comm", type=float, default=25.0)
    parser.add_argument("--namespace", default="test", choices=["validation", "test"])
    parser.add_argument("--references", default="ig,ig_paper")
    parser.add_argument("--differs-from", default="")
    parser.add_argument("--bar", action="store_true")
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    references = [r for r in args.references.split(",") if r]
    if args.bar:
        references = list(dict.fromkeys([*references, "ig", "ig_paper"]))
    config = EnvConfig().replace(team={"n_agents": args.agents, "comm_range": args.comm})
    if args.agents not in (2, 4, 8):
        config = config.replace(team={"start": "random"})
    result = evaluate(config, [*references, *args.planners], missions=args.missions, seed=0,
                      namespace=args.namespace, progress=False, workers=args.workers)
    entropy = {k: v[:, -1] for k, v in result.curves("entropy").items()}
    f1 = {k: v[:, -1] for k, v in result.curves("f1").items()}
    print(f"{args.namespace} missions: {args.missions}, {args.agents} UAVs, "
          f"D = {args.comm} m, r_M = {config.world.resolution} m")
    for label in result.labels:
        line = f"  {label:14s} H {entropy[label].mean():.4f}  F1 {f1[label].mean():.4f}"
        for ref in references:
            if label != ref:
                mean, se = paired(entropy, label, ref)
                line += f"  vs {ref} {mean:+.4f} +- {se:.4f}"
        if args.differs_from and label != args.differs_from:
            same = np.mean(np.abs(entropy[label] - entropy[args.differs_from]) > 1e-12)
            line += f"  differs from {args.differs_from} on {100 * same:.0f} %"
        if args.bar and label not in references:
            mean, se = paired(entropy, label, "ig")
            gap = float(np.mean(entropy["ig_paper"] - entropy[label]))
            line += (f"  bar: ahead of ig by 2 SE {mean < -2 * se}, "
                     f"0.15 below ig_paper {gap >= 0.15}")
        print(line)


if __name__ == "__main__":
    main()
