"""How likely each cell is to be interesting, judged from its neighbourhood.

The belief maps treat cells as independent: a cell nobody has measured sits at the prior
(p = 0.5) even when every cell around it was measured interesting. Real fields are spatially
correlated (hotspots and boundaries are regions, not single cells), so the neighbourhood
says more than the prior. :class:`InterestSmoother` estimates

    pi(c) = sum_c' K(c, c') p(c')

with K a Gaussian of standard deviation ``sigma`` metres, normalised over the cells inside
the area (so the border is not pulled towards 0). The table's metric is the entropy of the
*truly interesting* cells, so the value of reading a cell is pi(c) times the entropy a
reading removes from an interesting cell (:func:`~ipp_toolkit.belief.mapping.interesting_gain`):
the ``ig_spatial`` planner and the actor's ``gain`` planes with ``gain_smoothing > 0`` rank
waypoints by the footprint sums of that product.

Cost: the probabilities are averaged over blocks of about 0.5 m first (5 x 5 cells at
r_M = 0.1 m), the blocks are smoothed by two small matrix products, and the result is
repeated back to cells. For sigma of several metres the block average changes pi by far
less than a reading does; it keeps the smoothing at ~1 ms per 500 x 500 map.
"""

from __future__ import annotations

import functools
import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .mapping import BeliefMaps

__all__ = ["BlockMeanCache", "InterestSmoother", "block_means", "block_sums", "block_window",
           "interest_smoother", "smoothing_matrix", "square_cells"]

#: Side of the blocks the probabilities are averaged over before smoothing, in metres.
BLOCK_METRES = 0.5


def smoothing_matrix(size: int, sigma: float) -> np.ndarray:
    """(size, size) float32 Gaussian weights of std ``sigma`` (in entries), rows summing to 1.

    Row i holds the weights of entries 0 .. size-1 around entry i; renormalising each row
    over the entries that exist keeps a constant field constant up to the border.
    """
    if not sigma > 0 or not math.isfinite(sigma):
        raise ValueError(f"sigma must be a positive number, got {sigma!r}")
    offsets = np.arange(size)[:, None] - np.arange(size)[None, :]
    weights = np.exp(-0.5 * (offsets / sigma) ** 2)
    return (weights / weights.sum(axis=1, keepdims=True)).astype(np.float32)


def square_cells(size: int, resolution: float) -> int:
    """Side, in cells, of the ~0.5 m squares maps of ``size`` cells per side are averaged
    over: the largest divisor of ``size`` not above BLOCK_METRES / resolution (>= 1; 1 at
    r_M >= 0.5 m). The smoothing here and the learned field prior's inputs share it."""
    target = max(1, int(round(BLOCK_METRES / resolution)))
    return max(b for b in range(1, target + 1) if size % b == 0)


def _numpy_block_means(prob: np.ndarray, block: int) -> np.ndarray:
    n = prob.shape[-1] // block
    return prob.reshape(prob.shape[:-2] + (n, block, n, block)).mean(axis=(-3, -1),
                                                                     dtype=np.float32)


def _ordered_block_sums(prob: np.ndarray, block: int) -> np.ndarray:
    rows, cols = prob.shape[-2] // block, prob.shape[-1] // block  # any rectangle of blocks
    cells = prob.reshape(prob.shape[:-2] + (rows, block, cols, block))
    row_sums = cells[..., 0].astype(np.float32)  # each block row, left to right
    for j in range(1, block):
        row_sums += cells[..., j]
    sums = row_sums[..., 0, :].copy()  # then the block's rows, top to bottom
    for i in range(1, block):
        sums += row_sums[..., i, :]
    return sums


def _ordered_block_means(prob: np.ndarray, block: int) -> np.ndarray:
    sums = _ordered_block_sums(prob, block)
    return np.true_divide(sums, np.intp(block * block), out=sums, casting="unsafe")


def _numpy_block_sums(values: np.ndarray, block: int) -> np.ndarray:
    rows, cols = values.shape[-2] // block, values.shape[-1] // block
    lead = values.shape[:-2]
    # the contiguous axis first: two cheap reductions instead of one strided one
    return values.reshape(lead + (rows * block, cols, block)).sum(axis=-1).reshape(
        lead + (rows, block, cols)).sum(axis=-2)


