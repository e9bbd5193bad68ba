"""Weighted sums over footprint boxes, from the segments the boxes cut a map into.

The footprints of one altitude are boxes: footprint (y, x) covers the rows of waypoint row y
and the columns of waypoint column x. Their bounds, and the edges of the squares a weight is
constant on, cut the rows and columns of a map into segments (:class:`BoxLayout`); every
pair of a row and a column segment lies inside one square and inside or outside each box.
So the sum of a per-cell value times a blockwise weight over every box needs the value's
sum over each segment pair once (kept per map by
:class:`~ipp_toolkit.belief.gain.FootprintGainCache` and summed again only where a map changed),
then one product per segment pair and its additions per box. Every sum is float64 and added
in a fixed order, by the compiled kernels (:func:`ipp_toolkit._native.kernels.segment_sums`,
:func:`ipp_toolkit._native.kernels.weighted_segment_sums`) and by their NumPy references here alike.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from .._native import kernels
from .block_grid import Rect

__all__ = ["BoxLayout"]


class BoxLayout:
    """How the footprints of one altitude cut a map into segments, for weighted box sums.

    The footprints' row bounds and the edges of the weight's ``block`` x ``block`` squares
    cut the rows [0, H) into segments, the same bounds and edges the columns; footprint
    (y, x) covers whole row segments ``row_segments[y]`` and whole column segments
    ``col_segments[x]`` (half-open index ranges), and every segment pair lies inside one
    square of the weight. So a footprint's weighted sum is the sum over its segment pairs of
    the pair's weight times the pair's cell sum: the cell sums (:meth:`segment_sums`) change
    only where a map changed and are kept per map, and :meth:`weighted` multiplies and adds
    the few thousand segment pairs instead of every cell, each in one fixed order.

    Attributes:
        block: side in cells of the weight's squares (``block = 1``: a weight per cell).
        row_edges: (R + 1,) int64 cuts from 0 to H; row_segments (G, 2) int64 the first and
            past-the-last segment of each footprint row; row_block (R,) int64 the square row
            of each segment.
        col_edges, col_segments, col_block: the same for the columns.
    """

    def __init__(self, row_bounds: np.ndarray, col_bounds: np.ndarray, size: int,
                 block: int = 1) -> None:
        if block < 1 or size % block:
            raise ValueError(f"block = {block!r} must be a positive divisor of the map's "
                             f"{size} cells")
        self.block = block
        self.row_edges, self.row_segments = _segments(row_bounds, size, block)
        self.col_edges, self.col_segments = _segments(col_bounds, size, block)
        self.row_block = self.row_edges[:-1] // block
        self.col_block = self.col_edges[:-1] // block
        self.shape = (len(self.row_edges) - 1, len(self.col_edges) - 1)
        # The segment of every row and column, as lists: a region's segments are looked up
        # once per map, altitude and step, where NumPy's searchsorted costs more than a sum.
        self._row_segment_of = _segment_of(self.row_edges).tolist()
        self._col_segment_of = _segment_of(self.col_edges).tolist()

    def segment_sums(self, cells: np.ndarray, out: np.ndarray | None = None,
                     region: Rect | None = None) -> np.ndarray:
        """(R, C) float64 sums of ``cells`` over every segment pair, in a fixed order.

        Args:
            cells: (H, W) float32 per-cell values.
            out: (R, C) float64 to write into (a new array by default).
            region: (r0, r1, c0, c1): sum again only the segments that overlap it (the
                others in ``out`` are left as they are).
        """
        if out is None:
            out = np.empty(self.shape, dtype=np.float64)
        if region is None:
            s0, s1, t0, t1 = 0, self.shape[0], 0, self.shape[1]
        else:
            r0, r1, c0, c1 = region
            s0, s1 = self._row_segment_of[r0], self._row_segment_of[r1 - 1] + 1
            t0, t1 = self._col_segment_of[c0], self._col_segment_of[c1 - 1] + 1
        if kernels.AVAILABLE:
            kernels.segment_sums(cells, self.row_edges, self.col_edges, s0, s1, t0, t1, out)
        else:
            out[s0:s1, t0:t1] = self.reference_segment_sums(cells, s0, s1, t0, t1)
        return out

    def weighted(self, segment_sums: np.ndarray, weight: np.ndarray) -> np.ndarray:
        """(G, G) float64 sums over every footprint of the cells times the blockwise weight.

        Args:
            segment_sums: (R, C) float64 :meth:`segment_sums` of the cells; with ``block = 1``
                also the (H, W) float32 cells themselves (each segment is a cell, and its
                float64 sum is its value).
            weight: (H / block, W / block) float32 weight of each square.
        """
        if not kernels.AVAILABLE:
            return self.reference_weighted(segment_sums, weight)
        out = np.empty((len(self.row_segments), len(self.col_segments)), dtype=np.float64)
        kernels.weighted_segment_sums(segment_sums, weight, self.row_block, self.col_block,
                                      self.row_segments, self.col_segments, out)
        return out

    def sums(self, cells: np.ndarray, weight: np.ndarray) -> np.ndarray:
        """(G, G) float64 footprint sums of ``cells`` (H, W) times ``weight`` (blockwise)."""
        return self.weighted(self.segment_sums(cells), weight)

    def reference_segment_sums(self, cells: np.ndarray, s0: int, s1: int, t0: int,
                               t1: int) -> np.ndarray:
        """(s1 - s0, t1 - t0) :meth:`segment_sums` in NumPy, in the kernel's order (every
        sum is ``np.add.reduce`` along axis 0 of a C-contiguous array, which NumPy adds one
        row after another; its ``reduceat`` would not: it sums each column pairwise)."""
        r0, r1 = self.row_edges[s0], self.row_edges[s1]
        c0, c1 = self.col_edges[t0], self.col_edges[t1]
        values = cells[r0:r1, c0:c1].astype(np.float64)
        # Per row segment, per column: the rows added one after another.
        by_rows = _sums_along_rows(values, _pairs(self.row_edges[s0:s1 + 1] - r0))
        # Per (row segment, column segment): the columns added one after another.
        return _sums_along_rows(np.ascontiguousarray(by_rows.T),
                                _pairs(self.col_edges[t0:t1 + 1] - c0)).T

    def reference_weighted(self, segment_sums: np.ndarray, weight: np.ndarray) -> np.ndarray:
        """:meth:`weighted` in NumPy, in the kernel's order."""
        products = segment_sums * weight[np.ix_(self.row_block, self.col_block)].astype(
            np.float64)
        # Per row segment and footprint column its column segments, then per footprint row
        # its row segments.
        by_columns = _sums_along_rows(np.ascontiguousarray(products.T),
                                      self.col_segments)  # (G_x, R)
        return _sums_along_rows(np.ascontiguousarray(by_columns.T), self.row_segments)


