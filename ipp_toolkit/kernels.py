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

import importlib.util
import os
from typing import Any

import numpy as np

__all__ = ["AVAILABLE", "find_or_add", "apply_values", "apply_values_with_stats",
           "REGION_STATS", "N_STATS"]

REGION_STATS = ("entropy_interesting", "squared_error_interesting", "true_positive",
                "predicted_positive", "new_weights_old_entropy", "old_weighted_entropy",
                "new_weighted_entropy")
"""The statistics vector of :func:`apply_values_with_stats` (and of
:meth:`ipp_toolkit.mapping.BeliefMaps.refresh_with_stats`), in order: the changes inside the
region of the sum of H over interesting cells, of the sum of (1 - p)^2 over them, of the true
and of the predicted positives (p > 0.5), then the sums of W' H (posterior weights, prior
entropies), of W H before and of W' H' after."""

N_STATS = len(REGION_STATS)

AVAILABLE = (os.environ.get("IPP_TOOLKIT_NO_NUMBA", "") in ("", "0")
             and importlib.util.find_spec("numba") is not None)
"""Whether the compiled kernels are used (Numba importable and not switched off)."""

_module: Any = None


def _compiled() -> Any:
    """The compiled kernels, imported (and loaded from Numba's cache) on first use.

    Importing Numba and loading the kernels takes about a second; a process that never
    refreshes a map (a CLI refusing a bad flag) does not pay it.
    """
    global _module
    if _module is None:
        from . import _compiled_kernels

        _module = _compiled_kernels
    return _module


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
