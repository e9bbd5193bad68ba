"""PPO with parameter sharing (one policy for every UAV) through the SB3 view of the simulator.

Training (``ipp-train ppo``) runs sb3-contrib's ``MaskablePPO`` (default) or plain SB3 ``PPO``
on :func:`ipp_toolkit.vec.make_sb3_vec_env`: every agent slot is one SB3 env, every agent
gets the team reward, and the policy sees only its own (C, 11, 11) actor planes.

Files in the output folder:

* ``policy.pt`` / ``policy.json``: the final model: the policy's state dict, the observation
  shape, the PPO and env configs (``ipp_toolkit.io.save_torch``, kind ``ipp-toolkit/ppo``)
  and the same metadata as JSON. No SB3 zip is ever unpickled: :func:`load_policy` rebuilds
  the policy from the stored configs and loads the weights into it.
* ``checkpoint.pt`` / ``checkpoint.json``: the latest periodic training checkpoint (the model
  plus the optimiser state and the step count), written atomically; ``resume=True`` carries on
  from it.
* ``tb/``: TensorBoard logs.

:class:`PPOPlanner` (registry name ``ppo``) flies a saved model greedily: one batched forward
for the whole team, invalid actions masked out.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from sb3_contrib import MaskablePPO
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.policies import ActorCriticPolicy
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.vec_env import VecMonitor
from torch import nn
from tqdm.auto import tqdm

from ipp_toolkit.config import (
    EnvConfig,
    config_from_dict,
    config_to_dict,
    start_for_team_size,
)
from ipp_toolkit.io import CheckpointError, load_torch, save_torch, write_json
from ipp_toolkit.planners import AgentView, Planner, check_policy_transfer
from ipp_toolkit.settings import build_env_config
from ipp_toolkit.vec import make_sb3_vec_env

__all__ = [
    "PPOTrainConfig",
    "PPOPlanner",
    "SmallCNN",
    "training_env_config",
    "train_ppo",
    "load_policy",
    "main",
    "CHECKPOINT_KIND",
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
            of plain ``PPO`` (whose invalid samples are replaced by valid ones, see
            :func:`train_ppo`).
        seed: seed of the policy, the sampling and the training missions.
        resolution: map resolution (metres per cell) of the training world; coarser than the
            paper's 0.1 m so CPU training is fast (the 11 x 11 planes are resolution-free).
        n_agents: team size N during training.
        comm_range: communication range D (metres) during training.
        num_cpus: SuperSuit worker processes (0: everything in this process, fastest on two
            cores).
        checkpoint_every: agent-transitions between training checkpoints.
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
        for name in ("ent_coef", "vf_coef"):
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
        values = dataclasses.asdict(self)
        if math.isinf(values["comm_range"]):
            values["comm_range"] = "inf"
        return values

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> PPOTrainConfig:
        """Inverse of :meth:`to_dict`; unknown keys are rejected."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"invalid PPO config: unknown key(s) {unknown}")
        values = dict(values)
        if values.get("comm_range") == "inf":
            values["comm_range"] = math.inf
        return cls(**values)


def training_env_config(config: PPOTrainConfig, env_config: EnvConfig) -> EnvConfig:
    """``env_config`` with the training team size, range and resolution of ``config``."""
    start = start_for_team_size(env_config.team.start, int(config.n_agents), env_config.world)
    return env_config.replace(world={"resolution": float(config.resolution)},
                              team={"n_agents": int(config.n_agents),
                                    "comm_range": float(config.comm_range), "start": start})


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


def _policy_kwargs(config: PPOTrainConfig) -> dict[str, Any]:
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
                 **_policy_kwargs(config))
    return policy.to(device)


# --------------------------------------------------------------------------------------------
# Saving and loading


def _model_payload(model: Any, config: PPOTrainConfig, env_config: EnvConfig) -> dict[str, Any]:
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


def _metadata(payload: dict[str, Any], **extra: Any) -> dict[str, Any]:
    meta = {k: v for k, v in payload.items() if k not in ("policy", "optimizer")}
    return {"format": CHECKPOINT_KIND, **meta, **extra}


