"""Ground-truth terrains: which map cells are interesting.

A map is a 2-D array indexed ``[y, x]`` with row 0 at y = 0 (plot it with
``origin="lower"``); cell (row j, column i) has its centre at ((i + 0.5) r, (j + 0.5) r)
metres for the map resolution r. ``True`` means interesting.

Every random terrain is defined in metres and only sampled at the cell centres, so the same
random stream gives the same terrain at any map resolution (up to the cells the boundary
crosses). Kinds are dispatched through :data:`TERRAIN_GENERATORS` (owned by
:mod:`ipp_toolkit.world.registry`, re-exported here); :func:`register_terrain`
adds one, and installed packages add theirs by entry point in the group
:data:`ENTRY_POINT_GROUP` (``name = module:function``), read on a process's first lookup.
"""

from __future__ import annotations

import functools
import math
import os
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..config.limits import LimitError, check_raster_cells, check_resampling
from ..config.schema import NAN_POLICIES, TerrainConfig, WorldConfig
from ..config.terrain_checks import blob_lattice, drawn_kinds
from . import registry
from .registry import (
    ENTRY_POINT_GROUP,
    TERRAIN_GENERATORS,
    load_entry_point_terrains,
    register_terrain,
    takes_namespace,
)

__all__ = [
    "ENTRY_POINT_GROUP",
    "TERRAIN_GENERATORS",
    "load_entry_point_terrains",
    "TerrainGenerator",
    "register_terrain",
    "generate_terrain",
    "split_parameters",
    "split_offset",
    "half_plane",
    "blob_field",
    "load_raster",
    "prepare_raster",
    "resample_area_average",
    "resampled_raster",
    "check_raster_file",
]

TerrainGenerator = Callable[
    [TerrainConfig, WorldConfig, np.random.Generator, np.ndarray | None], np.ndarray
]
"""``(config, world, rng, raster) -> (H, W) bool map`` with H = W = ``world.map_cells``."""

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
TIFF_SUFFIXES = (".tif", ".tiff")
RASTER_SUFFIXES = (".npy", *IMAGE_SUFFIXES, *TIFF_SUFFIXES)



def generate_terrain(config: TerrainConfig, world: WorldConfig, rng: np.random.Generator,
                     raster: np.ndarray | None = None, namespace: str = "train") -> np.ndarray:
    """The ground truth of one mission.

    Args:
        config: the terrain section; ``config.kind`` picks the generator.
        world: the area and its map resolution.
        rng: the mission's terrain stream (unused by ``raster`` with a fixed threshold).
        raster: (h, w) numeric array, ``[y, x]`` with row 0 at y = 0, used instead of the
            file ``config.raster`` by kind ``raster``.
        namespace: the mission's namespace (``train``, ``validation``, ``test``); kinds that
            keep separate data per namespace (``real``) draw from its part.

    Returns:
        (H, W) bool map, H = W = ``world.map_cells``; True = interesting.

    Raises:
        ValueError: unknown kind, bad raster, or a map without any interesting cell.
    """
    load_entry_point_terrains()
    try:
        generator = registry.TERRAIN_GENERATORS[config.kind]
    except KeyError:
        raise ValueError(f"unknown terrain kind {config.kind!r}; registered kinds: "
                         f"{sorted(registry.TERRAIN_GENERATORS)}") from None
    size = world.map_cells
    if takes_namespace(config.kind):
        truth = np.asarray(generator(config, world, rng, raster, namespace=namespace))
    else:
        truth = np.asarray(generator(config, world, rng, raster))
    if truth.shape != (size, size):
        raise ValueError(f"terrain kind {config.kind!r} returned shape {truth.shape}, "
                         f"expected {(size, size)}")
    truth = truth.astype(bool, copy=False)
    if not truth.any():
        raise ValueError(f"terrain kind {config.kind!r} produced no interesting cell on the "
                         f"{size} x {size} map")
    return truth


