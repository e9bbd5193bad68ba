"""The ``coma`` planner: a trained actor, greedy and decentralised, behind the planner API.

Each UAV decides from its own observation planes (``AgentView.observation``, built with the
feature switches the policy was trained on) and mask; one batched forward pass serves the
whole team. Loading refuses a corrupt or foreign file; another planning grid, or more agents
than the policy's id plane numbers, is refused at ``reset``; a different team size, range,
budget or map resolution is the documented transfer of the paper's robustness study (listed
in :attr:`COMAPlanner.transfer_notes`).
"""

from __future__ import annotations

import os

import numpy as np
import torch

from ipp_toolkit.config.schema import EnvConfig, FeatureConfig
from ipp_toolkit.planning import AgentView, Planner, choose_for_views, policy_inputs
from ipp_toolkit.planning.discount import (
    OVERLAP_DISCOUNT,
    TeammateDiscount,
    check_overlap_discount,
)
from ipp_toolkit.planning.lookahead import LOOKAHEAD_DISCOUNT, LOOKAHEAD_STEPS, lookahead_options
from ipp_toolkit.sim.features import relative_option_gains

from .config import mission_settings
from .networks import GainPriorActor, masked_logits
from .persistence import (
    DEFAULT_SHIPPED,
    check_transfer,
    load_policy,
    resolve_policy,
)

__all__ = ["COMAPlanner", "choose_greedy", "teammate_discount"]


class COMAPlanner(Planner):
    """Greedy (eps = 0, argmax over valid actions) COMA actor.

    A gain-prior actor (:class:`~coma.networks.GainPriorActor`, whose logits add a learned
    residual to the ``gain`` planes' values) decides with ``ig``'s discount of the cells
    under heard, decided teammates' next footprints
    (:class:`~ipp_toolkit.planning.discount.TeammateDiscount`): its untrained start then
    chooses exactly what the ``ig`` planner of its planes' objective chooses.

    Args:
        checkpoint: a policy file (``best.pt`` / ``last.pt`` of ``ipp-train coma``) or a
            shipped policy by name, ``shipped:NAME`` (the keys of
            :data:`coma.persistence.SHIPPED_POLICIES`);
            default: the best validated shipped policy (``DEFAULT_SHIPPED``).
        overlap_discount: a gain-prior actor's factor on covered cells, in [0, 1] (1: the
            planes' values as they are, the choice before this rule); other actors ignore it.
        lookahead_steps, lookahead_discount: a gain-prior actor's prior term also values
            each option's best continuation along the agent's own path, as the ``ig``
            planners with these options do (:mod:`ipp_toolkit.planning.lookahead`); 1 step:
            the planes' one-step values; by default three steps, greedy without
            communication unless ``lookahead_silent`` (experiments/lookahead/README.md).
            Other actors ignore them.
    """

    name = "coma"
    needs_observations = True
    needs_local_maps = False
    #: Name of the shipped policy used when no checkpoint is given.
    shipped = DEFAULT_SHIPPED

    def __init__(self, checkpoint: str | os.PathLike[str] | None = None,
                 overlap_discount: float = OVERLAP_DISCOUNT,
                 lookahead_steps: int = LOOKAHEAD_STEPS,
                 lookahead_discount: float = LOOKAHEAD_DISCOUNT,
                 lookahead_silent: bool = False):
        torch.set_num_threads(1)
        path = resolve_policy(f"shipped:{self.shipped}" if checkpoint is None else checkpoint)
        if checkpoint is None and not os.path.exists(path):
            raise FileNotFoundError(f"no shipped COMA policy at {str(path)!r}; train one with "
                                    "`ipp-train coma --out RUN` and pass coma=RUN/best.pt")
        self.checkpoint = str(path)
        networks, _ = load_policy(path)
        self.actor = networks.actor
        self.trained_config = networks.env_config
        self.observation_features = networks.env_config.features
        self.variant = networks.coma_config.variant
        # Every (team size, range) the policy trained on, not only its base config's.
        self.trained_settings = mission_settings(networks.coma_config, networks.env_config)
        self.transfer_notes: list[str] = []
        self.overlap_discount = check_overlap_discount(overlap_discount)
        self.lookahead = lookahead_options(lookahead_steps, lookahead_discount,
                                           lookahead_silent)
        # The discount and the lookahead read each UAV's own local map.
        self.needs_local_maps = _decides_with_discount(self.actor, self.overlap_discount,
                                                       self.lookahead[0])
        self._discount: TeammateDiscount | None = None

    def reset(self, config: EnvConfig, seed: int) -> None:
        # The trained setting closest to this mission: a team size or range that was trained
        # on is not a transfer.
        def mismatches(trained: EnvConfig) -> int:
            return (int(trained.team.n_agents != config.team.n_agents)
                    + int(trained.team.comm_range != config.team.comm_range))

        trained = min(self.trained_settings, key=mismatches)
        self.transfer_notes = check_transfer(trained, config, self.checkpoint)
        self._discount = teammate_discount(self.actor, config, self.observation_features,
                                           self.overlap_discount, *self.lookahead,
                                           kept=self._discount)

    def act(self, views: list[AgentView]) -> np.ndarray:
        """(N,) int64: each agent's likeliest valid action, chosen in agent order, avoiding
        the 2-D targets heard lower-index teammates chose and, for a gain-prior actor,
        discounting their footprints (``ig``'s rules; the actors' logits come from one
        batched forward pass)."""
        if self.needs_local_maps and self._discount is None:
            raise RuntimeError("call reset(config, seed) before act()")
        observations, masks = policy_inputs(views)
        return choose_greedy(self.actor, observations, masks, views, self._discount)