def save_policy(path: str | Path, model: Any, config: PPOTrainConfig, env_config: EnvConfig,
                **extra: Any) -> Path:
    """Write ``path`` (weights + configs) and ``path.with_suffix('.json')`` atomically."""
    path = Path(path)
    payload = _model_payload(model, config, env_config)
    save_torch(path, payload, CHECKPOINT_KIND)
    write_json(path.with_suffix(".json"), _metadata(payload, **extra))
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
        checkpoint: a ``policy.pt`` written by :func:`train_ppo`; None loads the shipped
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


# --------------------------------------------------------------------------------------------
# Training


def _progress_callback(total: int, initial: int) -> BaseCallback:
    class TqdmCallback(BaseCallback):
        """tqdm bar over agent-transitions (SB3's own bar needs ``rich``)."""

        def _on_training_start(self) -> None:
            self.bar = tqdm(total=total, initial=initial, unit="step", desc="ppo",
                            dynamic_ncols=True)

        def _on_step(self) -> bool:
            self.bar.update(self.model.num_timesteps - self.bar.n)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return TqdmCallback()


def _time_limit_callback(deadline: float) -> BaseCallback:
    class TimeLimitCallback(BaseCallback):
        """Stops training once ``deadline`` (a perf_counter time) has passed.

        Returning False from a step ends SB3's rollout and ``learn`` (the partial rollout is
        not trained on).
        """

        def _on_step(self) -> bool:
            return time.perf_counter() < deadline

    return TimeLimitCallback()


