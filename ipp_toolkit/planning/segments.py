"""Per-segment sums of a UAV's per-cell values, kept across steps, for the lookahead.

The lookahead (:mod:`ipp_toolkit.planning.lookahead`) sums a planner's per-cell values over
footprints and over the intersections of footprints. Every edge of such a rectangle is the
edge of some footprint, and the probability of interest that the ``interesting`` objective
weights cells by is constant over ~0.5 m blocks (:func:`~ipp_toolkit.belief.interest.
square_cells`). So :class:`SegmentGrid` cuts the map by every footprint edge (all altitudes)
and every block edge into segments (156 x 156 on the default 50 m area at r_M = 0.1 m,
against 500 x 500 cells), and a sum over any such rectangle of per-cell values times a
per-block weight is a sum over whole segments of weight x the segment's sum.

A per-cell value of the ``ig`` family is a column of a table looked up by the cell's
log-odds (:class:`~ipp_toolkit.belief.value_table.ValueTable`), so its segment sums depend
on the UAV's local map alone: :class:`SegmentSums` keeps them per UAV and sums again only
the segments where the map changed since the UAV's last call (its own reading and the ones
it heard: a few footprints). :func:`objective_segment_values` turns them into the segment
values of a planner's objective at one altitude.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._native import kernels
from ..belief.box_sums import BoxLayout
from ..belief.interest import square_cells
from ..belief.value_table import ValueTable
from ..config.schema import WorldConfig
from ..probability import logit
from . import AgentView

__all__ = ["SegmentBox", "SegmentGrid", "SegmentSums", "objective_segment_values"]


#: (i0, i1, j0, j1) a box of whole segments: rows i0..i1 and columns j0..j1 of segments.
SegmentBox = tuple[int, int, int, int]


class SegmentGrid:
    """The cells of a ``size`` x ``size`` map cut by the edges of every footprint of ``rects``
    and of every ``block`` x ``block`` square: a
    :class:`~ipp_toolkit.belief.box_sums.BoxLayout` of the footprints of all altitudes.

    Args:
        rects: (Z, G, G, 4) int footprints (row0, row1, col0, col1) of every waypoint
            (``Camera.rects``).
        size: cells per side of the maps.
        block: side in cells of the squares per-block weights are given on (divides size).

    Attributes:
        layout: the segments' :class:`~ipp_toolkit.belief.box_sums.BoxLayout` (its
            ``row_edges``, ``col_edges`` and ``segment_sums``).
        shape: (R, C), rows and columns of segments.
        key: hashable, equal for grids cut from the same footprints, size and block.
    """

    def __init__(self, rects: np.ndarray, size: int, block: int) -> None:
        rects = np.asarray(rects, dtype=np.int64)
        self.size, self.block = int(size), int(block)
        #: What the segments are a function of: equal keys, equal grids.
        self.key = (self.size, self.block, rects.shape, rects.tobytes())
        self.layout = BoxLayout(rects[..., 0:2].reshape(-1, 2), rects[..., 2:4].reshape(-1, 2),
                                self.size, self.block)
        self.shape = self.layout.shape
        # map coordinate of a cut -> its index among the cuts (-1: not a cut)
        self._row_at = np.full(size + 1, -1, dtype=np.int64)
        self._row_at[self.layout.row_edges] = np.arange(len(self.layout.row_edges))
        self._col_at = np.full(size + 1, -1, dtype=np.int64)
        self._col_at[self.layout.col_edges] = np.arange(len(self.layout.col_edges))
        self._areas = np.outer(np.diff(self.layout.row_edges),
                               np.diff(self.layout.col_edges)).astype(np.float64)
        self._cells: np.ndarray | None = None
        self._sums: np.ndarray | None = None

    @classmethod
    def for_world(cls, rects: np.ndarray, world: WorldConfig) -> SegmentGrid:
        """The grid of a mission's footprints ``rects`` (``Camera.rects``) and of the
        ~0.5 m squares of its ``world`` (:func:`~ipp_toolkit.belief.interest.square_cells`),
        on which the ``interesting`` objective's probability of interest is given."""
        return cls(rects, world.map_cells, square_cells(world.map_cells, world.resolution))

    def edge_index(self, rects: np.ndarray) -> np.ndarray:
        """(..., 4) int the cut indices of the edges of (..., 4) rectangles (row0, row1,
        col0, col1) whose edges are cuts (a footprint, or an intersection of footprints)."""
        rects = np.asarray(rects, dtype=np.int64)
        out = np.empty(rects.shape, dtype=np.int64)
        out[..., :2] = self._row_at[rects[..., :2]]
        out[..., 2:] = self._col_at[rects[..., 2:]]
        return out

    def block_weights(self, blocks: np.ndarray, box: SegmentBox | None = None) -> np.ndarray:
        """(i1 - i0, j1 - j0) float64 the weight of each segment of ``box`` (default: all)
        from (size / block, size / block) per-block weights."""
        i0, i1, j0, j1 = box if box is not None else (0, self.shape[0], 0, self.shape[1])
        layout = self.layout
        rows = np.asarray(blocks).take(layout.row_block[i0:i1], axis=0)
        return rows.take(layout.col_block[j0:j1], axis=1).astype(np.float64)

    def covered(self, rects: np.ndarray, box: SegmentBox | None = None) -> np.ndarray:
        """(i1 - i0, j1 - j0) bool the segments of ``box`` (default: all) inside any of
        (K, 4) footprints."""
        i0, i1, j0, j1 = box if box is not None else (0, self.shape[0], 0, self.shape[1])
        mask = np.zeros((i1 - i0, j1 - j0), dtype=bool)
        for q0, q1, s0, s1 in self.edge_index(np.asarray(rects).reshape(-1, 4)).tolist():
            mask[max(q0 - i0, 0):max(q1 - i0, 0), max(s0 - j0, 0):max(s1 - j0, 0)] = True
        return mask

    def discount(self, values: np.ndarray, rects: np.ndarray, factor: float,
                 box: SegmentBox | None = None) -> None:
        """Scale, in place, the values of ``box``'s segments (default: all) inside any of
        (K, 4) ``rects`` (decided teammates' next footprints) by ``factor``: once per
        segment, however many cover it (:func:`~ipp_toolkit.planning.discount.
        discount_covered`, by segments)."""
        if len(rects) and factor != 1.0:
            values[self.covered(rects, box)] *= factor

    def segment_sums(self, cells: np.ndarray, box: SegmentBox) -> np.ndarray:
        """(i1 - i0, j1 - j0) float64 sums over the segments of ``box`` of (h, w) float32
        per-cell values of the box's cells, in
        :meth:`~ipp_toolkit.belief.box_sums.BoxLayout.segment_sums`' order."""
        r, c = self.layout.row_edges, self.layout.col_edges
        i0, i1, j0, j1 = box
        if self._cells is None:  # scratch: the layout sums cells at their map positions
            self._cells = np.zeros((self.size, self.size), dtype=np.float32)
            self._sums = np.zeros(self.shape)
        assert self._sums is not None
        self._cells[r[i0]:r[i1], c[j0]:c[j1]] = cells
        region = (int(r[i0]), int(r[i1]), int(c[j0]), int(c[j1]))
        return self.layout.segment_sums(self._cells, out=self._sums,
                                        region=region)[i0:i1, j0:j1].copy()

    def constant_sums(self, value: float) -> np.ndarray:
        """(R, C) float64 the segment sums of a map whose every cell holds float32
        ``value``: what :meth:`~ipp_toolkit.belief.box_sums.BoxLayout.segment_sums` gives,
        bit for bit (the float64 sums of fewer than 2^29 copies of a float32 are exact)."""
        return self._areas * np.float64(np.float32(value))


