"""PPO with parameter sharing (one policy for every UAV): the trained policy and its planner.

This module owns what flies a PPO policy: its architecture (:class:`PPOTrainConfig`, the
features extractor :class:`SmallCNN`, the optional gain prior) and its files. Training
(``ipp-train ppo``, its callbacks and command line) lives in :mod:`baselines.sb3.ppo_training`,
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

The ``ppo`` planner (:class:`baselines.sb3.planner.PPOPlanner`, the ``sb3`` planner with the
shipped policy as its default) flies a saved model greedily: one batched forward for the whole
team, invalid actions masked out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, MlpExtractor
from torch import nn

from ipp_toolkit.config.files import config_from_dict, config_to_dict
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import (
    CheckpointError,
    built_from_checkpoint,
    load_checkpoint,
    load_weights,
    save_checkpoint,
)
from ipp_toolkit.sim.features import (
    actor_plane_names,
    gain_plane_channels,
    option_gain_cells,
    relative_option_gains,
)
from ipp_toolkit.sim.team import N_ACTIONS

# The configs and names that need no torch live in run_config (the command lines build their
# flags from them without importing torch); every name stays importable from here.
from .run_config import (
    CHECKPOINT_KIND,
    CHECKPOINTS,
    DEFAULT_CHECKPOINT,
    DEFAULT_SHIPPED,
    SHIPPED_POLICIES,
    TRAINING_KIND,
    PPOTrainConfig,
    SB3RunConfig,
    check_policy_size,
    config_from_record,
    config_record,
    resolve_policy,
)

__all__ = [
    "SB3RunConfig",
    "PPOTrainConfig",
    "SmallCNN",
    "GainPriorExtractor",
    "GainPriorMlpExtractor",
    "GainPriorMaskablePolicy",
    "GainPriorPolicy",
    "policy_class", "policy_kwargs", "model_payload", "policy_metadata",
    "save_policy", "load_policy",
    "actor_logits", "masked_greedy_actions", "masked_argmax",
    "NoOptimizer",
    "CHECKPOINT_KIND",
    "TRAINING_KIND",
    "DEFAULT_CHECKPOINT",
    "DEFAULT_SHIPPED",
    "SHIPPED_POLICIES",
    "resolve_policy",
    "CHECKPOINTS",
    "config_record",
    "config_from_record",
    "check_policy_size",
]

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



class GainPriorExtractor(SmallCNN):
    """:class:`SmallCNN` features followed by each option's relative expected gain.

    Output (B, features_dim + 6): the CNN's features, then :meth:`plane_gains` (the planes at
    option a's waypoint, :func:`~ipp_toolkit.sim.features.option_gain_cells`; 0 and masked
    outside the area) over the best one's magnitude
    (:func:`~ipp_toolkit.sim.features.relative_option_gains`). :class:`GainPriorMlpExtractor`
    passes these six around the policy's hidden layer: the action layer sees them linearly.

    Args:
        observation_space: Box of shape (C, G, G).
        gain_channels: channels of ``gain_level``, ``gain_up``, ``gain_down``.
        width, features_dim: as :class:`SmallCNN`.
    """

    def __init__(self, observation_space: spaces.Box, gain_channels: Sequence[int],
                 width: int = 32, features_dim: int = 128):
        super().__init__(observation_space, width, features_dim)
        self._features_dim = features_dim + N_ACTIONS
        channel, row, col = option_gain_cells(gain_channels, observation_space.shape[-1])
        # Buffers, not parameters: rebuilt from the configs, never stored.
        self.register_buffer("option_channel", torch.from_numpy(channel), persistent=False)
        self.register_buffer("option_row", torch.from_numpy(row), persistent=False)
        self.register_buffer("option_col", torch.from_numpy(col), persistent=False)

    def plane_gains(self, observations: torch.Tensor) -> torch.Tensor:
        """(B, C, G, G) planes -> (B, 6) each option's gain as the planes hold it."""
        return observations[:, self.option_channel, self.option_row, self.option_col]

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return torch.cat([super().forward(observations),
                          relative_option_gains(self.plane_gains(observations))], dim=1)


