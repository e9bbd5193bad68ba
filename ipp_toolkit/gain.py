"""Expected gain of a reading from every waypoint, kept current incrementally.

The ``gain`` feature planes (and anything else that ranks waypoints by IG's objective) need,
for every local map k, altitude z and waypoint (x, y), the sum over the waypoint's footprint
of the per-cell expected weighted-entropy reduction
(:func:`~ipp_toolkit.mapping.expected_gain`). Computed from scratch this is three
``expected_gain`` passes over every map (250,000 cells each at r_M = 0.1 m) and two cumsums
per pass: ~70 ms per map and step on one core.

Only cells whose belief changed have a new per-cell gain, and a step changes a map only under
the footprints of the readings it fused. :class:`FootprintGainCache` keeps, per local map, the
per-cell gain at every altitude and the footprint sums, and updates both where the maps'
change log (:attr:`~ipp_toolkit.mapping.BeliefMaps.changes`) says a region was refreshed:
the per-cell gain is looked up for the region's log-odds (a table per mission: a cell's gain
is a function of its log-odds), and each waypoint's sum moves by the sum of the change over
the part of its footprint inside the region (footprints are separable into rows and columns,
so all G x G parts are one matrix product per region and altitude). Maps that hold identical
beliefs (every map at D = inf) share one computation as long as they stay identical, checked
exactly inside every refreshed region.

The result equals a full recomputation up to float64 summation order (checked over whole
missions in ``tests/test_gain.py``).

Two per-cell objectives are kept this way (``objective``): ``"ig"``, the ``ig`` planner's
:func:`~ipp_toolkit.mapping.expected_gain`, and ``"interesting"``,
:func:`~ipp_toolkit.mapping.interesting_gain` (the entropy a reading removes from a cell
that is interesting). The second is meant to be weighted by how likely each cell is to be
interesting (:mod:`ipp_toolkit.interest`); that weight moves everywhere at every step, so
:meth:`FootprintGainCache.weighted_sums` multiplies and sums whole maps (two matrix products
per map and altitude), while the per-cell gains under it are still kept incrementally.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial

import numpy as np

from . import kernels
from .mapping import BeliefMaps, expected_gain, interesting_gain
from .sensor import Camera

__all__ = ["FootprintGainCache", "OBJECTIVES", "cell_objective", "footprint_sums",
           "recomputed_footprint_sums"]

Rect = tuple[int, int, int, int]
#: (logodds, prob, entropy, accuracy, delta_logodds) -> per-cell gain, all (..., h, w) float32.
CellGain = Callable[..., np.ndarray]
#: The per-cell objectives a :class:`FootprintGainCache` can keep.
OBJECTIVES = ("ig", "interesting")


def cell_objective(objective: str, weights: tuple[float, float]) -> CellGain:
    """The per-cell gain function named ``objective`` (see :data:`OBJECTIVES`).

    ``weights`` are the reward's class weights (interesting, uninteresting); only ``"ig"``
    reads them.
    """
    if objective == "ig":
        return partial(expected_gain, weight_interesting=weights[0],
                       weight_uninteresting=weights[1])
    if objective == "interesting":
        return interesting_gain
    raise ValueError(f"unknown gain objective {objective!r}; expected one of {OBJECTIVES}")


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
    and altitude (:class:`~ipp_toolkit.sensor.Camera`); checked here, as the box sums rely on it.
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

    Build it once per mission (:func:`ipp_toolkit.features.footprint_gain` keeps one on the
    mission state); :meth:`sums` brings it up to date with the maps' change log first.

    Args:
        maps: the belief maps; only their change log and arrays are read.
        n_maps: how many maps (the first ones: the agents' local maps) to follow.
        camera: footprints, accuracies and log-odds increments per altitude.
        weights: the reward's class weights (interesting, uninteresting).
        objective: the per-cell gain kept (:data:`OBJECTIVES`).

    Attributes:
        cells: (n_maps, Z, H, W) float32 per-cell expected gain.
        totals: (n_maps, Z, G, G) float64 footprint sums of ``cells``.
        owner: (n_maps,) int, the map whose arrays map k shares (k itself when not shared).
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
        for iz in range(self.n_altitudes):
            gain = gain_of(prior, prior_prob, prior_entropy, camera.accuracy[iz],
                           camera.delta_logodds[iz])[0, 0, 0]
            self.cells[:, iz] = gain
            self.totals[:, iz] = area[iz] * np.float64(gain)
        self.row_bounds, self.col_bounds = _separable_bounds(camera.rects)
        self.owner = np.zeros(n_maps, dtype=np.int64)  # all identical at the prior
        self._overlap_cache: dict[tuple[int, ...], tuple[np.ndarray, np.ndarray]] = {}
        self.table = _GainTable(maps, camera, gain_of)
        # 0/1 row and column memberships of every footprint over the whole map, for
        # weighted_sums: (Z, G, H) and (Z, W, G).
        self.rows_full = np.stack([_overlap_matrix(b, 0, size) for b in self.row_bounds]
                                  ).astype(np.float32)
        self.cols_full_t = np.stack([_overlap_matrix(b, 0, size).T for b in self.col_bounds]
                                    ).astype(np.float32)
        self.seen = 0
        self._product: np.ndarray | None = None  # weighted_sums' buffer, (Z, H, W) float32
        self.update()

    def sums(self) -> np.ndarray:
        """(n_maps, Z, G, G) float64 footprint sums of the current beliefs."""
        self.update()
        return self.totals[self.owner]

    def weighted_sums(self, cell_weight: np.ndarray, block: int = 1) -> np.ndarray:
        """(n_maps, Z, G, G) float64 footprint sums of a per-cell weight times the per-cell gain.

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
        # Maps that share one belief (every map at D = inf) share one product: their cells
        # and so their weights are identical. One map at a time through one buffer: the same
        # products and the same matrix products per altitude as one stacked expression,
        # without a temporary the size of every map's cells.
        owners, inverse = np.unique(self.owner, return_inverse=True)
        if self._product is None:
            self._product = np.empty(self.cells.shape[1:], dtype=np.float32)
        product = self._product
        n_altitudes = self.cells.shape[1]
        sums = np.empty((len(owners),) + self.totals.shape[1:], dtype=np.float32)
        for row, owner in enumerate(owners.tolist()):
            cells = self.cells[owner]
            if block > 1:
                # The weights repeated along the rows only: broadcast over each square's
                # rows, the product still runs along whole rows (faster than repeating both
                # ways, and than broadcasting over 5 x 5 squares). The same products either
                # way.
                weight = np.repeat(cell_weight[owner], block, axis=-1)  # (H / block, W)
                squares = (n_altitudes, size // block, block, size)
                np.multiply(cells.reshape(squares), weight[None, :, None, :],
                            out=product.reshape(squares))
            else:
                np.multiply(cells, cell_weight[owner][None], out=product)
            sums[row] = self.rows_full @ product @ self.cols_full_t
        return sums[inverse].astype(np.float64)

    def update(self) -> None:
        """Fold the maps' changes since the last call into the cache."""
        changes = self.maps.changes
        if len(changes) == self.seen:
            return
        if len(changes) < self.seen:
            raise RuntimeError("the maps' change log was cut: build a new FootprintGainCache")
        n_maps = len(self.owner)
        regions: list[list[Rect]] = [[] for _ in range(n_maps)]
        for index, rect in changes[self.seen:]:
            if index < n_maps and rect not in regions[index]:
                regions[index].append(rect)
        self.seen = len(changes)
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

    def _refresh(self, k: int, region: Rect) -> None:
        r0, r1, c0, c1 = region
        if kernels.AVAILABLE:
            delta = np.empty((self.n_altitudes, r1 - r0, c1 - c0))
            kernels.gain_changes(self.table.up_to_date(), self.maps.value_index[k].view(np.uint32),
                                 self.cells[k], r0, r1, c0, c1, delta)
        else:
            new = self.table.lookup(k, region)  # (Z, rows, cols)
            old = self.cells[k, :, r0:r1, c0:c1]
            delta = new.astype(np.float64)
            delta -= old
            old[...] = new
        # The part of footprint (y, x) inside the region is rows(y) x cols(x), so all G x G
        # sums of the change are one matrix product: rows @ delta @ cols.T.
        for iz in range(self.n_altitudes):
            rows, cols = self._overlaps(iz, region)
            self.totals[k, iz] += rows @ delta[iz] @ cols.T

    def _overlaps(self, iz: int, region: Rect) -> tuple[np.ndarray, np.ndarray]:
        """(G, rows) and (G, cols) float64 memberships of ``region``'s rows and columns in the
        footprints at altitude ``iz`` (:func:`_overlap_matrix`), kept per region: a step
        refreshes the same footprints in every map that heard them, and UAVs come back."""
        key = (iz, *region)
        found = self._overlap_cache.get(key)
        if found is None:
            r0, r1, c0, c1 = region
            found = self._overlap_cache[key] = (_overlap_matrix(self.row_bounds[iz], r0, r1),
                                                _overlap_matrix(self.col_bounds[iz], c0, c1))
        return found


class _GainTable:
    """The per-cell expected gain per altitude of every log-odds value of the maps' table.

    A cell's gain at altitude z is a function of its log-odds (through its probability and
    entropy), so it is computed once per value of the maps'
    :class:`~ipp_toolkit.value_table.ValueTable`, with the objective's per-cell function on
    the table's own probability and entropy (the maps' caches hold the same numbers), and
    looked up through the maps' ``value_index``: a looked-up gain is bit for bit the one
    computed cell by cell.
    """

    def __init__(self, maps: BeliefMaps, camera: Camera, gain_of: CellGain):
        self.maps = maps
        self.camera = camera
        self.gain_of = gain_of
        self.values = np.empty((len(camera.accuracy), 0), dtype=np.float32)

    def _derive(self, logodds: np.ndarray, prob: np.ndarray, entropy: np.ndarray
                ) -> np.ndarray:
        """(Z, n) float32 per-altitude gain of n values (their probability and entropy)."""
        camera = self.camera
        return np.stack([self.gain_of(logodds, prob, entropy, camera.accuracy[iz],
                                      camera.delta_logodds[iz])
                         for iz in range(len(camera.accuracy))])

    def up_to_date(self) -> np.ndarray:
        """(Z, V) float32 gain of every value of the maps' table, new ones computed now."""
        table, known = self.maps.table, self.values.shape[1]
        if known < len(table):
            size = len(table)
            new = self._derive(table.values[known:], table.column("prob")[known:size],
                               table.column("entropy")[known:size])
            self.values = np.concatenate([self.values, new], axis=1)
        return self.values

    def lookup(self, k: int, region: Rect) -> np.ndarray:
        """(Z, rows, cols) float32 expected gain of map ``k``'s cells inside ``region``."""
        r0, r1, c0, c1 = region
        return self.up_to_date()[:, self.maps.value_index[k, r0:r1, c0:c1]]
