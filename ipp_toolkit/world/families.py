"""Terrain families that look like the world: ``fractal``, ``real`` and their ``mixture``.

``split`` (one straight boundary) is the paper's terrain; a policy trained only on it learns
"sweep along the boundary" and transfers badly. These families cover what real fields look
like, and :func:`ipp_toolkit.world.terrain.generate_terrain` dispatches to them by name:

``fractal``
    A Gaussian random field with a power-law spectrum (power ~ 1 / f^b, b drawn per mission
    from ``terrain.spectral_exponent``), thresholded at a quantile q drawn from
    ``terrain.threshold_quantile`` (default 0.4-0.9: 10-60 % interesting). Small b gives many
    small hotspots, large b a few large regions. Defined on a lattice in metres (1 m), so the
    same stream gives the same field at any map resolution.

``real``
    Crops of the real rasters bundled with the toolkit (``ipp_toolkit/data/rasters``:
    elevation, temperature, vegetation index, precipitation, wave height; source and licence
    of each in ``sources.json``). Each mission draws a source file, a layer, a square crop
    (side a fraction ``terrain.crop_fraction`` of the raster's shorter side), one of the eight
    rotations/flips and a threshold quantile; no-data cells are never interesting. The
    sources are split into train, validation and test files (never by crop): with
    ``terrain.real_sources = "mission"`` a mission crops only files of its own namespace, so
    test missions fly rasters no policy was trained or selected on.

``mixture``
    One kind per mission, drawn with the weights of ``terrain.mixture`` (default: split,
    blobs, fractal and real, equally weighted): domain randomisation over families.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from ..config.schema import TerrainConfig, WorldConfig
from ..config.terrain_checks import FRACTAL_LATTICE_SPACING, check_fractal_lattice, fractal_lattice
from .registry import RASTER_FOLDER, raster_manifest, real_raster_names
from .terrain import _bilinear_weights, generate_terrain, register_terrain, resample_area_average

__all__ = ["RealRaster", "real_rasters", "real_raster_names", "real_crop", "fractal_field",
           "DEFAULT_THRESHOLD_QUANTILE"]

DEFAULT_THRESHOLD_QUANTILE = (0.4, 0.9)
"""Quantile range of ``fractal`` and ``real`` when ``terrain.threshold_quantile`` is unset."""

_MIN_VALID_SHARE = 0.5  # a map cell is data when at least half of it lies on data pixels
_MAX_ATTEMPTS = 50


@dataclass(frozen=True)
class RealRaster:
    """One bundled real raster.

    Attributes:
        name: file stem.
        split: ``train``, ``validation`` or ``test``.
        measures: what the values are (e.g. ``elevation (m)``).
        layers: (L, h, w) float32, row 0 at the south edge, NaN = no data (read-only).
        source, licence: where it comes from and under which licence.
    """

    name: str
    split: str
    measures: str
    layers: np.ndarray
    source: str
    licence: str


@functools.lru_cache(maxsize=1)
def real_rasters() -> tuple[RealRaster, ...]:
    """Every bundled real raster, in ``sources.json`` order (loaded once)."""
    rasters = []
    for entry in raster_manifest():
        layers = np.load(RASTER_FOLDER / f"{entry['name']}.npy", allow_pickle=False)
        layers.setflags(write=False)
        rasters.append(RealRaster(entry["name"], entry["split"], entry["measures"], layers,
                                  entry["source"], entry["licence"]))
    return tuple(rasters)


def _quantile_range(config: TerrainConfig) -> tuple[float, float]:
    return config.threshold_quantile or DEFAULT_THRESHOLD_QUANTILE  # type: ignore[return-value]


def _threshold(values: np.ndarray, valid: np.ndarray, quantile: float) -> np.ndarray:
    """Cells at or above the ``quantile`` of the valid values (above it on a tie with the
    minimum, so a field that is mostly at its floor does not come out all interesting)."""
    finite = values[valid]
    level = float(np.quantile(finite, quantile))
    above = values > level if level <= float(finite.min()) else values >= level
    return above & valid


# --------------------------------------------------------------------------- fractal


def fractal_field(exponent: float, world: WorldConfig, rng: np.random.Generator) -> np.ndarray:
    """(H, W) float Gaussian random field with power spectrum ~ 1 / f^exponent at the cells.

    White noise on a periodic lattice twice the area's side (1 m spacing) is filtered by
    f^(-exponent / 2) (the mean removed) and read bilinearly at the cell centres of one
    quadrant, so the field does not wrap around inside the area.
    """
    # A WorldConfig alone does not know its terrain, so the EnvConfig's check may not have
    # run (generate_terrain called directly): refuse an oversized lattice before allocating.
    check_fractal_lattice(None, world)
    nodes = fractal_lattice(world.area_size)[1]
    noise = rng.standard_normal((nodes, nodes))
    fy = np.fft.fftfreq(nodes)[:, np.newaxis]
    fx = np.fft.rfftfreq(nodes)[np.newaxis, :]
    radius = np.hypot(fy, fx)
    radius[0, 0] = np.inf  # no mean
    spectrum = np.fft.rfft2(noise) * radius ** (-exponent / 2.0)
    field = np.fft.irfft2(spectrum, s=noise.shape)
    centres = (np.arange(world.map_cells) + 0.5) * world.resolution / FRACTAL_LATTICE_SPACING
    weights = _bilinear_weights(centres, nodes)
    return weights @ field @ weights.T


@register_terrain("fractal")
def _fractal_terrain(config: TerrainConfig, world: WorldConfig, rng: np.random.Generator,
                     raster: np.ndarray | None = None) -> np.ndarray:
    exponent = float(rng.uniform(*config.spectral_exponent))
    quantile = float(rng.uniform(*_quantile_range(config)))
    field = fractal_field(exponent, world, rng)
    return _threshold(field, np.ones(field.shape, dtype=bool), quantile)


# --------------------------------------------------------------------------- real


def _sources(config: TerrainConfig, namespace: str) -> list[RealRaster]:
    split = namespace if config.real_sources == "mission" else config.real_sources
    chosen = [r for r in real_rasters() if split in ("all", r.split, r.name)]
    if not chosen:
        raise ValueError(f"no bundled real raster for split {split!r} (terrain.real_sources = "
                         f"{config.real_sources!r}, mission namespace {namespace!r})")
    return chosen


def _dihedral(array: np.ndarray, index: int) -> np.ndarray:
    """One of the eight rotations/flips of a square array (index 0..7)."""
    turned = np.rot90(array, index % 4)
    return turned[:, ::-1] if index >= 4 else turned


def real_crop(config: TerrainConfig, world: WorldConfig, rng: np.random.Generator,
              namespace: str = "train") -> tuple[np.ndarray, dict[str, object]]:
    """One ``real`` ground truth and what was drawn for it.

    Returns:
        (H, W) bool map and a dict with the source name, layer, crop (row, col, side),
        rotation/flip index, quantile and interesting share.

    Raises:
        ValueError: no raster for the split, or no usable crop in 50 draws.
    """
    sources = _sources(config, namespace)
    shape = (world.map_cells, world.map_cells)
    for _ in range(_MAX_ATTEMPTS):
        source = sources[int(rng.integers(len(sources)))]
        layer_index = int(rng.integers(len(source.layers)))
        layer = source.layers[layer_index]
        h, w = layer.shape
        side = max(4, int(round(float(rng.uniform(*config.crop_fraction)) * min(h, w))))
        row, col = int(rng.integers(h - side + 1)), int(rng.integers(w - side + 1))
        turn = int(rng.integers(8))
        quantile = float(rng.uniform(*_quantile_range(config)))
        crop = _dihedral(layer[row:row + side, col:col + side], turn)
        data = np.isfinite(crop)
        if data.mean() < _MIN_VALID_SHARE:
            continue
        valid_share = resample_area_average(data.astype(np.float64), shape)
        values = resample_area_average(np.where(data, crop, 0.0), shape)
        valid = valid_share >= _MIN_VALID_SHARE
        values = np.divide(values, valid_share, out=np.zeros(shape), where=valid)
        truth = _threshold(values, valid, quantile)
        if truth.any() and not truth[valid].all():
            drawn = {"source": source.name, "layer": layer_index, "crop": (row, col, side),
                     "turn": turn, "quantile": quantile, "share": float(truth.mean())}
            return truth, drawn
    raise ValueError(f"no usable crop of the {namespace!r} real rasters in {_MAX_ATTEMPTS} "
                     "draws (crops mostly no-data or flat): widen terrain.crop_fraction")


@register_terrain("real", namespaced=True)
def _real_terrain(config: TerrainConfig, world: WorldConfig, rng: np.random.Generator,
                  raster: np.ndarray | None = None, namespace: str = "train") -> np.ndarray:
    return real_crop(config, world, rng, namespace)[0]


# --------------------------------------------------------------------------- mixture


@register_terrain("mixture", namespaced=True)
def _mixture_terrain(config: TerrainConfig, world: WorldConfig, rng: np.random.Generator,
                     raster: np.ndarray | None = None, namespace: str = "train") -> np.ndarray:
    kinds, weights = zip(*config.mixture_weights(), strict=True)
    probabilities = np.asarray(weights, dtype=np.float64) / sum(weights)
    kind = kinds[int(rng.choice(len(kinds), p=probabilities))]
    return generate_terrain(dataclasses.replace(config, kind=kind), world, rng, raster,
                            namespace=namespace)
