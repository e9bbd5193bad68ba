"""The Numba kernels of :mod:`ipp_toolkit._native.kernels` (imported on first use; see there)."""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from .region_stats import N_STATS

_jit = numba.njit(cache=True, nogil=True, boundscheck=False)


@intrinsic
def _prefetch(typingctx, array, index):
    """Ask the CPU to fetch the cache line of ``array[index]`` (1-D) ahead of its use.

    A footprint's rows are short (a few hundred bytes each, one map row apart), too short
    for the hardware prefetchers; fetching the next row while the current one is worked on
    keeps the passes from waiting on memory one row at a time.
    """
    def codegen(context, builder, signature, args):
        array_type = signature.args[0]
        view = context.make_array(array_type)(context, builder, args[0])
        pointer = cgutils.get_item_pointer(context, builder, array_type, view, [args[1]],
                                           wraparound=False)
        byte_pointer = ir.IntType(8).as_pointer()
        i32 = ir.IntType(32)
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [byte_pointer, i32, i32, i32]),
            "llvm.prefetch.p0i8")
        # read or write 1, locality 3 (keep in all cache levels), data cache 1
        builder.call(function, [builder.bitcast(pointer, byte_pointer), i32(1), i32(3), i32(1)])
        return context.get_dummy_value()

    return types.void(array, index), codegen


