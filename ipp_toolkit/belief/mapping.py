"""Occupancy-grid beliefs: log-odds fusion, entropy, weighted entropy and metrics.

The owner of every entropy computation in the toolkit. A map's state is each cell's index
into a table of the log-odds values the maps hold (float32, ``[y, x]``), with each value's
probability, entropy and weighted entropy computed once; the per-cell log-odds, probability
and entropy arrays are looked up from it on demand, only inside the rectangles that changed
since they were last read. The 11 x 11 planning-grid planes (block sums of probability and of
weighted entropy) are maintained incrementally, so a step costs in proportion to the
footprints, not to the map. A mission step fuses all its readings into every map in two
compiled passes (:meth:`BeliefMaps.fuse_targets`), with the numbers of the per-rectangle
:meth:`BeliefMaps.add_evidence` and :meth:`BeliefMaps.refresh`.
"""

from __future__ import annotations

from functools import cache, partial

import numpy as np

from .._native import kernels
from .._native.kernels import REGION_STATS
from ..probability import LOGODDS_CLIP, PROB_CLIP, binary_entropy, logit
from .block_grid import BlockGrid, Rect
from .value_table import DerivedMemo, ValueTable

__all__ = [
    "PROB_CLIP",
    "LOGODDS_CLIP",
    "logit",
    "binary_entropy",
    "entropy_from_logodds",
    "class_weights",
    "weighted_entropy",
    "fuse_measurement",
    "BELIEF_COLUMNS",
    "belief_columns",
    "BeliefMaps",
    "REGION_STATS",
    "f1_score",
    "expected_gain",
    "OUTCOME_WEIGHTINGS",
    "false_positive_gain",
    "false_positive_term_applies",
    "interesting_gain",
]

WEIGHT_TIE_TOLERANCE = 1e-3
"""Cells within this distance of 0.5 are 'unknown' and get weight 0.5."""


_INV_LN2 = np.float32(1.0 / np.log(2.0))


def entropy_from_logodds(logodds: np.ndarray) -> np.ndarray:
    """Entropy in bits of sigmoid(logodds), computed stably from |l|; same shape and dtype.

    With a = |l| and e = exp(-a): H = (log1p(e) + a e / (1 + e)) / ln 2, which needs one exp
    and one log1p per cell instead of two logs of probabilities.
    """
    a = np.abs(np.clip(logodds, -LOGODDS_CLIP, LOGODDS_CLIP))
    e = np.exp(-a)
    return (np.log1p(e) + a * e / (1 + e)) * _INV_LN2


def class_weights(p: np.ndarray, weight_interesting: float = 1.0,
                  weight_uninteresting: float = 0.0) -> np.ndarray:
    """Per-cell class weight W(p): w1 if p > 0.5, w2 if p < 0.5, 0.5 within 1e-3 of 0.5.

    Same shape as ``p``; float32 for float32 input (the hot path), float64 otherwise.
    """
    p = np.asarray(p)
    dtype = np.float32 if p.dtype == np.float32 else np.float64
    # Arithmetic on a boolean mask is several times faster than np.where with scalars.
    w = np.array(p > 0.5, dtype=dtype)
    if (weight_interesting, weight_uninteresting) != (1.0, 0.0):
        w *= dtype(weight_interesting - weight_uninteresting)
        w += dtype(weight_uninteresting)
    np.copyto(w, dtype(0.5), where=np.abs(p - dtype(0.5)) <= dtype(WEIGHT_TIE_TOLERANCE))
    return w


def weighted_entropy(p: np.ndarray, weight_interesting: float = 1.0,
                     weight_uninteresting: float = 0.0) -> np.ndarray:
    """Per-cell weighted entropy W(p) H(p) in bits; same shape as ``p``."""
    return class_weights(p, weight_interesting, weight_uninteresting) * binary_entropy(p)


def fuse_measurement(prob: np.ndarray | float, likelihood: np.ndarray | float,
                     prior: float = 0.5) -> np.ndarray:
    """Posterior of a binary Bayes filter in log-odds: l <- l + logit(z) - logit(prior).

    Args:
        prob: current probabilities, any shape.
        likelihood: per-cell P(interesting | reading), broadcastable to ``prob``.
        prior: the map prior.

    Returns:
        posterior probabilities, same shape as ``prob``, kept in [PROB_CLIP, 1 - PROB_CLIP].
    """
    logodds = np.clip(logit(prob) + logit(likelihood) - logit(prior), -LOGODDS_CLIP, LOGODDS_CLIP)
    return 1.0 / (1.0 + np.exp(-logodds))


