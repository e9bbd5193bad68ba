"""Greedy information gain with a learned field prior (``ig_learned``).

``ig_spatial`` values a cell by ``pi(c) * interesting_gain(c)`` with ``pi`` the Gaussian-
smoothed local map: "near what was seen interesting". This planner keeps that objective and
every rule of ``ig`` (index order, heard lower-index teammates' next footprints discounted,
their targets avoided) and replaces ``pi`` by a learned field prior
(:class:`ipp_toolkit.belief.field_prior.FieldPrior`): a small network that predicts, from the
UAV's own local map, how likely each 2 m block is to be interesting, having learned the
shapes fields take (straight boundaries continue, hotspots have sizes) from simulator ground
truth (``ipp-train prior``). No policy is learned: the decision is an argmax of the
objective, which, when the team communicates, also counts half the best value of the next
two moves of the UAV's own path (``lookahead_steps`` 3, :mod:`ipp_toolkit.planning.lookahead`;
greedy without communication, where the lookahead drew UAVs together;
experiments/lookahead/README.md).

In the mission's last 10 steps (of 15 in the paper's missions) a cell the map holds above 0.5
that the prior doubts is given value too (``false_positive_weight`` 0.5,
``false_positive_steps`` 10,
:class:`~baselines.heuristics.spatial_gain.SpatialGainPlanner`): the entropy over interesting
cells never counts such a false positive, the final F1 does. Cleaning up late keeps the F1 of
``ig_spatial`` at a small cost in entropy; the same term on every step cost split too much
(experiments/field-prior-cleanup/README.md). ``false_positive_weight=0`` flies the prior's
objective alone.

``ig_learned`` flies the shipped prior (``ipp_toolkit/data/field_prior.pt``, its JSON
record beside it; the learned ``gain`` planes of ``features.gain_interest = "learned"`` read
the same file); ``ig_learned=RUN/best.pt`` flies your own. Deterministic; the seed is
unused. Cost: ``ig_spatial``'s work plus one batched forward pass of the prior per step,
and the lookahead's segment values (:mod:`ipp_toolkit.planning.segments`) per UAV and step.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ipp_toolkit.belief.field_prior import SHIPPED_PRIOR, prior_file, shared_prior
from ipp_toolkit.planning import AgentView
from ipp_toolkit.planning.discount import OVERLAP_DISCOUNT
from ipp_toolkit.planning.lookahead import LOOKAHEAD_DISCOUNT, LOOKAHEAD_STEPS

from ..heuristics.spatial_gain import SpatialGainPlanner

__all__ = ["CLEANUP_STEPS", "CLEANUP_WEIGHT", "DEFAULT_PRIOR", "LearnedPriorPlanner"]

DEFAULT_PRIOR = SHIPPED_PRIOR
"""The shipped field prior."""
CLEANUP_WEIGHT = 0.5
"""The false-positive term's weight in ``ig_learned``'s default objective."""
CLEANUP_STEPS = 10
"""The last steps in which ``ig_learned``'s default objective values cleaning up."""


class LearnedPriorPlanner(SpatialGainPlanner):
    """``ig_spatial``'s objective with a learned probability of interest.

    Args:
        checkpoint: a field-prior file (``ipp-train prior`` writes ``RUN/best.pt``); None: the
            shipped one.
        overlap_discount: as for
            :class:`~baselines.heuristics.information_gain.InformationGainPlanner`.
        false_positive_weight, false_positive_steps: as for
            :class:`~baselines.heuristics.spatial_gain.SpatialGainPlanner`; the defaults clean
            up in the last 10 steps, weight 0 flies the prior's objective alone.
        lookahead_steps, lookahead_discount, lookahead_silent: as for
            :class:`~baselines.heuristics.information_gain.InformationGainPlanner`; by default three
            steps, greedy without communication (experiments/lookahead/README.md).
    """

    name = "ig_learned"
    needs_observations = False

    def __init__(self, checkpoint: str | Path | None = None,
                 overlap_discount: float = OVERLAP_DISCOUNT,
                 false_positive_weight: float = CLEANUP_WEIGHT,
                 false_positive_steps: int | None = CLEANUP_STEPS,
                 lookahead_steps: int = LOOKAHEAD_STEPS,
                 lookahead_discount: float = LOOKAHEAD_DISCOUNT,
                 lookahead_silent: bool = False) -> None:
        import torch

        super().__init__(overlap_discount=overlap_discount,
                         false_positive_weight=false_positive_weight,
                         false_positive_steps=false_positive_steps,
                         lookahead_steps=lookahead_steps, lookahead_discount=lookahead_discount,
                         lookahead_silent=lookahead_silent)
        # A batch of N small maps: extra intra-op threads only spin on busy cores.
        torch.set_num_threads(1)
        path = prior_file(DEFAULT_PRIOR if checkpoint is None else checkpoint)
        self.checkpoint = path
        # One network per file and process, shared with the learned gain planes.
        self.prior = shared_prior(path)
        self._fine: np.ndarray | None = None  # (N, H / b, W / b) prior of this step's views

    def act(self, views: list[AgentView]) -> np.ndarray:
        """(N,) int64 greedy actions (see ``ig``), after one batched prior prediction."""
        if self._config is None:
            raise RuntimeError("call reset(config, seed) before act()")
        world = self._config.world
        # The maps' square means, as the mission keeps them: the prior's inputs, and its
        # prediction on those squares (the interest blocks' side).
        squares = np.stack([view.square_means(self.block_cells) for view in views])
        self._fine = self.prior.square_values(squares, world.resolution, world.map_cells)
        return super().act(views)

    def interest_blocks(self, view: AgentView) -> np.ndarray:
        """The learned prior of ``view``'s blocks (predicted for the whole team in
        :meth:`act`)."""
        assert self._fine is not None
        return self._fine[view.index]