class SegmentSums:
    """Per UAV: the sums over each segment of ``grid`` of table columns of its local map.

    Args:
        grid: the segments.
        tables: the tables looked up by log-odds; each gives the ``columns`` (one per
            altitude, ``altitude_z``).
        columns: the column names, in altitude order.
        start: the log-odds every cell of a map holds at a mission's start (the prior's).

    Calling it with a view gives (T, Z, R, C) float64: table t's column z summed over every
    segment of the view's local map. Kept per agent index: a call sums again only the
    segments of the rows and columns where the map differs from the one of that agent's last
    call, or at a mission's first step from a map at ``start`` (any map works: what differs
    is summed again); asked again for the same view at the same step, it answers at once.
    A UAV whose map is, bit for bit, that of the first heard teammate summed at the same step
    (every UAV's at D = inf) shares that teammate's kept arrays instead of summing its own.
    Missions flown in lock-step through one instance would each find the other's map kept:
    for them, :meth:`box_sums` sums a few boxes from their cells.
    """

    def __init__(self, grid: SegmentGrid, tables: Sequence[ValueTable],
                 columns: Sequence[str], start: float) -> None:
        self.grid = grid
        self.tables = list(tables)
        self.columns = list(columns)
        self.start = np.float32(start)
        self._maps: dict[int, np.ndarray] = {}
        self._sums: dict[int, np.ndarray] = {}
        self._seen: dict[int, tuple[AgentView, int]] = {}  # the view each agent was last summed for

    @classmethod
    def of_tables(cls, grid: SegmentGrid, tables: Sequence[ValueTable],
                  prior: float) -> SegmentSums:
        """The kept sums of every column of ``tables`` (the objective tables' ``altitude_z``,
        in the first table's order) for missions whose maps start at the probability
        ``prior``."""
        return cls(grid, tables, tables[0].names if tables else (), float(logit(prior)))

    def __call__(self, view: AgentView) -> np.ndarray:
        logodds = self._checked_map(view)
        seen = self._seen.get(view.index)
        if seen is not None and seen[0] is view and seen[1] == view.step:
            return self._sums[view.index]  # this view's map, summed by the last call
        if view.index not in self._maps or view.step == 0:
            self._restart(view.index)
        if self._share(view, logodds):
            return self._sums[view.index]
        kept, sums = self._maps[view.index], self._sums[view.index]
        r, c = self.grid.layout.row_edges, self.grid.layout.col_edges
        for n, box in enumerate(self._changed_boxes(kept, logodds)):
            if n == 0:
                kept, sums = self._own(view)
            self._sum_box_into(logodds, box, sums)
            i0, i1, j0, j1 = box
            cells = (slice(r[i0], r[i1]), slice(c[j0], c[j1]))
            kept[cells] = logodds[cells]
        self._seen[view.index] = (view, view.step)
        return sums

    def _share(self, view: AgentView, logodds: np.ndarray) -> bool:
        """Take the kept map and sums of the first heard teammate summed at this step, if its
        map is this view's bit for bit (every UAV's map at D = inf): one refresh for the
        team instead of one per UAV. The arrays are shared until someone changes them
        (:meth:`_own`)."""
        heard = np.asarray(view.teammates)
        for other, (_, step) in self._seen.items():
            if other != view.index and step == view.step:
                if other not in heard:
                    return False
                kept = self._maps[other]
                same = (kernels.same_bits(kept.view(np.uint32), logodds.view(np.uint32))
                        if kernels.AVAILABLE else np.array_equal(kept.view(np.uint32),
                                                                 logodds.view(np.uint32)))
                if same:
                    self._maps[view.index], self._sums[view.index] = kept, self._sums[other]
                    self._seen[view.index] = (view, view.step)
                return same
        return False

    def _own(self, view: AgentView) -> tuple[np.ndarray, np.ndarray]:
        """The view's agent's kept map and sums, to change in place: copies first where
        another agent summed at this step shares them (its answer must stay). One whose
        last call was earlier keeps a map and its sums either way (the changed ones), and
        forgets its last answer."""
        agent = view.index
        kept = self._maps[agent]
        sharing = [other for other in self._maps if other != agent and self._maps[other] is kept]
        if any(self._seen[other][1] == view.step for other in sharing if other in self._seen):
            self._maps[agent] = kept.copy()
            self._sums[agent] = self._sums[agent].copy()
        else:
            for other in sharing:
                self._seen.pop(other, None)
        return self._maps[agent], self._sums[agent]

    def box_sums(self, view: AgentView, box: SegmentBox, altitudes: Sequence[int]
                 ) -> np.ndarray:
        """(T, len(altitudes), i1 - i0, j1 - j0) float64 the tables' columns of
        ``altitudes`` summed over the segments of ``box`` of the view's map, from its cells
        (nothing kept or reused: for a few boxes of a map, as one of several missions flown in
        lock-step sees them)."""
        out = np.empty((len(self.tables), len(altitudes), box[1] - box[0], box[3] - box[2]))
        self._sum_box(self._checked_map(view), box, altitudes, out)
        return out

    def _checked_map(self, view: AgentView) -> np.ndarray:
        logodds = view.local_logodds
        size = self.grid.size
        if logodds.shape != (size, size) or logodds.dtype != np.float32:
            raise ValueError(f"the view's local map is {logodds.dtype} of shape "
                             f"{logodds.shape}; the segments were cut for {size} x {size} "
                             "float32 cells")
        return logodds

    def _sum_box(self, logodds: np.ndarray, box: SegmentBox, altitudes: Sequence[int],
                 out: np.ndarray) -> None:
        """Write the tables' columns of ``altitudes`` summed over ``box``'s segments of
        ``logodds`` into (T, len(altitudes), i1 - i0, j1 - j0) ``out``."""
        r, c = self.grid.layout.row_edges, self.grid.layout.col_edges
        i0, i1, j0, j1 = box
        part = logodds[r[i0]:r[i1], c[j0]:c[j1]]
        for t, table in enumerate(self.tables):
            # Intern first: indices() may grow the table and replace its columns.
            index = table.indices(part)
            for slot, z in enumerate(altitudes):
                out[t, slot] = self.grid.segment_sums(table.column(self.columns[z])[index], box)

    def _sum_box_into(self, logodds: np.ndarray, box: SegmentBox, sums: np.ndarray) -> None:
        """:meth:`_sum_box` of every altitude into the box of (T, Z, R, C) ``sums``, compiled
        where Numba is (the same numbers:
        :func:`~ipp_toolkit._native.kernels.indexed_segment_sums`)."""
        r, c = self.grid.layout.row_edges, self.grid.layout.col_edges
        i0, i1, j0, j1 = box
        if not kernels.AVAILABLE:
            self._sum_box(logodds, box, range(len(self.columns)), sums[..., i0:i1, j0:j1])
            return
        part = logodds[r[i0]:r[i1], c[j0]:c[j1]]
        for t, table in enumerate(self.tables):
            index = table.indices(part)  # first: it may grow the table and its columns
            kernels.indexed_segment_sums(index, tuple(table.column(name) for name in
                                                      self.columns),
                                         r, c, i0, i1, j0, j1, sums[t])

    def _restart(self, agent: int) -> None:
        """Agent ``agent``'s kept map and sums: a map at :attr:`start` everywhere."""
        self._maps[agent] = np.full((self.grid.size,) * 2, self.start, dtype=np.float32)
        sums = np.empty((len(self.tables), len(self.columns)) + self.grid.shape)
        for t, table in enumerate(self.tables):
            index = int(table.indices(np.array([self.start], dtype=np.float32))[0])
            for z, name in enumerate(self.columns):
                sums[t, z] = self.grid.constant_sums(table.column(name)[index])
        self._sums[agent] = sums

    def _changed_boxes(self, kept: np.ndarray, logodds: np.ndarray) -> list[SegmentBox]:
        """Boxes of whole segments covering every cell where ``logodds`` differs from
        ``kept`` (bit patterns compared): one per run of consecutive changed segment rows,
        over the columns that changed in it."""
        layout = self.grid.layout
        r, c = layout.row_edges, layout.col_edges
        first, last = _row_differences(kept, logodds)
        row_differs = first >= 0
        rows = np.flatnonzero(np.logical_or.reduceat(row_differs, r[:-1]))
        boxes: list[SegmentBox] = []
        if len(rows) == 0:
            return boxes
        breaks = np.flatnonzero(np.diff(rows) > 1)
        tops = [rows[0]] + rows[breaks + 1].tolist()
        bottoms = rows[breaks].tolist() + [rows[-1]]
        for top, bottom in zip(tops, bottoms, strict=True):
            i0, i1 = int(top), int(bottom) + 1
            band = row_differs[r[i0]:r[i1]]
            # the segments of the band's first and last differing columns
            j0 = int(np.searchsorted(c, first[r[i0]:r[i1]][band].min(), side="right")) - 1
            j1 = int(np.searchsorted(c, last[r[i0]:r[i1]][band].max(), side="right"))
            boxes.append((i0, i1, j0, j1))
        return boxes