def f1_score(truth: np.ndarray, predicted: np.ndarray) -> float:
    """F1 of the positive class; 0 when there is no true or predicted positive."""
    truth = np.asarray(truth, dtype=bool)
    predicted = np.asarray(predicted, dtype=bool)
    tp = np.count_nonzero(truth & predicted)
    denominator = np.count_nonzero(truth) + np.count_nonzero(predicted)
    return 2.0 * tp / denominator if denominator else 0.0


BELIEF_COLUMNS = ("prob", "entropy", "weights", "wentropy")
"""The functions of a cell's log-odds that :attr:`BeliefMaps.table` keeps per value."""


def belief_columns(logodds: np.ndarray, weight_interesting: float = 1.0,
                   weight_uninteresting: float = 0.0) -> tuple[np.ndarray, ...]:
    """p = sigmoid(l), H(p) in bits, W(p) and W H of float32 log-odds; each like ``logodds``.

    Named by :data:`BELIEF_COLUMNS`; the one definition of a cell's cached values.
    """
    prob = 1.0 / (1.0 + np.exp(-logodds))
    entropy = entropy_from_logodds(logodds)
    weights = class_weights(prob, weight_interesting, weight_uninteresting)
    return prob, entropy, weights, weights * entropy


@cache
def _belief_memo(weight_interesting: float, weight_uninteresting: float) -> DerivedMemo:
    """The process-wide :class:`~ipp_toolkit.belief.value_table.DerivedMemo` of
    :func:`belief_columns`
    with these class weights (every mission of a configuration meets the same values)."""
    return DerivedMemo(partial(belief_columns, weight_interesting=weight_interesting,
                               weight_uninteresting=weight_uninteresting), len(BELIEF_COLUMNS))