def _segment_of(edges: np.ndarray) -> np.ndarray:
    """(edges[-1],) int64 the segment between consecutive ``edges`` that holds each index."""
    return np.repeat(np.arange(len(edges) - 1), np.diff(edges))


def _pairs(edges: np.ndarray) -> np.ndarray:
    """(len(edges) - 1, 2) the [start, end) of every segment between consecutive edges."""
    return np.stack([edges[:-1], edges[1:]], axis=1)


def _sums_along_rows(values: np.ndarray, ranges: Iterable[Sequence[int]]) -> np.ndarray:
    """(len(ranges), ...) the rows ``values[start:end]`` added one after another, per range."""
    return np.stack([np.add.reduce(values[start:end], axis=0) for start, end in ranges])


def _segments(bounds: np.ndarray, size: int, block: int) -> tuple[np.ndarray, np.ndarray]:
    """Cut [0, size) at every bound and every multiple of ``block``: (edges, ranges) as
    :class:`BoxLayout` keeps."""
    bounds = np.asarray(bounds, dtype=np.int64)
    if bounds.min() < 0 or bounds.max() > size or np.any(bounds[:, 0] > bounds[:, 1]):
        raise ValueError(f"footprint bounds must be ordered and lie within [0, {size}]")
    edges = np.unique(np.concatenate([np.arange(0, size + 1, block), bounds.ravel()]))
    ranges = np.searchsorted(edges, bounds)  # (G, 2) first and past-the-last segment
    return edges, ranges
