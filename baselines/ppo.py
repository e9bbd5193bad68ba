"""PPO with parameter sharing (one policy for every UAV): the trained policy and its planner.

This module owns what flies a PPO policy: its architecture (:class:`PPOTrainConfig`, the
features extractor :class:`SmallCNN`), its files and :class:`PPOPlanner`. Training
(``ipp-train ppo``, its callbacks and command line) lives in :mod:`baselines.ppo_training`,
which this module never imports.

Files in a run folder:

* ``policy.pt`` / ``policy.json``: the final model: the policy's state dict, the observation
  shape, the PPO and env configs (``ipp_toolkit.io.save_torch``, kind ``ipp-toolkit/ppo``)
  and the same metadata as JSON. No SB3 zip is ever unpickled: :func:`load_policy` rebuilds
  the policy from the stored configs and loads the weights into it.
* ``checkpoint.pt`` / ``checkpoint.json``: the latest periodic training checkpoint (the model
  plus the optimiser state and the step count), written atomically; training's
  ``resume=True`` carries on from it, and :func:`load_policy` reads it too.
* ``tb/``: TensorBoard logs.

:class:`PPOPlanner` (registry name ``ppo``) flies a saved model greedily: one batched forward
for the whole team, invalid actions masked out.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from ipp_toolkit.config import EnvConfig, config_from_dict, config_to_dict
from ipp_toolkit.io import CheckpointError, load_torch, save_torch, write_json
from ipp_toolkit.planners import AgentView, Planner, check_policy_transfer

__all__ = [
    "PPOTrainConfig",
    "PPOPlanner",
    "SmallCNN",
    "policy_kwargs",
    "model_payload",
    "policy_metadata",
    "save_policy",
    "load_policy",
    "masked_greedy_actions",
    "CHECKPOINT_KIND",
    "TRAINING_KIND",
    "DEFAULT_CHECKPOINT",
]

CHECKPOINT_KIND = "ipp-toolkit/ppo"
"""Format tag of ``policy.pt`` files."""
TRAINING_KIND = "ipp-toolkit/ppo-training"
"""Format tag of ``checkpoint.pt`` files (model + optimiser, for resuming)."""
DEFAULT_CHECKPOINT = Path(__file__).resolve().parent / "checkpoints" / "ppo_4agents_d25.pt"
"""The shipped policy (4 agents, D = 25 m), used when :class:`PPOPlanner` gets no checkpoint."""


# --------------------------------------------------------------------------------------------
# Configuration


def config_record(config: Any) -> dict[str, Any]:
    """A training-config dataclass as a JSON-safe dict (``comm_range`` inf as ``"inf"``)."""
    values = dataclasses.asdict(config)
    if math.isinf(values.get("comm_range", 0.0)):
        values["comm_range"] = "inf"
    return values


def config_from_record(cls: type, values: Mapping[str, Any], what: str) -> Any:
    """Inverse of :func:`config_record` for dataclass ``cls``; unknown keys are rejected."""
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"invalid {what} config: unknown key(s) {unknown}")
    values = dict(values)
    if values.get("comm_range") == "inf":
        values["comm_range"] = math.inf
    return cls(**values)


@dataclass(frozen=True)
class PPOTrainConfig:
    """Hyper-parameters of a PPO run (SB3 timesteps are agent-transitions).

    Attributes:
        total_timesteps: agent-transitions to train for (one joint step of N agents counts N).
        n_envs: simulator copies stepped together; SB3 sees ``n_envs * n_agents`` envs.
        n_steps: steps per env slot per rollout; a rollout holds
            ``n_steps * n_envs * n_agents`` transitions.
        batch_size: mini-batch size of the PPO update (transitions).
        n_epochs: passes over each rollout.
        lr: Adam learning rate (constant).
        gamma: discount factor.
        gae_lambda: GAE lambda.
        clip_range: PPO ratio clipping.
        ent_coef: entropy bonus coefficient.
        vf_coef: value-loss coefficient.
        max_grad_norm: gradient clipping norm.
        width: channels of the two 3x3 conv layers of :class:`SmallCNN`.
        features_dim: output size of :class:`SmallCNN` (its final linear layer).
        hidden: width of the one hidden layer of the policy and of the value head.
        masked: train with sb3-contrib ``MaskablePPO`` (invalid actions never sampled) instead
            of plain ``PPO`` (a sampled masked action holds the UAV for the step, see
            :func:`baselines.ppo_training.train_ppo`).
        seed: seed of the policy, the sampling and the training missions.
        resolution: map resolution (metres per cell) of the training world; coarser than the
            paper's 0.1 m so CPU training is fast (the 11 x 11 planes are resolution-free).
        n_agents: team size N during training.
        comm_range: communication range D (metres) during training.
        num_cpus: SuperSuit worker processes (0: everything in this process, fastest on two
            cores).
        checkpoint_every: agent-transitions between training checkpoints.
        invalid_penalty: reward subtracted from an agent slot whose (unmasked) action was
            masked; the UAV holds for that step (plain PPO only: MaskablePPO never picks one).
    """

    total_timesteps: int = 200_000
    n_envs: int = 4
    n_steps: int = 64
    batch_size: int = 256
    n_epochs: int = 5
    lr: float = 3e-4
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.01
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    width: int = 32
    features_dim: int = 128
    hidden: int = 64
    masked: bool = True
    seed: int = 0
    resolution: float = 0.5
    n_agents: int = 4
    comm_range: float = 25.0
    num_cpus: int = 0
    checkpoint_every: int = 20_000
    invalid_penalty: float = 0.0

    def __post_init__(self) -> None:
        for name in ("total_timesteps", "n_envs", "n_steps", "batch_size", "n_epochs", "width",
                     "features_dim", "hidden", "n_agents", "checkpoint_every"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
                raise ValueError(f"invalid PPO config: {name} must be an integer >= 1, "
                                 f"got {value!r}")
        for name in ("seed", "num_cpus"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 0:
                raise ValueError(f"invalid PPO config: {name} must be an integer >= 0, "
                                 f"got {value!r}")
        for name in ("lr", "clip_range", "resolution", "max_grad_norm"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"invalid PPO config: {name} must be a positive number, "
                                 f"got {value!r}")
        for name in ("gamma", "gae_lambda"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not 0.0 <= value <= 1.0:
                raise ValueError(f"invalid PPO config: {name} must lie in [0, 1], got {value!r}")
        for name in ("ent_coef", "vf_coef", "invalid_penalty"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
                raise ValueError(f"invalid PPO config: {name} must be a number >= 0, "
                                 f"got {value!r}")
        if not isinstance(self.comm_range, int | float) or self.comm_range < 0 \
                or math.isnan(self.comm_range):
            raise ValueError(f"invalid PPO config: comm_range must be >= 0 (inf allowed), "
                             f"got {self.comm_range!r}")
        if not isinstance(self.masked, bool):
            raise ValueError(f"invalid PPO config: masked must be a bool, got {self.masked!r}")
        rollout = self.n_steps * self.n_envs * self.n_agents
        if self.batch_size > rollout:
            raise ValueError(f"invalid PPO config: batch_size {self.batch_size} is larger than "
                             f"a rollout (n_steps * n_envs * n_agents = {rollout})")

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dict (an infinite comm_range becomes the string ``"inf"``)."""
        return config_record(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> PPOTrainConfig:
        """Inverse of :meth:`to_dict`; unknown keys are rejected."""
        return config_from_record(cls, values, "PPO")



# --------------------------------------------------------------------------------------------
# Network


class SmallCNN(BaseFeaturesExtractor):
    """Features of (C, G, G) planes: conv 3x3 (pad 1) -> conv 3x3 (stride 2, pad 1) -> linear.

    SB3's NatureCNN needs larger images; 3x3 kernels fit an 11 x 11 grid. Input (B, C, G, G)
    float32, output (B, features_dim).

    Args:
        observation_space: Box of shape (C, G, G).
        width: channels of both conv layers.
        features_dim: output size.
    """

    def __init__(self, observation_space: spaces.Box, width: int = 32, features_dim: int = 128):
        super().__init__(observation_space, features_dim)
        channels = observation_space.shape[0]
        self.cnn = nn.Sequential(
            nn.Conv2d(channels, width, 3, padding=1), nn.ReLU(),
            # Stride 2 shrinks 11 x 11 to 6 x 6 so the linear layer (and the file) stays small.
            nn.Conv2d(width, width, 3, stride=2, padding=1), nn.ReLU(),
            nn.Flatten(),
        )
        with torch.no_grad():
            n_flat = self.cnn(torch.zeros(1, *observation_space.shape)).shape[1]
        self.linear = nn.Sequential(nn.Linear(n_flat, features_dim), nn.ReLU())

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return self.linear(self.cnn(observations))


def policy_kwargs(config: PPOTrainConfig) -> dict[str, Any]:
    """SB3 ``policy_kwargs`` of the architecture ``config`` describes (:class:`SmallCNN`)."""
    return {
        "features_extractor_class": SmallCNN,
        "features_extractor_kwargs": {"width": config.width,
                                      "features_dim": config.features_dim},
        "net_arch": {"pi": [config.hidden], "vf": [config.hidden]},
    }


def _observation_space(shape: tuple[int, ...]) -> spaces.Box:
    return spaces.Box(-1.0, 1.0, shape, dtype=np.float32)


def _build_policy(config: PPOTrainConfig, obs_shape: tuple[int, ...], device: str = "cpu") -> Any:
    """A fresh (untrained) policy network of the architecture ``config`` describes."""
    cls = MaskableActorCriticPolicy if config.masked else ActorCriticPolicy
    policy = cls(_observation_space(obs_shape), spaces.Discrete(6), lambda _: config.lr,
                 **policy_kwargs(config))
    return policy.to(device)


# --------------------------------------------------------------------------------------------
# Saving and loading


def model_payload(model: Any, config: PPOTrainConfig, env_config: EnvConfig) -> dict[str, Any]:
    """What a policy file holds of an SB3 model: weights, observation shape, both configs."""
    obs_shape = tuple(int(d) for d in model.observation_space.shape)
    return {
        # No clone: the shared features extractor appears under three prefixes, and torch.save
        # writes tensors sharing one storage once (the file stays under 1 MB).
        "policy": model.policy.state_dict(),
        "obs_shape": list(obs_shape),
        "algo": "maskable_ppo" if config.masked else "ppo",
        "ppo_config": config.to_dict(),
        "env_config": config_to_dict(env_config),
        "num_timesteps": int(model.num_timesteps),
    }


def policy_metadata(payload: dict[str, Any], **extra: Any) -> dict[str, Any]:
    """The JSON beside a policy file: the payload without weights or optimiser, + ``extra``."""
    meta = {k: v for k, v in payload.items() if k not in ("policy", "optimizer")}
    return {"format": CHECKPOINT_KIND, **meta, **extra}


def save_policy(path: str | Path, model: Any, config: PPOTrainConfig, env_config: EnvConfig,
                **extra: Any) -> Path:
    """Write ``path`` (weights + configs) and ``path.with_suffix('.json')`` atomically."""
    path = Path(path)
    payload = model_payload(model, config, env_config)
    save_torch(path, payload, CHECKPOINT_KIND)
    write_json(path.with_suffix(".json"), policy_metadata(payload, **extra))
    return path


def load_policy(path: str | Path, device: str = "cpu") -> tuple[Any, dict[str, Any]]:
    """Rebuild the policy stored in a ``policy.pt`` (or ``checkpoint.pt``) and load its weights.

    Returns:
        (policy in eval mode, metadata dict with ``obs_shape`` (tuple), ``ppo_config``
        (:class:`PPOTrainConfig`), ``env_config`` (:class:`EnvConfig`), ``algo`` and
        ``num_timesteps``).

    Raises:
        CheckpointError: missing, corrupt or foreign file, or weights that do not fit.
    """
    path = Path(path)
    try:
        data = load_torch(path, CHECKPOINT_KIND)
    except CheckpointError:
        try:
            data = load_torch(path, TRAINING_KIND)
        except CheckpointError:
            pass
        else:
            return _rebuild(path, data, device)
        raise
    return _rebuild(path, data, device)


def _rebuild(path: Path, data: dict[str, Any], device: str) -> tuple[Any, dict[str, Any]]:
    missing = [key for key in ("policy", "obs_shape", "ppo_config", "env_config")
               if key not in data]
    if missing:
        raise CheckpointError(f"checkpoint {str(path)!r} lacks {missing}")
    try:
        config = PPOTrainConfig.from_dict(data["ppo_config"])
        env_config = config_from_dict(data["env_config"])
        obs_shape = tuple(int(d) for d in data["obs_shape"])
        if len(obs_shape) != 3:
            raise ValueError(f"obs_shape {obs_shape} is not (C, G, G)")
    except (TypeError, ValueError) as error:
        raise CheckpointError(f"checkpoint {str(path)!r} holds an invalid configuration: "
                              f"{error}") from None
    policy = _build_policy(config, obs_shape, device)
    try:
        policy.load_state_dict(data["policy"])
    except (RuntimeError, TypeError, AttributeError) as error:
        raise CheckpointError(f"checkpoint {str(path)!r}: the weights do not fit the policy its "
                              f"config describes ({str(error).splitlines()[0][:200]})") from None
    policy.set_training_mode(False)
    meta = {"obs_shape": obs_shape, "ppo_config": config, "env_config": env_config,
            "algo": data.get("algo"), "num_timesteps": int(data.get("num_timesteps", 0))}
    return policy, meta


def masked_greedy_actions(policy: Any, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """Greedy valid actions of a batch in one forward pass.

    Args:
        policy: an SB3 actor-critic policy (masked or not).
        observations: (B, C, G, G) float32 planes.
        masks: (B, 6) valid actions (any dtype; nonzero = valid).

    Returns:
        (B,) int64 argmax of the logits over the valid actions.
    """
    with torch.no_grad():
        obs = torch.as_tensor(np.asarray(observations, dtype=np.float32), device=policy.device)
        features = policy.extract_features(obs, policy.pi_features_extractor)
        logits = policy.action_net(policy.mlp_extractor.forward_actor(features))
        valid = torch.as_tensor(np.asarray(masks) != 0, device=policy.device)
        logits = logits.masked_fill(~valid, -math.inf)
        return logits.argmax(dim=1).cpu().numpy().astype(np.int64)


# --------------------------------------------------------------------------------------------
# Planner


class PPOPlanner(Planner):
    """Greedy shared PPO policy for every agent (one batched forward per step).

    Args:
        checkpoint: a ``policy.pt`` written by ``ipp-train ppo``; None loads the shipped
            ``baselines/checkpoints/ppo_4agents_d25.pt``.
        device: torch device of the forward pass.

    Raises:
        CheckpointError: no checkpoint, or a missing, corrupt or foreign one.
    """

    name = "ppo"
    needs_observations = True

    def __init__(self, checkpoint: str | Path | None = None, device: str = "cpu") -> None:
        # Batches of N observations: extra intra-op threads only spin (80x slower when the
        # cores are busy, measured), and evaluation runs one worker process per core.
        torch.set_num_threads(1)
        if checkpoint is None:
            if not DEFAULT_CHECKPOINT.is_file():
                raise CheckpointError(
                    f"no PPO checkpoint given and the shipped default {str(DEFAULT_CHECKPOINT)!r} "
                    "does not exist; train one with `ipp-train ppo --out runs/ppo` and pass "
                    "checkpoint='runs/ppo/policy.pt' (or copy it to that default path)")
            checkpoint = DEFAULT_CHECKPOINT
        self.checkpoint = Path(checkpoint)
        self.policy, self.meta = load_policy(self.checkpoint, device)
        self.obs_shape: tuple[int, ...] = self.meta["obs_shape"]
        self.observation_features = self.meta["env_config"].features
        self.transfer_notes: list[str] = []

    def reset(self, config: EnvConfig, seed: int) -> None:
        """Check the transfer to ``config`` (see ``check_policy_transfer``).

        The policy observes with its own feature planes (``observation_features``), so a
        mission config with other feature switches is flown, not refused; another planning
        grid, or more agents than the id plane numbers, is refused.
        """
        self.transfer_notes = check_policy_transfer(self.meta["env_config"], config,
                                                    str(self.checkpoint))

    def act(self, views: list[AgentView]) -> np.ndarray:
        """(N,) greedy valid actions from the agents' (C, G, G) planes and (6,) masks."""
        observations = np.stack([view.observation for view in views])
        if observations.shape[1:] != self.obs_shape:
            raise CheckpointError(
                f"PPO model {str(self.checkpoint)!r} expects observations of shape "
                f"{self.obs_shape}, got {observations.shape[1:]}")
        masks = np.stack([view.mask for view in views])
        return masked_greedy_actions(self.policy, observations, masks)