class BeliefMaps:
    """A stack of M occupancy maps in log-odds with cached probabilities and entropies.

    The state is :attr:`value_index`: each cell's index into :attr:`table`, which holds
    every log-odds value the maps hold with its :data:`BELIEF_COLUMNS`. The per-cell arrays
    :attr:`logodds`, :attr:`prob`, :attr:`entropy` and :attr:`wentropy` are those columns
    looked up at every cell, materialised on first use and brought up to date, inside the
    rectangles refreshed since (:attr:`changes`), whenever one of them is read: a mission
    step writes only the index array and the block sums, so a simulation that reads only
    the planning-grid planes (the actors' default observations) never builds them.

    Attributes:
        table: the :class:`~ipp_toolkit.belief.value_table.ValueTable` of every log-odds value the
            maps hold, with their :data:`BELIEF_COLUMNS`.
        value_index: (M, H, W) int32, each cell's index into :attr:`table` (as of its last
            refresh).
        logodds: (M, H, W) float32, the belief (the table's value at each cell).
        prob: (M, H, W) float32, sigmoid(logodds).
        entropy: (M, H, W) float32, binary entropy in bits.
        wentropy: (M, H, W) float32, weighted entropy W(p) H(p) in bits.
        prob_blocks: (M, G, G) float64 block sums of ``prob``.
        wentropy_blocks: (M, G, G) float64 block sums of the weighted entropy W(p) H(p).
        changes: every (map index, rect) refreshed so far, in order: caches built on the
            maps (:class:`ipp_toolkit.belief.gain.FootprintGainCache`, the arrays above) update
            only these regions.

    Writing :attr:`logodds` directly and then calling :meth:`refresh` over the written
    region sets a belief by hand (tests, hand-built states); :meth:`refresh` interns what
    :attr:`logodds` holds there.
    """

    def __init__(self, n_maps: int, blocks: BlockGrid, prior: float = 0.5,
                 weight_interesting: float = 1.0, weight_uninteresting: float = 0.0):
        size = blocks.map_cells
        self.blocks = blocks
        self.prior_logodds = float(logit(prior))
        self.weight_interesting = weight_interesting
        self.weight_uninteresting = weight_uninteresting
        memo = _belief_memo(weight_interesting, weight_uninteresting)
        self.table = ValueTable(memo.derive, BELIEF_COLUMNS,
                                first=np.full(1, self.prior_logodds, dtype=np.float32),
                                memo=memo)
        # Zeros (the prior's index) from the allocator's zeroed pages: only the pages under
        # footprints are ever touched.
        self.value_index = np.zeros((n_maps, size, size), dtype=np.int32)
        p0, h0, _, wh0 = (self.table.column(name)[0] for name in BELIEF_COLUMNS)
        self.prior_prob, self.prior_entropy = p0, h0  # the caches' value in every new cell
        self.prior_wentropy = wh0
        self.prob_blocks = np.broadcast_to(blocks.block_area * float(p0),
                                           (n_maps,) + blocks.block_area.shape).copy()
        self.wentropy_blocks = np.broadcast_to(blocks.block_area * float(wh0),
                                               (n_maps,) + blocks.block_area.shape).copy()
        self.changes: list[tuple[int, Rect]] = []
        self._arrays: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None
        self._synced = 0  # changes[:_synced] are in _arrays
        self._pairs = np.empty(0, dtype=np.uint32)  # fuse_targets' scratch, kept between steps
        # _transitions[k, 2 s + r]: the index of clip(value k + the increment of a reading r
        # with the increments of delta slot s), -1 until first met (fuse_targets).
        self._delta_slots: dict[tuple[float, float], int] = {}
        self._transitions = np.full((0, 0), -1, dtype=np.int32)

    @property
    def logodds(self) -> np.ndarray:
        """(M, H, W) float32 log-odds (see the class docstring)."""
        return self._synced_arrays()[0]

    @property
    def prob(self) -> np.ndarray:
        """(M, H, W) float32 sigmoid(logodds)."""
        return self._synced_arrays()[1]

    @property
    def entropy(self) -> np.ndarray:
        """(M, H, W) float32 binary entropy in bits."""
        return self._synced_arrays()[2]

    @property
    def wentropy(self) -> np.ndarray:
        """(M, H, W) float32 weighted entropy W(p) H(p) in bits."""
        return self._synced_arrays()[3]

    def changes_since(self, seen: int, reader: str) -> list[tuple[int, Rect]]:
        """The distinct (map index, rect) of :attr:`changes` after its first ``seen``, in
        order of first appearance: what a cache that has folded ``changes[:seen]`` in still
        has to fold in.

        Raises:
            RuntimeError: the log holds fewer than ``seen`` changes (it was cut); ``reader``
                names the cache to build anew.
        """
        if len(self.changes) < seen:
            raise RuntimeError(f"the maps' change log was cut: build a new {reader}")
        return list(dict.fromkeys(self.changes[seen:]))

    def _synced_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The per-cell arrays, built at the prior on first use, with every change since
        the last call looked up from :attr:`value_index` (a lookup writes the values the
        arrays already hold wherever they are current, so looking up too much is harmless)."""
        if self._arrays is None:
            shape = self.value_index.shape
            self._arrays = tuple(np.full(shape, value, dtype=np.float32) for value in (
                self.prior_logodds, self.prior_prob, self.prior_entropy, self.prior_wentropy))
            self._synced = 0
        if self._synced < len(self.changes):
            pending = self.changes_since(self._synced, "BeliefMaps")
            self._synced = len(self.changes)
            prob, entropy, _, wentropy = (self.table.column(name) for name in BELIEF_COLUMNS)
            values = self.table.values
            if kernels.AVAILABLE:
                kernels.gather_caches(self.value_index.view(np.uint32), values, prob, entropy,
                                      wentropy, np.array([m for m, _ in pending], np.int64),
                                      np.array([r for _, r in pending], np.int64).reshape(-1, 4),
                                      *self._arrays)
            else:
                for m, (r0, r1, c0, c1) in pending:
                    indices = self.value_index[m, r0:r1, c0:c1]
                    for array, column in zip(self._arrays, (values, prob, entropy, wentropy),
                                             strict=True):
                        array[m, r0:r1, c0:c1] = column[indices]
        return self._arrays

    def add_evidence(self, index: int, rect: Rect, delta_logodds: np.ndarray) -> None:
        """Fuse one measurement into map ``index`` (log-odds only; call :meth:`refresh` after).

        Args:
            index: which map of the stack.
            rect: the measurement's footprint.
            delta_logodds: (rows, cols) logit(z) - logit(prior) of the measurement.
        """
        r0, r1, c0, c1 = rect
        region = self.logodds[index, r0:r1, c0:c1]
        region += delta_logodds
        np.clip(region, -LOGODDS_CLIP, LOGODDS_CLIP, out=region)

    def refresh(self, index: int, rect: Rect) -> None:
        """Recompute the caches of map ``index`` inside ``rect`` from its log-odds.

        Overlapping rectangles may be refreshed one after another: a cell refreshed twice
        contributes a zero change the second time, so block sums and any statistics built
        from the changes (:meth:`refresh_with_stats`) stay exact.
        """
        self._refresh(index, rect, None)

    def refresh_with_stats(self, index: int, rect: Rect, truth: np.ndarray) -> np.ndarray:
        """:meth:`refresh`, returning how the metric and reward sums moved inside ``rect``.

        Args:
            truth: (rows, cols) bool ground truth of the rectangle.

        Returns:
            (len(REGION_STATS),) float64 changes, named by :data:`REGION_STATS`.
        """
        return self._refresh(index, rect, truth)

    def _refresh(self, index: int, rect: Rect, truth: np.ndarray | None) -> np.ndarray | None:
        r0, r1, c0, c1 = (int(v) for v in rect)
        arrays = self._synced_arrays()  # before the change is logged: it reads the log
        self.changes.append((index, (r0, r1, c0, c1)))
        cells = (index, slice(r0, r1), slice(c0, c1))
        ids = self.table.indices(arrays[0][cells])
        if not kernels.AVAILABLE:
            return self._apply_numpy(index, (r0, r1, c0, c1), ids, truth, arrays)
        prob, entropy, weights, wentropy = (self.table.column(name) for name in BELIEF_COLUMNS)
        rows, cols = self.blocks.block_of_cell[r0:r1], self.blocks.block_of_cell[c0:c1]
        caches = (self.value_index[cells], arrays[1][cells], arrays[2][cells], arrays[3][cells])
        if truth is None:
            kernels.apply_values(ids, *caches, prob, entropy, wentropy, rows, cols,
                                 self.prob_blocks[index], self.wentropy_blocks[index])
            return None
        return kernels.apply_values_with_stats(ids, *caches, prob, entropy, weights, wentropy,
                                               rows, cols, self.prob_blocks[index],
                                               self.wentropy_blocks[index], truth)

    def fuse_targets(self, rects: np.ndarray, readings: np.ndarray, offsets: np.ndarray,
                     deltas: np.ndarray, target_maps: np.ndarray, target_offsets: np.ndarray,
                     senders: np.ndarray, truth: np.ndarray) -> np.ndarray:
        """Fuse readings into several maps and refresh them, in compiled passes.

        Target t is map ``target_maps[t]`` receiving the readings
        ``senders[target_offsets[t]:target_offsets[t + 1]]``. The result is exactly that of,
        for each target in order, :meth:`add_evidence` of each of its readings and then
        :meth:`refresh` of each of their rectangles, :meth:`refresh_with_stats` for the last
        target: the same caches, block sums, value indices, change log and statistics, to
        the last bit.

        Args:
            rects: (F, 4) int64 footprint rectangle of each reading.
            readings: (cells,) bool the readings one after another, each row-major
                (:func:`ipp_toolkit._native.kernels.read_cells`).
            offsets: (F + 1,) int64 where each reading starts in ``readings`` (and the end).
            deltas: (F, 2) float32 log-odds increments (d0, d1) of a 0 / 1 in each reading.
            target_maps: (T,) int64 map indices; target_offsets (T + 1,) int64; senders
                (S,) int64 indices into ``rects``.
            truth: (H, W) bool ground truth, for the statistics of the last target.

        Returns:
            (senders of the last target, len(REGION_STATS)) float64, one row per rectangle
            as :meth:`refresh_with_stats` returns it.

        Raises:
            RuntimeError: the compiled kernels are not available (:data:`kernels.AVAILABLE`).
        """
        if not kernels.AVAILABLE:
            raise RuntimeError("fuse_targets needs the compiled kernels; without them call "
                               "add_evidence and refresh per rectangle")
        rect_list = [tuple(rect) for rect in rects.tolist()]
        bounds, sender_list = target_offsets.tolist(), senders.tolist()
        self.changes += [(index, rect_list[u])
                         for t, index in enumerate(target_maps.tolist())
                         for u in sender_list[bounds[t]:bounds[t + 1]]]
        clip = np.float32(LOGODDS_CLIP)
        value_index = self.value_index.view(np.uint32)  # unsigned: cheaper indexing
        areas = (rects[:, 1] - rects[:, 0]) * (rects[:, 3] - rects[:, 2])
        needed = 2 * int(areas[senders].sum())  # every target's footprints, overlaps twice
        if len(self._pairs) < needed:
            self._pairs = np.empty(needed, dtype=np.uint32)
        pairs = self._pairs
        delta_slots = np.array([self._delta_slot(pair) for pair in deltas.tolist()],
                               dtype=np.int64)
        cursor = np.array([0, 0, -1, 0], dtype=np.int64)  # target, footprint, row, pair

        def run(slot: np.ndarray, table_bits: np.ndarray, size: int, shift: np.uint32,
                multiplier: np.uint32, limit: int) -> tuple[int, bool]:
            transitions = self._grown_transitions(len(table_bits))
            return kernels.fuse_evidence(value_index, readings, offsets, rects, deltas, clip,
                                         target_maps, target_offsets, senders, slot,
                                         table_bits, size, shift, multiplier, limit, cursor,
                                         pairs, table_bits.view(np.float32), transitions,
                                         delta_slots)

        self.table.intern_resumable(run, room=self.value_index.shape[2])
        columns = (self.table.column(name) for name in BELIEF_COLUMNS)
        stats = np.zeros((target_offsets[-1] - target_offsets[-2], len(REGION_STATS)))
        kernels.apply_targets(pairs, *columns, self.blocks.block_of_cell, self.blocks.edges,
                              self.prob_blocks, self.wentropy_blocks, rects, target_maps,
                              target_offsets, senders, truth, stats)
        return stats

    def _delta_slot(self, pair: list[float]) -> int:
        """The column pair of :attr:`_transitions` of a reading's increments (d0, d1)."""
        slot = self._delta_slots.setdefault(tuple(pair), len(self._delta_slots))
        self._grown_transitions(0, 2 * slot + 2)
        return slot

    def _grown_transitions(self, rows: int, columns: int = 0) -> np.ndarray:
        """:attr:`_transitions`, grown to at least ``rows`` rows (one per table entry) and
        ``columns`` columns; new entries unknown (-1)."""
        old = self._transitions
        if old.shape[0] < rows or old.shape[1] < columns:
            shape = (max(rows, old.shape[0]), max(columns, old.shape[1]))
            self._transitions = np.full(shape, -1, dtype=np.int32)
            self._transitions[:old.shape[0], :old.shape[1]] = old
        return self._transitions

    def _apply_numpy(self, index: int, rect: Rect, new: np.ndarray, truth: np.ndarray | None,
                     arrays: tuple[np.ndarray, ...]) -> np.ndarray | None:
        """The caches' update of :meth:`_refresh` in NumPy (the kernels' reference)."""
        r0, r1, c0, c1 = rect
        cells = (index, slice(r0, r1), slice(c0, c1))
        prob, entropy, weights, wentropy = (self.table.column(name) for name in BELIEF_COLUMNS)
        cached_prob, cached_entropy, cached_wentropy = arrays[1], arrays[2], arrays[3]
        self.value_index[cells] = new
        old_prob, old_entropy = cached_prob[cells].copy(), cached_entropy[cells].copy()
        old_wentropy = cached_wentropy[cells].copy()
        new_prob, new_entropy, new_wentropy = prob[new], entropy[new], wentropy[new]
        self.blocks.add_block_sums(self.prob_blocks[index], new_prob - old_prob, rect)
        self.blocks.add_block_sums(self.wentropy_blocks[index], new_wentropy - old_wentropy,
                                   rect)
        cached_prob[cells] = new_prob
        cached_entropy[cells] = new_entropy
        cached_wentropy[cells] = new_wentropy
        if truth is None:
            return None
        # (1 - p')^2 - (1 - p)^2 = (p - p') (2 - p - p')
        squared_error_change = (old_prob - new_prob) * (2.0 - old_prob - new_prob)
        old_positive, new_positive = old_prob > 0.5, new_prob > 0.5
        return np.array([
            np.sum(new_entropy - old_entropy, where=truth, dtype=np.float64),
            np.sum(squared_error_change, where=truth, dtype=np.float64),
            np.count_nonzero(new_positive & truth) - np.count_nonzero(old_positive & truth),
            np.count_nonzero(new_positive) - np.count_nonzero(old_positive),
            np.sum(weights[new] * old_entropy, dtype=np.float64),
            np.sum(old_wentropy, dtype=np.float64),
            np.sum(new_wentropy, dtype=np.float64),
        ], dtype=np.float64)

    def prob_plane(self, index: int) -> np.ndarray:
        """(G, G) mean probability of map ``index`` per planning-grid block."""
        return self.prob_blocks[index] / self.blocks.block_area

    def wentropy_plane(self, index: int) -> np.ndarray:
        """(G, G) mean weighted entropy W(p) H(p) of map ``index`` per block (mean of W H)."""
        return self.wentropy_blocks[index] / self.blocks.block_area


