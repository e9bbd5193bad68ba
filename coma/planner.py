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
import warnings

import numpy as np
import torch

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planners import AgentView, Planner, choose_for_views, policy_inputs

from .config import mission_settings
from .networks import masked_logits
from .persistence import (
    DEFAULT_SHIPPED,
    check_transfer,
    load_policy,
    resolve_policy,
)

__all__ = ["COMAPlanner", "COMAPriorPlanner"]


class COMAPlanner(Planner):
    """Greedy (eps = 0, argmax over valid actions) COMA actor.

    Args:
        checkpoint: a policy file (``best.pt`` / ``last.pt`` of ``ipp-train coma``) or a
            shipped policy by name, ``shipped:NAME`` (the keys of
            :data:`coma.persistence.SHIPPED_POLICIES`);
            default: the best validated shipped policy (``DEFAULT_SHIPPED``).
    """

    name = "coma"
    needs_observations = True
    needs_local_maps = False
    #: Name of the shipped policy used when no checkpoint is given.
    shipped = DEFAULT_SHIPPED

    #: For a deprecated alias: the spelling to use instead (warned at construction).
    deprecated = ""

    def __init__(self, checkpoint: str | os.PathLike[str] | None = None):
        if self.deprecated:
            warnings.warn(f"planner {self.name!r} is deprecated; use {self.deprecated}",
                          DeprecationWarning, stacklevel=2)
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

    def reset(self, config: EnvConfig, seed: int) -> None:
        # The trained setting closest to this mission: a team size or range that was trained
        # on is not a transfer.
        def mismatches(trained: EnvConfig) -> int:
            return (int(trained.team.n_agents != config.team.n_agents)
                    + int(trained.team.comm_range != config.team.comm_range))

        trained = min(self.trained_settings, key=mismatches)
        self.transfer_notes = check_transfer(trained, config, self.checkpoint)

    def act(self, views: list[AgentView]) -> np.ndarray:
        """(N,) int64: each agent's likeliest valid action, chosen in agent order, avoiding
        the 2-D targets heard lower-index teammates chose (``ig``'s rule; the actors' logits
        come from one batched forward pass)."""
        observations, masks = policy_inputs(views)
        return choose_for_views(masked_logits(self.actor, observations, masks), views)


class COMAPriorPlanner(COMAPlanner):
    """Deprecated alias of ``coma=shipped:prior``: the gain-prior policy (4 agents, 25 m).

    Its actor is a :class:`~coma.networks.GainPriorActor`: logits = a learned residual +
    beta x each option's expected gain (the ``ig`` planner's objective, from the ``gain``
    feature planes). Trained by COMA from that start, the ``ig``-like policy, at 4 UAVs and
    D = 25 m (``ipp-train coma --feature gain=true --warm-start none --set gain_prior=50
    ...``, the whole command in ``coma/checkpoints/coma_prior_4agents_d25.json``; not in the
    paper) and applied to other teams without retraining, like ``coma``. It
    observes the gain planes, which cost more per step than the paper's planes (about 50 ms
    per distinct local map at r_M = 0.1 m). ``checkpoint`` overrides the packaged file.
    """

    name = "coma_prior"
    shipped = "prior"
    deprecated = "coma=shipped:prior"
