"""Expected gain of a reading from every waypoint, kept current incrementally.

The ``gain`` feature planes (and anything else that ranks waypoints by IG's objective) need,
for every local map k, altitude z and waypoint (x, y), the sum over the waypoint's footprint
of the per-cell expected weighted-entropy reduction
(:func:`~ipp_toolkit.belief.mapping.expected_gain`). Computed from scratch this is three
``expected_gain`` passes over every map (250,000 cells each at r_M = 0.1 m) and two cumsums
per pass: ~70 ms per map and step on one core.

Only cells whose belief changed have a new per-cell gain, and a step changes a map only under
the footprints of the readings it fused. :class:`FootprintGainCache` keeps, per local map, the
per-cell gain at every altitude and the footprint sums, and updates both where the maps'
change log (:attr:`~ipp_toolkit.belief.mapping.BeliefMaps.changes`) says a region was refreshed:
the per-cell gain is looked up for the region's log-odds (a table per mission: a cell's gain
is a function of its log-odds), and each waypoint's sum moves by the sum of the change over
the part of its footprint inside the region (footprints are separable into rows and columns,
so all G x G parts are one matrix product per region and altitude). Maps that hold identical
beliefs (every map at D = inf) share one computation as long as they stay identical, checked
exactly inside every refreshed region.

The result equals a full recomputation up to float64 summation order (checked over whole
missions in ``tests/test_gain.py``).

Three per-cell objectives are kept this way (``objective``): ``"ig"``, the ``ig`` planner's
:func:`~ipp_toolkit.belief.mapping.expected_gain`; ``"interesting"``,
:func:`~ipp_toolkit.belief.mapping.interesting_gain` (the entropy a reading removes from a cell
that is interesting); and ``"false_positive"``,
:func:`~ipp_toolkit.belief.mapping.false_positive_gain` (the entropy it removes from a cell
believed interesting that is not). The last two are meant to be weighted by how likely each
cell is to be interesting, or not (:mod:`ipp_toolkit.belief.interest`); that weight moves
everywhere at every step, but it is constant over squares of cells (blocks of ~0.5 m). The
footprints' bounds and the squares' edges cut every map into segments (:class:`BoxLayout`),
and each segment's sum of the per-cell gain is kept per map and summed again only where the
map changed;
:meth:`FootprintGainCache.weighted_sums` then multiplies each segment's sum by its square's
weight and adds the products per footprint: some 15,000 segments per map and altitude at
r_M = 0.1 m instead of 250,000 cells. Every sum is float64 and added in a fixed order, so a
segment summed again equals one summed from scratch and the result is the same on every CPU
(unlike float32 matrix products, whose rounding depends on the BLAS kernel).
"""

from __future__ import annotations

import weakref
from collections.abc import Callable
from functools import partial

import numpy as np

from .._native import kernels
from ..world.sensor import Camera
from .block_grid import Rect
from .box_sums import BoxLayout
from .mapping import (
    BeliefMaps,
    belief_columns,
    expected_gain,
    false_positive_gain,
    interesting_gain,
)
from .value_table import DerivedMemo, ValueTable, exact_memo

__all__ = ["CellGain", "FootprintGainCache", "OBJECTIVES", "cell_objective",
           "footprint_sums", "footprint_sums_in_box", "gains_by_altitude", "objective_table",
           "recomputed_footprint_sums"]

#: (logodds, prob, entropy, accuracy, delta_logodds) -> per-cell gain, all (..., h, w) float32.
CellGain = Callable[..., np.ndarray]
#: The per-cell objectives a :class:`FootprintGainCache` can keep.
OBJECTIVES = ("ig", "interesting", "false_positive")