def block_sums(values: np.ndarray, block: int) -> np.ndarray:
    """(..., n, m) float32 sum of every ``block`` x ``block`` square of (..., n * block,
    m * block) float32 ``values``: bit for bit NumPy's sum over each square's columns, then
    over its rows (the order :func:`block_means` relies on, checked alike), several times
    faster for small blocks."""
    if (values.dtype != np.float32 or not values.flags.c_contiguous
            or not _ordered_matches_numpy(values.shape, block, sums=True)):
        return _numpy_block_sums(values, block)
    return _ordered_block_sums(values, block)


#: Per (shape, block, sums): whether :func:`_ordered_block_means` (or, for sums,
#: :func:`_ordered_block_sums`) gave NumPy's numbers on a probe.
_ORDER_CHECKED: dict[tuple[tuple[int, ...], int, bool], bool] = {}


def block_means(prob: np.ndarray, block: int) -> np.ndarray:
    """(..., n, n) float32 mean of every ``block`` x ``block`` square of (..., n * block,
    n * block) float32 ``prob``: bit for bit ``prob.reshape(..., n, block, n, block)
    .mean(axis=(-3, -1), dtype=np.float32)``, about seven times faster.

    NumPy adds a square's cells in a fixed order here: each of its rows left to right, then
    the row sums top to bottom (its pairwise summation unrolls only runs of 8 or more, so
    ``block < 8``; with one block per side a square is one contiguous run, summed pairwise).
    The whole-array additions below keep that order; they are checked against NumPy's mean
    on a random probe once per shape (a NumPy that adds otherwise gets its own mean back).
    """
    if (prob.dtype != np.float32 or not prob.flags.c_contiguous
            or not _ordered_matches_numpy(prob.shape, block)):
        return _numpy_block_means(prob, block)
    return _ordered_block_means(prob, block)


def _ordered_matches_numpy(shape: tuple[int, ...], block: int, sums: bool = False) -> bool:
    """Whether :func:`_ordered_block_means` gives NumPy's mean (``sums``: whether
    :func:`_ordered_block_sums` gives :func:`_numpy_block_sums`) for float32 maps of
    ``shape`` (False where NumPy sums otherwise: ``block >= 8`` or one block per side; else
    checked on a random probe, once per shape)."""
    if shape[-1] // block < 2 or block >= 8:
        return False
    key = (tuple(shape), block, sums)
    if key not in _ORDER_CHECKED:
        rng = np.random.default_rng(0)
        probe = (rng.standard_normal(shape)
                 * 10.0 ** rng.uniform(-3, 3, shape)).astype(np.float32)
        ordered, reference = ((_ordered_block_sums, _numpy_block_sums) if sums
                              else (_ordered_block_means, _numpy_block_means))
        _ORDER_CHECKED[key] = np.array_equal(ordered(probe, block), reference(probe, block))
    return _ORDER_CHECKED[key]


