"""The terrain registry is the one owner of the terrain kinds: the config's checks, the CLI's
help and its error messages read them from it."""

from __future__ import annotations

import re
from pathlib import Path

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


ROOT = Path(__file__).resolve().parents[1]


def _toolkit_kinds() -> set[str]:
    """The kinds the toolkit itself registers (a test's or a user's own are not documented)."""
    return {kind for kind, generator in terrain.TERRAIN_GENERATORS.items()
            if generator.__module__.startswith("ipp_toolkit.")}


def _named(text: str) -> set[str]:
    """The words in backticks that look like terrain kinds."""
    return {word for word in re.findall(r"`([^`]+)`", text)
            if re.fullmatch(r"[a-z][a-z0-9_-]*", word)}


def _from(text: str, start: str, end: str) -> str:
    """``text`` from the first ``start`` to the next ``end`` after it."""
    first = text.index(start)
    return text[first:text.index(end, first + len(start))]


def test_the_docs_list_every_terrain_kind():
    kinds = _toolkit_kinds()
    assert {"split", "fractal", "raster"} <= kinds
    readme = _named(_from((ROOT / "README.md").read_text(encoding="utf-8"),
                          "Terrain kinds (`terrain.kind`):", "\n\n"))
    assert readme == kinds, "README's list of terrain kinds is not the registry's"
    page = (ROOT / "docs" / "environment.md").read_text(encoding="utf-8")
    listed = (_named(_from(page, "Terrains:", "\n\n"))
              | _named(_from(page, "## Terrain families", "\n## ")))
    missing = kinds - listed
    assert not missing, f"docs/environment.md does not describe the terrain kinds {missing}"