@intrinsic
def _float_bits(typingctx, value):
    """The bit pattern of a float32 as a uint32 (a register move, no memory)."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(32))

    return types.uint32(types.float32), codegen


@_jit
def _prefetch_line(row):
    """Prefetch every cache line of the 1-D view ``row`` (4-byte items)."""
    for j in range(0, row.shape[0], 16):
        _prefetch(row, j)
    if row.shape[0]:
        _prefetch(row, row.shape[0] - 1)


@numba.njit(cache=True, nogil=True, boundscheck=False, inline="always")
def intern_pattern(pattern, slot, table_bits, size, shift, multiplier):
    """(index, size): the index of float32 bit pattern ``pattern`` in the open-addressing
    table (Knuth's multiplicative hash, linear probing), added at ``size`` if new.

    Inlined by Numba where it is called (a call per cell would cost more than the lookup).
    """
    mask = np.uint64(slot.shape[0] - 1)
    h = np.uint64(np.uint32(pattern * multiplier) >> shift)
    while True:
        index = slot[h]
        if index < 0:
            table_bits[size] = pattern
            slot[h] = size
            return size, size + 1
        if table_bits[index] == pattern:
            return index, size
        h = (h + np.uint64(1)) & mask


@_jit
def find_or_add(bits, slot, table_bits, size, shift, multiplier, out):
    """See :func:`ipp_toolkit._native.kernels.find_or_add`."""
    rows, cols = bits.shape
    for i in range(rows):
        for j in range(cols):
            out[i, j], size = intern_pattern(bits[i, j], slot, table_bits, size, shift,
                                             multiplier)
    return size

@_jit
def apply_values(ids, value_index, prob, entropy, wentropy, table_prob, table_entropy,
                 table_wentropy, block_of_row, block_of_col, prob_blocks,
                 wentropy_blocks):
    """See :func:`ipp_toolkit._native.kernels.apply_values`."""
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
    """See :func:`ipp_toolkit._native.kernels.apply_values_with_stats`."""
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


@_jit
def gather_caches(value_index, values, table_prob, table_entropy, table_wentropy, maps,
                  rects, logodds, prob, entropy, wentropy):
    """See :func:`ipp_toolkit._native.kernels.gather_caches`."""
    for r in range(maps.shape[0]):
        m = maps[r]
        r0, r1, c0, c1 = rects[r, 0], rects[r, 1], rects[r, 2], rects[r, 3]
        for i in range(r0, r1):
            indices = value_index[m, i, c0:c1]
            logodds_row = logodds[m, i, c0:c1]
            prob_row = prob[m, i, c0:c1]
            entropy_row = entropy[m, i, c0:c1]
            wentropy_row = wentropy[m, i, c0:c1]
            for j in range(c1 - c0):
                index = indices[j]
                logodds_row[j] = values[index]
                prob_row[j] = table_prob[index]
                entropy_row[j] = table_entropy[index]
                wentropy_row[j] = table_wentropy[index]


@_jit
def gain_changes(values, value_index, cells, r0, r1, c0, c1, delta):
    """See :func:`ipp_toolkit._native.kernels.gain_changes`."""
    for i in range(r1 - r0):
        indices = value_index[r0 + i, c0:c1]
        for z in range(values.shape[0]):
            column = values[z]
            row = cells[z, r0 + i, c0:c1]
            out = delta[z, i]
            for j in range(c1 - c0):
                new = column[indices[j]]
                out[j] = np.float64(new) - np.float64(row[j])
                row[j] = new


@_jit
def gain_lookup(values, value_index, cells, r0, r1, c0, c1):
    """See :func:`ipp_toolkit._native.kernels.gain_lookup`."""
    for i in range(r1 - r0):
        indices = value_index[r0 + i, c0:c1]
        for z in range(values.shape[0]):
            column = values[z]
            row = cells[z, r0 + i, c0:c1]
            for j in range(c1 - c0):
                row[j] = column[indices[j]]


@_jit
def segment_sums(cells, row_edges, col_edges, s0, s1, t0, t1, out):
    """See :func:`ipp_toolkit._native.kernels.segment_sums`."""
    c0, c1 = col_edges[t0], col_edges[t1]
    column_sums = np.empty(c1 - c0)
    for s in range(s0, s1):
        column_sums[:] = 0.0
        for i in range(row_edges[s], row_edges[s + 1]):
            # Views indexed from 0: Numba drops its negative-index handling and the loop
            # vectorises. The rows of a segment are added one after another.
            values = cells[i, c0:c1]
            for j in range(c1 - c0):
                column_sums[j] += np.float64(values[j])
        sums = out[s]
        for t in range(t0, t1):
            part = column_sums[col_edges[t] - c0:col_edges[t + 1] - c0]
            total = 0.0
            for j in range(part.shape[0]):
                total += part[j]
            sums[t] = total


@_jit
def weighted_segment_sums(sums, weight, row_block, col_block, row_segments, col_segments,
                          out):
    """See :func:`ipp_toolkit._native.kernels.weighted_segment_sums`.

    Every loop that adds runs along the row segments (or footprint columns), one independent
    sum per element, so the additions vectorise; each element's sum still takes its terms one
    after another, in the order of the NumPy reference.
    """
    n_rows, n_cols = sums.shape
    # products[t, s]: row segment s's weighted sum over column segment t.
    products = np.empty((n_cols, n_rows))
    for s in range(n_rows):
        weights = weight[row_block[s]]
        row = sums[s]
        for t in range(n_cols):
            products[t, s] = row[t] * np.float64(weights[col_block[t]])
    # Per footprint column and row segment, the footprint column's segments in order.
    by_columns = np.zeros((col_segments.shape[0], n_rows))
    for x in range(col_segments.shape[0]):
        column = by_columns[x]
        for t in range(col_segments[x, 0], col_segments[x, 1]):
            part = products[t]
            for s in range(n_rows):
                column[s] += part[s]
    by_rows = np.ascontiguousarray(by_columns.T)  # (R, G_x)
    # Per footprint row, its row segments in order.
    for y in range(row_segments.shape[0]):
        line = out[y]
        line[:] = 0.0
        for s in range(row_segments[y, 0], row_segments[y, 1]):
            part = by_rows[s]
            for x in range(line.shape[0]):
                line[x] += part[x]


@_jit
def summed_area(values, table):
    """See :func:`ipp_toolkit._native.kernels.summed_area`."""
    rows, cols = values.shape
    for j in range(cols + 1):
        table[0, j] = 0.0
    for i in range(rows):
        table[i + 1, 0] = 0.0
    # Down the rows first, then along them, each one addition after another: the order
    # of the two np.cumsum passes.
    for j in range(cols):
        table[1, j + 1] = values[0, j]
    for i in range(1, rows):
        above, row, out = table[i], values[i], table[i + 1]
        for j in range(cols):
            out[j + 1] = above[j + 1] + row[j]
    for i in range(1, rows + 1):
        line = table[i]
        for j in range(1, cols):
            line[j + 1] = line[j] + line[j + 1]


@_jit
def path_values(tables, altitudes, rects, term_step, term_sign, weights, first, valid, out):
    """See :func:`ipp_toolkit._native.kernels.path_values`."""
    n_paths, n_later = valid.shape[1], altitudes.shape[2]
    n_terms = term_step.shape[0]
    for f in first:
        best = -np.inf
        for s in range(n_paths):
            if not valid[f, s]:
                continue
            total = 0.0
            k = 0
            for t in range(n_later):
                z = altitudes[f, s, t]
                table = tables[z]
                new = 0.0
                while k < n_terms and term_step[k] == t:
                    q0, q1, s0, s1 = rects[k, f, s, 0], rects[k, f, s, 1], rects[k, f, s, 2], \
                        rects[k, f, s, 3]
                    new += term_sign[k] * (table[q1, s1] - table[q0, s1] - table[q1, s0]
                                           + table[q0, s0])
                    k += 1
                total += weights[t] * new
            if total != total:  # NaN wins the maximum, as in np.max
                best = total
                break
            if total > best:
                best = total
        out[f] = best if np.isfinite(best) else 0.0


@_jit
def indexed_segment_sums(index, columns, row_edges, col_edges, s0, s1, t0, t1, out):
    """See :func:`ipp_toolkit._native.kernels.indexed_segment_sums`."""
    r0, c0 = row_edges[s0], col_edges[t0]
    width = col_edges[t1] - c0
    column_sums = np.empty(width)
    for z in range(len(columns)):
        column = columns[z]
        for s in range(s0, s1):
            column_sums[:] = 0.0
            for i in range(row_edges[s], row_edges[s + 1]):
                ids = index[i - r0]
                for j in range(width):
                    column_sums[j] += np.float64(column[ids[j]])
            sums = out[z, s]
            for t in range(t0, t1):
                total = 0.0
                for j in range(col_edges[t] - c0, col_edges[t + 1] - c0):
                    total += column_sums[j]
                sums[t] = total


@_jit
def _rows_differ(a, b):
    """Whether two 1-D uint32 rows differ: one pass that vectorises (no early exit)."""
    differ = np.uint32(0)
    for j in range(a.shape[0]):
        differ |= a[j] ^ b[j]
    return differ != 0


@_jit
def row_differences(kept, new, first, last):
    """See :func:`ipp_toolkit._native.kernels.row_differences`."""
    rows, cols = kept.shape
    for i in range(rows):
        a, b = kept[i], new[i]
        if not _rows_differ(a, b):  # most rows are the same
            first[i], last[i] = -1, -1
            continue
        j = 0
        while a[j] == b[j]:
            j += 1
        first[i] = j
        k = cols - 1
        while a[k] == b[k]:
            k -= 1
        last[i] = k


@_jit
def same_bits(a, b):
    """See :func:`ipp_toolkit._native.kernels.same_bits`."""
    for i in range(a.shape[0]):
        if _rows_differ(a[i], b[i]):
            return False
    return True
