"""The manual's results tables, written from the current defaults by one command.

    python -m reports.manual_tables              # every table (a few minutes on 2 cores)
    python -m reports.manual_tables a8-d0        # one table

Each table is ``ipp-compare`` with the default planners on the 50 test missions of one team
setting (:data:`TABLES`: the quick start's run and the paper's 8-UAV run without
communication). Its summary goes to ``docs/results/NAME.md`` with the command that made it
and, in a comment the tests read, the run's mission config, planners and the sha256 of every
checkpoint it flew. :func:`stale_reasons` compares that record with what the same command
would fly today, so a change of default (a planner, a shipped policy, a config field) fails
the test suite until the table is written again. The run folders go to
``results/manual/NAME`` (resumable; kept out of the manual).
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ipp_toolkit.config.files import config_to_dict
from ipp_toolkit.config.settings import build_env_config
from ipp_toolkit.io import atomic_write

from .compare import DEFAULT_PLANNERS, planner_checkpoints

__all__ = ["TABLES", "TITLES", "table_config", "current_checkpoints", "write_table",
           "read_record", "stale_reasons", "main"]

#: Table name -> the team setting of its ``ipp-compare`` run (agents, comm range in metres).
TABLES: dict[str, tuple[int, float]] = {"a4-d25": (4, 25.0), "a8-d0": (8, 0.0)}
#: Table name -> the page's title.
TITLES = {"a4-d25": "`ipp-compare` on defaults (4 UAVs, D = 25 m)",
          "a8-d0": "`ipp-compare --agents 8 --comm 0`"}
TRIALS = 50
_RECORD = re.compile(r"<!-- table record: (\{.*\}) -->")


def command(name: str) -> list[str]:
    """The ``ipp-compare`` command line of table ``name``."""
    agents, comm = TABLES[name]
    return ["ipp-compare", "--agents", str(agents), "--comm", f"{comm:g}",
            "--trials", str(TRIALS), "--out", f"results/manual/{name}"]


def table_config(name: str) -> dict[str, Any]:
    """The mission config table ``name`` flies today, as a plain dict."""
    agents, comm = TABLES[name]
    return config_to_dict(build_env_config(agents=agents, comm=comm))


def current_checkpoints(planners: Sequence[str] = DEFAULT_PLANNERS) -> dict[str, str]:
    """``{planner: sha256}`` of the weights each planner flies by default (those with any)."""
    from ipp_toolkit.planning import make_planner
    from ipp_toolkit.planning.specs import PlannerSpec

    built = [(PlannerSpec(name), make_planner(name)) for name in planners]
    return {label: entry["sha256"] for label, entry in planner_checkpoints(built).items()}


def write_table(name: str, docs: Path, workers: int = 2, progress: bool = True) -> Path:
    """Run table ``name``'s comparison and write its page ``docs/NAME.md``; the page's path."""
    from .compare import compare_planners

    agents, comm = TABLES[name]
    out = Path(f"results/manual/{name}")
    comparison = compare_planners(agents=agents, comm=comm, planners=list(DEFAULT_PLANNERS),
                                  trials=TRIALS, seed=0, workers=workers, out=out,
                                  progress=progress)
    stored = json.loads((out / "config.json").read_text(encoding="utf-8"))
    record = {"command": command(name), "planners": list(DEFAULT_PLANNERS),
              "config": stored["config"],
              "checkpoints": {label: entry["sha256"]
                              for label, entry in stored.get("checkpoints", {}).items()}}
    page = docs / f"{name}.md"
    text = (
        f"# {TITLES[name]}\n\n"
        f"Written by `python -m reports.manual_tables {name}`, which runs\n\n"
        f"```bash\n{' '.join(command(name))}\n```\n\n"
        "on the current defaults (the test suite fails when a default planner, shipped policy "
        "or config field changes until the table is written again). The run's own summary:\n\n"
        f"{comparison.table.strip()}\n\n"
        f"<!-- table record: {json.dumps(record, sort_keys=True)} -->\n")
    page.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(page, lambda stream: stream.write(text.encode("utf-8")))
    return page


def read_record(page: Path) -> dict[str, Any]:
    """The record comment of a table page; ValueError naming the page when it has none."""
    match = _RECORD.search(page.read_text(encoding="utf-8"))
    if match is None:
        raise ValueError(f"{page} holds no table record; write it with "
                         "python -m reports.manual_tables")
    return json.loads(match.group(1))


def stale_reasons(name: str, page: Path) -> list[str]:
    """Why ``page`` no longer shows what table ``name``'s command flies today (empty: fresh)."""
    record = read_record(page)
    reasons = []
    if record["command"] != command(name):
        reasons.append(f"its command was {' '.join(record['command'])}")
    if record["planners"] != list(DEFAULT_PLANNERS):
        reasons.append(f"its planners {record['planners']} are not today's defaults "
                       f"{list(DEFAULT_PLANNERS)}")
    if record["config"] != table_config(name):
        reasons.append("its mission config differs from today's defaults")
    now = current_checkpoints(record["planners"])
    for planner in sorted(set(now) | set(record["checkpoints"])):
        if now.get(planner) != record["checkpoints"].get(planner):
            reasons.append(f"{planner}'s weights changed (sha256 "
                           f"{str(record['checkpoints'].get(planner))[:12]} -> "
                           f"{str(now.get(planner))[:12]})")
    return reasons


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m reports.manual_tables [NAME ...]``; 0 on success, 2 on an unknown name."""
    parser = argparse.ArgumentParser(prog="python -m reports.manual_tables",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help=f"tables (default: all of {list(TABLES)})")
    parser.add_argument("--docs", default="docs/results",
                        help="folder of the pages (default: docs/results)")
    parser.add_argument("--workers", type=int, default=2, help="processes (default: 2)")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.names) - set(TABLES))
    if unknown:
        print(f"manual_tables: error: unknown table(s) {unknown}; tables: {list(TABLES)}",
              file=sys.stderr)
        return 2
    for name in args.names or list(TABLES):
        print(f"wrote {write_table(name, Path(args.docs), args.workers)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
