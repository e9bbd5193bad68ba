"""The Numba kernels of :mod:`ipp_toolkit.kernels` (imported on first use; see there)."""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from .kernels import N_STATS

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


@_jit
def _prefetch_line(row):
    """Prefetch every cache line of the 1-D view ``row`` (4-byte items)."""
    for j in range(0, row.shape[0], 16):
        _prefetch(row, j)
    if row.shape[0]:
        _prefetch(row, row.shape[0] - 1)


@_jit
def _prefetch_cache_row(value_index, prob, entropy, wentropy, m, i, c0, c1):
    """Prefetch row ``i``, columns ``c0:c1``, of map ``m``'s index and three caches (the
    row the refresh loops read next)."""
    _prefetch_line(value_index[m, i, c0:c1])
    _prefetch_line(prob[m, i, c0:c1])
    _prefetch_line(entropy[m, i, c0:c1])
    _prefetch_line(wentropy[m, i, c0:c1])


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


# ---------------------------------------------------------------------------------------------
# One step's fusion (ipp_toolkit.kernels.read_cells, fuse_evidence, apply_targets).


@_jit
def _block_sum(values, start, n):
    """NumPy's pairwise float64 sum of values[start:start + n], n <= 128, bit for bit.

    NumPy's add.reduce and add.reduceat sum a run of up to 128 values with 8 interleaved
    accumulators (longer runs are halved recursively first), not left to right; the
    measurement planes must be the numbers ``np.add.reduceat`` gave, so this follows its
    loop exactly. Planning blocks of over 129 cells, which would need the halving, take the
    per-rectangle path instead (:attr:`ipp_toolkit.mission.MissionGeometry.whole_step`).
    """
    if n < 8:
        res = -0.0
        for i in range(start, start + n):
            res += values[i]
        return res
    r0 = values[start]
    r1 = values[start + 1]
    r2 = values[start + 2]
    r3 = values[start + 3]
    r4 = values[start + 4]
    r5 = values[start + 5]
    r6 = values[start + 6]
    r7 = values[start + 7]
    whole = n - n % 8
    for i in range(8, whole, 8):
        r0 += values[start + i]
        r1 += values[start + i + 1]
        r2 += values[start + i + 2]
        r3 += values[start + i + 3]
        r4 += values[start + i + 4]
        r5 += values[start + i + 5]
        r6 += values[start + i + 6]
        r7 += values[start + i + 7]
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for i in range(whole, n):
        res += values[start + i]
    return res


@_jit
def _segment_sum(values, start, n):
    """One segment (n <= 129) of ``np.add.reduceat``: its first value plus the rest's sum."""
    if n == 1:
        return values[start]
    return values[start] + _block_sum(values, start + 1, n - 1)


@_jit
def _block_rows(readings, cols, lo, n, weight_no, weight_yes, out, accumulators):
    """``out[j] = _block_sum`` over rows lo..lo + n (n <= 128) of column j of a reading's
    weights (``weight_yes`` where ``readings``, its (rows * cols,) cells row-major, holds a
    1, else ``weight_no``), for every column j.

    The same additions, in the same order for each column, done row by row so that the
    rows are read in memory order: row i goes to accumulator i % 8.
    """
    if n < 8:
        for j in range(cols):
            out[j] = -0.0
        for i in range(lo, lo + n):
            row = readings[i * cols:(i + 1) * cols]
            for j in range(cols):
                out[j] += weight_yes if row[j] else weight_no
        return
    whole = n - n % 8
    for i in range(whole):
        row = readings[(lo + i) * cols:(lo + i + 1) * cols]
        accumulator = accumulators[i % 8]
        if i < 8:
            for j in range(cols):
                accumulator[j] = weight_yes if row[j] else weight_no
        else:
            for j in range(cols):
                accumulator[j] += weight_yes if row[j] else weight_no
    for j in range(cols):
        out[j] = (((accumulators[0, j] + accumulators[1, j])
                   + (accumulators[2, j] + accumulators[3, j]))
                  + ((accumulators[4, j] + accumulators[5, j])
                     + (accumulators[6, j] + accumulators[7, j])))
    for i in range(whole, n):
        row = readings[(lo + i) * cols:(lo + i + 1) * cols]
        for j in range(cols):
            out[j] += weight_yes if row[j] else weight_no


