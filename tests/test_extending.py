"""Every ``python`` block of docs/extending.md runs as written (each in a fresh interpreter)."""

from __future__ import annotations

import configparser
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "extending.md"
BLOCKS = re.findall(r"```python\n(.*?)```", PAGE.read_text(encoding="utf-8"), flags=re.S)
TOML_BLOCKS = re.findall(r"```toml\n(.*?)```", PAGE.read_text(encoding="utf-8"), flags=re.S)


def test_the_page_has_its_recipes():
    assert len(BLOCKS) >= 3


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_a_recipe_runs(index, tmp_path):
    done = subprocess.run([sys.executable, "-c", BLOCKS[index]], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip()


def test_the_package_recipe_names_the_groups_the_toolkit_reads():
    """The pyproject.toml of the entry-point recipes installs as written (a build system, a
    project) and names the groups that ipp-compare and the terrain registry read."""
    from ipp_toolkit.planning import ENTRY_POINT_GROUP as PLANNER_GROUP
    from ipp_toolkit.world.terrain import ENTRY_POINT_GROUP as TERRAIN_GROUP

    files = [tomllib.loads(block) for block in TOML_BLOCKS]
    assert files and "build-system" in files[0] and "name" in files[0]["project"]
    groups: dict[str, dict[str, str]] = {}
    for data in files:
        groups.update(data.get("project", {}).get("entry-points", {}))
    assert groups == {PLANNER_GROUP: {"always-first": "my_planners.simple:AlwaysFirst"},
                      TERRAIN_GROUP: {"stripes": "my_planners.terrains:stripes"}}


def test_the_page_says_what_a_planner_added_inside_a_checkout_needs():
    """The toolkit's own planners are entry points of setup.cfg, and finding the names loads
    no planner module: a module added to the tree is unknown until its entry point is
    installed (or something imports it), as the page says."""
    from ipp_toolkit.planning import ENTRY_POINT_GROUP

    config = configparser.ConfigParser()
    config.read(ROOT / "setup.cfg", encoding="utf-8")
    assert "baselines.heuristics.information_gain:InformationGainPlanner" in \
        config["options.entry_points"][ENTRY_POINT_GROUP]
    script = ("import sys; import reports.cli; from ipp_toolkit.planning import "
              "available_planners; assert 'ig' in available_planners(); "
              "print(sorted(m for m in sys.modules if m.split('.')[0] in "
              "('baselines', 'coma')))")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0 and done.stdout.strip() == "[]", done.stderr[-2000:]
    text = " ".join(PAGE.read_text(encoding="utf-8").split())
    start = text.index("The toolkit's own planners are found the same way")
    paragraph = text[start:text.index("`IPP_TOOLKIT_NO_PLUGINS=1`", start)]
    for needed in ("A planner added inside a checkout", "`setup.cfg`", f"`{ENTRY_POINT_GROUP}`",
                   "`[options.entry_points]`", "installed again (`pip install -e .`",
                   "`register_planner`"):
        assert needed in paragraph, needed
