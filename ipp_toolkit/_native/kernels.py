"""Compiled inner loops of the belief maps (Numba), with the NumPy code as their reference.

A refresh of one footprint rectangle of one map
(:meth:`ipp_toolkit.belief.mapping.BeliefMaps.refresh`)
reads each cell's log-odds, finds its value in the maps'
:class:`~ipp_toolkit.belief.value_table.ValueTable`, writes the cached probability, entropy and
weighted entropy and moves the planning-grid block sums by the change; for the global map it
also moves the running sums of the metrics and the reward. In NumPy that is some twenty passes
over the rectangle; compiled it is two (find the values, then apply them), several times
faster, with bit-identical cached values (the kernels only look values up, every value is
computed by the table's NumPy code) and block and metric sums equal up to float64 summation
order.

A whole step of the mission (:func:`ipp_toolkit.sim.mission.step_mission`) has its own three
kernels, which do for every map at once what the per-rectangle calls above do one call at a
time, with the same float operations in the same order (so the same numbers to the last bit):
:func:`read_cells` turns the sensor noise into readings and their block planes,
:func:`fuse_evidence` adds the readings' log-odds to every receiving map and interns the new
values (most cells through a table of known transitions, value index and reading -> value
index), writing only the maps' index array and a list of (old, new) index pairs, and
:func:`apply_targets` moves the block sums and metric sums from those pairs (after the new
values' columns are derived). The per-cell log-odds and caches are looked up from the index
array only when somebody reads them (:func:`gather_caches`;
:class:`~ipp_toolkit.belief.mapping.BeliefMaps`). A cell that several footprints of one map cover
is looked up and written once (a second refresh would move nothing); the statistics of the
global map still count it once per footprint, as the reward always did.
:func:`sensor_noise` draws the step's sensor noise (NumPy's streams, bit for bit;
:mod:`ipp_toolkit.world.sensor_noise`). The NumPy fallback keeps the per-rectangle code.

The planners' lookahead has five more (:mod:`ipp_toolkit.planning.segments`,
:mod:`ipp_toolkit.planning.lookahead`): :func:`row_differences` finds where a UAV's map changed
since its kept copy (:func:`same_bits`: whether a teammate's map is the same),
:func:`indexed_segment_sums` sums table columns over segments straight from the cells' value
indices, :func:`summed_area` builds a summed-area table and :func:`path_values` sums every
path's inclusion-exclusion rectangles from the tables. Each adds
what its NumPy reference adds, in the same order: the same numbers to the last bit.

Numba is a dependency of the toolkit; where it cannot be imported (an exotic platform, or
``IPP_TOOLKIT_NO_NUMBA=1`` in the environment, which the tests use to check both paths) the
callers fall back to their NumPy code and :data:`AVAILABLE` is False. Compiled functions are
cached on disk (``cache=True``), so a new process (an evaluation worker) loads them instead of
compiling them again. The first time (a new checkout, or a kernel's source changed), the
workers of a pool share the compiling (:func:`compile_mission_kernels`) instead of each
compiling every kernel.
"""

from __future__ import annotations

import importlib.util
import itertools
import os
import sys
from collections.abc import Callable
from typing import Any

import numpy as np

from .region_stats import N_STATS, REGION_STATS

__all__ = ["AVAILABLE", "find_or_add", "apply_values", "apply_values_with_stats",
           "read_cells", "fuse_evidence", "apply_targets", "gather_caches", "gain_changes",
           "gain_lookup", "segment_sums", "weighted_segment_sums", "summed_area",
           "path_values", "indexed_segment_sums", "row_differences", "same_bits",
           "sensor_noise",
           "mission_kernels", "compile_mission_kernels", "cached", "COMPILE_NOTE",
           "print_compile_note",
           "REGION_STATS", "N_STATS"]

AVAILABLE = (os.environ.get("IPP_TOOLKIT_NO_NUMBA", "") in ("", "0")
             and importlib.util.find_spec("numba") is not None)
"""Whether the compiled kernels are used (Numba importable and not switched off)."""

_module: Any = None
_step_module: Any = None
_noise_module: Any = None


def _compiled() -> Any:
    """The compiled kernels, imported (and loaded from Numba's cache) on first use.

    Importing Numba and loading the kernels takes about a second; a process that never
    refreshes a map (a CLI refusing a bad flag) does not pay it.
    """
    global _module
    if _module is None:
        from . import compiled_kernels

        _module = compiled_kernels
    return _module


