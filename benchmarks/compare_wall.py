"""Wall time of the main job, ``ipp-compare`` on defaults (run by hand).

    python benchmarks/compare_wall.py            # bare ipp-compare, then the pinned planners
    python benchmarks/compare_wall.py --repeat 3 --runs bare --phases

Runs, each into a fresh temporary folder (nothing is resumed):
  bare     ``ipp-compare`` (the quick start: the default planners, 50 test missions,
           4 UAVs, D = 25 m, r_M = 0.1 m, 2 workers);
  pinned   ``ipp-compare --planners ig,coverage,random,coma,ppo --agents 4 --comm 25``,
           the same list written out, so the figure does not move when the defaults do.
Prints the wall seconds and the CPU seconds of every process (user + system, workers
included) per run. It runs the console script beside this Python (as the quick start does:
the spawned workers import the script's module, which ``python -c`` would spare them), else
the same entry point through ``python -c``. ``--phases`` splits each run's wall time by the
output files' times: start-up (until the first mission is stored: imports, the planners'
checks, the workers' start), the missions (until the last one is stored) and the end (the
workers' exit, the tables, the curves, the process's exit).

Measure on an otherwise idle machine: a second job on a 2-core machine takes the core one
evaluation worker needs. ``PYTHONPATH=OTHER_TREE python benchmarks/compare_wall.py`` times
another tree (e.g. a ``git archive`` of an older commit) with the same virtual environment.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

RUNS = {
    "bare": [],
    "pinned": ["--planners", "ig,coverage,random,coma,ppo", "--agents", "4", "--comm", "25"],
}


def command() -> list[str]:
    """The ``ipp-compare`` console script beside this interpreter, else its entry point."""
    script = Path(sys.executable).with_name("ipp-compare")
    if script.is_file():
        return [sys.executable, str(script)]
    return [sys.executable, "-c",
            "import sys; from reports.cli import compare_main; sys.exit(compare_main())"]


def phases(out: Path, start: float, end: float) -> tuple[float, float, float]:
    """(start-up, missions, end) seconds of a run into ``out`` from its files' times."""
    stored = [p.stat().st_mtime for p in (out / "shards").rglob("mission_*.json")]
    first, last = min(stored) - start, max(stored) - start
    return first, last - first, end - start - last


def timed(args: list[str], show_phases: bool = False) -> tuple[float, float, str]:
    """(wall, CPU, phases text) of one ipp-compare run with ``args`` into a fresh folder."""
    out = Path(tempfile.mkdtemp(prefix="compare-wall-"))
    try:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start_epoch, start = time.time(), time.perf_counter()
        subprocess.run([*command(), *args, "--out", str(out), "--no-progress"],
                       check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        text = ""
        if show_phases:
            first, missions, end = phases(out, start_epoch, start_epoch + wall)
            text = f"   start-up {first:5.1f} s, missions {missions:5.1f} s, end {end:4.1f} s"
        return wall, cpu, text
    finally:
        shutil.rmtree(out, ignore_errors=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--runs", default="bare,pinned", help="comma-separated: bare, pinned")
    parser.add_argument("--phases", action="store_true",
                        help="also split each run into start-up, missions and end")
    args = parser.parse_args()
    print(f"ipp-compare on {os.cpu_count()} CPUs; wall and CPU seconds (all processes)")
    for name in args.runs.split(","):
        for _ in range(args.repeat):
            load = os.getloadavg()[0]
            wall, cpu, text = timed(RUNS[name], args.phases)
            print(f"{name:7s} wall {wall:6.1f} s   CPU {cpu:6.1f} s   (load before {load:.2f})"
                  + text, flush=True)


if __name__ == "__main__":
    main()
