"""The whole-step Numba kernels of :mod:`ipp_toolkit._native.kernels` (imported on first use; see
there)."""

from __future__ import annotations

import numba
import numpy as np

from .compiled_kernels import _float_bits, _jit, _prefetch_line, intern_pattern


@_jit
def _block_sum(values, start, n):
    """NumPy's pairwise float64 sum of values[start:start + n], n <= 128, bit for bit.

    NumPy's add.reduce and add.reduceat sum a run of up to 128 values with 8 interleaved
    accumulators (longer runs are halved recursively first), not left to right; the
    measurement planes must be the numbers ``np.add.reduceat`` gave, so this follows its
    loop exactly. Planning blocks of over 129 cells, which would need the halving, take the
    per-rectangle path instead (:attr:`ipp_toolkit.sim.mission.MissionGeometry.whole_step`).
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
    """See :func:`ipp_toolkit._native.kernels.read_cells`."""
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


@numba.njit(cache=True, nogil=True, boundscheck=False, inline="always")
def _plus_reading(value, deltas, f, read, low, high):
    """clip(value + the increment of reading ``read`` of footprint f, low, high): one
    cell's addition in :meth:`ipp_toolkit.belief.mapping.BeliefMaps.add_evidence`."""
    value = value + (deltas[f, 1] if read else deltas[f, 0])
    if value < low:
        return low
    if value > high:
        return high
    return value


@_jit
def _add_readings(row_values, rects, readings, offsets, deltas, senders, u, last, i, runs,
                  seg_lo, seg_hi, low, high):
    """Add to ``row_values`` (row i, indexed by column) the increments of every footprint
    senders[u:last] over the runs, footprint by footprint, each sum clipped to [low, high]:
    per cell, the additions of :meth:`ipp_toolkit.belief.mapping.BeliefMaps.add_evidence`, in
    order."""
    for v in range(u, last):
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
            line = row_values[lo:hi]
            read = readings[begin + lo:begin + hi]
            for j in range(hi - lo):
                value = line[j] + (d1 if read[j] else d0)
                if value < low:
                    value = low
                elif value > high:
                    value = high
                line[j] = value