def cell_objective(objective: str, weights: tuple[float, float],
                   outcome_weighting: str = "predictive") -> CellGain:
    """The per-cell gain function named ``objective`` (see :data:`OBJECTIVES`): the one
    definition the gain planes and the gain-based planners (``ig`` and its family) share.

    ``weights`` are the reward's class weights (interesting, uninteresting) and
    ``outcome_weighting`` how the two readings are weighted
    (:data:`~ipp_toolkit.belief.mapping.OUTCOME_WEIGHTINGS`: ``ig_paper`` flies ``"belief"``);
    only ``"ig"`` reads them.
    """
    if objective == "ig":
        return partial(expected_gain, weight_interesting=weights[0],
                       weight_uninteresting=weights[1], outcome_weighting=outcome_weighting)
    if objective == "interesting":
        return interesting_gain
    if objective == "false_positive":
        return false_positive_gain
    raise ValueError(f"unknown gain objective {objective!r}; expected one of {OBJECTIVES}")


def gains_by_altitude(logodds: np.ndarray, accuracy: np.ndarray, delta_logodds: np.ndarray,
                      cell_gain: CellGain, prob: np.ndarray | None = None,
                      entropy: np.ndarray | None = None) -> list[np.ndarray]:
    """Per-cell gain of a reading at every altitude, for (n,) float32 log-odds values.

    Args:
        logodds: (n,) float32 values.
        accuracy: (Z,) sensor accuracy per altitude (``Camera.accuracy``).
        delta_logodds: (Z, 2) log-odds increments per altitude (``Camera.delta_logodds``).
        cell_gain: the per-cell objective (:func:`cell_objective`).
        prob, entropy: the values' probability and entropy; by default
            :func:`~ipp_toolkit.belief.mapping.belief_columns` of them, the function the maps' value
            table holds, so a gain looked up by log-odds is bit for bit the one computed
            from the maps' caches.

    Returns:
        Z arrays (n,) float32, one per altitude.
    """
    if prob is None or entropy is None:
        prob, entropy = belief_columns(logodds)[:2]
    return [cell_gain(logodds, prob, entropy, accuracy[z], delta_logodds[z])
            for z in range(len(accuracy))]


def objective_table(weights: tuple[float, float], camera: Camera, objective: str,
                    outcome_weighting: str = "predictive") -> ValueTable:
    """A table of the per-cell ``objective`` (:func:`cell_objective` of the class ``weights``
    and ``outcome_weighting``) by log-odds, one column ``altitude_z`` per altitude z of
    ``camera``: the gain-based planners look a map's cells up in it by value."""
    derive = partial(gains_by_altitude, accuracy=camera.accuracy,
                     delta_logodds=camera.delta_logodds,
                     cell_gain=cell_objective(objective, weights, outcome_weighting))
    return ValueTable(derive, [f"altitude_{z}" for z in range(len(camera.accuracy))])


def footprint_sums(cells: np.ndarray, rects: np.ndarray) -> np.ndarray:
    """Sum of ``cells`` over every footprint rectangle, with one summed-area table.

    Args:
        cells: (K, H, W) per-cell values of K maps.
        rects: (G, G, 4) int footprint rectangles (row0, row1, col0, col1) of one altitude.

    Returns:
        (K, G, G) float64 sums.
    """
    k, h, w = cells.shape
    table = np.zeros((k, h + 1, w + 1), dtype=np.float64)
    np.cumsum(cells, axis=1, dtype=np.float64, out=table[:, 1:, 1:])
    np.cumsum(table[:, 1:, 1:], axis=2, out=table[:, 1:, 1:])
    r0, r1, c0, c1 = np.moveaxis(rects, -1, 0)
    return table[:, r1, c1] - table[:, r0, c1] - table[:, r1, c0] + table[:, r0, c0]


