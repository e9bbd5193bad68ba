"""The names a terrain config may use: the terrain kinds and the bundled real rasters.

:data:`TERRAIN_GENERATORS` maps each kind to its generator. The built-in kinds register
themselves when :mod:`ipp_toolkit.world` is imported (its ``__init__`` imports
:mod:`~ipp_toolkit.world.terrain` and :mod:`~ipp_toolkit.world.families`, so they are registered
wherever any module of the package is used); :func:`register_terrain` adds one, and installed
packages add theirs by entry point in the group :data:`ENTRY_POINT_GROUP`
(``name = module:function``), read on a process's first lookup
(:func:`load_entry_point_terrains`). :func:`real_raster_names` lists the bundled rasters of
``ipp_toolkit/data/rasters``.

This module imports nothing of the toolkit but :mod:`ipp_toolkit.plugins` (which imports
nothing of it): the config checks names against it
(:func:`ipp_toolkit.config.schema.terrain_kinds`) without an import circle.
"""

from __future__ import annotations

import functools
import json
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..plugins import entry_points

__all__ = ["ENTRY_POINT_GROUP", "TERRAIN_GENERATORS", "RASTER_FOLDER", "register_terrain",
           "load_entry_point_terrains", "takes_namespace", "raster_manifest", "real_raster_names"]

TERRAIN_GENERATORS: dict[str, Callable[..., Any]] = {}
"""Terrain kind -> generator; :func:`ipp_toolkit.world.terrain.generate_terrain` dispatches on
``config.kind``."""

ENTRY_POINT_GROUP = "ipp_toolkit.terrains"
"""The entry-point group of terrains from installed packages: ``kind = module:function``."""

RASTER_FOLDER = Path(__file__).resolve().parents[1] / "data" / "rasters"
"""The bundled real rasters and their list, ``sources.json``."""


def register_terrain(name: str, *, replace: bool = False, namespaced: bool = False
                     ) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Decorator adding a terrain generator under ``name`` to :data:`TERRAIN_GENERATORS`.

    The generator is called as ``fn(config, world, rng, raster)`` and must return an
    (H, W) array (H = W = ``world.map_cells``) that is cast to bool; with ``namespaced`` it
    also gets the mission's namespace as ``namespace=`` (``train``, ``validation`` or
    ``test``), e.g. to draw from separate data. Registering a taken name is an error unless
    ``replace`` is true, so a typo cannot silently shadow a built-in.
    """
    if not isinstance(name, str) or not name:
        raise ValueError(f"terrain kind must be a non-empty string, got {name!r}")

    def decorator(fn: Callable[..., Any]) -> Callable[..., Any]:
        if name in TERRAIN_GENERATORS and not replace:
            raise ValueError(f"terrain kind {name!r} is already registered; "
                             "pass replace=True to override it")
        TERRAIN_GENERATORS[name] = fn
        _NAMESPACED.discard(name)
        if namespaced:
            _NAMESPACED.add(name)
        return fn

    return decorator


_NAMESPACED: set[str] = set()
_ENTRY_POINTS_READ = False


def load_entry_point_terrains() -> None:
    """Register the terrains of the entry-point group :data:`ENTRY_POINT_GROUP`, once per
    process (every lookup of the kinds calls it: :func:`ipp_toolkit.config.schema.terrain_kinds`,
    :func:`ipp_toolkit.world.terrain.generate_terrain`).

    This is what makes a package's terrain known in worker processes, which never run the
    script that registered one by decorator. Each entry point's module is imported; its
    object is registered under the entry point's name unless the module registered it
    already (with :func:`register_terrain`, e.g. ``namespaced=True``). A module that fails
    to import, or a name taken by another generator, is skipped with a warning: the other
    kinds stay usable.
    """
    global _ENTRY_POINTS_READ
    if _ENTRY_POINTS_READ:
        return
    _ENTRY_POINTS_READ = True  # first: a module that builds a config looks the kinds up again
    # Through ipp_toolkit.plugins: IPP_TOOLKIT_NO_PLUGINS=1 keeps only the toolkit's own.
    for entry in entry_points(ENTRY_POINT_GROUP):
        try:
            generator = entry.load()
        except Exception as err:  # noqa: BLE001 - one broken package must not hide the others
            warnings.warn(f"terrain entry point {entry.name!r} ({entry.value}) cannot be "
                          f"loaded: {err}", RuntimeWarning, stacklevel=2)
            continue
        registered = TERRAIN_GENERATORS.get(entry.name)
        if registered is None:
            register_terrain(entry.name)(generator)
        elif registered is not generator:
            owner = (f"{getattr(registered, '__module__', '?')}."
                     f"{getattr(registered, '__qualname__', registered)}")
            warnings.warn(f"terrain entry point {entry.name!r} ({entry.value}) is skipped: "
                          f"the kind is registered by {owner}", RuntimeWarning, stacklevel=2)


def takes_namespace(kind: str) -> bool:
    """Whether the generator of ``kind`` was registered with ``namespaced=True`` (it is called
    with the mission's ``namespace=``)."""
    return kind in _NAMESPACED


@functools.lru_cache(maxsize=1)
def raster_manifest() -> tuple[dict, ...]:
    manifest = RASTER_FOLDER / "sources.json"
    try:
        return tuple(json.loads(manifest.read_text()))
    except (OSError, json.JSONDecodeError) as err:
        raise ValueError(f"cannot read the bundled raster list {str(manifest)!r}: {err}") from None


def real_raster_names(split: str = "all") -> tuple[str, ...]:
    """Names of the bundled real rasters (of one split: train, validation, test, or all)."""
    return tuple(e["name"] for e in raster_manifest() if split in ("all", e["split"]))
