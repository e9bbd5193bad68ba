"""Open-loop lookahead over a UAV's own path, for planners that rank moves by footprint gains.

A greedy planner of the ``ig`` family ranks each move by the summed per-cell value of the
footprint it would see next. With ``steps`` d > 1 a move is also worth ``discount`` (gamma)
times the best value of the d - 1 moves that could follow it along the UAV's own path:

    value(a) = gain(a) + gamma * max over paths a, m_1, ..., m_{d-1} of
               sum_t gamma^(t-1) * (value of the cells of footprint t no earlier footprint
               of the path covers)

The path is open loop (the map is not updated between its readings) and a cell counts once,
at its first reading on the path: a second reading of the same ground is worth less and
counting it zero keeps every term a rectangle sum. Footprints are rectangles and so are
their intersections, so each term is an inclusion-exclusion over the earlier footprints,
taken from a summed-area table of each altitude's values over the segments every footprint
edge and every ~0.5 m block edge cut the map into (:mod:`ipp_toolkit.planning.segments`),
within the box the paths can reach at that altitude. Paths that leave the grid of waypoints
are skipped; a path is as long as the steps left in the mission allow.

The segment values come from the planner (a callable), with whatever the planner applies to
the first move (a teammate's same-step discount) applied to the whole path: used by the
``ig`` family (``lookahead_steps``) and by the planners that read the gain planes
(:class:`~ipp_toolkit.planning.discount.TeammateDiscount`). Their tables' segment sums are
kept per UAV and summed again only where its map changed
(:class:`~ipp_toolkit.planning.segments.SegmentSums`).

Cost per UAV and step: the segment sums where the map changed (its own and the heard
readings), one product per segment of each altitude's box (about 100 x 100 segments at
r_M = 0.1 m, d = 3) and its summed-area table, and four look-ups per rectangle of the
6^(d-1) paths per move; the rectangles themselves depend on the waypoint alone and are kept
for the last waypoints asked for. The tables and the paths' sums are compiled
(:func:`~ipp_toolkit._native.kernels.summed_area`,
:func:`~ipp_toolkit._native.kernels.path_values`), adding in the NumPy code's order.
"""

from __future__ import annotations

import functools
import itertools
from collections import OrderedDict
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from .._native import kernels
from ..sim.team import ACTION_DELTAS, N_ACTIONS
from . import AgentView
from .segments import SegmentBox, SegmentGrid

__all__ = ["LOOKAHEAD_DISCOUNT", "LOOKAHEAD_STEPS", "MAX_LOOKAHEAD_STEPS", "check_lookahead",
           "continuation_values", "lookahead_options", "mission_lookahead", "steps_left"]

#: Most moves a path may look at (6^(d-1) continuations per first move).
MAX_LOOKAHEAD_STEPS = 4
#: The default weight per step further along the path.
LOOKAHEAD_DISCOUNT = 0.5
#: The steps the learned-prior planners look at by default (``ig_learned``, ``coma`` and
#: ``ppo``); the other ``ig`` planners and ``sb3`` are greedy (1) unless asked.
LOOKAHEAD_STEPS = 3


def mission_lookahead(steps: int, silent: bool, comm_range: float) -> int:
    """The steps a planner looks at on missions of ``comm_range``: ``steps``, or 1 (greedy)
    without communication unless ``silent``.

    Without communication no UAV hears where the others go, and the lookahead drew UAVs to
    the same promising ground: on validation missions (``split``, 4 and 8 UAVs, D = 0) the
    final entropy rose by 0.02-0.03 (2-4 standard errors) and the UAVs flew within one waypoint
    of each other half as often again; with communication it fell (experiments/lookahead/README.md).
    """
    return steps if silent or comm_range > 0 else 1


def steps_left(steps: int, view: AgentView) -> int:
    """The moves a path from ``view`` looks at: ``steps``, or fewer near the mission's end
    (a path never runs past the budget)."""
    return min(steps, view.budget - view.step)