def footprint_sums_in_box(gain: np.ndarray, box: Rect, rects: np.ndarray) -> np.ndarray:
    """Sum of ``gain`` over each of a few footprint rectangles inside one box.

    The sums the greedy planners rank their candidate moves by (``ig`` and its family: four
    horizontal moves share a box). Each is a float64 sum of a slice: with a handful of
    rectangles that is ~20x cheaper than the summed-area table of :func:`footprint_sums`,
    and its rounding is fixed by numpy's summation of the slice alone. The two can differ in
    the last bits, so a planner keeps one of them for its ties to stay put.

    Args:
        gain: (h, w) per-cell values of the box.
        box: (row0, row1, col0, col1) of ``gain`` in map cells.
        rects: (K, 4) int footprint rectangles (row0, row1, col0, col1) inside ``box``.

    Returns:
        (K,) float64 sums.
    """
    r0, _, c0, _ = box
    return np.array([gain[q0 - r0:q1 - r0, s0 - c0:s1 - c0].sum(dtype=np.float64)
                     for q0, q1, s0, s1 in np.asarray(rects).tolist()], dtype=np.float64)


def recomputed_footprint_sums(maps: BeliefMaps, n_maps: int, camera: Camera,
                              weights: tuple[float, float], objective: str = "ig",
                              cell_weight: np.ndarray | None = None) -> np.ndarray:
    """(n_maps, Z, G, G) float64 footprint sums computed from the whole maps, from scratch.

    The reference :class:`FootprintGainCache` must equal (and the cost it avoids: three
    per-cell gain passes over every cell of every map). ``cell_weight`` (n_maps, H, W)
    multiplies the per-cell gain first (the reference of
    :meth:`FootprintGainCache.weighted_sums`).
    """
    gain = cell_objective(objective, weights)
    out = np.empty((n_maps, len(camera.accuracy)) + camera.rects.shape[1:3], dtype=np.float64)
    for iz in range(len(camera.accuracy)):
        cells = gain(maps.logodds[:n_maps], maps.prob[:n_maps], maps.entropy[:n_maps],
                     camera.accuracy[iz], camera.delta_logodds[iz])
        if cell_weight is not None:
            cells = cells * cell_weight
        out[:, iz] = footprint_sums(cells, camera.rects[iz])
    return out


