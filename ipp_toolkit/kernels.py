"""Compiled inner loops of the belief maps (Numba), with the NumPy code as their reference.

A refresh of one footprint rectangle of one map (:meth:`ipp_toolkit.mapping.BeliefMaps.refresh`)
reads each cell's log-odds, finds its value in the maps'
:class:`~ipp_toolkit.value_table.ValueTable`, writes the cached probability, entropy and
weighted entropy and moves the planning-grid block sums by the change; for the global map it
also moves the running sums of the metrics and the reward. In NumPy that is some twenty passes
over the rectangle; compiled it is two (find the values, then apply them), several times
faster, with bit-identical cached values (the kernels only look values up, every value is
computed by the table's NumPy code) and block and metric sums equal up to float64 summation
order.

Numba is a dependency of the toolkit; where it cannot be imported (an exotic platform, or
``IPP_TOOLKIT_NO_NUMBA=1`` in the environment, which the tests use to check both paths) the
callers fall back to their NumPy code and :data:`AVAILABLE` is False. Compiled functions are
cached on disk (``cache=True``), so a new process (an evaluation worker) loads them instead of
compiling them again.
"""

from __future__ import annotations

import os

import numpy as np

__all__ = ["AVAILABLE", "find_or_add", "apply_values", "apply_values_with_stats",
           "N_STATS"]

N_STATS = 7
"""Entries of the statistics vector of :func:`apply_values_with_stats`: the changes of the sum
of H over interesting cells, of the sum of (1 - p)^2 over them, of the true and of the predicted
positives, then the sum of W' H (posterior weights, prior entropies), of W H before and of
W' H' after."""

AVAILABLE = False
if os.environ.get("IPP_TOOLKIT_NO_NUMBA", "") in ("", "0"):
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency; this is the fallback
        numba = None
    if numba is not None:
        AVAILABLE = True

if AVAILABLE:
    _jit = numba.njit(cache=True, nogil=True, boundscheck=False)

    @_jit
    def find_or_add(bits, slot, table_bits, size, shift, multiplier, out):  # pragma: no cover
        """out[i, j] = index of bits[i, j] in an open-addressing table, adding new patterns.

        Args:
            bits: (rows, cols) uint32 bit patterns (of float32 values; any strides).
            slot: (2**b,) intp hash slot -> index (-1 empty); at most half full afterwards
                (the caller reserves room).
            table_bits: (capacity,) uint32 pattern of each index; new ones appended at
                ``size``.
            size: how many patterns the table holds.
            shift, multiplier: the hash, ``(pattern * multiplier mod 2**32) >> shift``.
            out: (rows, cols) intp output.

        Returns:
            the new size (new patterns got indices size.. in order of first appearance).
        """
        mask = slot.shape[0] - 1
        rows, cols = bits.shape
        for i in range(rows):
            for j in range(cols):
                pattern = bits[i, j]
                s = np.intp(np.uint32(pattern * multiplier) >> shift)
                while True:
                    index = slot[s]
                    if index < 0:
                        table_bits[size] = pattern
                        slot[s] = size
                        out[i, j] = size
                        size += 1
                        break
                    if table_bits[index] == pattern:
                        out[i, j] = index
                        break
                    s = (s + 1) & mask
        return size

    @_jit
    def apply_values(ids, value_index, prob, entropy, wentropy, table_prob, table_entropy,
                     table_wentropy, block_of_row, block_of_col, prob_blocks,
                     wentropy_blocks):  # pragma: no cover
        """Write the caches of one rectangle from its value indices; move the block sums.

        Args:
            ids: (rows, cols) intp value index of every cell.
            value_index, prob, entropy, wentropy: (rows, cols) views of the map's caches.
            table_prob, table_entropy, table_wentropy: (n,) float32 columns of the table.
            block_of_row, block_of_col: (rows,), (cols,) planning-grid block of each row and
                column of the rectangle.
            prob_blocks, wentropy_blocks: (G, G) float64 block sums of the map, updated.
        """
        rows, cols = ids.shape
        for i in range(rows):
            block_row = block_of_row[i]
            for j in range(cols):
                index = ids[i, j]
                new_prob = table_prob[index]
                new_wentropy = table_wentropy[index]
                block_col = block_of_col[j]
                prob_blocks[block_row, block_col] += np.float64(new_prob - prob[i, j])
                wentropy_blocks[block_row, block_col] += np.float64(new_wentropy
                                                                    - wentropy[i, j])
                value_index[i, j] = index
                prob[i, j] = new_prob
                entropy[i, j] = table_entropy[index]
                wentropy[i, j] = new_wentropy

    @_jit
    def apply_values_with_stats(ids, value_index, prob, entropy, wentropy, table_prob,
                                table_entropy, table_weights, table_wentropy, block_of_row,
                                block_of_col, prob_blocks, wentropy_blocks,
                                truth):  # pragma: no cover
        """:func:`apply_values`, also returning the changes of the metric and reward sums.

        Args:
            truth: (rows, cols) bool ground truth of the rectangle; the other arguments as
                in :func:`apply_values`, plus the table's class weights ``table_weights``.

        Returns:
            (N_STATS,) float64, see :data:`N_STATS`.
        """
        stats = np.zeros(N_STATS)
        two = np.float32(2.0)
        half = np.float32(0.5)
        rows, cols = ids.shape
        for i in range(rows):
            block_row = block_of_row[i]
            for j in range(cols):
                index = ids[i, j]
                old_prob = prob[i, j]
                old_entropy = entropy[i, j]
                old_wentropy = wentropy[i, j]
                new_prob = table_prob[index]
                new_entropy = table_entropy[index]
                new_wentropy = table_wentropy[index]
                block_col = block_of_col[j]
                prob_blocks[block_row, block_col] += np.float64(new_prob - old_prob)
                wentropy_blocks[block_row, block_col] += np.float64(new_wentropy
                                                                    - old_wentropy)
                if truth[i, j]:
                    stats[0] += np.float64(new_entropy - old_entropy)
                    stats[1] += np.float64((old_prob - new_prob) * (two - old_prob - new_prob))
                    stats[2] += int(new_prob > half) - int(old_prob > half)
                stats[3] += int(new_prob > half) - int(old_prob > half)
                stats[4] += np.float64(table_weights[index] * old_entropy)
                stats[5] += np.float64(old_wentropy)
                stats[6] += np.float64(new_wentropy)
                value_index[i, j] = index
                prob[i, j] = new_prob
                entropy[i, j] = new_entropy
                wentropy[i, j] = new_wentropy
        return stats
else:  # pragma: no cover - exercised with IPP_TOOLKIT_NO_NUMBA=1
    find_or_add = apply_values = apply_values_with_stats = None
