"""Choose the default ``coma`` among trained COMA policies on validation missions.

Flies the candidates beside ig and ig_learned on the validation missions of ipp-compare's
default setting (4 UAVs, D = 25 m, r_M = 0.1 m, split terrain) and prints each one's mean final
entropy and F1, its paired difference to ig (mean +- standard error) and the share of missions
where its final entropy differs from ig_learned's.

    python experiments/coma-scratch/validate_default.py --missions 50 coma=shipped:paper-actor ...
"""

from __future__ import annotations

import argparse

import numpy as np

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.runs.evaluation import evaluate


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("planners", nargs="+")
    parser.add_argument("--missions", type=int, default=50)
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    planners = ["ig", "ig_learned", *args.planners]
    result = evaluate(EnvConfig(), planners, missions=args.missions, seed=0,
                      namespace="validation", progress=False, workers=args.workers)
    entropy = {k: v[:, -1] for k, v in result.curves("entropy").items()}
    f1 = {k: v[:, -1] for k, v in result.curves("f1").items()}
    for label in result.labels:
        diff = entropy[label] - entropy["ig"]
        same = np.mean(np.abs(entropy[label] - entropy["ig_learned"]) > 1e-12)
        print(f"{label:40s} H {entropy[label].mean():.4f}  F1 {f1[label].mean():.4f}  "
              f"vs ig {diff.mean():+.4f} +- {diff.std(ddof=1) / np.sqrt(len(diff)):.4f}  "
              f"differs from ig_learned on {100 * same:.0f} %")


if __name__ == "__main__":
    main()