def _row_differences(kept: np.ndarray, logodds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H,) int64 each row's first and last column where two float32 maps' bit patterns
    differ, -1 where the row is the same (:func:`~ipp_toolkit._native.kernels.row_differences`,
    or NumPy)."""
    a, b = kept.view(np.uint32), logodds.view(np.uint32)
    first = np.empty(len(a), dtype=np.int64)
    last = np.empty(len(a), dtype=np.int64)
    if kernels.AVAILABLE:
        kernels.row_differences(a, b, first, last)
    else:
        differs = a != b
        found = differs.any(axis=1)
        first[:] = np.where(found, differs.argmax(axis=1), -1)
        last[:] = np.where(found, differs.shape[1] - 1 - differs[:, ::-1].argmax(axis=1), -1)
    return first, last


def objective_segment_values(sums: np.ndarray, altitude: int, interest: np.ndarray | None,
                             false_positive_weight: float = 0.0) -> np.ndarray:
    """(R, C) float64 the segment values of a reading at ``altitude`` of the ``ig`` family's
    objectives, from a :class:`SegmentSums` result.

    Args:
        sums: (T, Z, R, C) segment sums of the objective's gain table (t = 0) and, for the
            false-positive term, of the ``false_positive`` table (t = 1).
        altitude: the altitude index z of the reading.
        interest: (R, C) the probability of interest of each segment
            (:meth:`SegmentGrid.block_weights`), or None for the ``ig`` objective (the gain
            alone).
        false_positive_weight: w > 0 adds w x (1 - interest) x the false-positive sums (the
            clean-up term, where it applies).
    """
    if interest is None:
        return sums[0, altitude].copy()
    values = interest * sums[0, altitude]
    if false_positive_weight > 0:
        values += false_positive_weight * (1.0 - interest) * sums[1, altitude]
    return values
