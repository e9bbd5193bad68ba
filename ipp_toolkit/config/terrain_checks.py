"""Checks of terrain fields for :mod:`ipp_toolkit.config.schema`: a range given as a number
or a pair (:func:`terrain_range`) and the lattices the ``blobs`` and ``fractal`` terrains
imply, bounded before a mission is built.

:func:`ipp_toolkit.world.terrain.blob_field` draws white noise on a lattice in metres (1 m
spacing, ``blob_scale / 2`` below 2 m), padded by 5 kernel stds on each side, and smooths it
with an FFT. A ``terrain.blob_scale`` far below a map's cells (1e-6 m, 0.002 m) makes that
lattice too fine, one far above the map (1e6 m) pads it too wide: either exhausts memory or
time. :func:`check_blob_lattice` refuses both with the range of ``blob_scale`` the map allows.

:func:`ipp_toolkit.world.families.fractal_field` draws white noise on a periodic lattice of
1 m spacing twice the area's side and filters it with an FFT: its size follows from
``world.area_size`` alone (a 20 km area asks for 40,002 x 40,002 nodes, 12.8 GB per array).
:func:`check_fractal_lattice` refuses an area whose lattice exceeds the same bound, naming
the largest area the ``fractal`` kind allows.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from .field_types import short_repr

if TYPE_CHECKING:
    from .schema import TerrainConfig, WorldConfig

__all__ = ["BLOB_LATTICE_SPACING", "BLOB_PADDING_SIGMAS", "FRACTAL_LATTICE_SPACING",
           "MAX_LATTICE_NODES", "blob_lattice", "blob_scale_range", "check_blob_lattice",
           "check_fractal_lattice", "drawn_kinds", "fractal_area_limit", "fractal_lattice",
           "terrain_range"]

BLOB_LATTICE_SPACING = 1.0  # metres; finer only when blob_scale is below 2 spacings
BLOB_PADDING_SIGMAS = 5.0  # padding of the lattice on each side, in kernel stds
FRACTAL_LATTICE_SPACING = 1.0  # metres: the fractal field ignores r_M
MAX_LATTICE_NODES = 8192
"""Nodes per side of a terrain's lattice (8192 x 8192 float64: 512 MiB per array)."""


def terrain_range(name: str, value: Any, low: float, high: float,
                  open_ends: bool) -> tuple[float, float]:
    """``value`` (a number or a pair) as an ordered (lo, hi) pair inside [low, high]; else a
    ValueError naming the field ``terrain.name`` and the value."""
    pair = (value, value) if isinstance(value, int | float) and not isinstance(value, bool) \
        else value
    try:
        lo, hi = (float(v) for v in pair)
    except (TypeError, ValueError):
        _fail(name, value, "must be a number or a pair [min, max]")
    inside = (low < lo <= hi < high) if open_ends else (low <= lo <= hi <= high)
    if not inside:
        bounds = f"({low:g}, {high:g})" if open_ends else f"[{low:g}, {high:g}]"
        _fail(name, value, f"needs min <= max inside {bounds}")
    return lo, hi


def _fail(name: str, value: Any, why: str) -> None:
    """ValueError naming the field ``terrain.name``, its value and ``why``."""
    raise ValueError(f"invalid config: terrain.{name} = {short_repr(value)}: {why}")


def blob_lattice(blob_scale: float, area_size: float) -> tuple[float, float, int, int]:
    """Spacing (m), kernel std (lattice steps), padding and nodes per side of the lattice of
    a ``blobs`` field of correlation length ``blob_scale`` over an area of side
    ``area_size`` metres."""
    spacing = min(BLOB_LATTICE_SPACING, blob_scale / 2)
    sigma = blob_scale / spacing
    inside = math.ceil(area_size / spacing - 1e-9) + 1  # nodes covering [0, area]
    pad = math.ceil(BLOB_PADDING_SIGMAS * sigma)
    return spacing, sigma, pad, inside + 2 * pad