_LOGODDS_CLIP32 = np.float32(LOGODDS_CLIP)


OUTCOME_WEIGHTINGS = ("predictive", "belief")
"""How :func:`expected_gain` weights the two readings: by the predictive distribution of the
reading (``predictive``, the toolkit's default) or by the current belief p, as the paper
authors' IG baseline does (``belief``)."""


def expected_gain(logodds: np.ndarray, prob: np.ndarray, entropy: np.ndarray,
                  accuracy: float, delta_logodds: np.ndarray,
                  weight_interesting: float = 1.0, weight_uninteresting: float = 0.0,
                  outcome_weighting: str = "predictive") -> np.ndarray:
    """Expected weighted-entropy reduction per cell of one reading at one altitude.

    With p the cell's probability, a the accuracy and q = P(reading = 1) = p a + (1-p)(1-a),
    the posteriors are l1 = clip(l + d1) and l0 = clip(l + d0), and the gain is
    ``q W(p1) (H(p) - H(p1)) + (1 - q) W(p0) (H(p) - H(p0))`` in bits, W the class weights of
    the posterior (as in the reward). With ``outcome_weighting="belief"`` the two readings
    are weighted by the belief instead, ``p W(p1) (...) + (1 - p) W(p0) (...)``: the authors'
    IG (their ``IG_baseline.py``), which treats the reading as if it were the cell's true
    state. Only the weights of the two outcomes change; the posteriors stay Bayes' rule.

    Element-wise: the three arrays may have any common shape, e.g. (h, w) for one map's
    window or (K, H, W) for a stack of maps.

    Args:
        logodds: (h, w) float32 log-odds l of the cells.
        prob: (h, w) float32 sigmoid(l) (the map's cache).
        entropy: (h, w) float32 H(p) in bits (the map's cache).
        accuracy: probability a that a reading at this altitude is correct.
        delta_logodds: (2,) float32 log-odds increments (d0, d1) of a reading 0 / 1.
        weight_interesting, weight_uninteresting: the reward's class weights.
        outcome_weighting: one of :data:`OUTCOME_WEIGHTINGS`.

    Returns:
        (h, w) float32 expected gain per cell.
    """
    if outcome_weighting not in OUTCOME_WEIGHTINGS:
        raise ValueError(f"outcome_weighting must be one of {OUTCOME_WEIGHTINGS}, "
                         f"got {outcome_weighting!r}")
    a = np.float32(accuracy)
    d0, d1 = (np.float32(d) for d in delta_logodds)
    joint1 = prob * a  # P(cell = 1, reading = 1)
    q = prob * (a + a - np.float32(1.0))
    q += np.float32(1.0) - a
    # Bayes' rule gives the posterior probabilities with one division each instead of a
    # sigmoid of l1 / l0; they only feed the weights, whose bands (p > 0.5, |p - 0.5| <= 1e-3)
    # lie far inside the log-odds clip, so clipping cannot change them.
    p1 = joint1 / q
    not_q = np.float32(1.0) - q
    p0 = prob - joint1
    p0 /= not_q
    # d1 > 0 > d0 (accuracy > 0.5), so each posterior can only cross one side of the clip.
    l1 = logodds + d1
    np.minimum(l1, _LOGODDS_CLIP32, out=l1)
    l0 = logodds + d0
    np.maximum(l0, -_LOGODDS_CLIP32, out=l0)
    if outcome_weighting == "belief":
        # The authors weight reading 1 by P(cell = 1) rather than P(reading = 1); q and
        # not_q are no longer needed for the posteriors, so they are overwritten in place.
        np.copyto(q, prob)
        np.subtract(np.float32(1.0), prob, out=not_q)
    gain1 = entropy - entropy_from_logodds(l1)
    gain1 *= class_weights(p1, weight_interesting, weight_uninteresting)
    gain1 *= q
    gain0 = entropy - entropy_from_logodds(l0)
    gain0 *= class_weights(p0, weight_interesting, weight_uninteresting)
    gain0 *= not_q
    gain1 += gain0
    return gain1