def check_lookahead(steps: int, discount: float) -> tuple[int, float]:
    """``(steps, discount)`` checked: an integer in [1, :data:`MAX_LOOKAHEAD_STEPS`] (1 = the
    greedy choice) and a number in [0, 1].

    Raises:
        ValueError: naming the bad value.
    """
    if (isinstance(steps, bool) or not isinstance(steps, (int, np.integer))
            or not 1 <= steps <= MAX_LOOKAHEAD_STEPS):
        raise ValueError(f"lookahead_steps must be an integer in [1, {MAX_LOOKAHEAD_STEPS}], "
                         f"got {steps!r}")
    if isinstance(discount, bool) or not isinstance(discount, (int, float)) or not (
            0.0 <= discount <= 1.0):
        raise ValueError(f"lookahead_discount must be a number in [0, 1], got {discount!r}")
    return int(steps), float(discount)


def lookahead_options(steps: int, discount: float, silent: bool) -> tuple[int, float, bool]:
    """``(steps, discount, silent)`` checked (:func:`check_lookahead`), as a planner that
    hands them to :class:`~ipp_toolkit.planning.discount.TeammateDiscount` keeps them."""
    return (*check_lookahead(steps, discount), bool(silent))


@functools.lru_cache(maxsize=MAX_LOOKAHEAD_STEPS)
def _continuations(steps: int) -> np.ndarray:
    """(6^steps, steps, 3) cumulative waypoint offsets of every sequence of ``steps`` moves."""
    sequences = np.array(list(itertools.product(range(N_ACTIONS), repeat=steps)),
                         dtype=np.int64).reshape(-1, steps)
    offsets = np.cumsum(ACTION_DELTAS[sequences], axis=1)
    offsets.flags.writeable = False
    return offsets


def _intersect(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 4) intersection of (row0, row1, col0, col1) rectangles, within ``a``'s extent
    even when empty (zero extent: row1 = row0 or col1 = col0), so its sum can be read from
    ``a``'s table."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=np.int64)
    out[..., 0] = np.minimum(np.maximum(a[..., 0], b[..., 0]), a[..., 1])
    out[..., 1] = np.maximum(np.minimum(a[..., 1], b[..., 1]), out[..., 0])
    out[..., 2] = np.minimum(np.maximum(a[..., 2], b[..., 2]), a[..., 3])
    out[..., 3] = np.maximum(np.minimum(a[..., 3], b[..., 3]), out[..., 2])
    return out


def _reached_boxes(paths: _PathTerms, first: np.ndarray) -> list[tuple[int, SegmentBox]]:
    """(altitude, box) of every altitude the valid paths of the ``first`` moves read at: the
    smallest box of whole segments (cut indices i0, i1, j0, j1) holding all their later
    footprints there; kept on ``paths`` per set of first moves."""
    key = first.tobytes()
    found = paths.boxes.get(key)
    if found is not None:
        return found
    later, iz, valid = paths.later[first], paths.altitudes[first], paths.valid[first]
    found = []
    for altitude in np.unique(iz[valid]).tolist():
        reached = later[valid[:, :, None] & (iz == altitude)]
        i0, j0 = reached[:, [0, 2]].min(axis=0).tolist()
        i1, j1 = reached[:, [1, 3]].max(axis=0).tolist()
        found.append((int(altitude), (i0, i1, j0, j1)))
    paths.boxes[key] = found
    return found


def _segment_tables(boxes: list[tuple[int, SegmentBox]],
                    segment_values: Callable[[int, SegmentBox], np.ndarray],
                    shape: tuple[int, int]) -> np.ndarray:
    """(Z, R + 1, C + 1) float64 per altitude of ``boxes`` the summed-area table of the
    values at that altitude over the segments of its box (a grid of ``shape`` = (R, C)
    segments; :mod:`ipp_toolkit.planning.segments`), at the box's segments, so that a
    rectangle's corners index it directly (the rest is never read, but [0, 0, 0] = 0: what
    the empty rectangle of a path off the grid reads)."""
    tables = np.empty((max((altitude for altitude, _ in boxes), default=0) + 1, shape[0] + 1,
                       shape[1] + 1))
    for altitude, (i0, i1, j0, j1) in boxes:
        table = tables[altitude, i0:i1 + 1, j0:j1 + 1]
        values = segment_values(altitude, (i0, i1, j0, j1))
        if kernels.AVAILABLE:
            kernels.summed_area(values, table)
        else:
            table[0], table[:, 0] = 0.0, 0.0
            np.cumsum(values, axis=0, out=table[1:, 1:])
            np.cumsum(table[1:, 1:], axis=1, out=table[1:, 1:])
    tables[0, 0, 0] = 0.0
    return tables