def blob_scale_range(area_size: float) -> tuple[float, float] | None:
    """The ``blob_scale`` (metres) whose lattice fits :data:`MAX_LATTICE_NODES` over an area
    of side ``area_size``, rounded inwards to 3 digits; None when no scale fits."""
    # Below 2 m: nodes <= 2 A / b + 22; from 2 m: nodes <= A + 4 + 10 b (ceil's margins).
    low = 2 * area_size / (MAX_LATTICE_NODES - 22)
    high = (MAX_LATTICE_NODES - area_size - 4) / (2 * BLOB_PADDING_SIGMAS)
    if low >= 2 * BLOB_LATTICE_SPACING or high < 2 * BLOB_LATTICE_SPACING:
        return None
    return float(f"{low * 1.01:.3g}"), float(f"{high * 0.99:.3g}")


def check_blob_lattice(terrain: TerrainConfig, world: WorldConfig) -> None:
    """ValueError naming ``terrain.blob_scale`` and its allowed range when the terrain draws
    ``blobs`` (itself or in its ``mixture``) on a lattice of more than
    :data:`MAX_LATTICE_NODES` nodes per side."""
    if "blobs" not in drawn_kinds(terrain):
        return
    if terrain.blob_scale >= 1e15 or world.area_size / terrain.blob_scale >= 1e15:
        nodes = math.inf  # past any lattice, and past math.ceil's ints
    else:
        nodes = blob_lattice(terrain.blob_scale, world.area_size)[3]
    if nodes <= MAX_LATTICE_NODES:
        return
    allowed = blob_scale_range(world.area_size)
    where = (f"choose one in [{allowed[0]:g}, {allowed[1]:g}] m for this {world.area_size:g} m "
             "area" if allowed else f"no blob_scale fits a {world.area_size:g} m area: use a "
             "smaller world.area_size or another terrain kind")
    raise ValueError(f"invalid config: terrain.blob_scale = {terrain.blob_scale!r}: its "
                     f"smoothing lattice would have {nodes:.3g} nodes per side, more than "
                     f"{MAX_LATTICE_NODES} (too fine or too coarse for the map); {where}")


def drawn_kinds(terrain: TerrainConfig) -> list[str]:
    """The kinds a terrain draws missions from: its own, or those of its ``mixture``."""
    return [kind for kind, _ in terrain.mixture_weights()] if terrain.kind == "mixture" \
        else [terrain.kind]


def fractal_lattice(area_size: float) -> tuple[int, int]:
    """Nodes covering [0, ``area_size``] and nodes per side of the periodic lattice of a
    ``fractal`` field (twice as many, so the field does not wrap around inside the area)."""
    inside = math.ceil(area_size / FRACTAL_LATTICE_SPACING - 1e-9) + 1
    return inside, 2 * inside


def fractal_area_limit() -> float:
    """The largest ``world.area_size`` (metres) whose ``fractal`` lattice fits
    :data:`MAX_LATTICE_NODES` per side: 2 (A + 1) <= nodes."""
    return (MAX_LATTICE_NODES // 2 - 1) * FRACTAL_LATTICE_SPACING


def check_fractal_lattice(terrain: TerrainConfig | None, world: WorldConfig) -> None:
    """ValueError naming ``world.area_size`` and the largest area allowed when the terrain
    draws ``fractal`` (itself or in its ``mixture``; ``terrain`` None: it does) on a lattice
    of more than :data:`MAX_LATTICE_NODES` nodes per side; checked before it is allocated."""
    if terrain is not None and "fractal" not in drawn_kinds(terrain):
        return
    area = world.area_size
    # Past 1e15 lattice steps math.ceil's ints grow without bound: such an area is refused.
    nodes = math.inf if area / FRACTAL_LATTICE_SPACING >= 1e15 else fractal_lattice(area)[1]
    if nodes <= MAX_LATTICE_NODES:
        return
    raise ValueError(f"invalid config: world.area_size = {area!r}: the fractal terrain's "
                     f"lattice ({FRACTAL_LATTICE_SPACING:g} m spacing, twice the area's side) "
                     f"would have {nodes:.6g} nodes per side, more than {MAX_LATTICE_NODES}; "
                     f"terrain kind 'fractal' (itself or in a mixture) allows an area of up to "
                     f"{fractal_area_limit():g} m: use a smaller world.area_size or another "
                     "terrain kind")
