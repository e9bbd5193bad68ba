"""The terrain registry is the one owner of the terrain kinds: the config's checks, the CLI's
help and its error messages read them from it."""

from __future__ import annotations

import numpy as np

from ipp_toolkit import EnvConfig
from ipp_toolkit.config.schema import terrain_kinds
from ipp_toolkit.config.settings import named_terrain_kinds
from ipp_toolkit.world import terrain


def test_a_registered_terrain_is_a_kind_everywhere(monkeypatch):
    def stripes(config, world, rng, raster):
        cells = np.arange(world.map_cells)
        return np.broadcast_to((cells // 10) % 2 == 0, (world.map_cells, world.map_cells))

    monkeypatch.setitem(terrain.TERRAIN_GENERATORS, "stripes", stripes)
    assert "stripes" in terrain_kinds() and "stripes" in named_terrain_kinds()
    assert EnvConfig().replace(terrain={"kind": "stripes"}).terrain.kind == "stripes"
    from reports.cli import _compare_parser

    assert "stripes" in " ".join(_compare_parser().format_help().split())


def test_the_kinds_are_the_registry_s_names():
    assert terrain_kinds() == tuple(terrain.TERRAIN_GENERATORS)
    assert "raster" in terrain_kinds() and "raster" not in named_terrain_kinds()
