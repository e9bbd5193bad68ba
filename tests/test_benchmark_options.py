"""Bad options of the hand-run benchmarks are refused before anything runs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_compare_wall_refuses_a_reference_that_is_not_a_source_tree(tmp_path):
    missing = tmp_path / "not-a-tree"
    done = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "compare_wall.py"),
                           "--runs", "bare", "--reference", str(missing)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert str(missing) in done.stderr and "not a source tree" in done.stderr
