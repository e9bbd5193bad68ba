"""Copy a scratch run's best.pt into the package with its JSON record.

    python experiments/coma-scratch/ship.py RUN --seed S --missions M --name scratch \
        --out coma/checkpoints/coma_scratch_4agents_d25.pt [--note TEXT]

The record holds the exact command, ``best_update``, the validation curve (validation final
entropy and F1 against missions and agent-transitions), the training time and the machine.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import platform
import shutil
from pathlib import Path

import torch


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--seed", type=int, required=True)
    parser.add_argument("--missions", type=int, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--note", default="")
    args = parser.parse_args()
    best = torch.load(args.run / "best.pt", weights_only=True)
    best_update = int(best["update"])
    rows = list(csv.DictReader(open(args.run / "progress.csv")))
    rows = [r for r in rows if int(r["missions"]) <= args.missions]
    curve = [{"update": int(r["update"]), "missions": int(r["missions"]),
              "transitions": int(r["transitions"]),
              "validation_final_entropy": round(float(r["eval_entropy_final"]), 4),
              "validation_final_f1": round(float(r["eval_f1_final"]), 4)}
             for r in rows if r["eval_entropy_final"]]
    record = {
        "command": f"ipp-train coma --preset scratch --seed {args.seed} "
                   f"--missions {args.missions} --out runs/scratch",
        "note": args.note,
        "best_update": best_update,
        "missions_trained": int(rows[-1]["missions"]),
        "agent_transitions": int(rows[-1]["transitions"]),
        "training_wall_minutes": round(float(rows[-1]["wall_s"]) / 60, 1),
        "machine": f"{platform.machine()}, {platform.processor() or 'cpu'}, torch "
                   f"{torch.__version__}",
        "date": datetime.date.today().isoformat(),
        "validation_by_update": curve,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(args.run / "best.pt", args.out)
    args.out.with_suffix(".json").write_text(json.dumps(record, indent=1) + "\n")
    print(json.dumps({k: v for k, v in record.items() if k != "validation_by_update"},
                     indent=1))


if __name__ == "__main__":
    main()