@_jit
def read_cells(truth, rects, thresholds, noise, offsets, weights, edges, readings, planes):
    """See :func:`ipp_toolkit.kernels.read_cells`."""
    n_blocks = edges.shape[0] - 1
    for f in range(rects.shape[0]):
        r0, r1, c0, c1 = rects[f, 0], rects[f, 1], rects[f, 2], rects[f, 3]
        rows, cols = r1 - r0, c1 - c0
        base = offsets[f]
        threshold = thresholds[f]
        for i in range(rows):
            # Row views indexed from 0: per-cell indexing of the 2-D arrays costs several
            # times more (Numba's negative-index handling on every access).
            truth_row = truth[r0 + i, c0:c1]
            noise_row = noise[base + i * cols:base + (i + 1) * cols]
            read_row = readings[base + i * cols:base + (i + 1) * cols]
            for j in range(cols):
                read_row[j] = truth_row[j] != (noise_row[j] >= threshold)
        # The planes: two np.add.reduceat passes over the weights W(z) H(z), rows then
        # columns; each segment is its first value plus the pairwise sum of the rest.
        weight_no, weight_yes = weights[f, 0], weights[f, 1]
        reading = readings[base:base + rows * cols]
        column_sums = np.empty(cols)
        rest = np.empty(cols)
        accumulators = np.empty((8, cols))
        for block_row in range(n_blocks):
            lo = max(edges[block_row], r0) - r0
            hi = min(edges[block_row + 1], r1) - r0
            if lo >= hi:
                continue
            first_row = reading[lo * cols:(lo + 1) * cols]
            if hi - lo > 1:
                _block_rows(reading, cols, lo + 1, hi - lo - 1, weight_no, weight_yes, rest,
                            accumulators)
                for j in range(cols):
                    column_sums[j] = (weight_yes if first_row[j] else weight_no) + rest[j]
            else:
                for j in range(cols):
                    column_sums[j] = weight_yes if first_row[j] else weight_no
            for block_col in range(n_blocks):
                clo = max(edges[block_col], c0)
                chi = min(edges[block_col + 1], c1)
                if clo < chi:
                    planes[f, block_row, block_col] += _segment_sum(column_sums, clo - c0,
                                                                    chi - clo)


@_jit
def _uncovered(rects, senders, first, current, row, c0, c1, lo_buf, hi_buf, seg_lo, seg_hi):
    """Column runs of row ``row`` in [c0, c1) outside the rectangles of senders[first:current].

    Writes them to seg_lo / seg_hi in increasing order and returns how many there are.
    """
    n = 0
    for u in range(first, current):
        g = senders[u]
        if rects[g, 0] <= row < rects[g, 1]:
            lo = max(rects[g, 2], c0)
            hi = min(rects[g, 3], c1)
            if lo < hi:
                k = n  # insertion sort by start: there are only a few senders
                while k > 0 and lo_buf[k - 1] > lo:
                    lo_buf[k] = lo_buf[k - 1]
                    hi_buf[k] = hi_buf[k - 1]
                    k -= 1
                lo_buf[k] = lo
                hi_buf[k] = hi
                n += 1
    count = 0
    cursor = c0
    for k in range(n):
        if lo_buf[k] > cursor:
            seg_lo[count] = cursor
            seg_hi[count] = lo_buf[k]
            count += 1
        if hi_buf[k] > cursor:
            cursor = hi_buf[k]
    if cursor < c1:
        seg_lo[count] = cursor
        seg_hi[count] = c1
        count += 1
    return count


@_jit
def _most_senders(target_offsets):
    """1 + the largest number of footprints of one target (room for _uncovered's runs)."""
    width = 1
    for t in range(target_offsets.shape[0] - 1):
        width = max(width, target_offsets[t + 1] - target_offsets[t] + 1)
    return width