def _compiled_step() -> Any:
    """The whole-step kernels (:mod:`ipp_toolkit._native.compiled_step`), imported on first use."""
    global _step_module
    if _step_module is None:
        from . import compiled_step

        _step_module = compiled_step
    return _step_module


def find_or_add(bits: np.ndarray, slot: np.ndarray, table_bits: np.ndarray, size: int,
                shift: np.uint32, multiplier: np.uint32, out: np.ndarray) -> int:
    """out[i, j] = index of bits[i, j] in an open-addressing table, adding new patterns.

    Args:
        bits: (rows, cols) uint32 bit patterns (of float32 values; any strides).
        slot: (2**b,) intp hash slot -> index (-1 empty); the caller reserves room so that
            it is at most half full afterwards.
        table_bits: (capacity,) uint32 pattern of each index; new ones appended at ``size``.
        size: how many patterns the table holds.
        shift, multiplier: the hash, ``(pattern * multiplier mod 2**32) >> shift``.
        out: (rows, cols) intp output.

    Returns:
        the new size (new patterns got indices ``size..`` in order of first appearance).
    """
    return _compiled().find_or_add(bits, slot, table_bits, size, shift, multiplier, out)


def apply_values(*arrays: np.ndarray) -> None:
    """Write the caches of one rectangle from its value indices; move the block sums.

    Args, in order: ids (rows, cols) intp value index of every cell; value_index, prob,
    entropy, wentropy (rows, cols) views of the map's caches; table_prob, table_entropy,
    table_wentropy (n,) float32 columns of the table; block_of_row (rows,) and block_of_col
    (cols,) planning-grid block of each row and column; prob_blocks and wentropy_blocks
    (G, G) float64 block sums of the map, updated in place.
    """
    _compiled().apply_values(*arrays)


def apply_values_with_stats(*arrays: np.ndarray) -> np.ndarray:
    """:func:`apply_values`, also returning the changes of the metric and reward sums.

    Args, in order: as :func:`apply_values` with the table's class weights ``table_weights``
    after ``table_entropy``, then ``truth`` (rows, cols) bool ground truth of the rectangle.

    Returns:
        (N_STATS,) float64, named by :data:`REGION_STATS`.
    """
    return _compiled().apply_values_with_stats(*arrays)


def read_cells(*arrays: np.ndarray) -> None:
    """Readings of several footprints from their noise, and each reading's block sums.

    Args, in order: truth (H, W) bool ground truth; rects (F, 4) int64 footprint rectangles;
    thresholds (F,) float32 the sensor accuracy of each (a cell is read wrongly where its
    noise is >= it); noise (cells,) float32 the uniform noise of all footprints one after
    another, each row-major; offsets (F + 1,) int64 where each footprint starts in it (and
    the end); weights
    (F, 2) float64 the value of a 0 and of a 1 reading in the planes; edges (G + 1,) int64
    first map cell of each planning block; readings (cells,) bool output, laid out like
    ``noise``; planes (F, G, G) float64, zero on entry: ``+=`` the block sums of each
    footprint's weights, summed exactly as two ``np.add.reduceat`` passes sum them
    (planning blocks of at most 129 cells a side).
    """
    _compiled_step().read_cells(*arrays)


def fuse_evidence(*arrays: Any) -> tuple[int, bool]:
    """Add readings to maps and intern the maps' new log-odds values; may stop when full.

    For each target t (map ``target_maps[t]``, its footprints
    ``senders[target_offsets[t]:target_offsets[t + 1]]``, indices into ``rects``), each cell
    of the footprints is visited once, in the first footprint that covers it: the log-odds
    increments of every footprint over it are added in order to its value (d1 where the
    reading is 1, else d0, each sum clipped to [-clip, clip], as
    :meth:`ipp_toolkit.belief.mapping.BeliefMaps.add_evidence`), then the sum is interned into the
    open-addressing table (as :func:`find_or_add`) and its index written to ``value_index``.
    Values are interned in the order the per-footprint refreshes intern them, so they get
    the same indices. A cell's value is the table's value at its index: the maps' index
    array is the only map array read or written.

    Args, in order: value_index (M, H, W) the int32 array viewed as uint32; readings
    (cells,) bool and offsets (F + 1,) int64 as in :func:`read_cells`; rects (F, 4) int64;
    deltas (F, 2) float32 (d0, d1); clip float32; target_maps (T,) int64; target_offsets
    (T + 1,) int64; senders (S,) int64; slot, table_bits, size, shift, multiplier as in
    :func:`find_or_add`; limit, the most values the table may hold; cursor (4,) int64, where
    to start (target, footprint, row, position in ``pairs``), (0, 0, -1, 0) at first; pairs
    (2 P,) uint32 output, the (old, new) index of every cell visited, in order, and on the
    last target (the global map) also (current, current) of the cells of each footprint an
    earlier one refreshed (P = the sum of the targets' footprint areas is always enough);
    values (capacity,) float32, the table's patterns as values (``table_bits`` viewed as
    float32); transitions (capacity, 2 D) int32, the index of value k plus the increments of
    delta slot s and reading r at column 2 s + r, -1 until first met (filled in here);
    delta_slots (F,) int64, the delta slot of each footprint's (d0, d1).

    Returns:
        (size, done): the table's new size, and whether the pass finished; if not, the next
        row could fill the table past ``limit`` and ``cursor`` says where the pass stopped:
        grow the table (room for a row of cells) and call again with the same cursor.
    """
    return _compiled_step().fuse_evidence(*arrays)


