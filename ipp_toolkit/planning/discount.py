"""``ig``'s discount of teammates' same-step footprints, for planners that read the gain planes.

The ``ig`` family decides in agent order, and agent k values a cell that the next footprint
of a heard, already decided teammate covers at ``overlap_discount`` (0.5) times its gain: the
teammate will measure it this step. A learned planner that scores its options from the
``gain`` planes (:func:`ipp_toolkit.sim.features.gain_planes`; the gain-prior actors of COMA
and PPO) gets planes built before anyone decided, holding every option's whole gain.
:class:`TeammateDiscount` gives such a planner the value ``ig``'s family would use: for agent
k and the targets its decided teammates chose, each option's plane value minus
``(1 - overlap_discount)`` times the part of it under their footprints, computed from agent
k's own local map with the objective the planes were built with (``ig``'s, or
``ig_spatial``'s / ``ig_learned``'s with a smoothed or learned probability of interest and the
clean-up term). With the policy's own correction at zero, the planner then chooses what the
``ig`` planner of the same objective chooses. With ``lookahead_steps`` > 1 it also adds each
option's best continuation along the agent's own path, as the ``ig`` planner with the same
options does (:mod:`ipp_toolkit.planning.lookahead`).

Cost without a lookahead: nothing while no decided teammate is heard; otherwise the team's
probability of interest (a learned prior answers from the gain planes' call of the same
step, see :meth:`~ipp_toolkit.belief.field_prior.FieldPrior.square_values`) and the
objective's sums over the segments (:mod:`ipp_toolkit.planning.segments`) of the boxes of
the options whose footprints a teammate's overlaps, from their cells. A lookahead adds, for
every agent and step, the probability of interest and the continuation's summed-area tables
over the segments, from the tables' segment sums kept per agent and summed again where its
map changed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from ..belief.field_prior import shared_prior
from ..belief.gain import objective_table
from ..belief.interest import interest_smoother
from ..belief.mapping import false_positive_term_applies
from ..config.schema import GAIN_INTEREST_SMOOTHED, EnvConfig, FeatureConfig
from ..sim.features import gain_normaliser, plane_objective
from ..sim.team import ACTION_DELTAS, N_ACTIONS
from ..world.sensor import Camera
from . import AgentView
from .lookahead import (
    LOOKAHEAD_DISCOUNT,
    check_lookahead,
    continuation_values,
    mission_lookahead,
    steps_left,
)
from .segments import SegmentBox, SegmentGrid, SegmentSums, objective_segment_values

__all__ = ["OVERLAP_DISCOUNT", "TeammateDiscount", "bounding_box", "check_overlap_discount",
           "covered_mask", "discount_covered"]

OVERLAP_DISCOUNT = 0.5
"""The ``ig`` family's default factor on cells a decided teammate's next footprint covers."""

#: (row0, row1, col0, col1) of a rectangle of map cells.
Rect = tuple[int, int, int, int]


def check_overlap_discount(value: float) -> float:
    """``value`` as a float, or ValueError naming it unless it lies in [0, 1]."""
    if not 0.0 <= value <= 1.0 or math.isnan(value):
        raise ValueError(f"overlap_discount must lie in [0, 1], got {value!r}")
    return float(value)


def bounding_box(rects: np.ndarray) -> Rect:
    """Union bounding box of (K, 4) rectangles (row0, row1, col0, col1)."""
    return (int(rects[:, 0].min()), int(rects[:, 1].max()), int(rects[:, 2].min()),
            int(rects[:, 3].max()))


def covered_mask(box: Rect, rects: np.ndarray) -> np.ndarray | None:
    """(h, w) bool cells of ``box`` inside any of ``rects`` ((K, 4) row0, row1, col0, col1):
    a mask, so a cell several rectangles cover counts once; None when none is covered."""
    r0, r1, c0, c1 = box
    mask = np.zeros((r1 - r0, c1 - c0), dtype=bool)
    hit = False
    for q0, q1, s0, s1 in np.asarray(rects).tolist():
        top, bottom, left, right = max(q0, r0), min(q1, r1), max(s0, c0), min(s1, c1)
        if top < bottom and left < right:
            mask[top - r0:bottom - r0, left - c0:right - c0] = True
            hit = True
    return mask if hit else None


def discount_covered(values: np.ndarray, box: Rect, rects: np.ndarray, factor: float) -> None:
    """Scale, in place, the (h, w) ``values`` of ``box``'s cells inside any of ``rects``
    ((K, 4) decided teammates' next footprints) by ``factor``: once per cell, however many
    rectangles cover it. Nothing to do without rectangles or with ``factor`` 1."""
    if len(rects) == 0 or factor == 1.0:
        return
    covered = covered_mask(box, rects)
    if covered is not None:
        np.multiply(values, np.float32(factor), out=values, where=covered)


class TeammateDiscount:
    """``ig``'s same-step discount on the options' values read from the ``gain`` planes, and
    optionally the ``ig`` family's lookahead over the agent's own path.

    Args:
        config: the mission's config (its world, camera and class weights).
        features: the feature switches the planes were built with (a policy's own: its
            ``gain_smoothing``, ``gain_interest``, ``gain_false_positive`` and
            ``gain_false_positive_steps``).
        overlap_discount: factor in [0, 1] on covered cells; 1 leaves the values alone.
        lookahead_steps, lookahead_discount: each option's value also gains
            ``lookahead_discount`` times its best continuation along the agent's own path
            (:func:`~ipp_toolkit.planning.lookahead.continuation_values`, the planes'
            objective, teammates' footprints discounted), as the ``ig`` planner with these
            options values its moves; 1 step (default): the planes' one-step values.
        lookahead_silent: look ahead on missions without communication too (default:
            not, :func:`~ipp_toolkit.planning.lookahead.mission_lookahead`).
    """

    def __init__(self, config: EnvConfig, features: FeatureConfig,
                 overlap_discount: float = OVERLAP_DISCOUNT, lookahead_steps: int = 1,
                 lookahead_discount: float = LOOKAHEAD_DISCOUNT,
                 lookahead_silent: bool = False) -> None:
        #: the arguments it was built with (:meth:`for_mission` keeps it while they hold)
        self.built_for = (config, features, overlap_discount, lookahead_steps,
                          lookahead_discount, bool(lookahead_silent))
        self.overlap_discount = check_overlap_discount(overlap_discount)
        steps, self.lookahead_discount = check_lookahead(lookahead_steps, lookahead_discount)
        #: the steps looked at on these missions
        self.lookahead_steps = mission_lookahead(steps, lookahead_silent,
                                                 config.team.comm_range)
        self.camera = Camera(config.world, config.sensor)
        self.features = features
        self.objective = plane_objective(features.gain_smoothing, features.gain_interest)
        weights = (config.reward.weight_interesting, config.reward.weight_uninteresting)
        self._table = objective_table(weights, self.camera, self.objective)
        self._checking = (objective_table(weights, self.camera, "false_positive")
                          if self.objective == "interesting" and features.gain_false_positive > 0
                          else None)
        self._normaliser = gain_normaliser(config.reward, self.camera, self.objective)
        world = config.world
        self._size, self._resolution = world.map_cells, world.resolution
        self._interest: dict[int, np.ndarray] = {}
        # The lookahead's segment sums of the objective's tables, kept per agent; the grid's
        # squares are those the probability of interest is taken on.
        self._segments = SegmentGrid.for_world(self.camera.rects, world)
        self._block = self._segments.block
        tables = [self._table] + ([self._checking] if self._checking is not None else [])
        self._kept_sums = SegmentSums.of_tables(self._segments, tables, world.prior)

    @classmethod
    def for_mission(cls, kept: TeammateDiscount | None, config: EnvConfig,
                    features: FeatureConfig, overlap_discount: float = OVERLAP_DISCOUNT,
                    lookahead_steps: int = 1, lookahead_discount: float = LOOKAHEAD_DISCOUNT,
                    lookahead_silent: bool = False) -> TeammateDiscount:
        """``kept`` where it was built with these arguments, else a new discount: a planner's
        next mission of the same configuration reuses the tables and segments (its kept
        segment sums restart at the mission's first step)."""
        arguments = (config, features, overlap_discount, lookahead_steps, lookahead_discount,
                     bool(lookahead_silent))
        if kept is not None and kept.built_for == arguments:
            return kept
        return cls(*arguments)

    def start_step(self, views: Sequence[AgentView]) -> None:
        """Estimate, in one batch, every agent's probability of interest when one of them
        hears a lower-index teammate this step, or always with a lookahead; call before
        :meth:`discounted`."""
        self._interest = {}
        if self.objective != "interesting" or not self.active:
            return
        if self.lookahead_steps == 1 and not any(
                (np.asarray(view.teammates) < view.index).any() for view in views):
            return
        # The whole team, as the gain planes ask the learned prior: the same squares, so
        # the prior answers from its last call instead of a second forward pass.
        if any(view.local_prob.shape != (self._size, self._size) for view in views):
            raise ValueError("TeammateDiscount needs the views' local maps (a planner that "
                             "uses it sets needs_local_maps)")
        # The means the mission keeps (those of the gain planes, to the bit).
        means = np.stack([view.square_means(self._block) for view in views])
        if self.features.gain_interest != GAIN_INTEREST_SMOOTHED:
            blocks = shared_prior(self.features.gain_interest).square_values(
                means, self._resolution, self._size)
        else:
            blocks = interest_smoother(self._size, self._resolution,
                                       self.features.gain_smoothing).smooth(means)
        self._interest = {view.index: blocks[i] for i, view in enumerate(views)}

    @property
    def active(self) -> bool:
        """Whether it changes any value: a discount below 1 or a lookahead."""
        return self.overlap_discount < 1.0 or self.lookahead_steps > 1

    def looks_ahead(self, view: AgentView) -> bool:
        """Whether ``view``'s options get a continuation (two or more steps left)."""
        return steps_left(self.lookahead_steps, view) > 1

    def discounted(self, view: AgentView, gains: np.ndarray, mate_targets: np.ndarray
                   ) -> np.ndarray:
        """(6,) the options' plane ``gains`` with the cells under the next footprints of
        decided teammates (``mate_targets``: (K, 3) int their chosen waypoints) discounted.

        Args:
            view: the deciding agent's view, with its local map.
            gains: (6,) the options' values read from its ``gain`` planes.
            mate_targets: (K, 3) int next waypoints of the heard teammates that decided.
        """
        gains = np.asarray(gains, dtype=np.float64)
        if len(mate_targets) == 0 or self.overlap_discount == 1.0:
            return gains
        return gains - (1.0 - self.overlap_discount) * self.covered_gains(view, mate_targets)

    def rescorer(self, views: Sequence[AgentView], gains: np.ndarray, scores: np.ndarray,
                 masks: np.ndarray, logits_of: Callable[[int, np.ndarray], np.ndarray]
                 ) -> Callable[[int, np.ndarray], np.ndarray]:
        """``rescore(k, targets)`` for :func:`~ipp_toolkit.planning.choose_for_views`: agent
        k's ``scores`` while no decided teammate is heard, else ``logits_of(k, discounted)``
        (a policy's (6,) logits from its options' discounted gains), masked. Starts the step
        (:meth:`start_step`).

        Args:
            views: the team's views, with local maps.
            gains: (N, 6) the options' values read from each agent's ``gain`` planes.
            scores: (N, 6) the policy's scores from its batched forward pass.
            masks: (N, 6) valid actions.
            logits_of: the policy's logits of agent k given its (6,) discounted gains.
        """
        self.start_step(views)

        def rescore(k: int, mate_targets: np.ndarray) -> np.ndarray:
            ahead = self.looks_ahead(views[k])
            if len(mate_targets) == 0 and not ahead:
                return scores[k]  # nothing to change: the batched forward pass's scores
            values = self.discounted(views[k], gains[k], mate_targets)
            if ahead:
                values = values + self.lookahead_discount * self.continuation(
                    views[k], mate_targets, np.asarray(masks[k], dtype=bool))
            return np.where(masks[k], logits_of(k, values), -np.inf)

        return rescore

    def continuation(self, view: AgentView, mate_targets: np.ndarray, valid: np.ndarray
                     ) -> np.ndarray:
        """(6,) float64 each valid option's best continuation in plane units
        (:func:`~ipp_toolkit.planning.lookahead.continuation_values` of the planes' objective,
        cells under ``mate_targets``' footprints discounted); 0 for the others."""
        camera, grid = self.camera, self._segments
        mate_rects = self._rects_of(mate_targets)

        def segment_values(altitude: int, box: SegmentBox) -> np.ndarray:
            values = self._segment_values(view, altitude, box)
            grid.discount(values, mate_rects, self.overlap_discount, box)
            return values

        candidates = np.asarray(view.position, dtype=np.int64)[None, :] + ACTION_DELTAS
        return continuation_values(camera.rects, candidates, valid,
                                   steps_left(self.lookahead_steps, view),
                                   self.lookahead_discount, segment_values, grid
                                   ) / self._normaliser

    def covered_gains(self, view: AgentView, mate_targets: np.ndarray) -> np.ndarray:
        """(6,) float64 the part of each option's plane value that lies under the footprints
        from ``mate_targets`` (a cell several cover counts once); 0 for options outside the
        area or the altitudes."""
        camera, grid = self.camera, self._segments
        z_count, n_points = camera.rects.shape[0], camera.rects.shape[1]
        mate_rects = self._rects_of(mate_targets)
        candidates = np.asarray(view.position, dtype=np.int64)[None, :] + ACTION_DELTAS
        inside = ((candidates[:, :2] >= 0).all(1) & (candidates[:, :2] < n_points).all(1)
                  & (candidates[:, 2] >= 0) & (candidates[:, 2] < z_count))
        covered = np.zeros(N_ACTIONS, dtype=np.float64)
        for altitude in np.unique(candidates[inside, 2]).tolist():
            options = np.flatnonzero(inside & (candidates[:, 2] == altitude))
            ix, iy, _ = candidates[options].T
            rects = grid.edge_index(camera.rects[altitude, iy, ix])  # (K, 4) cut indices
            box = (int(rects[:, 0].min()), int(rects[:, 1].max()), int(rects[:, 2].min()),
                   int(rects[:, 3].max()))
            mask = grid.covered(mate_rects, box)
            if not mask.any():
                continue
            # From the box's cells, not the kept sums: the greedy COMA validation flies
            # several missions in lock-step through one discount.
            sums = self._kept_sums.box_sums(view, box, [altitude])
            values = np.where(mask, self._objective_values(view, sums, 0, box), 0.0)
            for option, (q0, q1, s0, s1) in zip(options.tolist(), rects.tolist(), strict=True):
                covered[option] = values[q0 - box[0]:q1 - box[0], s0 - box[2]:s1 - box[2]].sum()
        return covered / self._normaliser

    def _rects_of(self, targets: np.ndarray) -> np.ndarray:
        """(K, 4) the footprints of (K, 3) int waypoints."""
        targets = np.asarray(targets, dtype=np.int64).reshape(-1, 3)
        return self.camera.rects[targets[:, 2], targets[:, 1], targets[:, 0]]

    def _segment_values(self, view: AgentView, altitude: int, box: SegmentBox) -> np.ndarray:
        """(i1 - i0, j1 - j0) float64 the planes' per-cell objective of a reading at
        ``altitude`` summed over each segment of ``box`` of ``view``'s local map, from the
        tables' kept segment sums (:class:`~ipp_toolkit.planning.segments.SegmentSums`)."""
        i0, i1, j0, j1 = box
        return self._objective_values(view, self._kept_sums(view)[..., i0:i1, j0:j1],
                                      altitude, box)

    def _objective_values(self, view: AgentView, sums: np.ndarray, altitude: int,
                          box: SegmentBox) -> np.ndarray:
        """:func:`~ipp_toolkit.planning.segments.objective_segment_values` of (T, Z, h, w)
        table ``sums`` over ``box`` at altitude slot ``altitude``, with the planes' probability
        of interest and clean-up term."""
        if self.objective != "interesting":
            return objective_segment_values(sums, altitude, None)
        weight = 0.0
        if self._checking is not None and false_positive_term_applies(
                view.budget - view.step, self.features.gain_false_positive_steps):
            weight = self.features.gain_false_positive
        return objective_segment_values(
            sums, altitude, self._segments.block_weights(self._interest[view.index], box),
            weight)
