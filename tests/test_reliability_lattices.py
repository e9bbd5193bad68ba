"""The fractal terrain's lattice is bounded as the blobs' is: an area whose periodic lattice
(1 m spacing, twice the area's side) would take gigabytes is refused, naming
``world.area_size``, before anything is allocated: from a config, a YAML file, the command
line, and a direct call of the terrain generator."""

from __future__ import annotations

import re

import numpy as np
import pytest

import ipp_toolkit.world.families as families
from ipp_toolkit.config.schema import EnvConfig, TerrainConfig, WorldConfig
from ipp_toolkit.config.terrain_checks import MAX_LATTICE_NODES, fractal_area_limit
from ipp_toolkit.world.terrain import generate_terrain
from reports.cli import compare_main

# A 20 km area at 20 m cells is a small map (1000 x 1000) with 21 x 21 waypoints, but its
# fractal lattice would be 40,002 x 40,002 float64 nodes: 12.8 GB per array.
HUGE = {"area_size": 20000.0, "resolution": 20.0, "grid_spacing": 1000.0}
RANDOM_STARTS = {"start": "random"}  # the paper's fixed starts lie in its 50 m area


class _NoLattice:
    """A terrain stream that fails the test if the lattice's noise is ever drawn."""

    def uniform(self, low: float, high: float) -> float:
        return (low + high) / 2

    def standard_normal(self, shape: tuple[int, ...]) -> np.ndarray:
        raise AssertionError(f"the fractal lattice {shape} was allocated")


@pytest.fixture
def no_fractal_field(monkeypatch):
    """Every fractal field fails the test: the refusal must come before one is drawn."""
    def allocated(*args, **kwargs):
        raise AssertionError("a fractal field was drawn")

    monkeypatch.setattr(families, "fractal_field", allocated)


@pytest.mark.parametrize("terrain", [{"kind": "fractal"},
                                     {"kind": "mixture", "mixture": {"fractal": 1, "split": 1}}])
def test_a_fractal_area_whose_lattice_would_take_gigabytes_is_refused(terrain):
    with pytest.raises(ValueError, match=re.escape("world.area_size = 20000.0")) as err:
        EnvConfig(world=HUGE, terrain=terrain, team=RANDOM_STARTS)
    message = str(err.value)
    assert "40002 nodes per side" in message and f"more than {MAX_LATTICE_NODES}" in message
    assert "up to 4095 m" in message
    EnvConfig(world=HUGE, terrain={"kind": "split"}, team=RANDOM_STARTS)  # no lattice


def test_the_largest_fractal_area_is_accepted_and_one_metre_more_is_refused():
    assert fractal_area_limit() == 4095.0
    # 1000 cells and 10 waypoint steps per side, whatever the area
    EnvConfig(world={"area_size": 4095.0, "resolution": 4.095, "grid_spacing": 409.5},
              terrain={"kind": "fractal"}, team=RANDOM_STARTS)
    with pytest.raises(ValueError, match=re.escape("world.area_size = 4096.0")):
        EnvConfig(world={"area_size": 4096.0, "resolution": 4.096, "grid_spacing": 409.6},
                  terrain={"kind": "fractal"}, team=RANDOM_STARTS)


def test_the_terrain_generator_refuses_the_lattice_before_drawing_it():
    # A WorldConfig alone does not know its terrain, so the config's check never ran here.
    with pytest.raises(ValueError, match=re.escape("world.area_size = 20000.0")):
        generate_terrain(TerrainConfig(kind="fractal"), WorldConfig(**HUGE), _NoLattice())


def test_the_command_line_names_the_area_from_a_flag_and_from_a_file(tmp_path, capsys,
                                                                     no_fractal_field):
    out = tmp_path / "out"
    # One mission in this process, where a field drawn by mistake fails on the fixture.
    run = ["--planners", "random", "--trials", "1", "--workers", "1", "--out", str(out),
           "--no-progress"]
    flags = ["--area-size", "20000", "--resolution", "20", "--grid-spacing", "1000"]
    assert compare_main(["--terrain", "fractal", *flags, "--agents", "3", *run]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "world.area_size = 20000.0" in err
    config = tmp_path / "fractal.yaml"
    config.write_text("world: {area_size: 20000.0, resolution: 20.0, grid_spacing: 1000.0}\n"
                      "terrain: {kind: fractal}\nteam: {start: random}\n")
    assert compare_main(["--config", str(config), *run]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "world.area_size = 20000.0" in err
    assert str(config) in err
    assert not out.exists()