def apply_targets(*arrays: np.ndarray) -> None:
    """Move the block sums of the targets of :func:`fuse_evidence`, with the statistics.

    Args, in order: pairs (2 P,) uint32 of :func:`fuse_evidence`; table_prob, table_entropy,
    table_weights, table_wentropy the table's columns (every pair's values derived);
    block_of_cell (H,) int64 and edges (G + 1,) int64 of the planning grid; prob_blocks and
    wentropy_blocks (M, G, G) float64; rects, target_maps, target_offsets, senders as in
    :func:`fuse_evidence`; truth (H, W) bool; stats (S_last, N_STATS) float64 output, one
    row per footprint of the last target (the global map), named by :data:`REGION_STATS`
    and summed over all of its cells as :func:`apply_values_with_stats` sums them. The
    block and metric sums take the cells in the order the per-footprint kernels take them.
    """
    _compiled_step().apply_targets(*arrays)


def gather_caches(*arrays: np.ndarray) -> None:
    """Write the log-odds and caches of several rectangles from the maps' value indices.

    Args, in order: value_index (M, H, W) int32 viewed as uint32; values, table_prob,
    table_entropy, table_wentropy the table's values and columns; maps (R,) int64 and rects
    (R, 4) int64 the rectangles; logodds, prob, entropy, wentropy (M, H, W) float32 outputs.
    """
    _compiled().gather_caches(*arrays)


def gain_changes(values: np.ndarray, value_index: np.ndarray, cells: np.ndarray, r0: int,
                 r1: int, c0: int, c1: int, delta: np.ndarray) -> None:
    """Look a region's per-cell gains up anew and return how they changed, in one pass.

    For the cells of rows r0..r1, columns c0..c1: ``delta[z] = float64(new) -
    float64(cells[z])`` and then ``cells[z] = new``, with ``new = values[z, value_index]``
    (the float64 difference of the two float32 numbers, as NumPy takes it).

    Args:
        values: (Z, V) float32 gain of every table value per altitude.
        value_index: (H, W) the map's int32 value indices viewed as uint32.
        cells: (Z, H, W) float32 the cached per-cell gains of the map, updated in place.
        r0, r1, c0, c1: the region.
        delta: (Z, r1 - r0, c1 - c0) float64 output.
    """
    _compiled().gain_changes(values, value_index, cells, r0, r1, c0, c1, delta)


def gain_lookup(values: np.ndarray, value_index: np.ndarray, cells: np.ndarray, r0: int,
                r1: int, c0: int, c1: int) -> None:
    """:func:`gain_changes` without the changes: ``cells[z] = values[z, value_index]`` over
    the region rows r0..r1, columns c0..c1 (same arguments)."""
    _compiled().gain_lookup(values, value_index, cells, r0, r1, c0, c1)


