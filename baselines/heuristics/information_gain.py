"""Greedy information gain (Carbone et al. 2021): each UAV takes its most informative next step."""

from __future__ import annotations

import numpy as np

from ipp_toolkit.belief.gain import footprint_sums_in_box, objective_table
from ipp_toolkit.belief.mapping import OUTCOME_WEIGHTINGS, expected_gain
from ipp_toolkit.belief.value_table import ValueTable
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planning import AgentView, Planner
from ipp_toolkit.planning.discount import (
    OVERLAP_DISCOUNT,
    bounding_box,
    check_overlap_discount,
    discount_covered,
)
from ipp_toolkit.planning.lookahead import (
    LOOKAHEAD_DISCOUNT,
    check_lookahead,
    continuation_values,
    mission_lookahead,
    steps_left,
)
from ipp_toolkit.planning.segments import (
    SegmentBox,
    SegmentGrid,
    SegmentSums,
    objective_segment_values,
)
from ipp_toolkit.sim.team import ACTION_DELTAS, ACTION_NAMES, N_ACTIONS, unclaimed_options
from ipp_toolkit.world.sensor import Camera

__all__ = ["InformationGainPlanner", "PaperInformationGainPlanner", "expected_gain", "gain_table"]

Rect = tuple[int, int, int, int]

_HORIZONTAL = tuple(ACTION_NAMES.index(name) for name in ("north", "east", "south", "west"))
_VERTICAL = tuple(ACTION_NAMES.index(name) for name in ("up", "down"))


def gain_table(config: EnvConfig, camera: Camera, objective: str,
               outcome_weighting: str = "predictive") -> ValueTable:
    """A table of the per-cell ``objective`` (:func:`~ipp_toolkit.belief.gain.cell_objective`)
    by log-odds, one column ``altitude_z`` per altitude z of ``camera``
    (:func:`~ipp_toolkit.belief.gain.objective_table` of ``config``'s class weights)."""
    weights = (config.reward.weight_interesting, config.reward.weight_uninteresting)
    return objective_table(weights, camera, objective, outcome_weighting)