# --------------------------------------------------------------------------- split


def split_parameters(config: TerrainConfig, rng: np.random.Generator,
                     axis_aligned: bool = False) -> tuple[float, float]:
    """Draw the angle theta (rad) of the boundary's normal and the interesting share s.

    theta ~ U[0, 2 pi) (or uniform over {0, pi/2, pi, 3 pi/2} when ``axis_aligned``), then
    s ~ U[share_min, share_max]. Always two draws in this order, so a test can replay them.
    """
    if axis_aligned:
        theta = float(rng.integers(4)) * (math.pi / 2)
    else:
        theta = float(rng.uniform(0.0, 2 * math.pi))
    share = float(rng.uniform(config.share_min, config.share_max))
    return theta, share


def _unit_normal(theta: float) -> tuple[float, float]:
    # cos(pi/2) is 6e-17, not 0: snap it so axis-aligned boundaries make rows/columns exact.
    c, s = math.cos(theta), math.sin(theta)
    return (0.0 if abs(c) < 1e-12 else c), (0.0 if abs(s) < 1e-12 else s)


def split_offset(theta: float, share: float, area_size: float) -> float:
    """Offset t (m) such that the part of the square area with projection > t has ``share``.

    The projection of a point onto the normal (cos theta, sin theta), measured from the area
    centre, is the sum of two independent uniforms for a uniform point, so its tail has a
    closed form (a trapezoid law); inverting it makes the boundary independent of the map
    resolution.
    """
    if not 0.0 <= share <= 1.0:
        raise ValueError(f"share must lie in [0, 1], got {share!r}")
    c, s = _unit_normal(theta)
    # Half-widths of the two uniform summands, larger first.
    a, b = sorted((abs(c) * area_size / 2, abs(s) * area_size / 2), reverse=True)
    q = min(share, 1.0 - share)  # the law is symmetric: solve for the smaller tail
    if q >= b / (2 * a):
        t = a * (1.0 - 2.0 * q)  # flat part of the trapezoid
    else:
        t = a + b - math.sqrt(8.0 * a * b * q)  # sloped end
    return t if share <= 0.5 else -t


def half_plane(theta: float, share: float, world: WorldConfig) -> np.ndarray:
    """(H, W) bool map: cells whose centre projects above the ``split_offset`` on the normal.

    H = W = ``world.map_cells``; the interesting share is ``share`` up to the cells that the
    boundary crosses.
    """
    size, r, area = world.map_cells, world.resolution, world.area_size
    centres = (np.arange(size) + 0.5) * r - area / 2
    c, s = _unit_normal(theta)
    projection = centres[np.newaxis, :] * c + centres[:, np.newaxis] * s
    return projection > split_offset(theta, share, area)


@register_terrain("split")
def _split_terrain(config: TerrainConfig, world: WorldConfig, rng: np.random.Generator,
                   raster: np.ndarray | None = None) -> np.ndarray:
    return half_plane(*split_parameters(config, rng), world)


@register_terrain("split-axis")
def _split_axis_terrain(config: TerrainConfig, world: WorldConfig, rng: np.random.Generator,
                        raster: np.ndarray | None = None) -> np.ndarray:
    return half_plane(*split_parameters(config, rng, axis_aligned=True), world)


# --------------------------------------------------------------------------- blobs


def _bilinear_weights(points: np.ndarray, nodes: int) -> np.ndarray:
    """(len(points), nodes) weights interpolating linearly at ``points`` in lattice units."""
    lower = np.clip(np.floor(points).astype(np.int64), 0, nodes - 2)
    frac = points - lower
    weights = np.zeros((len(points), nodes))
    rows = np.arange(len(points))
    weights[rows, lower] = 1.0 - frac
    weights[rows, lower + 1] = frac
    return weights