def _separable_bounds(rects: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row bounds (Z, G, 2) per waypoint row and column bounds (Z, G, 2) per waypoint column.

    A footprint's rows depend only on the waypoint's y and altitude and its columns only on x
    and altitude (:class:`~ipp_toolkit.world.sensor.Camera`); checked here, as the box sums rely on
    it.
    """
    rows, cols = rects[:, :, :1, 0:2], rects[:, :1, :, 2:4]
    if not (np.array_equal(np.broadcast_to(rows, rects[..., 0:2].shape), rects[..., 0:2])
            and np.array_equal(np.broadcast_to(cols, rects[..., 2:4].shape), rects[..., 2:4])):
        raise ValueError("footprint rectangles are not separable into rows (y) and columns (x)")
    return rows[:, :, 0], cols[:, 0]


def _overlap_matrix(bounds: np.ndarray, lo: int, hi: int) -> np.ndarray:
    """(G, hi - lo) float64: 1 where cell lo + j lies inside waypoint g's bounds [b0, b1)."""
    cells = np.arange(lo, hi)
    return ((cells >= bounds[:, :1]) & (cells < bounds[:, 1:])).astype(np.float64)


class _OverlapCache:
    """Footprint memberships of refreshed regions, ``(iz, *region) -> (rows, cols)``."""

    def __init__(self) -> None:
        self.entries: dict[tuple[int, ...], tuple[np.ndarray, np.ndarray]] = {}
        self.nbytes = 0


_OVERLAP_CACHES: weakref.WeakKeyDictionary[Camera, _OverlapCache] = (
    weakref.WeakKeyDictionary())
_OVERLAP_CACHE_BYTES = 16 << 20  # per camera; cleared when full


def _overlap_cache(camera: Camera) -> _OverlapCache:
    """The overlap cache of ``camera``, shared by every mission that flies it."""
    cache = _OVERLAP_CACHES.get(camera)
    if cache is None:
        cache = _OVERLAP_CACHES[camera] = _OverlapCache()
    return cache


def _coalesce(regions: list[Rect]) -> list[Rect]:
    """One bounding box for overlapping regions where it holds fewer cells than they do."""
    if len(regions) < 2:
        return regions
    box = (min(r[0] for r in regions), max(r[1] for r in regions),
           min(r[2] for r in regions), max(r[3] for r in regions))
    cells = sum((r1 - r0) * (c1 - c0) for r0, r1, c0, c1 in regions)
    return [box] if (box[1] - box[0]) * (box[3] - box[2]) <= cells else regions


class FootprintGainCache:
    """Footprint sums of the expected gain on the first ``n_maps`` maps of ``maps``.

    Build it once per mission (:func:`ipp_toolkit.sim.features.footprint_gain` keeps one on the
    mission state); :meth:`sums` brings it up to date with the maps' change log first.

    Args:
        maps: the belief maps; only their change log and arrays are read.
        n_maps: how many maps (the first ones: the agents' local maps) to follow.
        camera: footprints, accuracies and log-odds increments per altitude.
        weights: the reward's class weights (interesting, uninteresting).
        objective: the per-cell gain kept (:data:`OBJECTIVES`).

    Attributes:
        cells: (n_maps, Z, H, W) float32 per-cell expected gain of the maps that own their
            arrays (``owner[k] == k``; the others' are unset: read ``cells[owner[k]]``).
        totals: (n_maps, Z, G, G) float64 footprint sums of ``cells``, current while
            ``keeps_totals`` (for the owners, as ``cells``).
        keeps_totals: whether ``totals`` is kept current: from the start for the ``"ig"``
            objective, else from the first :meth:`sums` on.
        owner: (n_maps,) int, the map whose arrays map k shares (k itself when not shared).
        segments: per block side of a :meth:`weighted_sums` weight, the altitudes'
            :class:`BoxLayout` and Z arrays (n_maps, R, C) float64 of every map's segment
            sums of ``cells`` (for single cells, ``block = 1``: views of ``cells``).
    """

    def __init__(self, maps: BeliefMaps, n_maps: int, camera: Camera,
                 weights: tuple[float, float], objective: str = "ig") -> None:
        self.maps = maps
        self.camera = camera
        self.objective = objective
        gain_of = cell_objective(objective, weights)
        self.n_altitudes = len(camera.accuracy)
        size = maps.value_index.shape[1]
        grid = camera.rects.shape[1]
        self.cells = np.empty((n_maps, self.n_altitudes, size, size), dtype=np.float32)
        self.totals = np.empty((n_maps, self.n_altitudes, grid, grid), dtype=np.float64)
        # Every map starts at the prior, where the per-cell gain is one number per altitude;
        # the change log then brings the cache to the maps' current beliefs.
        prior = np.full((1, 1, 1), maps.prior_logodds, dtype=np.float32)
        prior_prob = np.full_like(prior, maps.prior_prob)
        prior_entropy = np.full_like(prior, maps.prior_entropy)
        area = ((camera.rects[..., 1] - camera.rects[..., 0])
                * (camera.rects[..., 3] - camera.rects[..., 2]))  # (Z, G, G)
        # Map 0 owns the arrays of all until they differ (owner); a map that leaves copies
        # its group's arrays (_regroup), so only the owner's are filled here.
        for iz in range(self.n_altitudes):
            gain = gain_of(prior, prior_prob, prior_entropy, camera.accuracy[iz],
                           camera.delta_logodds[iz])[0, 0, 0]
            self.cells[0, iz] = gain
            self.totals[0, iz] = area[iz] * np.float64(gain)
        self.row_bounds, self.col_bounds = _separable_bounds(camera.rects)
        self.owner = np.zeros(n_maps, dtype=np.int64)  # all identical at the prior
        self._overlap_cache = _overlap_cache(camera)
        self.table = _GainTable(maps, camera, gain_of,
                                _gain_memo(objective, tuple(weights), camera))
        # Per block side of a weight: the altitudes' layouts and every map's segment sums
        # (Z arrays (n_maps, R, C)), kept from the first weighted_sums with that block on.
        self.segments: dict[int, tuple[list[BoxLayout], list[np.ndarray]]] = {}
        # The ``ig`` objective's readers take sums() at every step; the other objective's
        # take weighted_sums(), so its totals are summed only if sums() is ever asked for.
        self.keeps_totals = objective == "ig"
        self.seen = 0
        self.update()

    def sums(self) -> np.ndarray:
        """(n_maps, Z, G, G) float64 footprint sums of the current beliefs."""
        self.update()
        if not self.keeps_totals:  # first call: summed from the cells, then kept
            owners = np.flatnonzero(self.owner == np.arange(len(self.owner)))
            for iz in range(self.n_altitudes):
                self.totals[owners, iz] = footprint_sums(self.cells[owners, iz],
                                                         self.camera.rects[iz])
            self.keeps_totals = True
        return self.totals[self.owner]

    def weighted_sums(self, cell_weight: np.ndarray, block: int = 1) -> np.ndarray:
        """(n_maps, Z, G, G) float64 footprint sums of a per-cell weight times the per-cell gain.

        The gain's sums over the segments of :class:`BoxLayout` are kept per map and summed
        again only where a map changed; each segment's weight times its sum is added in a
        fixed order: the same numbers on every CPU and with or without Numba.

        Args:
            cell_weight: (n_maps, H / block, W / block) float32 weight of every map's cells,
                constant over ``block`` x ``block`` squares of cells (``block = 1``: one
                weight per cell).
            block: side in cells of the squares ``cell_weight`` is given on (divides H).
        """
        self.update()
        n_maps = len(self.owner)
        size = self.cells.shape[-1]
        if block < 1 or size % block or cell_weight.shape != (n_maps,) + (size // block,) * 2:
            raise ValueError(f"cell_weight must have shape {(n_maps,) + (size // block,) * 2} "
                             f"for blocks of {block} cells, got {cell_weight.shape}")
        cell_weight = np.ascontiguousarray(cell_weight, dtype=np.float32)
        layouts, segment_sums = self._segment_sums(block)
        # Maps that share one belief (every map at D = inf) share one sum: their cells and so
        # their weights are identical.
        owners, inverse = np.unique(self.owner, return_inverse=True)
        sums = np.empty((len(owners),) + self.totals.shape[1:], dtype=np.float64)
        for row, owner in enumerate(owners.tolist()):
            for iz, layout in enumerate(layouts):
                sums[row, iz] = layout.weighted(segment_sums[iz][owner], cell_weight[owner])
        return sums[inverse]

    def _segment_sums(self, block: int) -> tuple[list[BoxLayout], list[np.ndarray]]:
        """The layouts and segment sums for weights on ``block`` x ``block`` squares, summed
        over the whole maps the first time a block side is asked for."""
        found = self.segments.get(block)
        if found is None:
            size = self.cells.shape[-1]
            layouts = [BoxLayout(rows, cols, size, block)
                       for rows, cols in zip(self.row_bounds, self.col_bounds, strict=True)]
            if block == 1:
                # Every segment is one cell, whose float64 sum is its float32 gain, exactly:
                # the cells serve as the segment sums (views, current as they are).
                sums = [self.cells[:, iz] for iz in range(self.n_altitudes)]
            else:
                sums = [np.zeros((len(self.owner),) + layout.shape) for layout in layouts]
                for k in np.flatnonzero(self.owner == np.arange(len(self.owner))).tolist():
                    for iz, layout in enumerate(layouts):
                        layout.segment_sums(self.cells[k, iz], out=sums[iz][k])
            found = self.segments[block] = (layouts, sums)
        return found

    def _kept_segment_sums(self) -> list[tuple[list[BoxLayout], list[np.ndarray]]]:
        """The segment sums kept apart from the cells (every block side but 1)."""
        return [found for block, found in self.segments.items() if block != 1]

    def update(self) -> None:
        """Fold the maps' changes since the last call into the cache."""
        if len(self.maps.changes) == self.seen:
            return
        n_maps = len(self.owner)
        regions: list[list[Rect]] = [[] for _ in range(n_maps)]
        for index, rect in self.maps.changes_since(self.seen, "FootprintGainCache"):
            if index < n_maps:
                regions[index].append(rect)
        self.seen = len(self.maps.changes)
        self._regroup(regions)
        for k in np.flatnonzero(self.owner == np.arange(n_maps)):
            for region in _coalesce(regions[k]):
                self._refresh(int(k), region)

    def _regroup(self, regions: list[list[Rect]]) -> None:
        """Split the groups of maps that shared one belief where their beliefs now differ.

        Two maps of a group were identical before the step and changed only inside their
        refreshed regions, so they are still identical exactly when they agree inside the
        union of both maps' regions. A map that leaves its group starts from copies of the
        group's old arrays (made before any group is refreshed) and is refreshed on its own.
        """
        # Equal indices are equal log-odds (the table interns bit patterns); comparing them
        # leaves the maps' per-cell arrays unbuilt.
        value_index = self.maps.value_index
        old_owner = self.owner.copy()
        for group_owner in np.unique(old_owner).tolist():
            leaders: list[int] = []
            for k in np.flatnonzero(old_owner == group_owner).tolist():
                for leader in leaders:
                    if all(np.array_equal(value_index[k, r0:r1, c0:c1],
                                          value_index[leader, r0:r1, c0:c1])
                           for r0, r1, c0, c1 in set(regions[k]) | set(regions[leader])):
                        self.owner[k] = leader
                        break
                else:
                    leaders.append(k)
                    self.owner[k] = k
                    if k != group_owner:
                        self.cells[k] = self.cells[group_owner]
                        self.totals[k] = self.totals[group_owner]
                        for _, segment_sums in self._kept_segment_sums():
                            for by_map in segment_sums:
                                by_map[k] = by_map[group_owner]

    def _refresh(self, k: int, region: Rect) -> None:
        r0, r1, c0, c1 = region
        if not self.keeps_totals:  # the per-cell gains only
            if kernels.AVAILABLE:
                kernels.gain_lookup(self.table.up_to_date(),
                                    self.maps.value_index[k].view(np.uint32), self.cells[k],
                                    r0, r1, c0, c1)
            else:
                self.cells[k, :, r0:r1, c0:c1] = self.table.lookup(k, region)
        elif kernels.AVAILABLE:
            delta = np.empty((self.n_altitudes, r1 - r0, c1 - c0))
            kernels.gain_changes(self.table.up_to_date(), self.maps.value_index[k].view(np.uint32),
                                 self.cells[k], r0, r1, c0, c1, delta)
        else:
            new = self.table.lookup(k, region)  # (Z, rows, cols)
            old = self.cells[k, :, r0:r1, c0:c1]
            delta = new.astype(np.float64)
            delta -= old
            old[...] = new
        if self.keeps_totals:
            # The part of footprint (y, x) inside the region is rows(y) x cols(x), so all
            # G x G sums of the change are one matrix product: rows @ delta @ cols.T.
            for iz in range(self.n_altitudes):
                rows, cols = self._overlaps(iz, region)
                self.totals[k, iz] += rows @ delta[iz] @ cols.T
        for layouts, segment_sums in self._kept_segment_sums():
            for iz, layout in enumerate(layouts):
                layout.segment_sums(self.cells[k, iz], out=segment_sums[iz][k], region=region)

    def _overlaps(self, iz: int, region: Rect) -> tuple[np.ndarray, np.ndarray]:
        """(G, rows) and (G, cols) float64 memberships of ``region``'s rows and columns in the
        footprints at altitude ``iz`` (:func:`_overlap_matrix`), kept per region: a step
        refreshes the same footprints in every map that heard them, UAVs come back, and the
        missions of one geometry (one camera) share them."""
        key = (iz, *region)
        cache = self._overlap_cache
        found = cache.entries.get(key)
        if found is None:
            r0, r1, c0, c1 = region
            found = (_overlap_matrix(self.row_bounds[iz], r0, r1),
                     _overlap_matrix(self.col_bounds[iz], c0, c1))
            size = found[0].nbytes + found[1].nbytes
            if cache.nbytes + size > _OVERLAP_CACHE_BYTES:
                cache.entries.clear()  # rarely: coalesced regions of many shapes
                cache.nbytes = 0
            cache.entries[key] = found
            cache.nbytes += size
        return found


def _camera_key(camera: Camera) -> tuple[bytes, ...]:
    """What a cell's gain depends on besides its log-odds: the per-altitude accuracies and
    log-odds increments, exactly (dtype and bits)."""
    return tuple(np.asarray(a).dtype.str.encode() + np.asarray(a).tobytes()
                 for a in (camera.accuracy, camera.delta_logodds))


_GAIN_MEMOS: dict[tuple[object, ...], DerivedMemo] = {}


def _gain_memo(objective: str, weights: tuple[float, ...], camera: Camera) -> DerivedMemo:
    """The process-wide :class:`~ipp_toolkit.belief.value_table.DerivedMemo` of the per-altitude
    gains of a log-odds value for this objective and camera: every mission of a
    configuration meets the same values, and computes their gains once per process."""
    key = (objective, weights, _camera_key(camera))
    memo = _GAIN_MEMOS.get(key)
    if memo is None:
        # Copies of the camera's arrays, not the camera: the memo outlives the missions.
        derive = partial(gains_by_altitude, accuracy=camera.accuracy.copy(),
                         delta_logodds=camera.delta_logodds.copy(),
                         cell_gain=cell_objective(objective, weights))
        memo = _GAIN_MEMOS[key] = DerivedMemo(derive, len(camera.accuracy))
    return memo


class _GainTable:
    """The per-cell expected gain per altitude of every log-odds value of the maps' table.

    A cell's gain at altitude z is a function of its log-odds (through its probability and
    entropy), so it is computed once per value of the maps'
    :class:`~ipp_toolkit.belief.value_table.ValueTable`, with the objective's per-cell function on
    the table's own probability and entropy (the maps' caches hold the same numbers), and
    looked up through the maps' ``value_index``: a looked-up gain is bit for bit the one
    computed cell by cell.
    """

    def __init__(self, maps: BeliefMaps, camera: Camera, gain_of: CellGain,
                 memo: DerivedMemo | None = None):
        self.maps = maps
        self.camera = camera
        self.gain_of = gain_of
        self.values = np.empty((len(camera.accuracy), 0), dtype=np.float32)
        self.memo = exact_memo(memo)

    def up_to_date(self) -> np.ndarray:
        """(Z, V) float32 gain of every value of the maps' table, new ones computed now."""
        table, known = self.maps.table, self.values.shape[1]
        if known < len(table):
            size = len(table)
            if self.memo is not None:
                new = self.memo.columns(table.values[known:])
            else:  # the table's own probabilities and entropies
                camera = self.camera
                new = np.stack(gains_by_altitude(
                    table.values[known:], camera.accuracy, camera.delta_logodds, self.gain_of,
                    table.column("prob")[known:size], table.column("entropy")[known:size]))
            self.values = np.concatenate([self.values, new], axis=1)
        return self.values

    def lookup(self, k: int, region: Rect) -> np.ndarray:
        """(Z, rows, cols) float32 expected gain of map ``k``'s cells inside ``region``."""
        r0, r1, c0, c1 = region
        return self.up_to_date()[:, self.maps.value_index[k, r0:r1, c0:c1]]