class GainPriorMlpExtractor(nn.Module):
    """SB3's policy/value MLPs on the CNN features, the six gains passed to the action layer.

    ``forward_actor`` gives (B, hidden + 6): the policy MLP's latent, then the gains;
    ``forward_critic`` gives the value MLP's (B, hidden) latent of the CNN features.
    """

    def __init__(self, feature_dim: int, net_arch: Any, activation_fn: type[nn.Module],
                 device: torch.device | str = "auto"):
        super().__init__()
        self.mlp = MlpExtractor(feature_dim - N_ACTIONS, net_arch, activation_fn, device)
        self.latent_dim_pi = self.mlp.latent_dim_pi + N_ACTIONS
        self.latent_dim_vf = self.mlp.latent_dim_vf

    def forward(self, features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.forward_actor(features), self.forward_critic(features)

    def forward_actor(self, features: torch.Tensor) -> torch.Tensor:
        cnn, gains = features[:, :-N_ACTIONS], features[:, -N_ACTIONS:]
        return torch.cat([self.mlp.forward_actor(cnn), gains], dim=1)

    def forward_critic(self, features: torch.Tensor) -> torch.Tensor:
        return self.mlp.forward_critic(features[:, :-N_ACTIONS])


class _GainPriorMixin:
    """Actor-critic policy whose logits are ``residual(latent) + gain_prior * relative gains``.

    The action layer's weights on the six gains start at ``gain_prior`` times the identity and
    its weights on the latent at zero, so the untrained policy's logits are the prior alone;
    PPO then trains all of it (the prior's weights included).
    """

    def __init__(self, *args: Any, gain_prior: float, **kwargs: Any):
        self.gain_prior = float(gain_prior)
        super().__init__(*args, **kwargs)  # type: ignore[call-arg]

    def _build_mlp_extractor(self) -> None:
        self.mlp_extractor = GainPriorMlpExtractor(
            self.features_dim, net_arch=self.net_arch,  # type: ignore[attr-defined]
            activation_fn=self.activation_fn, device=self.device)  # type: ignore[attr-defined]

    def _build(self, lr_schedule: Any) -> None:
        super()._build(lr_schedule)  # type: ignore[misc]
        action_net: nn.Linear = self.action_net  # type: ignore[attr-defined]
        with torch.no_grad():
            action_net.weight.zero_()
            action_net.bias.zero_()
            action_net.weight[:, -N_ACTIONS:] = self.gain_prior * torch.eye(N_ACTIONS)


class GainPriorMaskablePolicy(_GainPriorMixin, MaskableActorCriticPolicy):
    """MaskablePPO's policy with a gain prior (see :class:`_GainPriorMixin`)."""


class GainPriorPolicy(_GainPriorMixin, ActorCriticPolicy):
    """Plain PPO's policy with a gain prior (see :class:`_GainPriorMixin`)."""


def policy_class(config: PPOTrainConfig) -> type[ActorCriticPolicy]:
    """The SB3 policy class of ``config``: masked or not, with a gain prior or not."""
    if config.gain_prior > 0:
        return GainPriorMaskablePolicy if config.masked else GainPriorPolicy
    return MaskableActorCriticPolicy if config.masked else ActorCriticPolicy


def policy_kwargs(config: PPOTrainConfig, env_config: EnvConfig) -> dict[str, Any]:
    """SB3 ``policy_kwargs`` of the architecture ``config`` describes on ``env_config``'s planes.

    Raises:
        ValueError: ``gain_prior`` > 0 without the ``gain`` planes, or networks over the
            parameter limit (``ipp_toolkit.config.limits``).
    """
    check_policy_size(len(actor_plane_names(env_config.features)), env_config.world.grid_points,
                      config.width, config.features_dim, config.hidden, "a PPO policy")
    extractor_kwargs: dict[str, Any] = {"width": config.width,
                                        "features_dim": config.features_dim}
    kwargs: dict[str, Any] = {"net_arch": {"pi": [config.hidden], "vf": [config.hidden]}}
    if config.gain_prior > 0:
        try:
            extractor_kwargs["gain_channels"] = gain_plane_channels(env_config.features)
        except ValueError as error:
            raise ValueError(f"invalid PPO config: gain_prior = {config.gain_prior!r}: "
                             f"{error}") from None
        kwargs["gain_prior"] = config.gain_prior
    kwargs["features_extractor_class"] = (GainPriorExtractor if config.gain_prior > 0
                                          else SmallCNN)
    kwargs["features_extractor_kwargs"] = extractor_kwargs
    return kwargs


def _observation_space(shape: tuple[int, ...]) -> spaces.Box:
    return spaces.Box(-1.0, 1.0, shape, dtype=np.float32)


class NoOptimizer:
    """The optimiser of a policy rebuilt only to act (:func:`load_policy`): it refuses to step.

    SB3 policies build their optimiser in ``_build``, and constructing any torch optimiser
    imports ``torch._dynamo`` (``Optimizer.add_param_group`` is wrapped by
    ``torch._disable_dynamo``): about 3 s of the ``ppo`` planner's construction, paid by
    ``ipp-compare``'s main process and by each of its workers. A loaded policy is never
    trained (training resumes through SB3's own model), so it gets this stub instead.

    Args:
        params: the policy's parameters (unused).
        **kwargs: the optimiser's options SB3 passes (``lr``, ...; unused).
    """

    def __init__(self, params: Any, **kwargs: Any) -> None:
        self.param_groups: list[dict[str, Any]] = []

    def zero_grad(self, set_to_none: bool = True) -> None:
        raise RuntimeError("this policy was loaded to act, not to train: it has no optimiser")

    def step(self, closure: Any = None) -> None:
        raise RuntimeError("this policy was loaded to act, not to train: it has no optimiser")


def _build_policy(config: PPOTrainConfig, env_config: EnvConfig, obs_shape: tuple[int, ...],
                  device: str = "cpu", optimizer: bool = True) -> Any:
    """A fresh (untrained) policy network of the architecture ``config`` describes.

    ``optimizer=False`` gives it a :class:`NoOptimizer` (a policy that will only act).
    """
    kwargs = policy_kwargs(config, env_config)
    if not optimizer:
        kwargs["optimizer_class"] = NoOptimizer
    policy = policy_class(config)(_observation_space(obs_shape), spaces.Discrete(N_ACTIONS),
                                  lambda _: config.lr, **kwargs)
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
    payload = model_payload(model, config, env_config)
    return save_checkpoint(path, payload, CHECKPOINT_KIND, policy_metadata(payload, **extra))


def load_policy(path: str | Path, device: str = "cpu") -> tuple[Any, dict[str, Any]]:
    """Rebuild the policy stored in a ``policy.pt`` (or ``checkpoint.pt``) and load its weights.

    The policy is rebuilt to act: its optimiser is a :class:`NoOptimizer`.

    Returns:
        (policy in eval mode, metadata dict with ``obs_shape`` (tuple), ``ppo_config``
        (:class:`PPOTrainConfig`), ``env_config`` (:class:`EnvConfig`), ``algo`` and
        ``num_timesteps``).

    Raises:
        CheckpointError: missing, corrupt or foreign file, or weights that do not fit.
    """
    path = Path(path)
    return _rebuild(path, load_checkpoint(path, CHECKPOINT_KIND, TRAINING_KIND), device)


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
    policy = built_from_checkpoint(
        path, lambda: _build_policy(config, env_config, obs_shape, device, optimizer=False))
    load_weights(policy, data["policy"], path,
                 "the weights do not fit the policy its config describes")
    policy.set_training_mode(False)
    meta = {"obs_shape": obs_shape, "ppo_config": config, "env_config": env_config,
            "algo": data.get("algo"), "num_timesteps": int(data.get("num_timesteps", 0))}
    return policy, meta


def actor_logits(policy: Any, observations: np.ndarray) -> torch.Tensor:
    """(B, A) action logits of an SB3 actor-critic policy (masked or not) for (B, C, G, G)
    float32 planes, in one forward pass without gradients; masks are not applied."""
    with torch.no_grad():
        obs = torch.as_tensor(np.asarray(observations, dtype=np.float32), device=policy.device)
        features = policy.extract_features(obs, policy.pi_features_extractor)
        return policy.action_net(policy.mlp_extractor.forward_actor(features))


def masked_greedy_actions(policy: Any, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """Greedy valid actions of a batch in one forward pass.

    Args:
        policy: an SB3 actor-critic policy (masked or not).
        observations: (B, C, G, G) float32 planes.
        masks: (B, 6) valid actions (any dtype; nonzero = valid).

    Returns:
        (B,) int64 argmax of the logits over the valid actions.
    """
    return masked_argmax(actor_logits(policy, observations), masks)


def masked_argmax(scores: torch.Tensor, masks: np.ndarray) -> np.ndarray:
    """(B,) int64 argmax of (B, A) ``scores`` over the valid actions of (B, A) ``masks``
    (nonzero = valid); ValueError when the shapes differ."""
    valid = torch.as_tensor(np.asarray(masks) != 0, device=scores.device)
    if valid.shape != scores.shape:
        raise ValueError(f"masks of shape {tuple(valid.shape)} do not fit scores of shape "
                         f"{tuple(scores.shape)}")
    return scores.masked_fill(~valid, -math.inf).argmax(dim=1).cpu().numpy().astype(np.int64)