@_jit
def fuse_evidence(value_index, readings, offsets, rects, deltas, clip, target_maps,
                  target_offsets, senders, slot, table_bits, size, shift, multiplier, limit,
                  cursor, pairs, values, transitions, delta_slots):
    """See :func:`ipp_toolkit._native.kernels.fuse_evidence`.

    Each cell of a target is visited once, in the first of the target's footprints (in
    order) that covers it: its value (the table's value at its index) gets the readings of
    every footprint covering it, in order, and the sum is interned, so that interning
    follows the per-footprint order of :meth:`~ipp_toolkit.belief.mapping.BeliefMaps.refresh`.
    A cell under one footprint of the target (most cells) takes its new index from
    ``transitions[old index, 2 * delta slot + reading]`` once that is known: the same
    float32 sum of the same two numbers, so the same value, without the addition and the
    hash lookup. ``value_index`` is the maps' int32 array viewed as uint32 (non-negative:
    unsigned indexing spares Numba's negative-index handling in the inner loops).
    """
    width = _most_senders(target_offsets)
    lo_buf = np.empty(width, np.int64)
    hi_buf = np.empty(width, np.int64)
    seg_lo = np.empty(width, np.int64)
    seg_hi = np.empty(width, np.int64)
    low, high = -clip, clip
    shared = np.zeros(value_index.shape[2], np.bool_)  # per row: under a later footprint
    row_values = np.empty(value_index.shape[2], np.float32)
    row_bits = row_values.view(np.uint32)
    stats_target = target_maps.shape[0] - 1
    t0, u0, i0, position = cursor[0], cursor[1], cursor[2], cursor[3]
    for t in range(t0, target_maps.shape[0]):
        m = target_maps[t]
        first, last = target_offsets[t], target_offsets[t + 1]
        for u in range(u0 if t == t0 else first, last):
            f = senders[u]
            r0, r1, c0, c1 = rects[f, 0], rects[f, 1], rects[f, 2], rects[f, 3]
            code = 2 * delta_slots[f]
            for i in range(i0 if t == t0 and u == u0 and i0 >= 0 else r0, r1):
                if size + (c1 - c0) > limit:  # room for every cell of the row, or stop here
                    cursor[0], cursor[1], cursor[2], cursor[3] = t, u, i, position
                    return size, False
                if i + 1 < r1:
                    _prefetch_line(value_index[m, i + 1, c0:c1])
                runs = _uncovered(rects, senders, first, u, i, c0, c1, lo_buf, hi_buf, seg_lo,
                                  seg_hi)
                # Mark the cells a later footprint of the target covers too.
                later = False
                for v in range(u + 1, last):
                    g = senders[v]
                    if rects[g, 0] <= i < rects[g, 1]:
                        lo, hi = max(rects[g, 2], c0), min(rects[g, 3], c1)
                        if lo < hi:
                            shared[lo:hi] = True
                            later = True
                indices = value_index[m, i]
                if later:  # the float sums of the row's cells, for those under several
                    for s in range(runs):
                        for j in range(seg_lo[s], seg_hi[s]):
                            row_values[j] = values[indices[j]]
                    _add_readings(row_values, rects, readings, offsets, deltas, senders, u,
                                  last, i, runs, seg_lo, seg_hi, low, high)
                base = offsets[f] + (i - r0) * (c1 - c0) - c0  # readings[base + j]: cell j
                # pairs gets the (old, new) index of every cell, and on the global map also
                # (current, current) of the cells an earlier footprint refreshed
                # (apply_targets' statistics count them), in column order.
                covered_from = c0
                for s in range(runs + 1):
                    start = seg_lo[s] if s < runs else c1
                    if t == stats_target:
                        for k in range(covered_from, start):
                            pairs[position] = indices[k]
                            pairs[position + 1] = indices[k]
                            position += 2
                    if s == runs:
                        break
                    covered_from = seg_hi[s]
                    if not later:  # every cell under this footprint alone
                        misses = 0
                        count = covered_from - start
                        # Views indexed from 0: Numba's negative-index handling drops out.
                        run_indices = indices[start:covered_from]
                        run_reads = readings[base + start:base + covered_from]
                        run_pairs = pairs[position:position + 2 * count]
                        for q in range(count):
                            old = run_indices[q]
                            index = transitions[old, code + np.int64(run_reads[q])]
                            misses += index < 0
                            run_pairs[2 * q] = old
                            run_pairs[2 * q + 1] = index
                            run_indices[q] = index
                        position += 2 * count
                        if misses:  # first meetings: the float sum, interned in cell order
                            for q in range(count):
                                old = run_pairs[2 * q]
                                column = code + np.int64(run_reads[q])
                                index = np.int64(transitions[old, column])
                                if index < 0:
                                    value = _plus_reading(values[old], deltas, f, run_reads[q],
                                                          low, high)
                                    index, size = intern_pattern(_float_bits(value), slot,
                                                                 table_bits, size, shift,
                                                                 multiplier)
                                    transitions[old, column] = index
                                run_pairs[2 * q + 1] = index
                                run_indices[q] = index
                        continue
                    count = covered_from - start
                    run_indices = indices[start:covered_from]
                    run_reads = readings[base + start:base + covered_from]
                    run_pairs = pairs[position:position + 2 * count]
                    run_shared = shared[start:covered_from]
                    run_bits = row_bits[start:covered_from]
                    for q in range(count):
                        old = run_indices[q]
                        column = code
                        if run_shared[q]:
                            index = np.int64(-1)
                            pattern = run_bits[q]
                        else:
                            column = code + np.int64(run_reads[q])
                            index = np.int64(transitions[old, column])
                            if index < 0:
                                pattern = _float_bits(_plus_reading(
                                    values[old], deltas, f, run_reads[q], low, high))
                        if index < 0:
                            index, size = intern_pattern(pattern, slot, table_bits, size,
                                                         shift, multiplier)
                            if not run_shared[q]:
                                transitions[old, column] = index
                        run_pairs[2 * q] = old
                        run_pairs[2 * q + 1] = index
                        run_indices[q] = index
                    position += 2 * count
                if later:
                    shared[c0:c1] = False
    cursor[0], cursor[1], cursor[2], cursor[3] = target_maps.shape[0], 0, -1, position
    return size, True


@_jit
def _apply_run(pairs, position, n, table_prob, table_wentropy, block_sums, block_row,
               block_col, wentropy_sums):
    """Move one block's two sums by n cells' (old, new) index pairs from ``position``.

    The sums are carried in registers but added in cell order, so they are the numbers the
    per-cell ``+=`` of :func:`apply_values` gives. Returns the position after the run.
    """
    prob_sum = block_sums[block_row, block_col]
    wentropy_sum = wentropy_sums[block_row, block_col]
    run = pairs[position:position + 2 * n]  # indexed from 0: no negative-index handling
    for q in range(n):
        old, new = run[2 * q], run[2 * q + 1]
        prob_sum += np.float64(table_prob[new] - table_prob[old])
        wentropy_sum += np.float64(table_wentropy[new] - table_wentropy[old])
    block_sums[block_row, block_col] = prob_sum
    wentropy_sums[block_row, block_col] = wentropy_sum
    return position + 2 * n


