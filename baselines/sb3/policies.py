"""Shared policies of any supported SB3 algorithm: architecture, files and greedy actions.

The inference side of ``ipp-train sb3`` (:mod:`baselines.sb3.training` trains, this module and
:mod:`baselines.sb3.planner` fly; neither imports the training code). Supported algorithms
(:data:`ALGORITHMS`), all with one policy shared by every UAV (parameter sharing) and the
:class:`~baselines.sb3.ppo.SmallCNN` features extractor on the (C, G, G) actor planes:

* PPO, A2C, TRPO: ``ActorCriticPolicy``; greedy = argmax of the valid logits;
* MaskablePPO: ``MaskableActorCriticPolicy``; argmax of the valid logits;
* RecurrentPPO: ``RecurrentActorCriticPolicy``; argmax of the valid logits, with the actor
  LSTM's state kept per agent across the steps of a mission;
* DQN: ``DQNPolicy``; argmax of the valid Q-values;
* QRDQN: ``QRDQNPolicy``; argmax of the valid mean quantiles;
* ARS: ``ARSPolicy`` (an MLP on the flattened planes: ARS's policy takes no features
  extractor); argmax of the valid action-net outputs.

Files: a policy file is a plain state dict saved with :func:`ipp_toolkit.io.save_torch`
(format ``ipp-toolkit/sb3``; ``ipp-toolkit/sb3-training`` for a resumable checkpoint) holding
the weights, the algorithm, the observation shape, the action count, the architecture and the
configs; a JSON record sits beside it. PPO and MaskablePPO runs are written by
``ipp-train ppo`` (the PPO case of ``ipp-train sb3``) in its ``ipp-toolkit/ppo`` format;
:func:`~baselines.sb3.loading.load_sb3_policy` reads every one of them, and SB3's own
``model.save`` zips too (:mod:`baselines.sb3.zips`). Nothing is ever unpickled: the policy is
rebuilt from the records (or the zip's JSON) and the weights loaded with
``torch.load(weights_only=True)``.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from sb3_contrib.ars.policies import ARSPolicy
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from sb3_contrib.common.recurrent.policies import RecurrentActorCriticPolicy
from sb3_contrib.qrdqn.policies import QRDQNPolicy
from stable_baselines3.common.policies import ActorCriticPolicy, BasePolicy
from stable_baselines3.dqn.policies import DQNPolicy

from ipp_toolkit.config.field_types import check_integers
from ipp_toolkit.config.limits import check_layer_size
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import CheckpointError
from ipp_toolkit.sim.features import actor_plane_names
from ipp_toolkit.sim.team import N_ACTIONS

from .ppo import NoOptimizer, SmallCNN, actor_logits, check_policy_size, masked_argmax

# The algorithms' names need no torch: the command lines read them from run_config.
from .run_config import ALGORITHMS, canonical_algo

__all__ = [
    "ALGORITHMS",
    "ACTOR_CRITIC_ALGORITHMS",
    "MASKED_ALGORITHMS",
    "RECURRENT_ALGORITHMS",
    "LSTMStates",
    "SB3_POLICY_KIND",
    "SB3_TRAINING_KIND",
    "PolicyArchitecture",
    "LoadedPolicy",
    "canonical_algo",
    "policy_class",
    "sb3_policy_kwargs",
    "build_policy",
    "expected_obs_shape",
    "sb3_policy_metadata",
    "check_shapes",
    "masked_argmax",
    "action_scores",
    "greedy_actions",
    "initial_lstm_states",
]

ACTOR_CRITIC_ALGORITHMS = ("PPO", "A2C", "MaskablePPO", "TRPO")
"""Algorithms whose policy is an (optionally masked) ``ActorCriticPolicy``."""
MASKED_ALGORITHMS = ("MaskablePPO",)
"""Algorithms that read the action masks while training; the others train with the view's
``invalid_action="hold"`` (a masked action holds the UAV for the step)."""
RECURRENT_ALGORITHMS = ("RecurrentPPO",)
"""Algorithms whose policy carries an LSTM state from step to step."""
SB3_POLICY_KIND = "ipp-toolkit/sb3"
"""Format tag of the ``policy.pt`` of a non-PPO ``ipp-train sb3`` run."""
SB3_TRAINING_KIND = "ipp-toolkit/sb3-training"
"""Format tag of its ``checkpoint.pt`` (policy + optimiser, for resuming)."""

_POLICY_CLASSES: dict[str, type[BasePolicy]] = {
    "PPO": ActorCriticPolicy,
    "A2C": ActorCriticPolicy,
    "MaskablePPO": MaskableActorCriticPolicy,
    "RecurrentPPO": RecurrentActorCriticPolicy,
    "DQN": DQNPolicy,
    "QRDQN": QRDQNPolicy,
    "TRPO": ActorCriticPolicy,
    "ARS": ARSPolicy,
}
def policy_class(algo: str) -> type[BasePolicy]:
    """The SB3 policy class that ``algo`` trains and the planner rebuilds."""
    return _POLICY_CLASSES[canonical_algo(algo)]


# --------------------------------------------------------------------------------------------
# Architecture


@dataclass(frozen=True)
class PolicyArchitecture:
    """Sizes of a shared policy network (the same features extractor for every algorithm).

    Attributes:
        width: channels of the two 3x3 conv layers of :class:`~baselines.sb3.ppo.SmallCNN`.
        features_dim: output size of the features extractor.
        hidden: width of the one hidden layer of each head (policy, value, Q or quantiles).
        lstm_hidden_size: LSTM size (RecurrentPPO only).
        n_quantiles: quantiles per action (QRDQN only).
    """

    width: int = 32
    features_dim: int = 128
    hidden: int = 64
    lstm_hidden_size: int = 64
    n_quantiles: int = 25

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            check_integers(self, {name: 1}, "invalid architecture: {name} must be an integer "
                           ">= {minimum}, got {value!r}")
            check_layer_size(name, int(value), "invalid architecture")

    def to_dict(self) -> dict[str, int]:
        return {name: int(value) for name, value in asdict(self).items()}

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> PolicyArchitecture:
        """Inverse of :meth:`to_dict`; unknown keys are rejected."""
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"invalid architecture: unknown key(s) {unknown}")
        return cls(**values)


def sb3_policy_kwargs(algo: str, architecture: PolicyArchitecture) -> dict[str, Any]:
    """SB3 ``policy_kwargs`` of ``architecture`` for the policy class of ``algo``."""
    algo = canonical_algo(algo)
    if algo == "ARS":  # ARSPolicy flattens the planes itself: no features extractor to set
        return {"net_arch": [architecture.hidden]}
    kwargs: dict[str, Any] = {
        "features_extractor_class": SmallCNN,
        "features_extractor_kwargs": {"width": architecture.width,
                                      "features_dim": architecture.features_dim},
    }
    if algo in ("DQN", "QRDQN"):
        kwargs["net_arch"] = [architecture.hidden]
    else:
        kwargs["net_arch"] = {"pi": [architecture.hidden], "vf": [architecture.hidden]}
    if algo == "QRDQN":
        kwargs["n_quantiles"] = architecture.n_quantiles
    if algo == "RecurrentPPO":
        kwargs["lstm_hidden_size"] = architecture.lstm_hidden_size
    return kwargs


def build_policy(algo: str, architecture: PolicyArchitecture, obs_shape: tuple[int, ...],
                 n_actions: int = N_ACTIONS, device: str = "cpu") -> BasePolicy:
    """A fresh (untrained) policy of ``algo`` for (C, G, G) observations, in eval mode.

    It is built to act (weights are loaded into it): its optimiser is a
    :class:`~baselines.sb3.ppo.NoOptimizer`, as a torch optimiser's import of ``torch._dynamo``
    costs seconds per process.
    """
    lstm = float(architecture.lstm_hidden_size)
    check_policy_size(obs_shape[0], obs_shape[-1], architecture.width, architecture.features_dim,
                      architecture.hidden, f"an {algo} policy",
                      extra=8 * (architecture.features_dim + lstm + 2) * lstm
                      + architecture.hidden * N_ACTIONS * architecture.n_quantiles)
    observation_space = spaces.Box(-1.0, 1.0, tuple(obs_shape), dtype=np.float32)
    action_space = spaces.Discrete(int(n_actions))
    kwargs = sb3_policy_kwargs(algo, architecture)
    if canonical_algo(algo) == "ARS":  # no optimiser: ARS perturbs the weights directly
        policy = ARSPolicy(observation_space, action_space, **kwargs)
    else:
        policy = policy_class(algo)(observation_space, action_space, lambda _: 1e-4,
                                    optimizer_class=NoOptimizer, **kwargs)
    policy = policy.to(device)
    policy.set_training_mode(False)
    return policy


def expected_obs_shape(config: EnvConfig, features: Any = None) -> tuple[int, int, int]:
    """(C, G, G) of the actor planes of ``config``'s missions, observed with ``features``
    (default: the config's own feature switches)."""
    features = config.features if features is None else features
    grid = int(config.world.grid_points)
    return (len(actor_plane_names(features)), grid, grid)


# --------------------------------------------------------------------------------------------
# Files


@dataclass(frozen=True)
class LoadedPolicy:
    """What a policy file says about its policy (everything but the weights).

    Attributes:
        algo: SB3 spelling of the algorithm (see :data:`ALGORITHMS`).
        obs_shape: (C, G, G) observation shape it was trained on.
        n_actions: action count it was trained for.
        architecture: its network sizes.
        env_config: the training env config (its feature switches are the policy's planes);
            None for an SB3 zip, which does not record it (the planner then observes with
            the mission's own feature switches).
        num_timesteps: agent-transitions it was trained for.
        format: the file's format tag.
        record: the file's other records (hyper-parameters, ...), JSON-safe.
        normalization: the ``VecNormalize`` observation statistics of an SB3 zip trained
            under it (:class:`~baselines.sb3.normalization.ObsNormalization`), else None.
    """

    algo: str
    obs_shape: tuple[int, int, int]
    n_actions: int
    architecture: PolicyArchitecture
    env_config: EnvConfig | None
    num_timesteps: int
    format: str
    record: dict[str, Any] = field(default_factory=dict)
    normalization: Any = None


def sb3_policy_metadata(payload: dict[str, Any], **extra: Any) -> dict[str, Any]:
    """The JSON beside an ``ipp-toolkit/sb3`` file: the payload without weights or optimiser,
    plus ``extra`` (command line, training seconds)."""
    meta = {k: v for k, v in payload.items() if k not in ("policy", "optimizer")}
    return {"format": SB3_POLICY_KIND, **meta, **extra}


def check_shapes(path: Path, meta: LoadedPolicy) -> None:
    """CheckpointError unless ``meta`` records 6 actions and (C, G, G) planes its env config
    (if recorded) gives."""
    if meta.n_actions != N_ACTIONS:
        raise CheckpointError(f"checkpoint {str(path)!r} was trained for {meta.n_actions} "
                              f"actions; the simulator has {N_ACTIONS}")
    if len(meta.obs_shape) != 3:
        raise CheckpointError(f"checkpoint {str(path)!r}: observation shape {meta.obs_shape} "
                              "is not (C, G, G)")
    own = meta.obs_shape if meta.env_config is None else expected_obs_shape(meta.env_config)
    if meta.obs_shape != own:
        raise CheckpointError(f"checkpoint {str(path)!r} records observations of shape "
                              f"{meta.obs_shape}, but its env config gives {own}")


# --------------------------------------------------------------------------------------------
# Greedy actions


LSTMStates = tuple[torch.Tensor, torch.Tensor]


def initial_lstm_states(policy: BasePolicy, batch: int) -> LSTMStates:
    """Zero (hidden, cell) states of a recurrent policy's actor LSTM for ``batch`` agents,
    each (n_layers, batch, lstm_hidden_size)."""
    layers, _, size = policy.lstm_hidden_state_shape
    zeros = torch.zeros(layers, batch, size, device=policy.device)
    return zeros, zeros.clone()


def action_scores(policy: BasePolicy, algo: str, observations: np.ndarray,
                  lstm_states: LSTMStates | None = None
                  ) -> tuple[torch.Tensor, LSTMStates | None]:
    """What a policy of ``algo`` ranks a batch of agents' actions by, in one forward pass.

    The logits (PPO, MaskablePPO, A2C, TRPO, RecurrentPPO), the Q-values (DQN), the mean
    quantiles (QRDQN) or the deterministic action net's outputs (ARS); masks are not
    applied. Higher is better in every case.

    Args:
        policy: a policy of ``algo`` (from :func:`~baselines.sb3.loading.load_sb3_policy` or a
            trained model).
        algo: its algorithm (any case).
        observations: (B, C, G, G) float32 planes.
        lstm_states: RecurrentPPO only: the (hidden, cell) states of the B agents, each
            (n_layers, B, lstm_hidden_size); None starts from zeros (a mission start).

    Returns:
        ((B, A) float scores, the new LSTM states or None for non-recurrent policies).
    """
    algo = canonical_algo(algo)
    if algo in ACTOR_CRITIC_ALGORITHMS:
        return actor_logits(policy, observations), None
    with torch.no_grad():
        obs = torch.as_tensor(np.asarray(observations, dtype=np.float32), device=policy.device)
        if algo == "DQN":
            return policy.q_net(obs), None
        if algo == "QRDQN":
            return policy.quantile_net(obs).mean(dim=1), None
        if algo == "ARS":
            features = policy.extract_features(obs, policy.features_extractor)
            return policy.action_net(features), None
        if lstm_states is None:
            lstm_states = initial_lstm_states(policy, obs.shape[0])
        starts = torch.zeros(obs.shape[0], device=policy.device)
        distribution, new_states = policy.get_distribution(obs, lstm_states, starts)
        return distribution.distribution.logits, (new_states[0], new_states[1])


def greedy_actions(policy: BasePolicy, algo: str, observations: np.ndarray, masks: np.ndarray,
                   lstm_states: LSTMStates | None = None) -> tuple[np.ndarray, LSTMStates | None]:
    """Greedy valid actions of a batch of agents in one forward pass, each on its own.

    Args:
        policy: a policy of ``algo`` (from :func:`~baselines.sb3.loading.load_sb3_policy` or a
            trained model).
        algo: its algorithm (any case).
        observations: (B, C, G, G) float32 planes.
        masks: (B, A) valid actions (nonzero = valid); a masked action is never chosen.
        lstm_states: as in :func:`action_scores`.

    Returns:
        ((B,) int64 argmax of :func:`action_scores` over the valid actions, the new LSTM
        states or None for non-recurrent policies).
    """
    scores, states = action_scores(policy, algo, observations, lstm_states)
    return masked_argmax(scores, masks), states
