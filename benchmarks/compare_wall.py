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
evaluation worker needs. Where the machine's speed drifts (shared virtual machines), time
against a fixed reference in the same minutes: ``--reference TREE`` alternates every run
with the same run of another source tree's code (e.g. ``git worktree add /tmp/ref HEAD~1``)
in the same virtual environment and prints the ratio. The reference finds its planners through
this environment's entry points, so it must keep its planner modules where this tree keeps them:
a tree from before the planners moved into ``baselines/heuristics`` and its siblings (e.g.
e7668be, the last five-planner default) flies only the planners it can find there, and needs a
virtual environment of its own to be measured.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import statistics
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


def timed(args: list[str], show_phases: bool = False, tree: Path | None = None
          ) -> tuple[float, float, str]:
    """(wall, CPU, phases text) of one ipp-compare run with ``args`` into a fresh folder;
    with ``tree``, of that source tree's code (first on ``PYTHONPATH``)."""
    out = Path(tempfile.mkdtemp(prefix="compare-wall-"))
    try:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start_epoch, start = time.time(), time.perf_counter()
        env = None
        if tree is not None:
            env = dict(os.environ, PYTHONPATH=os.pathsep.join(
                [str(tree), *filter(None, [os.environ.get("PYTHONPATH")])]))
        subprocess.run([*command(), *args, "--out", str(out), "--no-progress"],
                       check=True, stdout=subprocess.DEVNULL, env=env)
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
    parser.add_argument("--reference", type=Path, default=None, metavar="TREE",
                        help="another source tree (e.g. a git worktree of an older commit): "
                             "every run alternates with the same run of its code, and the "
                             "ratio of the medians is printed")
    args = parser.parse_args()
    if args.reference is not None and not (args.reference / "reports" / "cli.py").is_file():
        parser.error(f"--reference {args.reference}: not a source tree of the toolkit "
                     "(no reports/cli.py)")
    print(f"ipp-compare on {os.cpu_count()} CPUs; wall and CPU seconds (all processes)")
    trees: list[tuple[str, Path | None]] = [("", None)]
    if args.reference is not None:
        trees.append((" (reference)", args.reference.resolve()))
    for name in args.runs.split(","):
        walls: dict[str, list[float]] = {label: [] for label, _ in trees}
        for _ in range(args.repeat):
            for label, tree in trees:
                load = os.getloadavg()[0]
                wall, cpu, text = timed(RUNS[name], args.phases, tree)
                walls[label].append(wall)
                print(f"{name + label:19s} wall {wall:6.1f} s   CPU {cpu:6.1f} s   "
                      f"(load before {load:.2f})" + text, flush=True)
        if args.reference is not None:
            ratio = statistics.median(walls[""]) / statistics.median(walls[" (reference)"])
            print(f"{name}: this tree takes {ratio:.2f} times the reference's wall time "
                  "(medians)", flush=True)


if __name__ == "__main__":
    main()