@_jit
def fuse_evidence(logodds, bits, value_index, readings, offsets, rects, deltas, clip,
                  target_maps, target_offsets, senders, slot, table_bits, size, shift,
                  multiplier, limit, cursor):
    """See :func:`ipp_toolkit.kernels.fuse_evidence`.

    Each cell of a target is visited once, in the first of the target's footprints (in
    order) that covers it; there the readings of every footprint covering it are added, in
    order, and its value is interned, so that interning follows the per-footprint order of
    :meth:`~ipp_toolkit.mapping.BeliefMaps.refresh`. ``value_index`` is the maps' int32
    array viewed as uint32 (non-negative: unsigned indexing spares Numba's negative-index
    handling in the inner loops).
    """
    mask = np.uint64(slot.shape[0] - 1)
    one = np.uint64(1)
    width = _most_senders(target_offsets)
    lo_buf = np.empty(width, np.int64)
    hi_buf = np.empty(width, np.int64)
    seg_lo = np.empty(width, np.int64)
    seg_hi = np.empty(width, np.int64)
    low, high = -clip, clip
    t0, u0, i0, resumed = cursor[0], cursor[1], cursor[2], cursor[3]
    for t in range(t0, target_maps.shape[0]):
        m = target_maps[t]
        first, last = target_offsets[t], target_offsets[t + 1]
        for u in range(u0 if t == t0 else first, last):
            f = senders[u]
            r0, r1, c0, c1 = rects[f, 0], rects[f, 1], rects[f, 2], rects[f, 3]
            for i in range(max(i0, r0) if t == t0 and u == u0 else r0, r1):
                if i + 1 < r1:
                    _prefetch_line(logodds[m, i + 1, c0:c1])
                    _prefetch_line(value_index[m, i + 1, c0:c1])
                runs = _uncovered(rects, senders, first, u, i, c0, c1, lo_buf, hi_buf, seg_lo,
                                  seg_hi)
                if not (resumed and t == t0 and u == u0 and i == i0):
                    for v in range(u, last):  # every footprint over the runs, in order
                        g = senders[v]
                        if not rects[g, 0] <= i < rects[g, 1]:
                            continue
                        g0, g1 = rects[g, 2], rects[g, 3]
                        d0, d1 = deltas[g, 0], deltas[g, 1]
                        begin = offsets[g] + (i - rects[g, 0]) * (g1 - g0) - g0
                        for s in range(runs):
                            lo, hi = max(seg_lo[s], g0), min(seg_hi[s], g1)
                            if lo >= hi:
                                continue
                            line = logodds[m, i, lo:hi]
                            read = readings[begin + lo:begin + hi]
                            for j in range(hi - lo):
                                value = line[j] + (d1 if read[j] else d0)
                                if value < low:
                                    value = low
                                elif value > high:
                                    value = high
                                line[j] = value
                for s in range(runs):
                    patterns = bits[m, i, seg_lo[s]:seg_hi[s]]
                    indices = value_index[m, i, seg_lo[s]:seg_hi[s]]
                    for j in range(patterns.shape[0]):
                        pattern = patterns[j]
                        h = np.uint64(np.uint32(pattern * multiplier) >> shift)
                        while True:
                            index = slot[h]
                            if index < 0:
                                if size >= limit:  # full: the caller grows the table
                                    cursor[0], cursor[1], cursor[2], cursor[3] = t, u, i, 1
                                    return size, False
                                table_bits[size] = pattern
                                slot[h] = size
                                index = size
                                size += 1
                                break
                            if table_bits[index] == pattern:
                                break
                            h = (h + one) & mask
                        indices[j] = index
    return size, True


@_jit
def _apply_run(indices, probs, entropies, wentropies, table_prob, table_entropy,
               table_wentropy, block_sums, block_row, block_col, wentropy_sums):
    """Write one run of cells of one block and move the block's two sums, cell by cell.

    The sums are carried in registers but added in cell order, so they are the numbers the
    per-cell ``+=`` of :func:`apply_values` gives.
    """
    prob_sum = block_sums[block_row, block_col]
    wentropy_sum = wentropy_sums[block_row, block_col]
    for j in range(indices.shape[0]):
        index = indices[j]
        new_prob = table_prob[index]
        new_wentropy = table_wentropy[index]
        prob_sum += np.float64(new_prob - probs[j])
        wentropy_sum += np.float64(new_wentropy - wentropies[j])
        probs[j] = new_prob
        entropies[j] = table_entropy[index]
        wentropies[j] = new_wentropy
    block_sums[block_row, block_col] = prob_sum
    wentropy_sums[block_row, block_col] = wentropy_sum


@_jit
def _apply_runs(value_index, prob, entropy, wentropy, table_prob, table_entropy,
                table_wentropy, block_of_cell, edges, prob_sums, wentropy_sums, m, i, runs,
                seg_lo, seg_hi):
    """:func:`_apply_run` over the runs (of :func:`_uncovered`) of row i of map m, block by
    block: cells an earlier footprint of the target refreshed are left out, as they would
    add 0 to the block sums and write the values they hold."""
    block_row = block_of_cell[i]
    for s in range(runs):
        j = seg_lo[s]
        while j < seg_hi[s]:
            block_col = block_of_cell[j]
            end = min(seg_hi[s], edges[block_col + 1])
            _apply_run(value_index[m, i, j:end], prob[m, i, j:end], entropy[m, i, j:end],
                       wentropy[m, i, j:end], table_prob, table_entropy, table_wentropy,
                       prob_sums, block_row, block_col, wentropy_sums)
            j = end


