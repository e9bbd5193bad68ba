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
taken from a summed-area table of each altitude's per-cell values, summed first into the
cells of the grid the footprints' edges cut the box the paths can reach into. Paths that
leave the grid of waypoints are skipped; a path is as long as the steps left in the mission
allow.

The per-cell values come from the planner (a callable), with whatever the planner applies to
the first move (a teammate's same-step discount) applied to the whole path: used by the
``ig`` family (``lookahead_steps``) and by the planners that read the gain planes
(:class:`~ipp_toolkit.planners.discount.TeammateDiscount`).

Cost per UAV and step: the per-cell values of each altitude the paths reach over that box
(about 25-35 m square at d = 3), two passes summing them into the edges' grid, and 6^(d-1)
paths per move.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable

import numpy as np

from ..sim.team import ACTION_DELTAS, N_ACTIONS
from . import AgentView

__all__ = ["LOOKAHEAD_DISCOUNT", "LOOKAHEAD_STEPS", "MAX_LOOKAHEAD_STEPS", "check_lookahead",
           "continuation_values", "mission_lookahead", "steps_left"]

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
    of each other half as often again; with communication it fell (docs/lookahead.md).
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


def _rectangle_sums(later: np.ndarray, iz: np.ndarray, valid: np.ndarray,
                    first_rects: np.ndarray,
                    cell_values: Callable[[int, tuple[int, int, int, int]], np.ndarray]
                    ) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """``sums(rect, altitude)``: the per-cell values at ``altitude`` summed over (..., 4)
    rectangles whose edges are edges of ``later`` (A, S, T, 4) or ``first_rects`` (A, 4)
    footprints and that lie in the box of the valid later footprints at that altitude.

    Every sum the lookahead takes is over a later footprint or a part of it, read at that
    footprint's altitude, so per altitude the values are summed into the cells of the grid
    the footprints' edges cut that box into, and one small summed-area table is taken over
    that grid.
    """
    from .discount import bounding_box  # discount imports this module

    reached = np.unique(iz[valid]).tolist()
    row_edges = np.unique(np.concatenate([first_rects[:, :2].ravel(),
                                          later[valid][..., :2].ravel()]))
    col_edges = np.unique(np.concatenate([first_rects[:, 2:].ravel(),
                                          later[valid][..., 2:].ravel()]))
    size = int(max(row_edges[-1], col_edges[-1])) + 1
    n_z = int(iz.max()) + 1
    row_index = np.zeros((n_z, size), dtype=np.int64)  # map row -> table row, per altitude
    col_index = np.zeros((n_z, size), dtype=np.int64)
    tables = np.zeros((n_z, len(row_edges), len(col_edges)), dtype=np.float64)
    for altitude in reached:
        r0, r1, c0, c1 = bounding_box(later[valid[:, :, None] & (iz == altitude)])
        rows = row_edges[(row_edges >= r0) & (row_edges <= r1)]
        cols = col_edges[(col_edges >= c0) & (col_edges <= c1)]
        row_index[altitude, rows] = np.arange(len(rows))
        col_index[altitude, cols] = np.arange(len(cols))
        grid = np.add.reduceat(np.asarray(cell_values(altitude, (r0, r1, c0, c1)),
                                          dtype=np.float64), rows[:-1] - r0, axis=0)
        grid = np.add.reduceat(grid, cols[:-1] - c0, axis=1)
        table = tables[altitude, 1:len(rows), 1:len(cols)]
        np.cumsum(grid, axis=0, out=table)
        np.cumsum(table, axis=1, out=table)

    def sums(rect: np.ndarray, altitude: np.ndarray) -> np.ndarray:
        q0, q1 = row_index[altitude, rect[..., 0]], row_index[altitude, rect[..., 1]]
        s0, s1 = col_index[altitude, rect[..., 2]], col_index[altitude, rect[..., 3]]
        return (tables[altitude, q1, s1] - tables[altitude, q0, s1]
                - tables[altitude, q1, s0] + tables[altitude, q0, s0])

    return sums


def continuation_values(rects: np.ndarray, first_targets: np.ndarray, allowed: np.ndarray,
                        steps: int, discount: float,
                        cell_values: Callable[[int, tuple[int, int, int, int]], np.ndarray]
                        ) -> np.ndarray:
    """(6,) float64 best discounted value of the ``steps - 1`` moves after each first move.

    The planner adds ``discount`` times it to each move's own footprint value.

    Args:
        rects: (Z, G, G, 4) int footprint of every waypoint ([iz, iy, ix]; ``Camera.rects``).
        first_targets: (6, 3) int waypoint (ix, iy, iz) each first move leads to.
        allowed: (6,) bool first moves to evaluate (the others get 0).
        steps: moves looked at in all, the first included (< 2: all 0).
        discount: gamma, the weight per step further along the path.
        cell_values: ``(altitude, box) -> (h, w)`` per-cell value of a reading at
            ``altitude`` of each cell of ``box`` (row0, row1, col0, col1).
    """
    n_z, n_y, n_x = rects.shape[:3]
    first = np.flatnonzero(allowed)
    values = np.zeros(N_ACTIONS, dtype=np.float64)
    if steps < 2 or len(first) == 0:
        return values
    top = np.array([n_x - 1, n_y - 1, n_z - 1])
    starts = np.asarray(first_targets, dtype=np.int64)[first]  # (A, 3)
    paths = starts[:, None, None, :] + _continuations(steps - 1)[None]  # (A, S, T, 3)
    valid = ((paths >= 0) & (paths <= top)).all(axis=(2, 3))  # (A, S)
    ix, iy, iz = np.moveaxis(np.clip(paths, 0, top), -1, 0)
    later = rects[iz, iy, ix]  # (A, S, T, 4)
    first_rects = rects[starts[:, 2], starts[:, 1], starts[:, 0]]  # (A, 4)
    sums = _rectangle_sums(later, iz, valid, first_rects, cell_values)
    # A path off the grid reads nothing: an empty rectangle (all zero).
    iz = np.where(valid[:, :, None], iz, 0)
    later = np.where(valid[:, :, None, None], later, 0)
    earlier = [np.broadcast_to(first_rects[:, None, :], later.shape[:2] + (4,))]
    total = np.zeros(valid.shape, dtype=np.float64)
    for t in range(steps - 1):
        rect, altitude = later[:, :, t], iz[:, :, t]
        new = np.zeros(valid.shape, dtype=np.float64)
        # inclusion-exclusion: footprint t minus the union of the earlier ones
        for chosen in itertools.product((False, True), repeat=len(earlier)):
            part = rect
            for inside, other in zip(chosen, earlier, strict=True):
                if inside:
                    part = _intersect(part, other)
            new += (-1.0) ** sum(chosen) * sums(part, altitude)
        total += discount ** t * new
        earlier.append(rect)
    best = np.where(valid, total, -np.inf).max(axis=1)
    values[first] = np.where(np.isfinite(best), best, 0.0)  # no path on a one-waypoint grid
    return values
