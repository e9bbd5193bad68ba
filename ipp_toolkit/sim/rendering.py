"""Pure-numpy rendering of a mission state to an RGB image (no matplotlib).

Maps are 2-D arrays indexed ``[y, x]`` with row 0 at y = 0; the image shows y pointing up, so
image row 0 is the north edge of the area. Map cell (row j, col i) covers
x in [i r, (i + 1) r), y in [j r, (j + 1) r) with r = area_size / map_cells.

Layout (``P = panel_px``, ``M`` a separator of a few pixels)::

    +-----------------+-----------------+
    |  ground truth   |   global map    |     two P x P panels; UAV footprints and markers
    |                 |                 |     drawn on both
    +----+----+----+--+-+----+----+----+
    | L0 | L1 | L2 | L3 |                     one small panel per UAV (its local map), four
    +----+----+----+----+                     a row, bordered in the UAV's colour
    [=========-------------------------]      progress bar (only with step and budget)

Maps are down-sampled by area averaging (vectorised gathers over index arrays), so a render
at 500 x 500 cells costs a few milliseconds.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .mission import MissionState

__all__ = ["PALETTE", "render_mission", "render_state", "save_png", "prob_to_rgb"]

PALETTE = np.array(
    [
        (0, 200, 83),  # green
        (255, 214, 0),  # yellow
        (0, 229, 255),  # cyan
        (213, 0, 249),  # magenta
        (255, 109, 0),  # orange
        (118, 255, 3),  # lime
        (101, 31, 255),  # violet
        (255, 64, 129),  # pink
    ],
    dtype=np.uint8,
)
"""(8, 3) uint8 UAV colours; UAV i gets ``PALETTE[i % 8]``."""

BACKGROUND = np.array((28, 28, 32), dtype=np.uint8)
OUTLINE_DARK = np.array((15, 15, 18), dtype=np.uint8)
GT_EMPTY = np.array((58, 64, 76), dtype=np.float64)
GT_INTERESTING = np.array((160, 66, 42), dtype=np.float64)
BAR_EMPTY = np.array((60, 60, 66), dtype=np.uint8)
BAR_FULL = np.array((200, 200, 205), dtype=np.uint8)

# Diverging blue (0) -> white (0.5) -> red (1) colormap (ColorBrewer RdBu anchors).
_CMAP_X = np.array([0.0, 0.25, 0.5, 0.75, 1.0])
_CMAP_RGB = np.array(
    [
        (33, 102, 172),
        (103, 169, 207),
        (247, 247, 247),
        (239, 138, 98),
        (178, 24, 43),
    ],
    dtype=np.float64,
)
_LUT_LEVELS = 256
_LUT_T = np.linspace(0.0, 1.0, _LUT_LEVELS)
_PROB_LUT = np.stack(
    [np.interp(_LUT_T, _CMAP_X, _CMAP_RGB[:, ch]) for ch in range(3)], axis=1
).round().astype(np.uint8)
_GT_LUT = (GT_EMPTY + _LUT_T[:, None] * (GT_INTERESTING - GT_EMPTY)).round().astype(np.uint8)

SMALL_PER_ROW = 4
"""Small (per-UAV) panels per row."""


def _lut_index(values: np.ndarray) -> np.ndarray:
    """Map values in [0, 1] (NaN -> 0.5) to LUT indices."""
    v = np.nan_to_num(values, nan=0.5, posinf=1.0, neginf=0.0)
    return (np.clip(v, 0.0, 1.0) * (_LUT_LEVELS - 1) + 0.5).astype(np.intp)


def prob_to_rgb(prob: np.ndarray) -> np.ndarray:
    """Colour probabilities with the blue -> white -> red colormap.

    Args:
        prob: (...) float in [0, 1]; values outside are clipped, NaN reads as 0.5.

    Returns:
        (..., 3) uint8.
    """
    return np.take(_PROB_LUT, _lut_index(np.asarray(prob, dtype=np.float64)), axis=0)


def _bin_axis(a: np.ndarray, n_out: int, axis: int) -> np.ndarray:
    """Average (down-sampling) or replicate (up-sampling) `a` along `axis` (0 or 1) to n_out.

    Output entry k averages the input range [floor(k n_in / n_out), floor((k + 1) n_in / n_out)).
    Bins are at most ceil(n_in / n_out) wide, so the sum is a few vectorised gathers (much
    faster than ``np.add.reduceat``, which pays per bin).
    """
    n_in = a.shape[axis]
    edges = (np.arange(n_out + 1, dtype=np.intp) * n_in) // n_out
    lo = edges[:-1]
    out = np.take(a, lo, axis=axis).astype(np.float64)
    if n_in <= n_out:
        return out
    widths = np.diff(edges)
    for d in range(1, int(widths.max())):
        sel = np.flatnonzero(widths > d)
        if axis == 0:
            out[sel] += a[lo[sel] + d]
        else:
            out[:, sel] += a[:, lo[sel] + d]
    return out / (widths[:, None] if axis == 0 else widths[None, :])


def _area_resample(a: np.ndarray, out_h: int, out_w: int) -> np.ndarray:
    """Area-average a (H, W) map to (out_h, out_w), rows flipped so that row 0 is the north edge.

    Up-sampling degenerates to nearest-neighbour replication.
    """
    if a.dtype == np.bool_:
        a = a.view(np.uint8)
    return _bin_axis(_bin_axis(a, out_h, 0), out_w, 1)[::-1]


def _fill(img: np.ndarray, r0: int, r1: int, c0: int, c1: int, color: np.ndarray) -> None:
    """Fill the half-open pixel rectangle [r0, r1) x [c0, c1) of img, clipped to it."""
    h, w = img.shape[:2]
    r0, r1 = max(r0, 0), min(r1, h)
    c0, c1 = max(c0, 0), min(c1, w)
    if r0 < r1 and c0 < c1:
        img[r0:r1, c0:c1] = color


def _outline(
    img: np.ndarray, r0: int, r1: int, c0: int, c1: int, t: int, color: np.ndarray
) -> None:
    """Draw a rectangle outline of thickness t inside [r0, r1) x [c0, c1), clipped to img."""
    if r1 <= r0 or c1 <= c0:
        return
    t = max(1, min(t, (r1 - r0 + 1) // 2, (c1 - c0 + 1) // 2))
    _fill(img, r0, r0 + t, c0, c1, color)
    _fill(img, r1 - t, r1, c0, c1, color)
    _fill(img, r0, r1, c0, c0 + t, color)
    _fill(img, r0, r1, c1 - t, c1, color)


def _footprint_px(rect: np.ndarray, map_shape: tuple[int, int], px: int) -> tuple[int, ...]:
    """Pixel rectangle (top, bottom, left, right), half-open, of a map-cell rectangle."""
    h, w = map_shape
    row0, row1, col0, col1 = (int(v) for v in rect)
    row0, row1 = min(max(row0, 0), h), min(max(row1, 0), h)
    col0, col1 = min(max(col0, 0), w), min(max(col1, 0), w)
    top = round((h - row1) * px / h)
    bottom = round((h - row0) * px / h)
    left = round(col0 * px / w)
    right = round(col1 * px / w)
    return top, bottom, left, right


def _draw_footprint(
    img: np.ndarray, rect: np.ndarray, map_shape: tuple[int, int], color: np.ndarray, t: int
) -> None:
    """Outline a footprint in `color` (t px) with a dark 1-px line on each side for contrast."""
    top, bottom, left, right = _footprint_px(rect, map_shape, img.shape[0])
    if bottom <= top or right <= left:
        return
    _outline(img, top - 1, bottom + 1, left - 1, right + 1, t + 2, OUTLINE_DARK)
    _outline(img, top, bottom, left, right, t, color)


def _draw_marker(
    img: np.ndarray, xy: np.ndarray, area_size: float, half: int, color: np.ndarray, border: int
) -> None:
    """Filled square marker of half-size `half` px with a dark border, centred on (x, y) metres."""
    px = img.shape[0]
    col = int(np.floor(float(xy[0]) / area_size * px))
    row = int(np.floor((1.0 - float(xy[1]) / area_size) * px))
    row = min(max(row, 0), px - 1)
    col = min(max(col, 0), img.shape[1] - 1)
    _fill(img, row - half - border, row + half + 1 + border,
          col - half - border, col + half + 1 + border, OUTLINE_DARK)
    _fill(img, row - half, row + half + 1, col - half, col + half + 1, color)


def _marker_half(alt_index: int, scale: float) -> int:
    """Half-size in px of a UAV marker: strictly growing with the altitude index."""
    return max(1, round(3 * scale)) + alt_index * max(1, round(2 * scale))


def _shape(a: np.ndarray) -> str:
    return str(tuple(a.shape))


def _validate(
    ground_truth: np.ndarray,
    global_prob: np.ndarray,
    local_probs: np.ndarray,
    positions: np.ndarray,
    footprints: np.ndarray,
    area_size: float,
    altitudes: Sequence[float],
    panel_px: int,
    step: int | None,
    budget: int | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    gt = np.asarray(ground_truth)
    if gt.ndim != 2 or gt.shape[0] == 0 or gt.shape[1] == 0:
        raise ValueError(f"ground_truth must be a non-empty (H, W) array, got shape {_shape(gt)}")
    hw = gt.shape
    gp = np.asarray(global_prob)
    if gp.shape != hw:
        raise ValueError(
            f"global_prob must have the shape of ground_truth {hw}, got shape {_shape(gp)}"
        )
    lp = np.asarray(local_probs)
    if lp.ndim != 3 or lp.shape[1:] != hw:
        raise ValueError(
            f"local_probs must be (N, H, W) with (H, W) = {hw} matching ground_truth, "
            f"got shape {_shape(lp)}"
        )
    n = lp.shape[0]
    pos = np.asarray(positions, dtype=np.float64)
    if pos.shape != (n, 3):
        raise ValueError(f"positions must be (N, 3) = {(n, 3)}, got shape {_shape(pos)}")
    if not np.all(np.isfinite(pos)):
        raise ValueError("positions must be finite")
    fp = np.asarray(footprints)
    if fp.shape != (n, 4):
        raise ValueError(f"footprints must be (N, 4) = {(n, 4)}, got shape {_shape(fp)}")
    if not np.issubdtype(fp.dtype, np.integer):
        fpf = np.asarray(fp, dtype=np.float64)
        if not np.all(np.isfinite(fpf)) or not np.array_equal(fpf, np.round(fpf)):
            raise ValueError(f"footprints must hold integer map-cell indices, got {fp.dtype}")
        fp = fpf.astype(np.int64)
    if not (math.isfinite(area_size) and area_size > 0):
        raise ValueError(f"area_size must be a positive number, got {area_size!r}")
    alts = np.asarray(altitudes, dtype=np.float64)
    if alts.ndim != 1 or alts.size == 0:
        raise ValueError(f"altitudes must be a non-empty sequence, got shape {_shape(alts)}")
    if int(panel_px) != panel_px or panel_px < 32:
        raise ValueError(f"panel_px must be an integer >= 32, got {panel_px!r}")
    if (step is None) != (budget is None):
        raise ValueError("step and budget must be given together (or both left out)")
    if budget is not None and budget <= 0:
        raise ValueError(f"budget must be positive, got {budget!r}")
    if step is not None and step < 0:
        raise ValueError(f"step must be non-negative, got {step!r}")
    return gt.astype(bool), gp, lp, pos, fp, alts


def render_mission(
    ground_truth: np.ndarray,
    global_prob: np.ndarray,
    local_probs: np.ndarray,
    positions: np.ndarray,
    footprints: np.ndarray,
    area_size: float,
    altitudes: tuple[float, ...] = (5.0, 10.0, 15.0),
    panel_px: int = 240,
    step: int | None = None,
    budget: int | None = None,
) -> np.ndarray:
    """Render a mission state to an RGB image.

    Args:
        ground_truth: (H, W) bool, 1 = interesting cell.
        global_prob: (H, W) float in [0, 1], the team's fused map.
        local_probs: (N, H, W) float in [0, 1], each UAV's own map.
        positions: (N, 3) float, UAV positions (x, y, z) in metres.
        footprints: (N, 4) int, each UAV's latest footprint as a half-open map-cell rectangle
            (row0, row1, col0, col1); an empty rectangle is not drawn.
        area_size: side of the square area in metres.
        altitudes: the altitude levels; a UAV's marker grows with the index of the level
            nearest to its z.
        panel_px: side in pixels of each of the two big panels.
        step, budget: if both given, a progress bar of step / budget is drawn at the bottom.

    Returns:
        (h, w, 3) uint8 image, with w = 2 panel_px + 3 M (M the separator width) and h
        depending on N (four small panels a row) and on whether the progress bar is shown.

    Raises:
        ValueError: on inconsistent shapes or invalid scalar arguments, naming the argument.
    """
    gt, gp, lp, pos, fp, alts = _validate(
        ground_truth, global_prob, local_probs, positions, footprints, area_size, altitudes,
        panel_px, step, budget,
    )
    layout = _Layout.of(int(panel_px), lp.shape[0], step is not None and budget is not None)
    img = np.empty((layout.height, layout.width, 3), dtype=np.uint8)
    img[:] = BACKGROUND
    n = lp.shape[0]
    marks = _Marks(pos=pos, footprints=fp, area_size=area_size, hw=(gt.shape[0], gt.shape[1]),
                   alt_idx=np.abs(pos[:, 2:3] - alts[None, :]).argmin(axis=1),
                   colors=PALETTE[np.arange(n) % len(PALETTE)])
    _draw_big_panels(img, gt, gp, marks, layout)
    _draw_local_panels(img, lp, marks, layout)
    if layout.show_bar:
        assert step is not None and budget is not None
        _draw_progress(img, step / budget, layout)
    return img


@dataclass(frozen=True)
class _Layout:
    """Where the panels of :func:`render_mission` go: ``p`` the side of a big panel, ``sep``
    the separator, ``small`` the side of a UAV's panel (with its border), ``bar_h`` the
    progress bar's height; ``scale`` sizes the lines and markers to the 240 px design."""

    p: int
    sep: int
    width: int
    height: int
    small: int
    bar_h: int
    show_bar: bool
    scale: float

    @classmethod
    def of(cls, p: int, n: int, show_bar: bool) -> _Layout:
        sep = max(2, p // 60)
        width = 2 * p + 3 * sep
        small = (width - (SMALL_PER_ROW + 1) * sep) // SMALL_PER_ROW
        small_rows = -(-n // SMALL_PER_ROW)
        bar_h = max(4, p // 30)
        height = sep + p + sep + small_rows * (small + sep) + ((bar_h + sep) if show_bar else 0)
        return cls(p, sep, width, height, small, bar_h, show_bar, p / 240.0)


@dataclass(frozen=True)
class _Marks:
    """What is drawn over the maps: each UAV's position, footprint, altitude level and
    colour, on a map of ``hw`` cells covering ``area_size`` metres."""

    pos: np.ndarray
    footprints: np.ndarray
    area_size: float
    hw: tuple[int, int]
    alt_idx: np.ndarray
    colors: np.ndarray


def _draw_big_panels(img: np.ndarray, gt: np.ndarray, gp: np.ndarray, marks: _Marks,
                     layout: _Layout) -> None:
    """Top row: ground truth and global map, with every UAV's footprint and marker."""
    p, sep, scale = layout.p, layout.sep, layout.scale
    line_t = max(1, round(2 * scale))
    gt_panel = np.take(_GT_LUT, _lut_index(_area_resample(gt, p, p)), axis=0)
    gp_panel = prob_to_rgb(_area_resample(gp, p, p))
    n = len(marks.colors)  # one per UAV
    for panel in (gt_panel, gp_panel):
        for i in range(n):
            _draw_footprint(panel, marks.footprints[i], marks.hw, marks.colors[i], line_t)
        for i in range(n):
            half = _marker_half(int(marks.alt_idx[i]), scale)
            _draw_marker(panel, marks.pos[i], marks.area_size, half, marks.colors[i],
                         max(1, round(scale)))
    img[sep:sep + p, sep:sep + p] = gt_panel
    img[sep:sep + p, 2 * sep + p:2 * sep + 2 * p] = gp_panel


def _draw_local_panels(img: np.ndarray, lp: np.ndarray, marks: _Marks,
                       layout: _Layout) -> None:
    """Small panels: each UAV's local map, bordered in its colour, with its own footprint
    and marker (none where the panel is too small for a map inside its border)."""
    p, sep, small = layout.p, layout.sep, layout.small
    border = max(2, round(3 * layout.scale))
    inner = small - 2 * border
    if inner <= 0:
        return
    small_scale = inner / 240.0
    for i in range(lp.shape[0]):
        row, col = divmod(i, SMALL_PER_ROW)
        y0 = 2 * sep + p + row * (small + sep)
        x0 = sep + col * (small + sep)
        panel = prob_to_rgb(_area_resample(lp[i], inner, inner))
        _draw_footprint(panel, marks.footprints[i], marks.hw, marks.colors[i], 1)
        half = _marker_half(int(marks.alt_idx[i]), 1.5 * small_scale)
        _draw_marker(panel, marks.pos[i], marks.area_size, half, marks.colors[i], 1)
        img[y0:y0 + small, x0:x0 + small] = marks.colors[i]
        img[y0 + border:y0 + border + inner, x0 + border:x0 + border + inner] = panel


def _draw_progress(img: np.ndarray, fraction: float, layout: _Layout) -> None:
    """The progress bar along the bottom, filled to ``fraction`` (clipped to [0, 1])."""
    sep = layout.sep
    y0 = layout.height - sep - layout.bar_h
    bar_w = layout.width - 2 * sep
    filled = round(bar_w * min(max(fraction, 0.0), 1.0))
    img[y0:y0 + layout.bar_h, sep:sep + bar_w] = BAR_EMPTY
    img[y0:y0 + layout.bar_h, sep:sep + filled] = BAR_FULL


def save_png(rgb: np.ndarray, path: str | os.PathLike[str]) -> None:
    """Write an (h, w, 3) uint8 image to `path` as PNG, atomically (temp file + os.replace)."""
    from PIL import Image

    arr = np.asarray(rgb)
    if arr.ndim != 3 or arr.shape[2] != 3 or arr.dtype != np.uint8:
        raise ValueError(f"rgb must be an (h, w, 3) uint8 array, got {arr.dtype} {_shape(arr)}")
    from ..io import atomic_write

    image = Image.fromarray(np.ascontiguousarray(arr))
    atomic_write(path, lambda handle: image.save(handle, format="PNG"))


def render_state(state: MissionState, panel_px: int = 240) -> np.ndarray:
    """:func:`render_mission` of a mission state: (h, w, 3) uint8 RGB."""
    return render_mission(
        ground_truth=state.ground_truth,
        global_prob=state.maps.prob[state.global_index],
        local_probs=state.maps.prob[: state.n_agents],
        positions=state.positions_m(),
        footprints=state.footprints,
        area_size=state.config.world.area_size,
        altitudes=state.config.world.altitudes,
        panel_px=panel_px,
        step=state.step,
        budget=state.budget,
    )
