"""The Numba kernels of :mod:`ipp_toolkit.kernels` (imported on first use; see there)."""

from __future__ import annotations

import numba
import numpy as np

from .kernels import N_STATS

_jit = numba.njit(cache=True, nogil=True, boundscheck=False)


@_jit
def find_or_add(bits, slot, table_bits, size, shift, multiplier, out):
    """See :func:`ipp_toolkit.kernels.find_or_add`."""
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
                 wentropy_blocks):
    """See :func:`ipp_toolkit.kernels.apply_values`."""
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
                            truth):
    """See :func:`ipp_toolkit.kernels.apply_values_with_stats`."""
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
