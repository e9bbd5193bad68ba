"""Wall time of every command's ``--help`` in a fresh interpreter (run by hand).

    python benchmarks/help_time.py              # best of 3 runs per command
    python benchmarks/help_time.py --runs 5

``--help`` should answer within a second: the parsers are built without importing torch, SB3
or Ray (``tests/test_help_defaults.py`` checks that; this prints the seconds, which depend on
the machine and its load). Prints one line per command: its fastest run and whether the
interpreter had imported torch by the time it exited.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

COMMANDS = {
    "ipp-simulate": "simulate_main([])",
    "ipp-compare": "compare_main([])",
    "ipp-study": "study_main([])",
    "ipp-train coma": "train_main(['coma'])",
    "ipp-train ppo": "train_main(['ppo'])",
    "ipp-train sb3": "train_main(['sb3'])",
    "ipp-train prior": "train_main(['prior'])",
    "ipp-train rllib": "train_main(['rllib'])",
}


def time_help(call: str) -> tuple[float, bool]:
    """Seconds of one ``--help`` in a fresh interpreter, and whether it imported torch."""
    args = call.replace("[])", "['--help'])").replace("'])", "', '--help'])")
    code = ("import sys, atexit\n"
            "atexit.register(lambda: print('torch' in sys.modules, file=sys.stderr))\n"
            "from reports.cli import compare_main, simulate_main, study_main, train_main\n"
            f"try:\n    {args}\nexcept SystemExit:\n    pass\n")
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, check=False)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"{call}: exit {done.returncode}\n{done.stderr[-2000:]}")
    return seconds, done.stderr.strip().splitlines()[-1] == "True"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3, help="runs per command (default: 3)")
    args = parser.parse_args()
    if args.runs < 1:
        parser.error("--runs must be >= 1")
    for name, call in COMMANDS.items():
        results = [time_help(call) for _ in range(args.runs)]
        best = min(seconds for seconds, _ in results)
        torch = any(imported for _, imported in results)
        print(f"{name + ' --help':<24} {best:6.2f} s  (best of {args.runs}; torch imported: "
              f"{'yes' if torch else 'no'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