class InformationGainPlanner(Planner):
    """Greedy one-step information gain on each UAV's local map (Carbone et al. 2021).

    Agents decide in index order. Agent k values each valid action by the expected
    weighted-entropy reduction of its own local map, summed over the footprint it would see
    from the action's target waypoint (:func:`expected_gain`: expectation over the predictive
    distribution of the reading, weights of the posterior like the reward). Coordination uses
    only what agent k hears: cells under the chosen next footprints of lower-index teammates
    in ``view.teammates`` count ``overlap_discount`` times their gain, and a 2-D target cell
    such a teammate already chose is avoided (the same-target rule would hold agent k back)
    unless nothing else is valid. Ties go to the lowest action index, so all-zero gains give
    the first valid action. Deterministic; the seed is unused.

    Cost: per agent and step the gain is looked up once over the union bounding box of the
    four horizontal candidates (they share the current altitude) and once over each of the
    up and down footprints. A cell's gain is a function of its log-odds, so it is computed
    once per distinct log-odds value (:class:`~ipp_toolkit.belief.value_table.ValueTable`, kept
    while the configuration is unchanged) and looked up by value. Each candidate's value is
    then a float64 slice sum of its box: with only four candidates per box that is ~20x
    cheaper than a summed-area table.

    ``overlap_discount`` default 0.5. Measured on 20 validation missions
    (``evaluate(..., missions=20, seed=0, namespace="validation")``, the default split
    terrain, 4 agents, D = 25 m, r_M = 0.1 m, B = 15), mean final entropy over interesting
    cells (sd) / mean final F1 of the global map::

        overlap_discount 0.0:  entropy 0.373 (sd 0.066)  F1 0.802
        overlap_discount 0.5:  entropy 0.372 (sd 0.067)  F1 0.803
        overlap_discount 1.0:  entropy 0.368 (sd 0.072)  F1 0.805   (no coordination)

    The three are within the noise of one another. 0.5 is kept as the middle ground: a second
    reading of a cell still carries information at 10-15 m (accuracy 0.735 / 0.625), so
    ignoring teammates' cells entirely (0.0) throws away real gain, while 1.0 ignores the
    teammates' choices altogether.

    The family's extension point is :meth:`cell_gains`, the per-cell value of a reading: a
    subclass that changes it keeps the footprint sums, the coordination and the valid-action
    rules (``ig_spatial`` multiplies it by a probability of interest, see
    ``SpatialGainPlanner.interest_blocks``; docs/extending.md).

    Args:
        overlap_discount: factor in [0, 1] on the gain of cells a heard lower-index teammate
            will already observe (0 = ignore them, 1 = no coordination).
        outcome_weighting: how the two readings are weighted in the expected gain, one of
            :data:`ipp_toolkit.belief.mapping.OUTCOME_WEIGHTINGS`: ``predictive`` (default) or
            ``belief``, the paper authors' form (see :class:`PaperInformationGainPlanner`).
        lookahead_steps: d in [1, 4]: a move is also worth ``lookahead_discount`` times the
            best value of the d - 1 moves of the agent's own path after it, each counting
            the cells no earlier footprint of the path covers
            (:mod:`ipp_toolkit.planning.lookahead`);
            1 (default): the greedy choice.
        lookahead_discount: gamma in [0, 1], the weight per step further along the path.
        lookahead_silent: look ahead on missions without communication too (default: greedy
            there, :func:`~ipp_toolkit.planning.lookahead.mission_lookahead`).
    """

    name = "ig"
    needs_observations = False
    #: The per-cell objective looked up on the local map
    #: (:data:`ipp_toolkit.belief.gain.OBJECTIVES`, built by
    #: :func:`~ipp_toolkit.belief.gain.cell_objective`).
    objective: str = "ig"

    def __init__(self, overlap_discount: float = OVERLAP_DISCOUNT,
                 outcome_weighting: str = "predictive", lookahead_steps: int = 1,
                 lookahead_discount: float = LOOKAHEAD_DISCOUNT,
                 lookahead_silent: bool = False) -> None:
        if outcome_weighting not in OUTCOME_WEIGHTINGS:
            raise ValueError(f"outcome_weighting must be one of {OUTCOME_WEIGHTINGS}, "
                             f"got {outcome_weighting!r}")
        self.overlap_discount = check_overlap_discount(overlap_discount)
        self.lookahead_steps, self.lookahead_discount = check_lookahead(lookahead_steps,
                                                                        lookahead_discount)
        self.lookahead_silent = bool(lookahead_silent)
        self._lookahead = 1  # the steps looked at on the missions of the last reset
        self.outcome_weighting = outcome_weighting
        self._config: EnvConfig | None = None
        self._camera: Camera | None = None
        self._gains: ValueTable | None = None
        self._segments: SegmentGrid | None = None
        self._kept_sums: SegmentSums | None = None  # built on the lookahead's first use

    def reset(self, config: EnvConfig, seed: int) -> None:
        """Build the camera geometry and gain table for ``config`` (kept while it is unchanged)."""
        if config != self._config:
            camera = Camera(config.world, config.sensor)
            self._gains = gain_table(config, camera, self.objective, self.outcome_weighting)
            self._camera, self._config = camera, config
            self._segments = SegmentGrid.for_world(camera.rects, config.world)
            self._kept_sums = None
        self._lookahead = mission_lookahead(self.lookahead_steps, self.lookahead_silent,
                                            config.team.comm_range)

    @property
    def camera(self) -> Camera:
        """The footprints and sensor model of the mission config of the last :meth:`reset`."""
        if self._camera is None:
            raise RuntimeError("call reset(config, seed) first")
        return self._camera

    def act(self, views: list[AgentView]) -> np.ndarray:
        """(N,) int64 greedy actions, chosen in agent order; each valid under its mask."""
        camera, config = self._camera, self._config
        if camera is None or config is None:
            raise RuntimeError("call reset(config, seed) before act()")
        n = len(views)
        actions = np.empty(n, dtype=np.int64)
        targets = np.empty((n, 3), dtype=np.int64)  # chosen next waypoint of each agent
        for k, view in enumerate(views):
            if view.index != k:
                raise ValueError(f"views must come in agent order: view {k} is agent "
                                 f"{view.index}")
            mates = view.teammates[view.teammates < k]  # heard and already decided
            mask = view.mask.astype(bool)
            if not mask.any():
                raise ValueError(f"agent {k} has no valid action")
            candidates = view.position[None, :].astype(np.int64) + ACTION_DELTAS  # (6, 3)
            allowed = unclaimed_options(view.position, mask, targets[mates])
            mate_rects = camera.rects[targets[mates, 2], targets[mates, 1],
                                      targets[mates, 0]]  # (K, 4)
            values = self._action_values(view, camera, candidates, allowed, mate_rects)
            # argmax returns the first maximum: ties go to the lowest action index.
            action = int(np.argmax(np.where(allowed, values, -np.inf)))
            actions[k] = action
            targets[k] = candidates[action]
        return actions

    def _action_values(self, view: AgentView, camera: Camera, candidates: np.ndarray,
                       allowed: np.ndarray, mate_rects: np.ndarray) -> np.ndarray:
        """(6,) float64 expected gain of each allowed action (0 for the others): the sums of
        :meth:`cell_gains` over the actions' footprints, teammates' cells discounted.

        Args:
            view: the deciding agent's view.
            camera: footprints and sensor model of the config.
            candidates: (6, 3) int target waypoint of each action.
            allowed: (6,) bool actions to evaluate.
            mate_rects: (K, 4) int footprints already claimed by lower-index teammates.
        """
        values = np.zeros(N_ACTIONS, dtype=np.float64)
        # One gain evaluation per altitude: the horizontal moves share the current one.
        groups = [[a for a in _HORIZONTAL if allowed[a]]] + [[a] for a in _VERTICAL if allowed[a]]
        for group in groups:
            if not group:
                continue
            ix, iy, iz = candidates[group].T
            altitude = int(iz[0])
            rects = camera.rects[altitude, iy, ix]  # (len(group), 4)
            box = bounding_box(rects)
            r0, r1, c0, c1 = box
            cells = (slice(r0, r1), slice(c0, c1))
            gain = self.cell_gains(view, altitude, cells)
            self._discount(gain, box, mate_rects)
            values[group] = footprint_sums_in_box(gain, box, rects)
        steps = steps_left(self._lookahead, view)
        if steps > 1:
            grid = self.segment_grid

            def segment_values(altitude: int, box: SegmentBox) -> np.ndarray:
                values = self.segment_values(view, altitude, box)
                grid.discount(values, mate_rects, self.overlap_discount, box)
                return values

            values += self.lookahead_discount * continuation_values(
                camera.rects, candidates, allowed, steps, self.lookahead_discount,
                segment_values, grid)
        return values

    @property
    def segment_grid(self) -> SegmentGrid:
        """The segments the lookahead sums over (:mod:`ipp_toolkit.planning.segments`)."""
        if self._segments is None:
            raise RuntimeError("call reset(config, seed) first")
        return self._segments

    def segment_values(self, view: AgentView, altitude: int, box: SegmentBox) -> np.ndarray:
        """(i1 - i0, j1 - j0) float64 :meth:`cell_gains` of a reading at ``altitude`` summed
        over each segment of ``box`` (i0, i1, j0, j1) of :attr:`segment_grid`: what the
        lookahead sums.

        The built-in objectives keep their tables' segment sums per agent across steps
        (:class:`~ipp_toolkit.planning.segments.SegmentSums`); a subclass that overrides
        :meth:`cell_gains` alone gets its values summed from :meth:`cell_gains` over the box
        at every step (the same values, slower).
        """
        if type(self).cell_gains is not InformationGainPlanner.cell_gains:
            return self._summed_cell_gains(view, altitude, box)
        i0, i1, j0, j1 = box
        return objective_segment_values(self._table_sums(view)[..., i0:i1, j0:j1], altitude,
                                        None)

    def _summed_cell_gains(self, view: AgentView, altitude: int, box: SegmentBox
                           ) -> np.ndarray:
        """(i1 - i0, j1 - j0) float64 :meth:`cell_gains` over ``box``, summed per segment."""
        grid = self.segment_grid
        r, c = grid.layout.row_edges, grid.layout.col_edges
        i0, i1, j0, j1 = box
        cells = self.cell_gains(view, altitude, (slice(r[i0], r[i1]), slice(c[j0], c[j1])))
        return grid.segment_sums(cells, box)

    def _segment_tables(self) -> list[ValueTable]:
        """The tables whose segment sums :meth:`segment_values` reads: the gain table."""
        assert self._gains is not None
        return [self._gains]

    def _table_sums(self, view: AgentView) -> np.ndarray:
        """(T, Z, R, C) the segment sums of :meth:`_segment_tables` on ``view``'s map."""
        if self._kept_sums is None:
            assert self._config is not None
            self._kept_sums = SegmentSums.of_tables(self.segment_grid, self._segment_tables(),
                                                    self._config.world.prior)
        return self._kept_sums(view)

    def cell_gains(self, view: AgentView, altitude: int,
                   cells: tuple[slice, slice]) -> np.ndarray:
        """(h, w) float32 value of a reading at ``altitude`` of each cell in the ``cells`` box.

        The extension point of the ``ig`` family: the planner ranks each candidate move by the
        sum of these values over its footprint (teammates' cells discounted). Here the
        planner's :attr:`objective` (``expected_gain``, with its ``outcome_weighting``) on the
        agent's local map, looked up by log-odds; a subclass may scale or replace it
        (``ig_spatial`` multiplies it by the probability that each cell is interesting).

        Args:
            view: the deciding agent's view (its local map; read-only).
            altitude: the altitude index of the reading (``self.camera.accuracy[altitude]``).
            cells: (rows, columns) slices of the box in map cells.

        Returns:
            a fresh (h, w) float32 array: the planner discounts it in place.
        """
        if self._gains is None:
            raise RuntimeError("call reset(config, seed) before act()")
        index = self._gains.indices(view.local_logodds[cells])
        return self._gains.column(f"altitude_{altitude}")[index]

    def _discount(self, gain: np.ndarray, box: Rect, mate_rects: np.ndarray) -> None:
        """Scale, in place, the gain of cells inside ``box`` under teammates' next footprints."""
        discount_covered(gain, box, mate_rects, self.overlap_discount)


