"""Wall time of the main job, ``ipp-compare`` on defaults (run by hand).

    python benchmarks/compare_wall.py            # bare ipp-compare, then the pinned planners
    python benchmarks/compare_wall.py --repeat 2

Runs, each into a fresh temporary folder (nothing is resumed):
  bare     ``ipp-compare`` (the quick start: the default planners, 50 test missions,
           4 UAVs, D = 25 m, r_M = 0.1 m, 2 workers);
  pinned   ``ipp-compare --planners ig,coverage,random,coma,ppo --agents 4 --comm 25``,
           the same list written out, so the figure does not move when the defaults do.
Prints the wall seconds and the CPU seconds of every process (user + system, workers
included) per run. Measure on an otherwise idle machine: a second job on a 2-core machine
takes the core one evaluation worker needs.
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

RUNS = {
    "bare": [],
    "pinned": ["--planners", "ig,coverage,random,coma,ppo", "--agents", "4", "--comm", "25"],
}


def timed(args: list[str]) -> tuple[float, float]:
    """(wall, CPU) seconds of one ipp-compare run with ``args`` into a fresh folder."""
    out = tempfile.mkdtemp(prefix="compare-wall-")
    try:
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        command = ("import sys; from reports.cli import compare_main; "
                   "sys.exit(compare_main(sys.argv[1:]))")
        subprocess.run([sys.executable, "-c", command, *args, "--out", out, "--no-progress"],
                       check=True, stdout=subprocess.DEVNULL)
        wall = time.perf_counter() - start
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        return wall, cpu
    finally:
        shutil.rmtree(out, ignore_errors=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--runs", default="bare,pinned", help="comma-separated: bare, pinned")
    args = parser.parse_args()
    print(f"ipp-compare on {os.cpu_count()} CPUs; wall and CPU seconds (all processes)")
    for name in args.runs.split(","):
        for _ in range(args.repeat):
            wall, cpu = timed(RUNS[name])
            print(f"{name:7s} wall {wall:6.1f} s   CPU {cpu:6.1f} s")


if __name__ == "__main__":
    main()
