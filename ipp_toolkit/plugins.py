"""The entry points the registries read: every installed package's, or the toolkit's own.

The planner registry (:mod:`ipp_toolkit.planning`, group ``ipp_toolkit.planners``) and the
terrain registry (:mod:`ipp_toolkit.world.registry`, group ``ipp_toolkit.terrains``) find
installed planners and terrains through :func:`entry_points`. With ``IPP_TOOLKIT_NO_PLUGINS=1``
in the environment they see only the entry points of the toolkit's own distribution
(:data:`DISTRIBUTION`, its built-in planners), so a run, and the toolkit's test suite, which
sets it, behave the same whatever other packages are installed. The variable is read at each
lookup (the terrain registry looks once per process) and worker processes inherit it.

This module imports nothing of the toolkit (the terrain registry, which must not, imports it).
"""

from __future__ import annotations

import os
import re
from importlib import metadata

__all__ = ["DISTRIBUTION", "NO_PLUGINS_VARIABLE", "plugins_enabled", "entry_points"]

DISTRIBUTION = "ipp-marl-toolkit"
"""The toolkit's distribution name (setup.cfg), whose entry points are always read."""

NO_PLUGINS_VARIABLE = "IPP_TOOLKIT_NO_PLUGINS"
"""Set to ``1`` to ignore the entry points of every other installed package."""


def plugins_enabled() -> bool:
    """Whether other packages' entry points are read (``IPP_TOOLKIT_NO_PLUGINS`` unset, empty
    or ``0``)."""
    return os.environ.get(NO_PLUGINS_VARIABLE, "") in ("", "0")


def _normalised(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()  # as pip compares distribution names


def entry_points(group: str) -> list[metadata.EntryPoint]:
    """The entry points of ``group``: of every installed package, or, with plug-ins off
    (:func:`plugins_enabled`), only those of the toolkit's own distribution."""
    entries = list(metadata.entry_points(group=group))
    if plugins_enabled():
        return entries
    return [entry for entry in entries
            if entry.dist is not None and _normalised(entry.dist.name) == DISTRIBUTION]