def _rect_sums(tables: np.ndarray, rect: np.ndarray, altitude: np.ndarray) -> np.ndarray:
    """(...) the sums over (..., 4) rectangles (corner indices) read from ``tables`` at
    ``altitude`` (...)."""
    q0, q1, s0, s1 = np.moveaxis(rect, -1, 0)
    return (tables[altitude, q1, s1] - tables[altitude, q0, s1]
            - tables[altitude, q1, s0] + tables[altitude, q0, s0])


class _PathTerms(NamedTuple):
    """The rectangles the lookahead sums for the paths from one waypoint's six first moves,
    as cut indices of a :class:`~ipp_toolkit.planning.segments.SegmentGrid` (see
    :func:`_path_terms`)."""

    valid: np.ndarray  # (6, S) bool: the path stays on the grid of waypoints
    altitudes: np.ndarray  # (6, S, T) int64 altitude of each later footprint (0 off the grid)
    later: np.ndarray  # (6, S, T, 4) int64 the later footprints (0 off the grid)
    rects: np.ndarray  # (K, 6, S, 4) int64 every inclusion-exclusion term's rectangle
    term_step: np.ndarray  # (K,) int64 the later step t of each term, in order
    term_sign: np.ndarray  # (K,) float64 its sign
    boxes: dict[bytes, list[tuple[int, SegmentBox]]]  # _reached_boxes, per set of first moves

    @property
    def nbytes(self) -> int:
        """Bytes of its arrays (the boxes are small)."""
        arrays = [self.valid, self.altitudes, self.later, self.rects, self.term_step,
                  self.term_sign]
        return sum(array.nbytes for array in arrays)


class _KeptPaths:
    """The :class:`_PathTerms` of the last grids, waypoints and depths asked for, oldest
    first, up to :data:`PATH_TERMS_BYTES` in all."""

    def __init__(self) -> None:
        self.entries: OrderedDict[tuple[object, bytes, int], _PathTerms] = OrderedDict()
        self.nbytes = 0

    def get(self, key: tuple[object, bytes, int]) -> _PathTerms | None:
        found = self.entries.get(key)
        if found is not None:
            self.entries.move_to_end(key)
        return found

    def add(self, key: tuple[object, bytes, int], terms: _PathTerms) -> None:
        self.entries[key] = terms
        self.nbytes += terms.nbytes
        while self.nbytes > PATH_TERMS_BYTES and len(self.entries) > 1:
            self.nbytes -= self.entries.popitem(last=False)[1].nbytes


#: Bytes of path terms the process keeps (at most 60 kB per waypoint at d = 3, 0.75 MB at
#: d = 4): shared by every planner of the same footprints and grid.
PATH_TERMS_BYTES = 32 * 2 ** 20
_KEPT_PATHS = _KeptPaths()


