"""Interned float32 values: every distinct value gets an index and columns derived from it once.

A belief map cell's probability, entropy, class weight and weighted entropy are functions of
its log-odds, and log-odds are clipped sums of a few reading increments, so a mission sees few
distinct values (a few thousand, against ~30,000 cells under one footprint at r_M = 0.1 m).
:class:`ValueTable` computes each derived column once per distinct value, with the caller's
own NumPy function (so a looked-up value is bit for bit the one computed cell by cell), and
finds a value's index through an open-addressing hash table of its bit pattern (Knuth's
multiplicative hash, linear probing, at most half full). Lookup and insertion run in a
compiled kernel (:func:`ipp_toolkit._native.kernels.find_or_add`) where Numba is available, else in
vectorised NumPy probing rounds; both give every value one index.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from .._native import kernels

__all__ = ["ValueTable", "DerivedMemo", "exact_memo"]

_MULTIPLIER = np.uint32(2654435761)
_MIN_SLOT_BITS = 12

#: float32 values (n,) -> one (n,) float32 array per derived column.
Derive = Callable[[np.ndarray], Sequence[np.ndarray]]


class DerivedMemo:
    """The derived columns of every value ``derive`` was given, kept for the whole process.

    Tables that share one ``derive`` (every mission of a configuration) meet the same values
    over and over; a table given a memo computes a value's columns once per process instead
    of once per table. A looked-up column is the one ``derive`` computed, which is the one it
    would compute again: NumPy's element-wise functions give an element the same result
    wherever it sits in the array. That is checked once (:meth:`exact`); where it does not
    hold, the memo is not used and every table derives its own values.
    """

    def __init__(self, derive: Derive, n_columns: int):
        self.derive = derive
        self._row: dict[int, int] = {}
        self._columns = np.empty((n_columns, 256), dtype=np.float32)
        self._exact: bool | None = None

    def exact(self) -> bool:
        """Whether ``derive`` gives each value the same columns in any position of its input
        (checked on a spread of values, whole and one at a time, on first call)."""
        if self._exact is None:
            values = np.linspace(-10.0, 10.0, 67, dtype=np.float32)
            whole = np.stack(self.derive(values))
            alone = np.concatenate([np.stack(self.derive(values[i:i + 1]))
                                    for i in range(len(values))], axis=1)
            shifted = np.stack(self.derive(values[5:]))
            self._exact = (np.array_equal(whole.view(np.uint32), alone.view(np.uint32))
                           and np.array_equal(whole[:, 5:].view(np.uint32),
                                              shifted.view(np.uint32)))
        return self._exact

    def columns(self, values: np.ndarray) -> np.ndarray:
        """(n_columns, n) float32 derived columns of (n,) float32 values."""
        patterns = values.view(np.uint32).tolist()
        new = [pattern for pattern in dict.fromkeys(patterns) if pattern not in self._row]
        if new:
            derived = np.stack(self.derive(np.array(new, dtype=np.uint32).view(np.float32)))
            start = len(self._row)
            if start + len(new) > self._columns.shape[1]:
                grown = np.empty((len(self._columns), 2 * (start + len(new))), np.float32)
                grown[:, :start] = self._columns[:, :start]
                self._columns = grown
            self._columns[:, start:start + len(new)] = derived
            self._row.update(zip(new, range(start, start + len(new)), strict=True))
        return self._columns[:, [self._row[pattern] for pattern in patterns]]


def exact_memo(memo: DerivedMemo | None) -> DerivedMemo | None:
    """``memo`` where it may serve a table (:meth:`DerivedMemo.exact`), else None: the table
    then derives its own values."""
    return memo if memo is not None and memo.exact() else None


class ValueTable:
    """Every distinct float32 value seen, with derived columns.

    Args:
        derive: computes the derived columns of new values (element-wise NumPy code).
        names: the names of the columns ``derive`` returns, in order.
        first: values to intern at once (index 0 for the first).
        memo: a :class:`DerivedMemo` of ``derive`` shared with other tables (used where it
            is exact).

    Attributes:
        size: how many distinct values are interned.
    """

    def __init__(self, derive: Derive, names: Sequence[str], first: np.ndarray | None = None,
                 memo: DerivedMemo | None = None):
        self.derive = derive
        self.memo = exact_memo(memo)
        self.names = tuple(names)
        self.size = 0
        self._capacity = 0
        self._bits = np.empty(0, dtype=np.uint32)
        self._columns: dict[str, np.ndarray] = {name: np.empty(0, np.float32) for name in names}
        self._slot_bits = _MIN_SLOT_BITS
        self._slot = np.full(1 << self._slot_bits, -1, dtype=np.intp)
        self._grow(1 << (_MIN_SLOT_BITS - 1))
        if first is not None:
            self.indices(np.asarray(first, dtype=np.float32))

    def __len__(self) -> int:
        return self.size

    @property
    def values(self) -> np.ndarray:
        """(size,) float32 the interned values, by index."""
        return self._bits[:self.size].view(np.float32)

    def column(self, name: str) -> np.ndarray:
        """(capacity,) float32 derived column ``name``; entries past :attr:`size` are unset.

        The full array (not cut at ``size``), so that a gather by index needs no slicing.
        """
        return self._columns[name]

    def indices(self, values: np.ndarray) -> np.ndarray:
        """(same shape) intp index of every float32 value (any strides), interning new ones."""
        if values.dtype != np.float32:
            raise TypeError(f"ValueTable holds float32 values, got {values.dtype}")
        bits = values.view(np.uint32)
        self._reserve(bits.size)
        out = np.empty(bits.shape, dtype=np.intp)
        old_size = self.size
        if kernels.AVAILABLE:
            self.size = int(kernels.find_or_add(
                bits if bits.ndim == 2 else bits.reshape(1, -1), self._slot, self._bits,
                self.size, np.uint32(32 - self._slot_bits), _MULTIPLIER,
                out if out.ndim == 2 else out.reshape(1, -1)))
        else:
            self._find_or_add_numpy(bits.reshape(-1), out.reshape(-1))
        if self.size > old_size:
            self._derive(old_size)
        return out

    def intern_resumable(self, run: Callable[..., tuple[int, bool]], room: int = 0) -> None:
        """Let a compiled pass intern values into the table, growing it when the pass stops.

        ``run(slot, bits, size, shift, multiplier, limit)`` interns (as
        :func:`ipp_toolkit._native.kernels.find_or_add` does) and returns ``(size, True)`` when it
        is done, or ``(size, False)`` when it stopped because the table might otherwise hold
        more than ``limit`` values; then the table grows, with room for at least ``room``
        more values, and ``run`` is called again, to go on where it stopped (it keeps its
        own place). New values get their derived columns once, at the end. Unlike
        :meth:`indices`, which reserves room for every cell it is given, the hash table
        grows only with the values it holds, so it stays small enough for the CPU cache.
        """
        old_size = self.size
        while True:
            limit = min(self._capacity, len(self._slot) // 2)
            self.size, done = run(self._slot, self._bits, self.size,
                                  np.uint32(32 - self._slot_bits), _MULTIPLIER, limit)
            if done:
                break
            self._reserve(max(self.size, room, 1 << (_MIN_SLOT_BITS - 1)))
        if self.size > old_size:
            self._derive(old_size)

    # ----------------------------------------------------------------------------------------

    def _derive(self, start: int) -> None:
        """Fill the values and derived columns of indices ``start..size``."""
        values = self._bits[start:self.size].view(np.float32)
        derived = self.memo.columns(values) if self.memo is not None else self.derive(values)
        if len(derived) != len(self.names):
            raise ValueError(f"derive returned {len(derived)} columns, expected {self.names}")
        for name, column in zip(self.names, derived, strict=True):
            self._columns[name][start:self.size] = column

    def _reserve(self, extra: int) -> None:
        """Room for ``extra`` more values, the hash table at most half full after them."""
        needed = self.size + extra
        if needed > self._capacity:
            self._grow(max(needed, 2 * self._capacity))
        if 2 * needed > len(self._slot):
            bits = max(self._slot_bits + 1, int(2 * needed - 1).bit_length())
            self._rehash(bits)

    def _grow(self, capacity: int) -> None:
        def grown(array: np.ndarray) -> np.ndarray:
            new = np.empty(capacity, dtype=array.dtype)
            new[:self.size] = array[:self.size]
            return new

        self._bits = grown(self._bits)
        self._columns = {name: grown(column) for name, column in self._columns.items()}
        self._capacity = capacity

    def _rehash(self, slot_bits: int) -> None:
        self._slot_bits = slot_bits
        self._slot = np.full(1 << slot_bits, -1, dtype=np.intp)
        mask = len(self._slot) - 1
        homes = (self._bits[:self.size] * _MULTIPLIER) >> np.uint32(32 - slot_bits)
        for index, slot in enumerate(homes.tolist()):
            while self._slot[slot] >= 0:
                slot = (slot + 1) & mask
            self._slot[slot] = index

    def _find_or_add_numpy(self, bits: np.ndarray, out: np.ndarray) -> None:
        """:func:`ipp_toolkit._native.kernels.find_or_add` in NumPy: probing rounds over all
        cells."""
        mask = len(self._slot) - 1
        slot = ((bits * _MULTIPLIER) >> np.uint32(32 - self._slot_bits)).astype(np.intp)
        pending = np.arange(len(bits))
        while len(pending):
            index = self._slot[slot[pending]]
            occupied = index >= 0
            hit = np.zeros(len(pending), dtype=bool)
            hit[occupied] = self._bits[index[occupied]] == bits[pending[occupied]]
            out[pending[hit]] = index[hit]
            if not occupied.all():
                # Probing reached an empty slot: the value is new. Intern each distinct one
                # from there; those cells then retry at the same slot and find it.
                cells = pending[~occupied]
                _, first = np.unique(bits[cells], return_index=True)
                for cell in cells[np.sort(first)].tolist():
                    self._insert(int(bits[cell]), int(slot[cell]), mask)
            collided = pending[occupied & ~hit]
            slot[collided] = (slot[collided] + 1) & mask
            pending = pending[~hit]

    def _insert(self, pattern: int, slot: int, mask: int) -> None:
        """Intern one bit pattern, probing from ``slot`` (it may be there already)."""
        while True:
            index = int(self._slot[slot])
            if index < 0:
                self._slot[slot] = self.size
                self._bits[self.size] = pattern
                self.size += 1
                return
            if int(self._bits[index]) == pattern:
                return
            slot = (slot + 1) & mask
