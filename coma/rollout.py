"""COMA's rollout: missions flown in lock-step by the shared actor (or by demonstrators).

This module owns :class:`Rollout` (one update's data: actor, critic and value inputs, masks,
actions, the behaviour policy's probabilities, rewards) and :func:`collect_rollout`, which
plays E missions of B steps at once, sampling every agent's action from the bounded softmax
of one actor forward pass per step. The learner (``coma.learner``) trains on rollouts, the
warm start (``coma.warm_start``) fills them with a demonstrator's actions, and the throughput
benchmark times them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from ipp_toolkit.config import EnvConfig
from ipp_toolkit.features import actor_observations
from ipp_toolkit.mission import MissionGeometry, MissionState, reset_mission, step_mission
from ipp_toolkit.planners import Planner, agent_views
from ipp_toolkit.seeding import planner_seed
from ipp_toolkit.team import N_ACTIONS

from .inputs import critic_input, value_input
from .networks import bounded_softmax
from .persistence import COMANetworks

__all__ = ["Rollout", "collect_rollout"]


@dataclass
class Rollout:
    """One update's data: E missions of T steps with N agents, in lock-step.

    Attributes:
        actor_obs: (E, N, T, C_actor, G, G) float32.
        critic_obs: (E, N, T, C_critic, G, G) float32.
        value_obs: (E, N, T, C_value, G, G) float32, or None unless ``central_qv``.
        masks: (E, N, T, 6) bool valid actions.
        actions: (E, N, T) int64.
        behaviour_probs: (E, N, T) probability of each action under the policy that chose
            it (1 for a demonstrator's actions).
        rewards: (E, T) float32 team rewards.
        returns: (E,) undiscounted return of each mission.
        final_entropy: (E,) entropy metric at the end of each mission.
    """

    actor_obs: torch.Tensor
    critic_obs: torch.Tensor
    value_obs: torch.Tensor | None
    masks: torch.Tensor
    actions: torch.Tensor
    behaviour_probs: torch.Tensor
    rewards: torch.Tensor
    returns: np.ndarray
    final_entropy: np.ndarray

    @property
    def transitions(self) -> int:
        """Agent-transitions in the rollout: E * N * T."""
        return int(np.prod(self.actions.shape))


def _stack_time(frames: list[np.ndarray]) -> torch.Tensor:
    """T frames of (E, N, ...) -> (E, N, T, ...)."""
    return torch.from_numpy(np.stack(frames, axis=2))


def _learning_masks(state: MissionState) -> np.ndarray:
    """(N, 6) bool masks the learner uses: the valid actions, or all actions in the no-mask
    ablation (``team.invalid_action = "hold"``: a masked choice holds the UAV in place)."""
    if state.config.team.invalid_action == "hold":
        return np.ones((state.n_agents, N_ACTIONS), dtype=bool)
    return state.masks().astype(bool)


def collect_rollout(networks: COMANetworks, env_config: EnvConfig, geometry: MissionGeometry,
                    seed: int, first_mission: int, n_missions: int, eps: float,
                    generator: torch.Generator, namespace: str = "train",
                    demonstrators: Sequence[Planner] | None = None) -> Rollout:
    """Play ``n_missions`` missions in lock-step with the bounded-softmax policy.

    Missions ``first_mission ... first_mission + n_missions - 1`` of run ``seed`` are used, so
    consecutive updates see fresh terrains. The actor runs once per step for all agents of all
    missions; the critic inputs are built with the joint action just sampled.

    Args:
        demonstrators: one planner per mission that acts instead of the actor (demonstrations
            for a warm start, see ``coma.warm_start``); ``eps`` is then unused.
    """
    variant = networks.coma_config.variant
    features = env_config.features
    states = [reset_mission(env_config, seed, first_mission + e, namespace, geometry)
              for e in range(n_missions)]
    if demonstrators is not None:
        if len(demonstrators) != n_missions:
            raise ValueError(f"need one demonstrator per mission ({n_missions}), got "
                             f"{len(demonstrators)}")
        for e, planner in enumerate(demonstrators):
            planner.reset(env_config, planner_seed(seed, first_mission + e, namespace))
    actor_frames, critic_frames, value_frames, mask_frames, action_frames, reward_frames = \
        [], [], [], [], [], []
    behaviour_frames: list[np.ndarray] = []
    returns = np.zeros(n_missions)
    for _ in range(env_config.team.budget):
        obs = np.stack([actor_observations(s, features) for s in states])  # (E, N, C, G, G)
        masks = np.stack([_learning_masks(s) for s in states])  # (E, N, 6)
        if demonstrators is None:
            with torch.no_grad():
                logits = networks.actor(torch.from_numpy(obs).flatten(0, 1))
                probs = bounded_softmax(logits, torch.from_numpy(masks).flatten(0, 1), eps)
            chosen = torch.multinomial(probs, 1, generator=generator)
            behaviour = probs.gather(-1, chosen).view(n_missions, -1).numpy()
            actions = chosen.view(n_missions, -1).numpy()
        else:
            actions = np.stack([np.asarray(planner.act(agent_views(s, planner.needs_observations,
                                                                   planner.observation_features)),
                                           dtype=np.int64)
                                for planner, s in zip(demonstrators, states, strict=True)])
            behaviour = np.ones(actions.shape, dtype=np.float32)
        critic_frames.append(np.stack([critic_input(s, features, variant, actions[e], obs[e])
                                       for e, s in enumerate(states)]))
        if networks.value is not None:
            value_frames.append(np.stack([value_input(s, features, obs[e])
                                          for e, s in enumerate(states)]))
        rewards = np.array([step_mission(s, actions[e]) for e, s in enumerate(states)])
        returns += rewards
        actor_frames.append(obs)
        mask_frames.append(masks)
        action_frames.append(actions)
        behaviour_frames.append(behaviour)
        reward_frames.append(rewards)
    return Rollout(
        actor_obs=_stack_time(actor_frames),
        critic_obs=_stack_time(critic_frames),
        value_obs=_stack_time(value_frames) if value_frames else None,
        masks=_stack_time(mask_frames),
        actions=_stack_time(action_frames).long(),
        behaviour_probs=_stack_time(behaviour_frames).float(),
        rewards=torch.from_numpy(np.stack(reward_frames, axis=1)).float(),
        returns=returns,
        final_entropy=np.array([s.history[-1].entropy for s in states]),
    )
