"""A package's planner and terrain, declared by entry point, fly in worker processes.

The package here is installed the cheapest way importlib.metadata knows: a
``NAME.dist-info`` folder (METADATA and entry_points.txt) beside the package on the path.
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

PLUGIN = '''
import os

import numpy as np

from ipp_toolkit.planning import Planner


def _mark(kind):
    # One file per process and kind: which processes flew the planner or drew the terrain.
    folder = os.environ["PLUGIN_MARKS"]
    open(os.path.join(folder, f"{kind}-{os.getpid()}"), "w").close()


class FirstValid(Planner):
    needs_observations = False

    def act(self, views):
        _mark("planner")
        return np.array([int(np.flatnonzero(view.mask)[0]) for view in views])


def stripes(config, world, rng, raster):
    _mark("terrain")
    cells = np.arange(world.map_cells)
    return np.broadcast_to((cells // 4) % 2 == 0, (world.map_cells, world.map_cells))
'''

ENTRY_POINTS = """
[ipp_toolkit.planners]
first-valid = my_plugin.plugin:FirstValid

[ipp_toolkit.terrains]
stripes-plugin = my_plugin.plugin:stripes
"""

RUN = """
import os, sys
from reports.cli import compare_main
print("main", os.getpid())
sys.exit(compare_main(sys.argv[1:]))
"""


def _install(site: Path) -> None:
    package = site / "my_plugin"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "plugin.py").write_text(textwrap.dedent(PLUGIN))
    info = site / "my_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: my-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(ENTRY_POINTS)


# Slow: an installed package in fresh processes. Fast: entry-point planners in a pool's
# workers (tests/test_evaluation.py), a registered terrain (tests/test_registry_names.py).
@pytest.mark.slow
def test_an_installed_planner_and_terrain_fly_in_worker_processes(tmp_path):
    site, marks, out = tmp_path / "site", tmp_path / "marks", tmp_path / "out"
    _install(site)
    marks.mkdir()
    path = os.pathsep.join([str(site), str(ROOT), os.environ.get("PYTHONPATH", "")])
    env = {**os.environ, "PYTHONPATH": path, "PLUGIN_MARKS": str(marks),
           "IPP_TOOLKIT_NO_PLUGINS": "0"}  # the suite's own processes see no plug-ins
    argv = ["--planners", "first-valid,random", "--terrain", "stripes-plugin", "--workers", "2",
            "--trials", "1", "--agents", "2", "--resolution", "1.0", "--budget", "3",
            "--no-progress", "--out", str(out)]
    done = subprocess.run([sys.executable, "-c", RUN, *argv], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    main = int(done.stdout.split()[1])
    with open(out / "results.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert {row["planner"] for row in rows} == {"first-valid", "random"}
    assert {row["terrain"] for row in rows} == {"stripes-plugin"}
    for kind in ("planner", "terrain"):
        pids = {int(mark.name.split("-")[1]) for mark in marks.glob(f"{kind}-*")}
        assert pids - {main}, f"the {kind} ran in no worker process: {pids}, main {main}"