@_jit
def apply_targets(pairs, table_prob, table_entropy, table_weights, table_wentropy,
                  block_of_cell, edges, prob_blocks, wentropy_blocks, rects, target_maps,
                  target_offsets, senders, truth, stats):
    """See :func:`ipp_toolkit._native.kernels.apply_targets`.

    Walks the targets as :func:`fuse_evidence` did, reading its (old, new) pairs in order:
    the maps themselves are not read. Cells an earlier footprint of the target refreshed
    are left out of the block sums (they would add 0).
    """
    width = _most_senders(target_offsets)
    lo_buf = np.empty(width, np.int64)
    hi_buf = np.empty(width, np.int64)
    seg_lo = np.empty(width, np.int64)
    seg_hi = np.empty(width, np.int64)
    two = np.float32(2.0)
    half = np.float32(0.5)
    stats_target = target_maps.shape[0] - 1
    position = 0
    for t in range(target_maps.shape[0]):
        m = target_maps[t]
        first, last = target_offsets[t], target_offsets[t + 1]
        prob_sums, wentropy_sums = prob_blocks[m], wentropy_blocks[m]
        for u in range(first, last):
            f = senders[u]
            r0, r1, c0, c1 = rects[f, 0], rects[f, 1], rects[f, 2], rects[f, 3]
            if t != stats_target:
                for i in range(r0, r1):
                    runs = _uncovered(rects, senders, first, u, i, c0, c1, lo_buf, hi_buf,
                                      seg_lo, seg_hi)
                    block_row = block_of_cell[i]
                    for s in range(runs):
                        j = seg_lo[s]
                        while j < seg_hi[s]:
                            block_col = block_of_cell[j]
                            end = min(seg_hi[s], edges[block_col + 1])
                            position = _apply_run(pairs, position, end - j, table_prob,
                                                  table_wentropy, prob_sums, block_row,
                                                  block_col, wentropy_sums)
                            j = end
                continue
            # The global map: the statistics cover every cell of the rectangle, refreshed
            # before or not, in order. A cell an earlier footprint refreshed holds its new
            # value already, so it adds 0 to the first four sums and W'H = W H = W' H' (its
            # weighted entropy) to the last three. The two counts are integers (exact, as
            # their float sums were).
            s0 = s1 = s4 = s5 = s6 = 0.0
            n2 = n3 = 0
            for i in range(r0, r1):
                runs = _uncovered(rects, senders, first, u, i, c0, c1, lo_buf, hi_buf, seg_lo,
                                  seg_hi)
                block_row = block_of_cell[i]
                interesting = truth[i]
                covered_from = c0
                for s in range(runs + 1):
                    start = seg_lo[s] if s < runs else c1
                    for _ in range(covered_from, start):  # refreshed before
                        known = np.float64(table_wentropy[pairs[position + 1]])
                        position += 2
                        s4 += known
                        s5 += known
                        s6 += known
                    if s == runs:
                        break
                    covered_from = seg_hi[s]
                    j = start
                    while j < covered_from:
                        block_col = block_of_cell[j]
                        end = min(covered_from, edges[block_col + 1])
                        prob_sum = prob_sums[block_row, block_col]
                        wentropy_sum = wentropy_sums[block_row, block_col]
                        run = pairs[position:position + 2 * (end - j)]  # from 0: see above
                        run_truth = interesting[j:end]
                        for q in range(end - j):
                            old, index = run[2 * q], run[2 * q + 1]
                            old_prob = table_prob[old]
                            old_entropy = table_entropy[old]
                            old_wentropy = table_wentropy[old]
                            new_prob = table_prob[index]
                            new_wentropy = table_wentropy[index]
                            positive = int(new_prob > half) - int(old_prob > half)
                            if run_truth[q]:
                                s0 += np.float64(table_entropy[index] - old_entropy)
                                s1 += np.float64((old_prob - new_prob)
                                                 * (two - old_prob - new_prob))
                                n2 += positive
                            n3 += positive
                            s4 += np.float64(table_weights[index] * old_entropy)
                            s5 += np.float64(old_wentropy)
                            s6 += np.float64(new_wentropy)
                            prob_sum += np.float64(new_prob - old_prob)
                            wentropy_sum += np.float64(new_wentropy - old_wentropy)
                        prob_sums[block_row, block_col] = prob_sum
                        wentropy_sums[block_row, block_col] = wentropy_sum
                        position += 2 * (end - j)
                        j = end
            row = u - first
            stats[row, 0] = s0
            stats[row, 1] = s1
            stats[row, 2] = n2
            stats[row, 3] = n3
            stats[row, 4] = s4
            stats[row, 5] = s5
            stats[row, 6] = s6