def _path_terms(grid: SegmentGrid, rects: np.ndarray, first_targets: np.ndarray,
                steps: int) -> _PathTerms:
    """The footprints of every path of ``steps`` moves whose first move leads to one of
    ``first_targets`` (6, 3), and the rectangles of each later footprint's
    inclusion-exclusion over the earlier ones: a function of the grid (and the footprints
    ``rects`` it was cut from), the waypoint and ``steps`` alone, kept for the last ones
    asked for (:data:`PATH_TERMS_BYTES`).

    Rectangles are the indices of their edges among the grid's cuts: the cuts are ordered,
    so intersections (minima and maxima of edges) are taken on the indices alike. A path
    off the grid of waypoints reads an empty rectangle at the origin (a sum of 0).
    """
    first_targets = np.asarray(first_targets, dtype=np.int64)
    key = (grid.key, first_targets.tobytes(), steps)
    found = _KEPT_PATHS.get(key)
    if found is not None:
        return found
    n_z, n_y, n_x = rects.shape[:3]
    top = np.array([n_x - 1, n_y - 1, n_z - 1])
    starts = np.clip(first_targets, 0, top)  # (6, 3); a start off the grid has no path
    paths = first_targets[:, None, None, :] + _continuations(steps - 1)[None]  # (6, S, T, 3)
    valid = (((paths >= 0) & (paths <= top)).all(axis=(2, 3))
             & ((first_targets >= 0) & (first_targets <= top)).all(axis=1)[:, None])
    ix, iy, iz = np.moveaxis(np.clip(paths, 0, top), -1, 0)
    later = np.where(valid[:, :, None, None], grid.edge_index(rects[iz, iy, ix]), 0)
    iz = np.where(valid[:, :, None], iz, 0)
    first_rects = grid.edge_index(rects[starts[:, 2], starts[:, 1], starts[:, 0]])  # (6, 4)
    earlier = [np.broadcast_to(first_rects[:, None, :], later.shape[:2] + (4,))]
    parts, term_step, term_sign = [], [], []
    for t in range(steps - 1):
        rect = later[:, :, t]
        for chosen in itertools.product((False, True), repeat=len(earlier)):
            part = rect
            for inside, other in zip(chosen, earlier, strict=True):
                if inside:
                    part = _intersect(part, other)
            parts.append(part)
            term_step.append(t)
            term_sign.append((-1.0) ** sum(chosen))
        earlier.append(rect)
    found = _PathTerms(valid, np.ascontiguousarray(iz, dtype=np.int64),
                       np.ascontiguousarray(later, dtype=np.int64),
                       np.ascontiguousarray(np.stack(parts), dtype=np.int64),
                       np.array(term_step, dtype=np.int64),
                       np.array(term_sign, dtype=np.float64), {})
    _KEPT_PATHS.add(key, found)
    return found


def continuation_values(rects: np.ndarray, first_targets: np.ndarray, allowed: np.ndarray,
                        steps: int, discount: float,
                        segment_values: Callable[[int, SegmentBox], np.ndarray],
                        grid: SegmentGrid) -> np.ndarray:
    """(6,) float64 best discounted value of the ``steps - 1`` moves after each first move.

    The planner adds ``discount`` times it to each move's own footprint value.

    Args:
        rects: (Z, G, G, 4) int footprint of every waypoint ([iz, iy, ix]; ``Camera.rects``).
        first_targets: (6, 3) int waypoint (ix, iy, iz) each first move leads to.
        allowed: (6,) bool first moves to evaluate (the others get 0).
        steps: moves looked at in all, the first included (< 2: all 0).
        discount: gamma, the weight per step further along the path.
        segment_values: ``(altitude, box) -> (i1 - i0, j1 - j0)`` float64 the per-cell
            values of a reading at ``altitude`` summed over each segment of ``box`` (i0, i1,
            j0, j1) of ``grid`` (:mod:`ipp_toolkit.planning.segments`).
        grid: the segments: cut by every footprint edge of ``rects``.
    """
    first = np.flatnonzero(allowed)
    values = np.zeros(N_ACTIONS, dtype=np.float64)
    if steps < 2 or len(first) == 0:
        return values
    paths = _path_terms(grid, rects, first_targets, steps)
    tables = _segment_tables(_reached_boxes(paths, first), segment_values, grid.shape)
    weights = np.array([discount ** t for t in range(steps - 1)])
    if kernels.AVAILABLE:
        kernels.path_values(tables, paths.altitudes, paths.rects, paths.term_step,
                            paths.term_sign, weights, first, paths.valid, values)
        return values
    valid, iz = paths.valid[first], paths.altitudes[first]
    total = np.zeros(valid.shape, dtype=np.float64)
    for t in range(steps - 1):
        new = np.zeros(valid.shape, dtype=np.float64)
        # inclusion-exclusion: footprint t minus the union of the earlier ones
        for k in np.flatnonzero(paths.term_step == t).tolist():
            new += paths.term_sign[k] * _rect_sums(tables, paths.rects[k][first], iz[:, :, t])
        total += weights[t] * new
    best = np.where(valid, total, -np.inf).max(axis=1)
    values[first] = np.where(np.isfinite(best), best, 0.0)  # no path on a one-waypoint grid
    return values