def segment_sums(cells: np.ndarray, row_edges: np.ndarray, col_edges: np.ndarray, s0: int,
                 s1: int, t0: int, t1: int, out: np.ndarray) -> None:
    """Sums of ``cells`` over the segments [s0, s1) x [t0, t1) of a cut map, in a fixed order.

    ``row_edges`` cut the rows into segments (segment s: rows ``row_edges[s]`` to
    ``row_edges[s + 1]``), ``col_edges`` the columns. Per segment s, its rows are added one
    after another into one float64 sum per column; per column segment t, those column sums
    are added one after another into ``out[s, t]``
    (:meth:`ipp_toolkit.belief.box_sums.BoxLayout.reference_segment_sums` adds in the same order).

    Args:
        cells: (H, W) float32 per-cell values (one map, one altitude).
        row_edges: (R + 1,) int64 increasing cuts of the rows, from 0 to H.
        col_edges: (C + 1,) int64 the same for the columns.
        s0, s1, t0, t1: the row and column segments to sum.
        out: (R, C) float64, written in [s0, s1) x [t0, t1) only.
    """
    _compiled().segment_sums(cells, row_edges, col_edges, s0, s1, t0, t1, out)


def weighted_segment_sums(sums: np.ndarray, weight: np.ndarray, row_block: np.ndarray,
                          col_block: np.ndarray, row_segments: np.ndarray,
                          col_segments: np.ndarray, out: np.ndarray) -> None:
    """Footprint sums of a blockwise weight times per-cell values, from the segment sums.

    Every segment lies inside one block of the weight, so its cells' weighted sum is
    ``sums[s, t] * float64(weight[row_block[s], col_block[t]])``. Footprint (y, x) is the row
    segments ``row_segments[y]`` times the column segments ``col_segments[x]``: per row
    segment, a footprint column's weighted segments are added in order, then per footprint
    row its row segments: a fixed order, on any CPU (:class:`ipp_toolkit.belief.box_sums.BoxLayout`
    holds the NumPy reference, in the same order).

    Args:
        sums: (R, C) float64 segment sums (:func:`segment_sums`; finite everywhere, also
            where no footprint reaches), or float32 values of single-cell segments.
        weight: (H / block, W / block) float32, one weight per block x block square.
        row_block: (R,) int64 the block row of every row segment; col_block the same for
            the columns.
        row_segments: (G, 2) int64 first and past-the-last row segment of each footprint row.
        col_segments: (G, 2) int64 the same for each footprint column.
        out: (G, G) float64 output.
    """
    _compiled().weighted_segment_sums(sums, weight, row_block, col_block, row_segments,
                                      col_segments, out)


def summed_area(values: np.ndarray, table: np.ndarray) -> None:
    """The summed-area table of ``values``, written into ``table``.

    ``table[0, :]`` and ``table[:, 0]`` are 0, and ``table[1:, 1:]`` is
    ``np.cumsum(np.cumsum(values, axis=0), axis=1)``, added in that order (so the same
    float64 numbers to the last bit).

    Args:
        values: (R, C) float64.
        table: (R + 1, C + 1) float64 output (any strides).
    """
    _compiled().summed_area(values, table)


def path_values(*arrays: np.ndarray) -> None:
    """The best discounted value of each first move's paths, from summed-area tables.

    For every first move f of ``first`` and every path s with ``valid[f, s]``: per later
    step t, ``new`` adds, in order, ``term_sign[k]`` times the rectangle sum of
    ``rects[k, f, s]`` (row0, row1, col0, col1 corner indices) read from
    ``tables[altitudes[f, s, t]]`` (the four corners taken as (q1, s1) - (q0, s1) -
    (q1, s0) + (q0, s0)) over the terms k with ``term_step[k] == t`` (``term_step`` is
    sorted), and the path's ``total`` adds ``weights[t] * new``; ``out[f]`` is the largest
    total, or 0 when none is finite. The same operations in the same order as the NumPy
    reference (:func:`ipp_toolkit.planning.lookahead.continuation_values`).

    Args, in order: tables (Z, R + 1, C + 1) float64; altitudes (6, S, T) int64;
    rects (K, 6, S, 4) int64; term_step (K,) int64; term_sign (K,) float64; weights (T,)
    float64; first (F,) int64; valid (6, S) bool; out (6,) float64, written at ``first``.
    """
    _compiled().path_values(*arrays)