def teammate_discount(actor: torch.nn.Module, config: EnvConfig, features: FeatureConfig,
                      overlap_discount: float = OVERLAP_DISCOUNT, lookahead_steps: int = 1,
                      lookahead_discount: float = LOOKAHEAD_DISCOUNT,
                      lookahead_silent: bool = False, kept: TeammateDiscount | None = None
                      ) -> TeammateDiscount | None:
    """The same-step discount (and lookahead) a greedy ``actor`` decides with on missions of
    ``config``: a gain-prior actor's over the planes of its ``features`` (``kept``, the one
    of the last mission, where it fits: :meth:`TeammateDiscount.for_mission`); None for other
    actors, or ``overlap_discount`` 1 without a lookahead."""
    if not _decides_with_discount(actor, overlap_discount, lookahead_steps):
        return None
    return TeammateDiscount.for_mission(kept, config, features, overlap_discount,
                                        lookahead_steps, lookahead_discount, lookahead_silent)


def _decides_with_discount(actor: torch.nn.Module, overlap_discount: float,
                           lookahead_steps: int = 1) -> bool:
    """Whether a greedy ``actor`` rescores its prior term: a gain-prior actor's, unless
    ``overlap_discount`` is 1 and it does not look ahead."""
    return isinstance(actor, GainPriorActor) and (overlap_discount < 1.0
                                                  or lookahead_steps > 1)


def choose_greedy(actor: torch.nn.Module, observations: np.ndarray, masks: np.ndarray,
                  views: list[AgentView], discount: TeammateDiscount | None,
                  scores: np.ndarray | None = None) -> np.ndarray:
    """The deployed policy's joint action: each agent's likeliest valid action in agent
    order, avoiding heard decided teammates' targets (``ig``'s rule) and, with ``discount``,
    valuing the gain-prior term's cells under their footprints as ``ig`` does.

    Args:
        actor: the actor network.
        observations: (N, C, G, G) float32 actor planes of the N agents.
        masks: (N, 6) valid actions.
        views: the agents' views (with local maps when ``discount`` is given).
        discount: :func:`teammate_discount` of the actor and mission, or None.
        scores: (N, 6) :func:`~coma.networks.masked_logits` of these planes when already
            computed (e.g. in a larger batch).

    Returns:
        (N,) int64 actions, each valid.
    """
    if scores is None:
        scores = masked_logits(actor, observations, masks)
    if discount is None:
        return choose_for_views(scores, views)
    assert isinstance(actor, GainPriorActor)
    with torch.no_grad():
        planes = torch.as_tensor(observations, dtype=torch.float32)
        residual = actor.residual(planes)
        gains = actor.plane_gains(planes).numpy()
        beta = actor.log_beta.exp()

    def logits_of(k: int, discounted: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            relative = relative_option_gains(torch.as_tensor(discounted[None],
                                                             dtype=torch.float32))
            return (residual[k:k + 1] + beta * relative)[0].numpy()

    rescore = discount.rescorer(views, gains, scores, masks, logits_of)
    return choose_for_views(scores, views, rescore)