def blob_field(config: TerrainConfig, world: WorldConfig,
               rng: np.random.Generator) -> np.ndarray:
    """(H, W) float smooth random field at the map cell centres (H = W = ``world.map_cells``).

    White Gaussian noise on a lattice in metres (1 m spacing, finer only if ``blob_scale`` is
    below 2 m so the kernel stays resolved), padded by 5 kernel stds so the FFT's circular
    convolution does not wrap, smoothed with a Gaussian of std ``blob_scale`` metres and
    interpolated bilinearly at the cell centres. The lattice ignores r_M, so one stream gives
    the same field at every resolution.
    """
    # The 5-std padding keeps the FFT's wrap-around below 1e-5; the lattice spacing is fixed
    # so the field ignores r_M (bounded by the config: ipp_toolkit.config.terrain_checks).
    spacing, sigma, pad, nodes = blob_lattice(config.blob_scale, world.area_size)
    noise = rng.standard_normal((nodes, nodes))
    fy = np.fft.fftfreq(nodes)[:, np.newaxis]
    fx = np.fft.rfftfreq(nodes)[np.newaxis, :]
    # Fourier transform of a unit-mass Gaussian of std sigma.
    kernel = np.exp(-2.0 * math.pi ** 2 * sigma ** 2 * (fy ** 2 + fx ** 2))
    field = np.fft.irfft2(np.fft.rfft2(noise) * kernel, s=noise.shape)
    centres = (np.arange(world.map_cells) + 0.5) * world.resolution / spacing + pad
    weights = _bilinear_weights(centres, nodes)
    return weights @ field @ weights.T


@register_terrain("blobs")
def _blob_terrain(config: TerrainConfig, world: WorldConfig, rng: np.random.Generator,
                  raster: np.ndarray | None = None) -> np.ndarray:
    field = blob_field(config, world, rng)
    share = float(rng.uniform(config.share_min, config.share_max))
    return field > np.quantile(field, 1.0 - share)


# --------------------------------------------------------------------------- raster


def _as_2d_numeric(data: Any, name: str) -> np.ndarray:
    """(h, w) float64 copy of ``data``; a trailing band axis of length 1 is dropped."""
    array = np.asarray(data)
    if array.ndim == 3 and array.shape[-1] == 1:
        array = array[..., 0]
    if array.ndim == 3:
        raise ValueError(f"raster {name} has shape {array.shape}: it must be single band "
                         "(h, w); convert multi-band (e.g. RGB) data to one band first")
    if array.ndim != 2:
        raise ValueError(f"raster {name} has shape {array.shape}: it must be 2-D (h, w)")
    if array.dtype.kind not in "biuf":
        raise ValueError(f"raster {name} has dtype {array.dtype}: it must be numeric")
    if array.size == 0:
        raise ValueError(f"raster {name} has shape {array.shape}: it must be at least 1 x 1")
    return np.array(array, dtype=np.float64)


def _read_npy(path: Path) -> np.ndarray:
    # Mapped first: the shape is checked against the limit before the values are read.
    data = np.load(path, allow_pickle=False, mmap_mode="r")
    if not isinstance(data, np.ndarray):  # an .npz archive renamed to .npy
        raise ValueError("not a single .npy array")
    check_raster_cells(data.shape, repr(str(path)))
    return data


def _image_shape(path: Path) -> tuple[int, int] | None:
    """The (h, w) of an image file from its header (None when it cannot be told)."""
    try:
        from PIL import Image

        with Image.open(path) as image:
            return image.size[1], image.size[0]
    except Exception:  # not an image Pillow knows: the reader reports it
        pass
    try:
        import tifffile

        with tifffile.TiffFile(path) as tiff:
            return tuple(tiff.series[0].shape)[:2]  # type: ignore[return-value]
    except Exception:
        return None


def _read_pillow(path: Path) -> np.ndarray:
    from PIL import Image

    with Image.open(path) as image:
        image.load()
        if image.mode == "P":
            # Palette indices are not values; expand them so the band check reports the shape.
            image = image.convert("RGBA" if "transparency" in image.info else "RGB")
        return np.asarray(image)