def block_window(block_values: np.ndarray, block: int, rows: slice, cols: slice) -> np.ndarray:
    """The per-cell values inside ``[rows, cols]`` of values given on ``block`` x ``block``
    squares of cells ((H / block, W / block), one map), without expanding the whole map."""
    r0, c0 = rows.start // block, cols.start // block  # the blocks the window touches
    r1, c1 = -(-rows.stop // block), -(-cols.stop // block)
    cells = np.repeat(np.repeat(block_values[r0:r1, c0:c1], block, axis=0), block, axis=1)
    return cells[rows.start - r0 * block:rows.stop - r0 * block,
                 cols.start - c0 * block:cols.stop - c0 * block]


class InterestSmoother:
    """pi = Gaussian-smoothed probability of the interesting class, per cell.

    Args:
        size: cells per side of the (square) maps.
        resolution: cell side r_M in metres.
        sigma: standard deviation of the smoothing in metres (> 0).

    Shapes: calling it maps (..., size, size) probabilities to the same shape, float32.
    """

    def __init__(self, size: int, resolution: float, sigma: float) -> None:
        if not sigma > 0 or not math.isfinite(sigma):
            raise ValueError(f"the smoothing sigma must be a positive number of metres, "
                             f"got {sigma!r}")
        self.size = int(size)
        self.block = square_cells(self.size, resolution)
        self.sigma = float(sigma)
        blocks = self.size // self.block
        self.matrix = smoothing_matrix(blocks, self.sigma / (self.block * resolution))

    def __call__(self, prob: np.ndarray) -> np.ndarray:
        smooth = self.block_values(prob)
        if self.block == 1:
            return smooth
        return np.repeat(np.repeat(smooth, self.block, axis=-2), self.block, axis=-1)

    def block_values(self, prob: np.ndarray) -> np.ndarray:
        """(..., size / block, size / block) float32 smoothed value of every block."""
        if prob.shape[-2:] != (self.size, self.size):
            raise ValueError(f"expected maps of {self.size} x {self.size} cells, got shape "
                             f"{prob.shape}")
        return self.smooth(block_means(prob, self.block))

    def smooth(self, means: np.ndarray) -> np.ndarray:
        """(..., size / block, size / block) float32 smoothed values of the block means
        ``means`` (:func:`block_means` of the probabilities, same shape)."""
        return self.matrix @ means @ self.matrix.T

    def window(self, block_values: np.ndarray, rows: slice, cols: slice) -> np.ndarray:
        """The per-cell values of ``block_values`` (one map) inside ``[rows, cols]`` only.

        Equal to ``self(prob)[rows, cols]`` without repeating the whole map back to cells.
        """
        return block_window(block_values, self.block, rows, cols)


@functools.lru_cache(maxsize=16)
def interest_smoother(size: int, resolution: float, sigma: float) -> InterestSmoother:
    """The shared :class:`InterestSmoother` of a map size, resolution and sigma (memoised)."""
    return InterestSmoother(size, resolution, sigma)


class BlockMeanCache:
    """``block_means(maps.prob[:n_maps], block)``, kept up to date from the maps' change log.

    Only the blocks a refreshed rectangle touches are summed again, from the probabilities
    their cells hold now (looked up from the maps' value table, so the maps' per-cell arrays
    are never built), each block in the order :func:`block_means` sums it: the same numbers.
    Where that order could not be checked for the full maps' shape (:func:`block_means` then
    takes NumPy's mean), the means are taken from the whole maps at every call instead.

    Args:
        maps: the :class:`~ipp_toolkit.belief.mapping.BeliefMaps` of a mission.
        n_maps: the first ``n_maps`` maps of the stack.
        block: side of the squares in cells (divides the map size).
    """

    def __init__(self, maps: BeliefMaps, n_maps: int, block: int) -> None:
        self.maps, self.n_maps, self.block = maps, n_maps, block
        size = maps.value_index.shape[-1]
        self.incremental = _ordered_matches_numpy((n_maps, size, size), block)
        prior = np.full((1, block, block), maps.prior_prob, dtype=np.float32)
        self._means = np.broadcast_to(_ordered_block_means(prior, block),
                                      (n_maps, size // block, size // block)).copy()
        self._seen = 0

    def means(self) -> np.ndarray:
        """(n_maps, size / block, size / block) float32 block means of the current maps."""
        maps, b = self.maps, self.block
        if not self.incremental:
            return block_means(maps.prob[:self.n_maps], b)
        prob = maps.table.column("prob")
        for m, (r0, r1, c0, c1) in maps.changes_since(self._seen, "BlockMeanCache"):
            if m >= self.n_maps:
                continue
            r0, c0 = r0 // b * b, c0 // b * b  # the blocks the rectangle touches
            r1, c1 = -(-r1 // b) * b, -(-c1 // b) * b
            cells = prob[self.maps.value_index[m, r0:r1, c0:c1]]
            self._means[m, r0 // b:r1 // b, c0 // b:c1 // b] = _ordered_block_means(cells, b)
        self._seen = len(maps.changes)
        return self._means