def _checkpoint_callback(every: int, save: Any) -> BaseCallback:
    class CheckpointCallback(BaseCallback):
        """Writes ``checkpoint.pt`` every ``every`` agent-transitions (atomically)."""

        def _on_training_start(self) -> None:
            self.next_save = (self.model.num_timesteps // every + 1) * every

        def _on_step(self) -> bool:
            if self.model.num_timesteps >= self.next_save:
                save()
                self.next_save = (self.model.num_timesteps // every + 1) * every
            return True

    return CheckpointCallback()


def train_ppo(config: PPOTrainConfig, env_config: EnvConfig, out_dir: str | Path,
              progress: bool = True, resume: bool = False,
              time_limit_s: float | None = None) -> Path:
    """Train a shared PPO policy and write it to ``out_dir/policy.pt``.

    The env is ``env_config`` with the team size, range and resolution of ``config``
    (:func:`training_env_config`). Plain PPO (``masked=False``) samples from the unmasked
    policy; the simulator refuses invalid actions, so such actions are replaced by the first
    valid one before stepping (and recorded as taken, a known bias of unmasked PPO here).

    Args:
        config: hyper-parameters.
        env_config: the mission configuration to train on.
        out_dir: output folder (created).
        progress: show a tqdm bar.
        resume: continue from ``out_dir/checkpoint.pt`` (its configs must match).
        time_limit_s: stop after this many seconds of training (this call; a partial rollout
            is dropped) and save what was learnt; None trains for ``total_timesteps``.

    Returns:
        the path of the saved ``policy.pt``.

    Raises:
        ValueError: bad arguments, an existing run in ``out_dir`` without ``resume``, or a
            checkpoint whose configs differ from the given ones.
    """
    if not isinstance(config, PPOTrainConfig):
        raise ValueError(f"config must be a PPOTrainConfig, got {type(config).__name__}")
    if not isinstance(env_config, EnvConfig):
        raise ValueError(f"env_config must be an EnvConfig, got {type(env_config).__name__}")
    if time_limit_s is not None and (not isinstance(time_limit_s, int | float)
                                     or not time_limit_s > 0):
        raise ValueError(f"time_limit_s must be a positive number or None, got {time_limit_s!r}")
    torch.set_num_threads(1)  # two cores, shared: more threads collapse (see the notes)
    env_cfg = training_env_config(config, env_config)
    out_dir = Path(out_dir)
    ckpt_path = out_dir / "checkpoint.pt"
    state = None
    if resume:
        if ckpt_path.is_file():
            state = load_torch(ckpt_path, TRAINING_KIND)
            stored = PPOTrainConfig.from_dict(state["ppo_config"])
            if dataclasses.replace(stored, total_timesteps=config.total_timesteps) != config:
                raise ValueError(f"cannot resume {str(ckpt_path)!r}: its PPO config "
                                 f"{stored} differs from the given {config} (only "
                                 "total_timesteps may change)")
            if config_from_dict(state["env_config"]) != env_cfg:
                raise ValueError(f"cannot resume {str(ckpt_path)!r}: it was trained on another "
                                 "env config")
        else:
            raise ValueError(f"nothing to resume: {str(ckpt_path)!r} does not exist (drop "
                             "--resume to start a new run)")
    elif ckpt_path.exists() or (out_dir / "policy.pt").exists():
        raise ValueError(f"{str(out_dir)!r} already holds a PPO run; pass resume=True "
                         "(--resume) or choose another output folder")
    out_dir.mkdir(parents=True, exist_ok=True)

    done = int(state["num_timesteps"]) if state is not None else 0
    # A resumed run starts new missions: copy c continues on run seed + done + c.
    env_seed = config.seed + done
    venv = make_sb3_vec_env(env_cfg, config.n_envs, env_seed, num_cpus=config.num_cpus)
    try:
        env = VecMonitor(venv)
        cls = MaskablePPO if config.masked else PPO
        model = cls("MlpPolicy", env, learning_rate=config.lr, n_steps=config.n_steps,
                    batch_size=config.batch_size, n_epochs=config.n_epochs, gamma=config.gamma,
                    gae_lambda=config.gae_lambda, clip_range=config.clip_range,
                    ent_coef=config.ent_coef, vf_coef=config.vf_coef,
                    max_grad_norm=config.max_grad_norm, policy_kwargs=_policy_kwargs(config),
                    tensorboard_log=str(out_dir / "tb"), seed=env_seed, device="cpu",
                    verbose=0)
        if not config.masked:
            _install_valid_action_fix(venv)
        if state is not None:
            model.policy.load_state_dict(state["policy"])
            model.policy.optimizer.load_state_dict(state["optimizer"])
            model.num_timesteps = done
            model._episode_num = int(state.get("episodes", 0))
        started = time.perf_counter()
        elapsed_before = float(state.get("train_seconds", 0.0)) if state is not None else 0.0

        def save_checkpoint() -> None:
            payload = _model_payload(model, config, env_cfg)
            payload["optimizer"] = model.policy.optimizer.state_dict()
            payload["episodes"] = int(model._episode_num)
            payload["train_seconds"] = elapsed_before + time.perf_counter() - started
            save_torch(ckpt_path, payload, TRAINING_KIND)
            write_json(ckpt_path.with_suffix(".json"),
                       _metadata(payload, train_seconds=payload["train_seconds"]))

        callbacks = [_checkpoint_callback(config.checkpoint_every, save_checkpoint)]
        if progress:
            callbacks.append(_progress_callback(config.total_timesteps, done))
        if time_limit_s is not None:
            callbacks.append(_time_limit_callback(started + time_limit_s))
        remaining = config.total_timesteps - done
        if remaining > 0:
            model.learn(total_timesteps=remaining, callback=callbacks,
                        reset_num_timesteps=state is None, tb_log_name="ppo")
        save_checkpoint()
        seconds = elapsed_before + time.perf_counter() - started
        return save_policy(out_dir / "policy.pt", model, config, env_cfg,
                           train_seconds=round(seconds, 1))
    finally:
        venv.close()


def _install_valid_action_fix(venv: Any) -> None:
    """Plain PPO ignores masks: map each invalid action to the first valid one before stepping."""
    step_async = venv.step_async

    def fixed(actions: np.ndarray) -> None:
        actions = np.asarray(actions).reshape(venv.num_envs).copy()
        masks = venv.action_masks()
        invalid = ~masks[np.arange(len(actions)), actions]
        actions[invalid] = masks[invalid].argmax(axis=1)
        step_async(actions)

    venv.step_async = fixed


# --------------------------------------------------------------------------------------------
# Command line


def _parser() -> argparse.ArgumentParser:
    defaults = PPOTrainConfig()
    parser = argparse.ArgumentParser(
        prog="ipp-train ppo",
        description="Train a shared (parameter-sharing) PPO policy on the simulator.")
    parser.add_argument("--config", help="env config YAML (defaults: the paper's world)")
    parser.add_argument("--out", default="runs/ppo", help="output folder (default runs/ppo)")
    parser.add_argument("--timesteps", type=int, default=defaults.total_timesteps,
                        help="agent-transitions to train for")
    parser.add_argument("--n-envs", type=int, default=defaults.n_envs,
                        help="simulator copies stepped together")
    parser.add_argument("--n-steps", type=int, default=defaults.n_steps,
                        help="rollout steps per agent slot")
    parser.add_argument("--batch-size", type=int, default=defaults.batch_size)
    parser.add_argument("--lr", type=float, default=defaults.lr)
    parser.add_argument("--ent-coef", type=float, default=defaults.ent_coef)
    parser.add_argument("--width", type=int, default=defaults.width,
                        help="conv channels of the features extractor")
    parser.add_argument("--seed", type=int, default=defaults.seed)
    parser.add_argument("--agents", type=int, default=None,
                        help=f"team size N (default: the --config file's, else "
                             f"{defaults.n_agents})")
    parser.add_argument("--comm", type=float, default=None,
                        help=f"communication range D in metres, inf allowed (default: the "
                             f"--config file's, else {defaults.comm_range:g})")
    parser.add_argument("--resolution", type=float, default=None,
                        help=f"training map resolution in metres per cell (default: the "
                             f"--config file's, else {defaults.resolution:g})")
    parser.add_argument("--num-cpus", type=int, default=defaults.num_cpus,
                        help="SuperSuit worker processes (0: none)")
    parser.add_argument("--checkpoint-every", type=int, default=defaults.checkpoint_every,
                        help="agent-transitions between checkpoints")
    parser.add_argument("--masked", action=argparse.BooleanOptionalAction,
                        default=defaults.masked, help="MaskablePPO (default) or plain PPO")
    parser.add_argument("--time-limit", type=float, default=None, metavar="MINUTES",
                        help="stop after this many minutes of training and save")
    parser.add_argument("--resume", action="store_true",
                        help="continue from OUT/checkpoint.pt")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    return parser


def main(argv: list[str] | None = None) -> int:
    """``ipp-train ppo [options]``; returns 0 on success, 2 on bad input."""
    parser = _parser()
    args = parser.parse_args(argv)  # exits with status 2 on malformed options
    try:
        defaults = PPOTrainConfig()
        env_config = build_env_config(
            args.config, agents=args.agents, comm=args.comm, resolution=args.resolution,
            defaults={"world": {"resolution": defaults.resolution},
                      "team": {"n_agents": defaults.n_agents,
                               "comm_range": defaults.comm_range}})
        config = PPOTrainConfig(
            total_timesteps=args.timesteps, n_envs=args.n_envs, n_steps=args.n_steps,
            batch_size=args.batch_size, lr=args.lr, ent_coef=args.ent_coef, width=args.width,
            masked=args.masked, seed=args.seed, resolution=env_config.world.resolution,
            n_agents=env_config.team.n_agents, comm_range=env_config.team.comm_range,
            num_cpus=args.num_cpus,
            checkpoint_every=args.checkpoint_every)
        training_env_config(config, env_config)  # validate before any work
        path = train_ppo(config, env_config, args.out, progress=not args.no_progress,
                         resume=args.resume,
                         time_limit_s=None if args.time_limit is None else args.time_limit * 60)
    except (ValueError, CheckpointError) as error:
        print(f"ipp-train ppo: error: {error}", file=sys.stderr)
        return 2
    print(f"saved {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