def _read_tiff(path: Path) -> np.ndarray:
    try:
        import tifffile

        return tifffile.imread(path)
    except Exception:  # tifffile missing, or a TIFF flavour it cannot decode: try Pillow
        return _read_pillow(path)


def load_raster(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a raster file into an (h, w) float64 array, ``[y, x]`` with row 0 at y = 0.

    ``.npy`` files are already in the map convention. Images (``.png``, ``.jpg``, ``.jpeg``,
    ``.tif``, ``.tiff``) store their first row at the north edge as displayed, so they are
    flipped vertically. Non-finite values are kept; :func:`prepare_raster` deals with them.

    Raises:
        ValueError: missing or unreadable file, unknown extension, or data that is not a
            single 2-D numeric band; the message names the path.
    """
    name = os.fspath(path)
    file = Path(name)
    if not file.exists():
        raise ValueError(f"cannot read raster file {name!r}: no such file")
    if not file.is_file():
        raise ValueError(f"cannot read raster file {name!r}: not a file")
    suffix = file.suffix.lower()
    if suffix not in RASTER_SUFFIXES:
        raise ValueError(f"cannot read raster file {name!r}: unknown extension {suffix!r}; "
                         f"use one of {', '.join(RASTER_SUFFIXES)}")
    reader = _read_npy if suffix == ".npy" else _read_tiff if suffix in TIFF_SUFFIXES \
        else _read_pillow
    if suffix != ".npy":
        shape = _image_shape(file)
        if shape is not None:
            check_raster_cells(shape, repr(name))  # before the pixels are decoded
    try:
        data = reader(file)
    except LimitError:
        raise
    except Exception as err:  # decoders raise many types; all mean "unreadable file"
        raise ValueError(f"cannot read raster file {name!r}: {err}") from err
    values = _as_2d_numeric(data, repr(name))
    return values if suffix == ".npy" else np.ascontiguousarray(values[::-1])


def prepare_raster(values: np.ndarray, nan_policy: str = "raise",
                   name: str = "array") -> np.ndarray:
    """Check a raster and fill its NaN cells; returns an (h, w) finite float64 copy.

    Args:
        values: (h, w) or (h, w, 1) numeric array.
        nan_policy: ``raise`` or fill NaN with the raster's ``min``, ``max`` or ``mean``.
        name: how error messages refer to the raster.

    Raises:
        ValueError: wrong shape or dtype, any +-inf, all NaN, or NaN with ``raise``.
    """
    if nan_policy not in NAN_POLICIES:
        raise ValueError(f"nan_policy must be one of {NAN_POLICIES}, got {nan_policy!r}")
    array = _as_2d_numeric(values, name)
    infinite = int(np.isinf(array).sum())
    if infinite:
        raise ValueError(f"raster {name} has {infinite} infinite cell(s): values must be "
                         "finite (NaN may be filled by terrain.nan_policy)")
    missing = np.isnan(array)
    count = int(missing.sum())
    if count == array.size:
        raise ValueError(f"raster {name} is all NaN ({array.shape}): nothing to threshold")
    if count:
        if nan_policy == "raise":
            raise ValueError(f"raster {name} has {count} NaN cell(s) and terrain.nan_policy is "
                             "'raise'; set nan_policy to 'min', 'max' or 'mean' to fill them")
        fill = {"min": np.nanmin, "max": np.nanmax, "mean": np.nanmean}[nan_policy](array)
        array[missing] = fill
    return array


def _overlap_weights(target: int, source: int) -> np.ndarray:
    """(target, source) share of each target interval covered by each source interval.

    Both grids split [0, 1]; in units of 1 / (target * source) every edge is an integer, so
    the weights are exact ratios and each row sums to 1.
    """
    t_edges = np.arange(target + 1) * source
    s_edges = np.arange(source + 1) * target
    low = np.maximum(t_edges[:-1, np.newaxis], s_edges[np.newaxis, :-1])
    high = np.minimum(t_edges[1:, np.newaxis], s_edges[np.newaxis, 1:])
    return np.clip(high - low, 0, None) / source


def _covering_ranges(target: int, source: int) -> tuple[np.ndarray, np.ndarray]:
    """(target,) first and one-past-last source pixel overlapping each target cell."""
    cells = np.arange(target)
    return (cells * source) // target, -((-(cells + 1) * source) // target)


def _range_reduce(values: np.ndarray, first: np.ndarray, stop: np.ndarray,
                  ufunc: np.ufunc) -> np.ndarray:
    """(len(first), ...) ``ufunc`` reduction of ``values`` over rows [first, stop) each.

    Loops over the offset within a range (a handful), not over cells.
    """
    out = values[first]
    for offset in range(1, int((stop - first).max())):
        out = ufunc(out, values[np.minimum(first + offset, stop - 1)])
    return out


def resample_area_average(values: np.ndarray, shape: tuple[int, int],
                          name: str = "array") -> np.ndarray:
    """Exact area-weighted average of a raster stretched over a grid of ``shape``.

    Each target cell gets the mean of the source over its footprint, source pixels weighted
    by the area they share with it; works for down- and up-sampling and any ratio.

    Args:
        values: (h, w) finite source raster.
        shape: (H, W) target grid.
        name: how a refusal names the raster.

    Returns:
        (H, W) float64 array, ``R @ values @ C.T`` with overlap matrices R (H, h), C (W, w),
        clipped to the range of the pixels under each cell.

    Raises:
        LimitError: the overlap matrices exceed ``IPP_MAX_RESAMPLE_WEIGHTS`` (a thin raster).
    """
    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 2 or values.size == 0:
        raise ValueError(f"values must be a non-empty 2-D array, got shape {values.shape}")
    if len(shape) != 2 or any(int(n) != n or n < 1 for n in shape):
        raise ValueError(f"shape must be two positive integers, got {shape!r}")
    (height, width), (h, w) = (int(shape[0]), int(shape[1])), values.shape
    check_resampling((h, w), (height, width), name)
    rows = _overlap_weights(height, h)
    cols = _overlap_weights(width, w)
    # Multiply in the order with fewer operations (a large source shrinks first).
    if height * h * w + height * w * width <= h * w * width + height * h * width:
        averaged = (rows @ values) @ cols.T
    else:
        averaged = rows @ (values @ cols.T)
    # The weights of a row do not sum to exactly 1 in floating point, so a uniform patch
    # (a 0/1 mask thresholded at 1, say) could land one ulp off its value; clipping to the
    # pixels under the cell restores it and never moves a correct average.
    row_first, row_stop = _covering_ranges(height, h)
    col_first, col_stop = _covering_ranges(width, w)
    bounds = []
    for ufunc in (np.minimum, np.maximum):
        by_rows = _range_reduce(values, row_first, row_stop, ufunc)
        bounds.append(_range_reduce(by_rows.T, col_first, col_stop, ufunc).T)
    return np.clip(averaged, *bounds)


@dataclass(frozen=True)
class _Resampled:
    values: np.ndarray  # (H, W) read-only area averages
    source_shape: tuple[int, int]
    source_min: float
    source_max: float


def _resample(source: np.ndarray, shape: tuple[int, int], name: str) -> _Resampled:
    averaged = resample_area_average(source, shape, name)
    averaged.setflags(write=False)
    return _Resampled(averaged, source.shape, float(source.min()), float(source.max()))


@functools.lru_cache(maxsize=4)
def _cached_file(path: str, mtime_ns: int, size: int, shape: tuple[int, int],
                 nan_policy: str) -> _Resampled:
    # mtime and size are part of the key only so that a rewritten file misses the cache.
    source = prepare_raster(load_raster(path), nan_policy, repr(path))
    return _resample(source, shape, repr(path))


def _file_entry(path: str | os.PathLike[str], shape: tuple[int, int],
                nan_policy: str) -> _Resampled:
    name = os.fspath(path)
    try:
        stat = os.stat(name)
    except OSError as err:
        raise ValueError(f"cannot read raster file {name!r}: "
                         f"{err.strerror or 'no such file'}") from err
    return _cached_file(os.path.abspath(name), stat.st_mtime_ns, stat.st_size,
                        (int(shape[0]), int(shape[1])), nan_policy)


def _warn_if_stretched(entry: _Resampled, name: str, stacklevel: int) -> None:
    h, w = entry.source_shape
    if h != w:
        warnings.warn(f"raster {name} has shape {entry.source_shape} (h, w), not square: it is "
                      "stretched onto the square area", UserWarning, stacklevel=stacklevel + 1)


def resampled_raster(path: str | os.PathLike[str], shape: tuple[int, int],
                     nan_policy: str = "raise") -> np.ndarray:
    """(H, W) float64 area averages of the raster file ``path`` on a grid of ``shape``.

    Loading and resampling are cached (keyed by path, file mtime and size, shape and
    nan_policy); the result is a fresh copy, so callers may modify it.
    """
    entry = _file_entry(path, shape, nan_policy)
    _warn_if_stretched(entry, repr(os.fspath(path)), stacklevel=2)
    return entry.values.copy()


def check_raster_file(config: TerrainConfig, world: WorldConfig) -> None:
    """Read and resample the raster file a terrain draws from (kind ``raster``, or a
    ``mixture`` with it) onto the map of ``world``, so that a run refuses a file that cannot
    be read or is over a limit (ValueError naming it) before it writes anything, not at its
    first mission; the result is cached for the missions. Nothing to do without a file."""
    if "raster" in drawn_kinds(config) and config.raster is not None:
        _file_entry(config.raster, (world.map_cells, world.map_cells), config.nan_policy)


@register_terrain("raster")
def _raster_terrain(config: TerrainConfig, world: WorldConfig, rng: np.random.Generator,
                    raster: np.ndarray | None = None) -> np.ndarray:
    if config.threshold is None and config.threshold_quantile is None:
        raise ValueError("terrain kind 'raster' needs terrain.threshold or "
                         "terrain.threshold_quantile")
    shape = (world.map_cells, world.map_cells)
    if raster is not None:
        name = "array"
        entry = _resample(prepare_raster(raster, config.nan_policy, name), shape, name)
    elif config.raster is not None:
        name = repr(config.raster)
        entry = _file_entry(config.raster, shape, config.nan_policy)
    else:
        raise ValueError("terrain kind 'raster' needs terrain.raster (a file) or a raster array")
    # Caller -> generate_terrain -> here: point the warning at the caller.
    _warn_if_stretched(entry, name, stacklevel=3)
    if config.threshold is None:  # a quantile of the area averages instead
        low, high = config.threshold_quantile  # type: ignore[misc]
        level = float(np.quantile(entry.values, float(rng.uniform(low, high))))
        return entry.values > level if level <= entry.values.min() else entry.values >= level
    interesting = entry.values >= config.threshold
    if interesting.all():
        raise ValueError(
            f"raster {name}: every map cell reaches terrain.threshold = {config.threshold!r}, "
            "so there is nothing to map; the raster spans "
            f"[{entry.source_min:g}, {entry.source_max:g}] (area averages on the map: "
            f"[{entry.values.min():g}, {entry.values.max():g}])")
    if not interesting.any():
        raise ValueError(
            f"raster {name}: no map cell reaches terrain.threshold = {config.threshold!r}; the "
            f"raster spans [{entry.source_min:g}, {entry.source_max:g}] (area averages on the "
            f"map: [{entry.values.min():g}, {entry.values.max():g}])")
    return interesting

