"""What each credit-assignment variant's critic sees.

``coma`` and ``central_qv``: the actor's planes, the global planes (f)-(i) and the other
agents' actions (j). ``actor_independent``: the same without (j). ``decentralised``: the
actor's planes only. Central-QV's state-value critic sees the planes of ``actor_independent``
(V(s) must not depend on the actions).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ipp_toolkit.config.schema import FeatureConfig
from ipp_toolkit.sim.features import actor_plane_names, critic_observations, critic_plane_names
from ipp_toolkit.sim.mission import MissionState

__all__ = ["critic_channels", "value_channels", "critic_input", "value_input"]


def _critic_features(variant: str, features: FeatureConfig) -> FeatureConfig | None:
    """The feature switches of the critic's input; ``None``: the actor's planes only."""
    if variant == "decentralised":
        return None
    if variant == "actor_independent":
        return dataclasses.replace(features, other_actions=False)
    return features


def critic_channels(variant: str, features: FeatureConfig) -> int:
    """Number of input planes of the Q critic of ``variant``."""
    critic_features = _critic_features(variant, features)
    if critic_features is None:
        return len(actor_plane_names(features))
    return len(critic_plane_names(critic_features))


def value_channels(features: FeatureConfig) -> int:
    """Number of input planes of Central-QV's state-value critic."""
    return len(critic_plane_names(dataclasses.replace(features, other_actions=False)))


def critic_input(state: MissionState, features: FeatureConfig, variant: str,
                 joint_action: np.ndarray, actor_obs: np.ndarray) -> np.ndarray:
    """The Q critic's input for every agent at the state where ``joint_action`` is chosen.

    Args:
        state: the mission before the joint action is applied.
        features: the mission's feature switches.
        variant: one of :data:`coma.config.VARIANTS`.
        joint_action: (N,) int actions of all agents.
        actor_obs: (N, C_actor, G, G) the actor observations of this state.

    Returns:
        (N, C_critic, G, G) float32 with ``C_critic = critic_channels(variant, features)``.
    """
    critic_features = _critic_features(variant, features)
    if critic_features is None:
        return actor_obs
    return critic_observations(state, critic_features, joint_action, actor_obs)


def value_input(state: MissionState, features: FeatureConfig,
                actor_obs: np.ndarray) -> np.ndarray:
    """Central-QV's V input: (N, C_value, G, G) float32, no action planes."""
    return critic_observations(state, dataclasses.replace(features, other_actions=False),
                               None, actor_obs)
