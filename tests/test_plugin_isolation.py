"""The test suite is isolated from installed plug-ins: with the package of docs/extending.md
installed (its ``always-first`` planner and ``stripes`` terrain), the registries of the suite's
processes list only the toolkit's own, and the checks that a plug-in broke pass.

The package is installed the cheapest way importlib.metadata knows: a ``NAME.dist-info``
folder (METADATA and entry_points.txt) beside the package on the path.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pytest

from ipp_toolkit import plugins
from ipp_toolkit.planning import ENTRY_POINT_GROUP as PLANNER_GROUP
from ipp_toolkit.planning import available_planners, entry_point_planners
from ipp_toolkit.world.registry import ENTRY_POINT_GROUP as TERRAIN_GROUP

ROOT = Path(__file__).resolve().parents[1]

MODULES = {
    "simple.py": '''
        import numpy as np

        from ipp_toolkit.planning import Planner, register_planner


        @register_planner("always-first")
        class AlwaysFirst(Planner):
            needs_observations = False

            def act(self, views):
                return np.array([np.flatnonzero(v.mask)[0] for v in views])
    ''',
    "terrains.py": '''
        import numpy as np

        from ipp_toolkit.world.terrain import register_terrain


        @register_terrain("stripes", replace=True)
        def stripes(config, world, rng, raster):
            width = rng.integers(5, 15)
            cells = np.arange(world.map_cells)
            return np.broadcast_to((cells // width) % 2 == 0,
                                   (world.map_cells, world.map_cells))
    ''',
}


def _docs_entry_points() -> str:
    """entry_points.txt of the package the page describes, from its ``toml`` blocks."""
    page = (ROOT / "docs" / "extending.md").read_text(encoding="utf-8")
    lines = []
    for block in re.findall(r"```toml\n(.*?)```", page, flags=re.S):
        for group, entries in tomllib.loads(block).get("project", {}).get(
                "entry-points", {}).items():
            lines += [f"[{group}]", *(f"{name} = {value}" for name, value in entries.items()), ""]
    return "\n".join(lines)


@pytest.fixture
def docs_plugin(tmp_path: Path) -> Path:
    """A site folder holding the docs' ``my-planners`` package, installed."""
    site = tmp_path / "site"
    package = site / "my_planners"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    for name, source in MODULES.items():
        (package / name).write_text(textwrap.dedent(source))
    info = site / "my_planners-0.1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: my-planners\nVersion: 0.1.0\n")
    entry_points = _docs_entry_points()
    assert "always-first = my_planners.simple:AlwaysFirst" in entry_points
    assert "stripes = my_planners.terrains:stripes" in entry_points
    (info / "entry_points.txt").write_text(entry_points)
    return site


def test_the_suite_runs_without_plug_ins():
    assert os.environ.get(plugins.NO_PLUGINS_VARIABLE) == "1"  # tests/conftest.py
    assert not plugins.plugins_enabled()


def test_an_installed_plug_in_is_seen_only_with_plug_ins_on(docs_plugin, monkeypatch):
    monkeypatch.syspath_prepend(str(docs_plugin))
    builtin = set(entry_point_planners())
    assert "always-first" not in available_planners()
    assert "stripes" not in {entry.name for entry in plugins.entry_points(TERRAIN_GROUP)}
    # The same lookups with plug-ins on: the package is installed, as a user's would be.
    monkeypatch.setenv(plugins.NO_PLUGINS_VARIABLE, "0")
    assert set(entry_point_planners()) == builtin | {"always-first"}
    assert "stripes" in {entry.name for entry in plugins.entry_points(TERRAIN_GROUP)}
    assert "always-first" in {entry.name for entry in plugins.entry_points(PLANNER_GROUP)}


# The checks the installed plug-in broke: a test terrain named like the plug-in's ("already
# registered", or replaced by it on the first lookup), and the docs recipe that registers
# always-first by decorator ("taken by the installed planner").
AFFECTED = ["tests/test_terrain.py::test_register_terrain_and_dispatch",
            "tests/test_registry_names.py::test_a_registered_terrain_is_a_kind_everywhere",
            "tests/test_extending.py::test_a_recipe_runs[0]"]


def test_the_checks_a_plug_in_broke_pass_with_it_installed(docs_plugin):
    # A fresh pytest, as a developer with the plug-in installed runs it: the variable comes
    # from the suite's conftest, not from this process.
    env = {key: value for key, value in os.environ.items()
           if key != plugins.NO_PLUGINS_VARIABLE}
    env["PYTHONPATH"] = os.pathsep.join([str(docs_plugin), str(ROOT),
                                         os.environ.get("PYTHONPATH", "")])
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           *AFFECTED], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-2000:]
    assert f"{len(AFFECTED)} passed" in done.stdout
