"""The planning grid's blocks: which map cells each waypoint's block holds.

The 11 x 11 planning-grid planes the policies see (block means of the maps' probability and
weighted entropy, footprint coverage) are sums over these blocks; :class:`BlockGrid` owns the
partition, and ``Rect`` the map-cell rectangles the toolkit's footprints and refreshed regions
are given as.
"""

from __future__ import annotations

import numpy as np

from ..world.sensor import Rect

__all__ = ["BlockGrid", "Rect"]


class BlockGrid:
    """Partition of the map into the cells of the 11 x 11 planning grid.

    Waypoint k sits at k * spacing; its block holds the map cells whose centres lie within
    spacing / 2 of it (clipped at the border), so the blocks tile the map.

    Args:
        map_cells: map cells per side (H = W).
        grid_points: waypoints per side (G).
        resolution: map cell side in metres.
        spacing: waypoint spacing in metres.
    """

    def __init__(self, map_cells: int, grid_points: int, resolution: float, spacing: float):
        centres = (np.arange(map_cells) + 0.5) * resolution
        block_of_cell = np.clip(np.floor(centres / spacing + 0.5).astype(np.int64), 0,
                                grid_points - 1)
        self.map_cells = map_cells
        self.grid_points = grid_points
        self.block_of_cell = block_of_cell  # (H,) planning-grid block of each row / column
        # edges[k] = first map cell of block k; edges[G] = map_cells.
        self.edges = np.searchsorted(block_of_cell, np.arange(grid_points + 1), side="left")
        if np.any(np.diff(self.edges) <= 0):
            raise ValueError(f"resolution {resolution} m is too coarse for waypoints every "
                             f"{spacing} m: some waypoint block holds no map cell")
        self._ranges: dict[tuple[int, int], tuple[int, int, np.ndarray]] = {}
        sizes = np.diff(self.edges).astype(np.float64)
        self.block_sizes = sizes
        self.block_area = np.outer(sizes, sizes)  # (G, G) cells per block

    def block_range(self, lo: int, hi: int) -> tuple[int, int, np.ndarray]:
        """Blocks overlapped by map cells [lo, hi) and the reduceat offsets inside it.

        Memoised: footprints come from a few hundred camera rectangles, and this sits on the
        simulator's hot path (several calls per map and step).
        """
        key = (lo, hi)
        found = self._ranges.get(key)
        if found is None:
            first = int(np.searchsorted(self.edges, lo, side="right")) - 1
            last = int(np.searchsorted(self.edges, hi, side="left"))  # exclusive
            offsets = np.maximum(self.edges[first:last], lo) - lo
            offsets.setflags(write=False)
            found = self._ranges[key] = (first, last, offsets)
        return found

    def add_block_sums(self, planes: np.ndarray, values: np.ndarray, rect: Rect) -> None:
        """planes[G, G] += block sums of ``values`` (shape of ``rect``) placed at ``rect``."""
        r0, r1, c0, c1 = rect
        br0, br1, row_offsets = self.block_range(r0, r1)
        bc0, bc1, col_offsets = self.block_range(c0, c1)
        sums = np.add.reduceat(np.add.reduceat(values, row_offsets, axis=0, dtype=np.float64),
                               col_offsets, axis=1)
        planes[br0:br1, bc0:bc1] += sums

    def block_means(self, values: np.ndarray) -> np.ndarray:
        """(G, G) mean of a full (H, W) map over each block."""
        sums = np.add.reduceat(np.add.reduceat(values, self.edges[:-1], axis=0, dtype=np.float64),
                               self.edges[:-1], axis=1)
        return sums / self.block_area

    def coverage(self, rects: Rect | np.ndarray) -> np.ndarray:
        """(..., G, G) fraction of each block covered by map-cell rectangles.

        Args:
            rects: one rectangle (r0, r1, c0, c1), or an array (..., 4) of them.
        """
        rects = np.asarray(rects)[..., None]  # (..., 4, 1) against the (G,) block edges
        lo, hi = self.edges[:-1], self.edges[1:]
        rows = np.clip(np.minimum(rects[..., 1, :], hi) - np.maximum(rects[..., 0, :], lo), 0,
                       None) / self.block_sizes
        cols = np.clip(np.minimum(rects[..., 3, :], hi) - np.maximum(rects[..., 2, :], lo), 0,
                       None) / self.block_sizes
        return rows[..., :, None] * cols[..., None, :]