def interesting_gain(logodds: np.ndarray, prob: np.ndarray, entropy: np.ndarray,
                     accuracy: float, delta_logodds: np.ndarray) -> np.ndarray:
    """Expected entropy reduction per cell of one reading, given that the cell is interesting.

    The table's metric is the mean entropy over the truly interesting cells, so a reading
    helps it only where the cell is interesting; there the reading is 1 with probability a:
    ``a (H(p) - H(p1)) + (1 - a) (H(p) - H(p0))`` in bits, with l1 = clip(l + d1) and
    l0 = clip(l + d0). Multiplied by the probability that the cell is interesting (e.g. the
    smoothed one of :class:`~ipp_toolkit.belief.interest.InterestSmoother`) it is the reading's
    expected contribution to the metric. ``prob`` is unused (same signature as
    :func:`expected_gain`, so the two are interchangeable per-cell objectives).

    Args:
        logodds, prob, entropy: (h, w) float32 log-odds, probability and entropy (bits).
        accuracy: probability a that a reading at this altitude is correct.
        delta_logodds: (2,) float32 log-odds increments (d0, d1) of a reading 0 / 1.

    Returns:
        (h, w) float32 expected gain per cell, at most 1; negative where the cell is believed
        uninteresting (p < 0.5), as a correct reading of 1 there first raises its entropy.
    """
    a = np.float32(accuracy)
    d0, d1 = (np.float32(d) for d in delta_logodds)
    l1 = logodds + d1
    np.minimum(l1, _LOGODDS_CLIP32, out=l1)
    l0 = logodds + d0
    np.maximum(l0, -_LOGODDS_CLIP32, out=l0)
    gain1 = entropy - entropy_from_logodds(l1)
    gain1 *= a
    gain0 = entropy - entropy_from_logodds(l0)
    gain0 *= np.float32(1.0) - a
    gain1 += gain0
    return gain1