@_jit
def apply_targets(value_index, prob, entropy, wentropy, table_prob, table_entropy,
                  table_weights, table_wentropy, block_of_cell, edges, prob_blocks,
                  wentropy_blocks, rects, target_maps, target_offsets, senders, truth, stats):
    """See :func:`ipp_toolkit.kernels.apply_targets` (``value_index`` viewed as uint32)."""
    width = _most_senders(target_offsets)
    lo_buf = np.empty(width, np.int64)
    hi_buf = np.empty(width, np.int64)
    seg_lo = np.empty(width, np.int64)
    seg_hi = np.empty(width, np.int64)
    two = np.float32(2.0)
    half = np.float32(0.5)
    stats_target = target_maps.shape[0] - 1
    for t in range(target_maps.shape[0]):
        m = target_maps[t]
        first, last = target_offsets[t], target_offsets[t + 1]
        prob_sums, wentropy_sums = prob_blocks[m], wentropy_blocks[m]
        for u in range(first, last):
            f = senders[u]
            r0, r1, c0, c1 = rects[f, 0], rects[f, 1], rects[f, 2], rects[f, 3]
            if t != stats_target:
                for i in range(r0, r1):
                    if i + 1 < r1:
                        _prefetch_cache_row(value_index, prob, entropy, wentropy, m, i + 1,
                                            c0, c1)
                    runs = _uncovered(rects, senders, first, u, i, c0, c1, lo_buf, hi_buf,
                                      seg_lo, seg_hi)
                    _apply_runs(value_index, prob, entropy, wentropy, table_prob,
                                table_entropy, table_wentropy, block_of_cell, edges, prob_sums,
                                wentropy_sums, m, i, runs, seg_lo, seg_hi)
                continue
            # The global map: the statistics cover every cell of the rectangle, refreshed
            # before or not, in order. A cell an earlier footprint refreshed holds its new
            # value already, so it adds 0 to the first four sums and W'H = W H = W' H' (its
            # weighted entropy) to the last three. Each row is summed first and written
            # after, which keeps the loops small enough for the registers. The two counts
            # are integers (exact, as their float sums were).
            s0 = s1 = s4 = s5 = s6 = 0.0
            n2 = n3 = 0
            for i in range(r0, r1):
                if i + 1 < r1:
                    _prefetch_cache_row(value_index, prob, entropy, wentropy, m, i + 1, c0, c1)
                runs = _uncovered(rects, senders, first, u, i, c0, c1, lo_buf, hi_buf, seg_lo,
                                  seg_hi)
                indices, probs = value_index[m, i], prob[m, i]
                entropies, wentropies = entropy[m, i], wentropy[m, i]
                interesting = truth[i]
                covered_from = c0
                for s in range(runs + 1):
                    start = seg_lo[s] if s < runs else c1
                    for k in range(covered_from, start):  # refreshed before
                        known = np.float64(wentropies[k])
                        s4 += known
                        s5 += known
                        s6 += known
                    if s == runs:
                        break
                    covered_from = seg_hi[s]
                    run_indices = indices[start:covered_from]
                    run_probs = probs[start:covered_from]
                    run_entropies = entropies[start:covered_from]
                    run_wentropies = wentropies[start:covered_from]
                    run_truth = interesting[start:covered_from]
                    for k in range(covered_from - start):
                        index = run_indices[k]
                        old_prob = run_probs[k]
                        old_entropy = run_entropies[k]
                        new_prob = table_prob[index]
                        positive = int(new_prob > half) - int(old_prob > half)
                        if run_truth[k]:
                            s0 += np.float64(table_entropy[index] - old_entropy)
                            s1 += np.float64((old_prob - new_prob)
                                             * (two - old_prob - new_prob))
                            n2 += positive
                        n3 += positive
                        s4 += np.float64(table_weights[index] * old_entropy)
                        s5 += np.float64(run_wentropies[k])
                        s6 += np.float64(table_wentropy[index])
                _apply_runs(value_index, prob, entropy, wentropy, table_prob, table_entropy,
                            table_wentropy, block_of_cell, edges, prob_sums, wentropy_sums, m,
                            i, runs, seg_lo, seg_hi)
            row = u - first
            stats[row, 0] = s0
            stats[row, 1] = s1
            stats[row, 2] = n2
            stats[row, 3] = n3
            stats[row, 4] = s4
            stats[row, 5] = s5
            stats[row, 6] = s6