class PaperInformationGainPlanner(InformationGainPlanner):
    """``ig`` with the paper authors' outcome weighting (their ``IG_baseline.py``).

    The authors weight the two possible readings of a cell by the current belief p
    (``p W(p1) (H(p) - H(p1)) + (1 - p) W(p0) (H(p) - H(p0))``) instead of by the predictive
    probability of the reading, q = p a + (1 - p)(1 - a). The two coincide at p = 0.5
    (q = 0.5 for any a) and nearly so for the accurate 5 m camera (a = 0.99, q ~ p); they
    differ most for the noisy 10-15 m readings of cells that already lean either way, where
    q is pulled towards 0.5 but p is not.

    Everything else is ``ig``'s: the same coordination (index order, heard lower-index
    teammates, ``overlap_discount``, claimed targets avoided) and the same valid-action rule,
    so the comparison isolates the outcome weighting. The authors' other differences (their
    coordination by 3-D candidate collisions with every teammate regardless of range, a
    masked "up" on all-zero gains) are bugs or design choices ``ig`` does not share; see
    docs/departures.md.

    Args:
        overlap_discount: as for :class:`InformationGainPlanner`.
    """

    name = "ig_paper"

    def __init__(self, overlap_discount: float = OVERLAP_DISCOUNT) -> None:
        super().__init__(overlap_discount, outcome_weighting="belief")
