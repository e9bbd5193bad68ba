"""How likely each cell is to be interesting, judged from its neighbourhood.

The belief maps treat cells as independent: a cell nobody has measured sits at the prior
(p = 0.5) even when every cell around it was measured interesting. Real fields are spatially
correlated (hotspots and boundaries are regions, not single cells), so the neighbourhood
says more than the prior. :class:`InterestSmoother` estimates

    pi(c) = sum_c' K(c, c') p(c')

with K a Gaussian of standard deviation ``sigma`` metres, normalised over the cells inside
the area (so the border is not pulled towards 0). The table's metric is the entropy of the
*truly interesting* cells, so the value of reading a cell is pi(c) times the entropy a
reading removes from an interesting cell (:func:`~ipp_toolkit.mapping.interesting_gain`):
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

import numpy as np

__all__ = ["InterestSmoother", "block_means", "interest_smoother", "smoothing_matrix"]

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


def _block_side(size: int, resolution: float) -> int:
    """The largest divisor of ``size`` not above BLOCK_METRES / resolution cells (>= 1)."""
    target = max(1, int(round(BLOCK_METRES / resolution)))
    return max(b for b in range(1, target + 1) if size % b == 0)


def _numpy_block_means(prob: np.ndarray, block: int) -> np.ndarray:
    n = prob.shape[-1] // block
    return prob.reshape(prob.shape[:-2] + (n, block, n, block)).mean(axis=(-3, -1),
                                                                     dtype=np.float32)


def _ordered_block_means(prob: np.ndarray, block: int) -> np.ndarray:
    n = prob.shape[-1] // block
    cells = prob.reshape(prob.shape[:-2] + (n, block, n, block))
    rows = cells[..., 0].astype(np.float32)  # (..., n, block, n): each block row, left to right
    for j in range(1, block):
        rows += cells[..., j]
    sums = rows[..., 0, :].copy()  # then the block's rows, top to bottom
    for i in range(1, block):
        sums += rows[..., i, :]
    return np.true_divide(sums, np.intp(block * block), out=sums, casting="unsafe")


#: Per (shape, block): whether :func:`_ordered_block_means` gave NumPy's numbers on a probe.
_ORDER_CHECKED: dict[tuple[tuple[int, ...], int], bool] = {}


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
    n = prob.shape[-1] // block
    if prob.dtype != np.float32 or not prob.flags.c_contiguous or n < 2 or block >= 8:
        return _numpy_block_means(prob, block)
    key = (prob.shape, block)
    if key not in _ORDER_CHECKED:
        rng = np.random.default_rng(0)
        probe = (rng.standard_normal(prob.shape)
                 * 10.0 ** rng.uniform(-3, 3, prob.shape)).astype(np.float32)
        _ORDER_CHECKED[key] = np.array_equal(_ordered_block_means(probe, block),
                                             _numpy_block_means(probe, block))
    if not _ORDER_CHECKED[key]:
        return _numpy_block_means(prob, block)
    return _ordered_block_means(prob, block)


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
        self.block = _block_side(self.size, resolution)
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
        return self.matrix @ block_means(prob, self.block) @ self.matrix.T

    def window(self, block_values: np.ndarray, rows: slice, cols: slice) -> np.ndarray:
        """The per-cell values of ``block_values`` (one map) inside ``[rows, cols]`` only.

        Equal to ``self(prob)[rows, cols]`` without repeating the whole map back to cells.
        """
        b = self.block
        r = np.arange(rows.start, rows.stop) // b
        c = np.arange(cols.start, cols.stop) // b
        return block_values[r[:, None], c[None, :]]


@functools.lru_cache(maxsize=16)
def interest_smoother(size: int, resolution: float, sigma: float) -> InterestSmoother:
    """The shared :class:`InterestSmoother` of a map size, resolution and sigma (memoised)."""
    return InterestSmoother(size, resolution, sigma)
