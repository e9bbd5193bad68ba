"""The ``sb3`` planner: flies a shared policy of any algorithm ``ipp-train sb3`` trains.

``ipp-compare --planners ig,sb3=RUN/policy.pt`` (or ``mine:sb3=RUN/policy.pt``) flies the
policy of an ``ipp-train sb3`` run of any algorithm (PPO, MaskablePPO, A2C, DQN, QRDQN,
RecurrentPPO, TRPO, ARS), the ``ipp-train ppo`` files, and SB3's own ``model.save`` zips of
a model trained on :func:`ipp_toolkit.vec.make_sb3_vec_env` (``sb3=model.zip``; read without
unpickling, :mod:`baselines.sb3.zips`). Inference only: this module never
imports the training code (:mod:`baselines.sb3.training`, :mod:`baselines.sb3.runner`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import CheckpointError
from ipp_toolkit.planning import (
    AgentView,
    Planner,
    check_policy_transfer,
    choose_for_views,
    policy_inputs,
)
from ipp_toolkit.planning.discount import (
    OVERLAP_DISCOUNT,
    TeammateDiscount,
    check_overlap_discount,
)
from ipp_toolkit.planning.lookahead import LOOKAHEAD_DISCOUNT, LOOKAHEAD_STEPS, lookahead_options
from ipp_toolkit.sim.features import relative_option_gains
from ipp_toolkit.sim.team import N_ACTIONS

from .loading import load_sb3_policy
from .policies import (
    RECURRENT_ALGORITHMS,
    LSTMStates,
    action_scores,
    expected_obs_shape,
    masked_argmax,
)
from .ppo import GainPriorExtractor, GainPriorMlpExtractor, resolve_policy

__all__ = ["SB3Planner", "PPOPlanner"]


#: The transfer note of an SB3 zip, which records no mission setting.
_UNKNOWN_SETTING = ("an SB3 zip records no training setting: it observes with this mission's "
                    "feature planes, and whether it was trained on such missions is unknown")


class SB3Planner(Planner):
    """Greedy shared SB3 policy for every agent (one batched forward per step).

    Acts deterministically on the policy's scores: the logits (PPO, MaskablePPO, A2C, TRPO,
    RecurrentPPO), Q-values (DQN), mean quantiles (QRDQN) or action-net outputs (ARS); a
    masked action is never chosen. By default the agents choose in agent order, each its
    best option among those whose 2-D target no heard teammate of lower index already chose
    (``ig``'s rule, :func:`~ipp_toolkit.planning.choose_for_views`), instead of each taking
    its own argmax and losing same-target contests. A policy with a gain prior
    (``ipp-train ppo --gain-prior``) also values, in that order, the cells under the next
    footprints of those teammates at ``overlap_discount`` times their gain, as ``ig`` does
    (:class:`~ipp_toolkit.planning.discount.TeammateDiscount`: the six relative gains its
    action layer reads are discounted, the rest of its forward pass kept). A RecurrentPPO
    policy keeps its LSTM state per agent across the steps of a mission and starts each
    mission from zeros.

    Args:
        checkpoint: a ``policy.pt`` (or ``checkpoint.pt``) of ``ipp-train sb3`` or
            ``ipp-train ppo``, an SB3 ``model.save`` zip, or a shipped PPO policy by name
            (``shipped:NAME``, :data:`baselines.sb3.ppo.SHIPPED_POLICIES`).
        device: torch device of the forward pass.
        in_order: choose in agent order under the same-step rule (default); False gives
            every agent its own argmax, as the policy acted while it trained.
        overlap_discount: a gain-prior policy's factor on covered cells in agent order, in
            [0, 1] (1: the planes' gains as they are); other policies ignore it.
        lookahead_steps, lookahead_discount, lookahead_silent: a gain-prior policy's six
            gains also count each option's best continuation along the UAV's own path, as
            the ``ig`` planners with these options do (:mod:`ipp_toolkit.planning.lookahead`;
            default 1 step: the planes' one-step gains); other policies ignore them.

    Raises:
        CheckpointError: no checkpoint; a missing, corrupt or foreign one; or one trained for
            another action count (see :func:`~baselines.sb3.loading.load_sb3_policy`).
        ValueError: an unknown ``shipped:`` name.
    """

    name = "sb3"
    needs_observations = True
    needs_local_maps = False

    def __init__(self, checkpoint: str | Path | None = None, device: str = "cpu",
                 in_order: bool = True, overlap_discount: float = OVERLAP_DISCOUNT,
                 lookahead_steps: int = 1, lookahead_discount: float = LOOKAHEAD_DISCOUNT,
                 lookahead_silent: bool = False) -> None:
        # Batches of N observations: extra intra-op threads only spin on busy cores.
        torch.set_num_threads(1)
        if checkpoint is None:
            raise CheckpointError("the sb3 planner needs a policy file: train one with "
                                  "`ipp-train sb3 --algo ALGO --out RUN` and pass "
                                  "sb3=RUN/policy.pt (checkpoint='RUN/policy.pt')")
        self.checkpoint = resolve_policy(checkpoint)
        self.in_order = bool(in_order)
        self.policy, self.meta = load_sb3_policy(self.checkpoint, device)
        self.algo: str = self.meta.algo
        self.obs_shape: tuple[int, int, int] = self.meta.obs_shape
        # An SB3 zip records no feature switches: it observes with the mission's own.
        self.observation_features = None if self.meta.env_config is None \
            else self.meta.env_config.features
        self.transfer_notes: list[str] = []
        self._lstm_states: LSTMStates | None = None
        self.overlap_discount = check_overlap_discount(overlap_discount)
        self.lookahead = lookahead_options(lookahead_steps, lookahead_discount,
                                           lookahead_silent)
        self._discounts = (self.in_order and (overlap_discount < 1.0 or lookahead_steps > 1)
                           and isinstance(getattr(self.policy, "mlp_extractor", None),
                                          GainPriorMlpExtractor))
        # The discount and the lookahead read each UAV's own local map.
        self.needs_local_maps = self._discounts
        self._discount: TeammateDiscount | None = None

    def reset(self, config: EnvConfig, seed: int) -> None:
        """Start a mission of ``config``: check the transfer and clear the LSTM states.

        The policy observes with its own feature planes (``observation_features``), so a
        mission config with other feature switches is flown; one whose planes would have
        another shape (another planning grid), or more agents than the id plane numbers, is
        refused. ``seed`` is unused: the planner is deterministic.

        Raises:
            CheckpointError: naming the policy's observation shape and the mission's.
        """
        mission_shape = expected_obs_shape(config, self.observation_features)
        if mission_shape != self.obs_shape:
            raise CheckpointError(
                f"{self.algo} policy {str(self.checkpoint)!r} was trained on observations of "
                f"shape {self.obs_shape}; missions of this config give {mission_shape} "
                "(another planning grid)")
        self.transfer_notes = [_UNKNOWN_SETTING] if self.meta.env_config is None else \
            check_policy_transfer(self.meta.env_config, config, str(self.checkpoint))
        self._lstm_states = None
        if self._discounts:
            features = self.observation_features or config.features
            self._discount = TeammateDiscount.for_mission(self._discount, config, features,
                                                          self.overlap_discount, *self.lookahead)

    def act(self, views: list[AgentView]) -> np.ndarray:
        """(N,) greedy valid actions from the agents' (C, G, G) planes and (6,) masks."""
        observations, masks = policy_inputs(
            views, self.obs_shape, f"{self.algo} policy {str(self.checkpoint)!r}")
        states = self._lstm_states
        if states is not None and states[0].shape[1] != len(views):
            states = None  # another team: a new mission without reset()
        inputs = observations if self.meta.normalization is None \
            else self.meta.normalization.apply(observations)  # as VecNormalize fed it
        if self.in_order and self._discounts:
            if self._discount is None:
                raise RuntimeError("call reset(config, seed) before act()")
            latent, gains = _gain_prior_latent(self.policy, observations)
            if inputs is observations:  # the latent's forward pass gives the logits too
                with torch.no_grad():
                    scores = self.policy.action_net(latent).cpu().numpy()
            else:
                scores = action_scores(self.policy, self.algo, inputs)[0].cpu().numpy()
            return choose_for_views(scores, views, _discounted_rescore(
                self.policy, latent, gains, masks, views, scores, self._discount))
        scores, states = action_scores(self.policy, self.algo, inputs, states)
        self._lstm_states = states if self.algo in RECURRENT_ALGORITHMS else None
        if self.in_order:
            return choose_for_views(scores.cpu().numpy(), views)
        return masked_argmax(scores, masks)


def _gain_prior_latent(policy: Any, observations: np.ndarray) -> tuple[torch.Tensor, np.ndarray]:
    """A gain-prior policy's (B, hidden + 6) actor latent of (B, C, G, G) planes (what its
    action layer reads) and the (B, 6) option gains its planes hold, in one forward pass."""
    with torch.no_grad():
        obs = torch.as_tensor(observations, dtype=torch.float32, device=policy.device)
        extractor = policy.pi_features_extractor
        assert isinstance(extractor, GainPriorExtractor)
        latent = policy.mlp_extractor.forward_actor(policy.extract_features(obs, extractor))
        return latent, extractor.plane_gains(obs).cpu().numpy()


def _discounted_rescore(policy: Any, latent: torch.Tensor, gains: np.ndarray,
                        masks: np.ndarray, views: list[AgentView], scores: np.ndarray,
                        discount: TeammateDiscount) -> Callable[[int, np.ndarray], np.ndarray]:
    """``rescore(k, targets)`` for :func:`~ipp_toolkit.planning.choose_for_views`: a
    gain-prior policy's logits for agent k with the six relative gains its action layer
    reads recomputed from its planes' ``gains`` discounted under ``targets``' footprints
    (``latent``: :func:`_gain_prior_latent`)."""

    def logits_of(k: int, discounted: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            relative = relative_option_gains(
                torch.as_tensor(discounted[None], dtype=torch.float32, device=latent.device))
            row = torch.cat([latent[k:k + 1, :-N_ACTIONS], relative], dim=1)
            return policy.action_net(row)[0].cpu().numpy()

    return discount.rescorer(views, gains, scores, masks, logits_of)


class PPOPlanner(SB3Planner):
    """The ``ppo`` planner: :class:`SB3Planner` whose default policy is the shipped PPO one.

    Args:
        checkpoint: a ``policy.pt`` of ``ipp-train ppo`` (or of ``ipp-train sb3``), or
            ``shipped:NAME`` (:data:`baselines.sb3.ppo.SHIPPED_POLICIES`); None loads the default
            shipped policy (:data:`baselines.sb3.ppo.DEFAULT_SHIPPED`).
        device: torch device of the forward pass.
        in_order, overlap_discount, lookahead_steps, lookahead_discount, lookahead_silent:
            as in :class:`SB3Planner`; by default a gain-prior policy looks three steps
            ahead with communication, as ``ig_learned`` does (experiments/lookahead/README.md).

    Raises:
        CheckpointError: no shipped policy, or a missing, corrupt or foreign file.
    """

    name = "ppo"

    def __init__(self, checkpoint: str | Path | None = None, device: str = "cpu",
                 in_order: bool = True, overlap_discount: float = OVERLAP_DISCOUNT,
                 lookahead_steps: int = LOOKAHEAD_STEPS,
                 lookahead_discount: float = LOOKAHEAD_DISCOUNT,
                 lookahead_silent: bool = False) -> None:
        from . import ppo  # the default is read at call time (tests point it elsewhere)

        if checkpoint is None:
            if not ppo.DEFAULT_CHECKPOINT.is_file():
                raise CheckpointError(
                    f"no PPO checkpoint given and the shipped default "
                    f"{str(ppo.DEFAULT_CHECKPOINT)!r} does not exist; train one with "
                    "`ipp-train ppo --out runs/ppo` and pass ppo=runs/ppo/policy.pt "
                    "(checkpoint='runs/ppo/policy.pt')")
            checkpoint = ppo.DEFAULT_CHECKPOINT
        super().__init__(checkpoint, device, in_order, overlap_discount, lookahead_steps,
                         lookahead_discount, lookahead_silent)