def indexed_segment_sums(index: np.ndarray, columns: tuple[np.ndarray, ...],
                         row_edges: np.ndarray, col_edges: np.ndarray, s0: int, s1: int,
                         t0: int, t1: int, out: np.ndarray) -> None:
    """:func:`segment_sums` of table columns looked up by value index, for each column.

    ``out[z]`` gets the sums over the segments [s0, s1) x [t0, t1) of ``columns[z][index]``
    (the cells' values), added in :func:`segment_sums`' order: the same numbers to the last
    bit, without the looked-up values in memory.

    Args:
        index: (h, w) intp value index of the cells from map row ``row_edges[s0]`` and
            column ``col_edges[t0]`` to ``row_edges[s1]`` and ``col_edges[t1]``.
        columns: Z (n,) float32 table columns.
        row_edges, col_edges: as in :func:`segment_sums`.
        s0, s1, t0, t1: the row and column segments to sum.
        out: (Z, R, C) float64, written in [s0, s1) x [t0, t1) only.
    """
    _compiled().indexed_segment_sums(index, columns, row_edges, col_edges, s0, s1, t0, t1,
                                     out)


def row_differences(kept: np.ndarray, new: np.ndarray, first: np.ndarray,
                    last: np.ndarray) -> None:
    """Per row, the first and the last column where two maps' bit patterns differ.

    Args:
        kept, new: (H, W) uint32 (float32 maps viewed as their bit patterns; any strides).
        first, last: (H,) int64 output: the first and last differing column of each row,
            -1 where the row is the same.
    """
    _compiled().row_differences(kept, new, first, last)


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two (H, W) uint32 arrays (float32 maps viewed as their bit patterns; any
    strides) are equal, stopping at the first row that differs."""
    return bool(_compiled().same_bits(a, b))


def sensor_noise(words: np.ndarray, offsets: np.ndarray, out: np.ndarray) -> None:
    """Uniform float32 noise of several fresh PCG64 streams, one after another.

    ``out[offsets[f]:offsets[f + 1]]`` = ``Generator(PCG64(SeedSequence(...))).random(n,
    dtype=np.float32)`` of the sequence whose assembled entropy is ``words[f]``.

    Args:
        words: (F, n) uint32 assembled entropy of each stream (see
            :mod:`ipp_toolkit.world.sensor_noise`).
        offsets: (F + 1,) int64 where each stream's numbers start in ``out`` (and the end).
        out: (cells,) float32 output.
    """
    _compiled_noise().sensor_noise(words, offsets, out)


def _compiled_noise() -> Any:
    """The sensor-noise kernel's module (:mod:`ipp_toolkit._native.compiled_noise`), imported on
    first use."""
    global _noise_module
    if _noise_module is None:
        from . import compiled_noise

        _noise_module = compiled_noise
    return _noise_module


def mission_kernels() -> list[tuple[Any, tuple[Any, ...]]]:
    """(compiled kernel, argument types) of the kernels every mission of ``ipp-compare``'s
    default planners flies, the simulator's slowest to compile first (measured: 2.8 s for
    ``fuse_evidence`` down to 0.1 s; 7.3 s in all), then the lookahead's.

    These are the types the simulator and those planners pass (a test flies ``ipp-compare``'s
    defaults and checks that they are all here, and no other). Kernels that only some paths
    call (the per-rectangle :func:`apply_values`) compile when first called.
    """
    from numba import types

    def array(dtype: Any, ndim: int = 1) -> Any:
        return types.Array(dtype, ndim, "C")

    def read_only(dtype: Any, ndim: int = 1) -> Any:
        return types.Array(dtype, ndim, "C", readonly=True)

    u32, i32, i64 = types.uint32, types.int32, types.int64
    f32, f64, flag = types.float32, types.float64, types.boolean
    step, noise, table = _compiled_step(), _compiled_noise(), _compiled()
    table_args = (array(i64), array(u32), i64, u32, u32, array(i64, 2))  # find_or_add's
    return [
        (step.fuse_evidence, (
            array(u32, 3), array(flag), array(i64), array(i64, 2), array(f32, 2), f32,
            array(i64), array(i64), array(i64), array(i64), array(u32), i64, u32, u32, i64,
            array(i64), array(u32), array(f32), array(i32, 2), array(i64))),
        (step.read_cells, (
            array(flag, 2), array(i64, 2), array(f32), array(f32), array(i64), array(f64, 2),
            array(i64), array(flag), array(f64, 3))),
        (step.apply_targets, (
            array(u32), array(f32), array(f32), array(f32), array(f32), array(i64),
            array(i64), array(f64, 3), array(f64, 3), array(i64, 2), array(i64), array(i64),
            array(i64), array(flag, 2), array(f64, 2))),
        (noise.sensor_noise, (array(u32, 2), array(i64), array(f32))),
        (table.weighted_segment_sums, (
            array(f64, 2), array(f32, 2), array(i64), array(i64), array(i64, 2),
            array(i64, 2), array(f64, 2))),
        (table.gather_caches, (
            array(u32, 3), array(f32), array(f32), array(f32), array(f32), array(i64),
            array(i64, 2), array(f32, 3), array(f32, 3), array(f32, 3), array(f32, 3))),
        (table.segment_sums, (array(f32, 2), array(i64), array(i64), i64, i64, i64, i64,
                              array(f64, 2))),
        (table.gain_lookup, (array(f32, 2), array(u32, 2), array(f32, 3), i64, i64, i64, i64)),
        (table.find_or_add, (array(u32, 2), *table_args)),
        (table.find_or_add, (types.Array(u32, 2, "A", readonly=True), *table_args)),
        # the lookahead of the learned-prior planners (ig_learned, coma, ppo)
        (table.indexed_segment_sums, (array(i64, 2), types.UniTuple(array(f32), 3), array(i64),
                                      array(i64), i64, i64, i64, i64, array(f64, 3))),
        (table.path_values, (array(f64, 3), array(i64, 3), array(i64, 4), array(i64),
                             array(f64), array(f64), array(i64), array(flag, 2), array(f64))),
        (table.summed_area, (array(f64, 2), types.Array(f64, 2, "A"))),
        (table.row_differences, (array(u32, 2), read_only(u32, 2), array(i64), array(i64))),
        (table.same_bits, (array(u32, 2), read_only(u32, 2))),
    ]


COMPILE_NOTE = ("note: compiling the simulator's kernels (Numba): they are not in its cache "
                "yet (a first run, or the toolkit changed); up to a minute, once; later runs "
                "load them")
"""What a process says when it starts compiling kernels that Numba's cache does not hold: a
first run is otherwise silent for that long."""


def print_compile_note() -> None:
    """Print :data:`COMPILE_NOTE` on stderr (an ``announce`` of :func:`compile_mission_kernels`)."""
    print(COMPILE_NOTE, file=sys.stderr, flush=True)


def cached(kernel: Any, argument_types: tuple[Any, ...]) -> bool | None:
    """Whether compiled ``kernel`` (a Numba dispatcher) for ``argument_types`` is a load, not a
    compile: compiled in this process already, or in Numba's disk cache for this source, CPU
    and Numba version. None where this Numba's cache cannot be read that way (its index key
    and file are Numba internals, read here as Numba 0.60 to 0.68 write them)."""
    types = tuple(argument_types)
    try:
        if types in kernel.overloads:
            return True
        cache = kernel._cache
        key = cache._index_key(types, kernel.targetctx.codegen())
        return key in cache._cache_file._load_index()
    except Exception:  # another Numba's internals: cannot tell, so say nothing
        return None


def compile_mission_kernels(claim: Callable[[], int] | None = None,
                            announce: Callable[[], None] | None = None) -> int:
    """Compile, or load from Numba's cache, the kernels of :func:`mission_kernels` now.

    A process calls its kernels' compiler on first use; compiled, each is saved in Numba's
    cache, where other processes load it. Processes that start together (a pool's workers)
    can share the compiling instead of each compiling all of them: each takes the next
    kernel not yet taken from a shared ``claim`` until none is left; one that compiled
    something then waits for the others to finish theirs (else it would compile one they
    are still compiling) and loads theirs from the cache when it first calls them
    (:class:`ipp_toolkit.runs.process_pool.WorkerPool` does this). Once cached, this is a load
    (about 0.35 s for all of them).

    Args:
        claim: gives the index (into :func:`mission_kernels`) of the next kernel to take,
            one index per call over all the processes that share it; an index past the end
            means done. None: all of them, in this process.
        announce: called once, before the first kernel this process takes that Numba's cache
            does not hold (:func:`cached`), e.g. :func:`print_compile_note`; never when every
            one is a load.

    Returns:
        how many of the kernels this process took had to be compiled (not in Numba's
        cache); 0 without Numba (see :data:`AVAILABLE`).
    """
    if not AVAILABLE:
        return 0
    found = mission_kernels()
    claim = claim or itertools.count().__next__
    compiled = 0
    while (index := claim()) < len(found):
        kernel, argument_types = found[index]
        if announce is not None and cached(kernel, argument_types) is False:
            announce()
            announce = None
        misses = sum(kernel.stats.cache_misses.values())
        kernel.compile(argument_types)
        compiled += sum(kernel.stats.cache_misses.values()) > misses
    return compiled
