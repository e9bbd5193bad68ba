"""The credit-assignment study's table over training seeds, from an ipp-compare results.csv.

Planners are labelled ``VARIANT_sK`` (seed K). For each variant: the final entropy and F1 of
each seed (mean over the test missions), their mean and the standard deviation over seeds, and
the paired difference of the variant's seed-averaged final entropy to COMA's on the same
missions (mean +- standard error over missions).

    python experiments/coma-scratch/credit_table.py RUN/results.csv
"""

from __future__ import annotations

import argparse
import collections
import csv
import math

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("results")
    parser.add_argument("--baseline", default="coma")
    args = parser.parse_args()
    last: dict[tuple[str, int], tuple[int, float, float]] = {}
    for row in csv.DictReader(open(args.results, encoding="utf-8")):
        key = (row["planner"], int(row["mission"]))
        step = int(row["step"])
        if key not in last or step > last[key][0]:
            last[key] = (step, float(row["entropy"]), float(row["f1"]))
    seeds: dict[str, dict[int, tuple[np.ndarray, np.ndarray]]] = collections.defaultdict(dict)
    for label in sorted({planner for planner, _ in last}):
        variant, _, seed = label.rpartition("_s")
        missions = sorted(m for p, m in last if p == label)
        values = np.array([last[(label, m)][1:] for m in missions])
        seeds[variant if seed.isdigit() else label][int(seed) if seed.isdigit() else 0] = (
            values[:, 0], values[:, 1])
    base = np.mean([h for h, _ in seeds[args.baseline].values()], axis=0)
    print(f"| variant | seeds | final entropy per seed | mean ± sd | F1 mean | "
          f"− {args.baseline} (paired, seed means) |")
    print("|---|---|---|---:|---:|---:|")
    for variant, runs in seeds.items():
        per_seed = [float(h.mean()) for h, _ in runs.values()]
        f1 = np.mean([float(f.mean()) for _, f in runs.values()])
        diff = np.mean([h for h, _ in runs.values()], axis=0) - base
        sd = np.std(per_seed, ddof=1) if len(per_seed) > 1 else float("nan")
        paired = ("-" if variant == args.baseline else
                  f"{diff.mean():+.3f} ± {diff.std(ddof=1) / math.sqrt(len(diff)):.3f}")
        print(f"| {variant} | {','.join(map(str, runs))} | "
              f"{' / '.join(f'{v:.3f}' for v in per_seed)} | {np.mean(per_seed):.3f} ± {sd:.3f} | "
              f"{f1:.3f} | {paired} |")


if __name__ == "__main__":
    main()
