"""Shared fixtures; the helpers the test modules import are in helpers.py."""

from __future__ import annotations

import os
from pathlib import Path

# Only the toolkit's own entry points (its built-in planners): planners and terrains of other
# installed packages (a plug-in built from docs/extending.md, say) would change what the
# registries list and refuse. Set before the toolkit is imported; every process the tests
# start inherits it. Tests of plug-ins set it to 0 where they need them.
os.environ["IPP_TOOLKIT_NO_PLUGINS"] = "1"

import pytest
from helpers import small_config

from ipp_toolkit.config.schema import EnvConfig


@pytest.fixture
def config() -> EnvConfig:
    return small_config()


@pytest.fixture
def placeholder_figures(monkeypatch) -> None:
    """Figures are built, but each file of one is a placeholder, written (atomically) where
    the figure would be: their layout and rendering are most of a small run's time. For
    tests of a run's tables, results, refusals and of when a figure is drawn again;
    tests/test_reports.py and the end-to-end test of tests/test_cli.py render them."""
    import importlib

    from ipp_toolkit.io import atomic_write
    from reports.plots import FORMATS

    def placeholder(figure, stem, formats=FORMATS, dpi=150):
        paths = [Path(f"{stem}.{fmt}") for fmt in formats]
        for path in paths:
            atomic_write(path, lambda handle: handle.write(b"placeholder figure\n"))
        return paths

    # Every module imported before any is patched: one imported later would take the
    # placeholder for good (``from .plots import save_figure``).
    modules = [importlib.import_module(f"reports.{name}")
               for name in ("plots", "generalisation", "studies", "training")]
    for module in modules:
        monkeypatch.setattr(module, "save_figure", placeholder)
