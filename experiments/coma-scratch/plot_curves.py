"""Validation final entropy against agent-transitions for COMA runs (progress.csv files).

    python experiments/coma-scratch/plot_curves.py OUT.png LABEL=RUN/progress.csv ... \
        [--reference ig=0.388]
"""

from __future__ import annotations

import argparse
import csv

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out")
    parser.add_argument("runs", nargs="+", help="LABEL=PATH/progress.csv")
    parser.add_argument("--reference", action="append", default=[], help="NAME=VALUE")
    parser.add_argument("--title", default="COMA from random networks (4 UAVs, D = 25 m)")
    parser.add_argument("--max-missions", type=int, default=None,
                        help="draw only up to this many training missions")
    args = parser.parse_args()
    figure, axes = plt.subplots(figsize=(7, 4.2))
    colours: dict[str, str] = {}
    for spec in args.runs:
        label, path = spec.split("=", 1)
        rows = [r for r in csv.DictReader(open(path)) if r["eval_entropy_final"]
                and (args.max_missions is None or int(r["missions"]) <= args.max_missions)]
        # Runs labelled GROUP@sK share GROUP's colour; each seed has its own line style.
        group, _, seed = label.partition("@")
        style = ["-", "--", ":"][int(seed[1:]) % 3] if seed[1:].isdigit() else "-"
        line, = axes.plot([int(r["transitions"]) / 1e6 for r in rows],
                          [float(r["eval_entropy_final"]) for r in rows], marker=".",
                          linestyle=style, color=colours.get(group),
                          label=(group if seed else label) if group not in colours else None)
        colours.setdefault(group, line.get_color())
    for spec in args.reference:
        name, value = spec.split("=", 1)
        axes.axhline(float(value), color="grey", linestyle="--", linewidth=1)
        axes.text(0.01, float(value), f" {name} ", transform=axes.get_yaxis_transform(),
                  color="grey", va="bottom")
    axes.set_xlabel("agent-transitions (millions)")
    axes.set_ylabel("validation final entropy (greedy)")
    axes.set_title(args.title)
    axes.legend(fontsize=8)
    axes.grid(alpha=0.3)
    figure.tight_layout()
    figure.savefig(args.out, dpi=110)


if __name__ == "__main__":
    main()