def false_positive_term_applies(steps_left: int, last_steps: int | None) -> bool:
    """Whether the false-positive term counts with ``steps_left`` steps of the budget to go,
    when it is kept to the mission's last ``last_steps`` steps (None or 0: every step)."""
    return not last_steps or steps_left <= last_steps


def false_positive_gain(logodds: np.ndarray, prob: np.ndarray, entropy: np.ndarray,
                        accuracy: float, delta_logodds: np.ndarray) -> np.ndarray:
    """Expected entropy reduction per cell of one reading, given that the cell is not
    interesting, where the map believes it is (p > 0.5); 0 elsewhere.

    The mirror of :func:`interesting_gain` for the cells that cost F1: a cell of the
    uninteresting class held above 0.5 (a noisy reading from 10-15 m) is a false positive,
    which the entropy over interesting cells never sees. A reading there is 0 with
    probability a: ``a (H(p) - H(p0)) + (1 - a) (H(p) - H(p1))`` in bits where l > 0.
    Weighted by the probability that the cell is *not* interesting it is the value of
    checking it (``false_positive_weight`` of the ``ig_spatial`` family). ``prob`` is unused.

    Args:
        logodds, prob, entropy: (h, w) float32 log-odds, probability and entropy (bits).
        accuracy: probability a that a reading at this altitude is correct.
        delta_logodds: (2,) float32 log-odds increments (d0, d1) of a reading 0 / 1.

    Returns:
        (h, w) float32 expected gain per cell, at most 1; 0 where p <= 0.5.
    """
    a = np.float32(accuracy)
    d0, d1 = (np.float32(d) for d in delta_logodds)
    l0 = logodds + d0
    np.maximum(l0, -_LOGODDS_CLIP32, out=l0)
    l1 = logodds + d1
    np.minimum(l1, _LOGODDS_CLIP32, out=l1)
    gain0 = entropy - entropy_from_logodds(l0)
    gain0 *= a
    gain1 = entropy - entropy_from_logodds(l1)
    gain1 *= np.float32(1.0) - a
    gain0 += gain1
    gain0 *= logodds > 0
    return gain0
