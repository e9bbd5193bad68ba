"""The settings of one ``ipp-train rllib`` run (:class:`RLlibTrainConfig`) and what its files
record of them: the checks a resumed run must pass (:func:`same_run`), the env config as
stored (:func:`env_record`) and the size limits of its missions, batches and network
(:func:`check_sizes`).

Shared by the command line (:mod:`baselines.rllib.training`, which never imports Ray) and the
run itself (:mod:`baselines.rllib.run`, which does).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ipp_toolkit.config.field_types import check_integers, is_real
from ipp_toolkit.config.files import check_same_run, config_from_dict, config_to_dict
from ipp_toolkit.config.limits import check_mission, check_rollout
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.sim.features import actor_plane_names

from ..sb3.run_config import check_policy_size, config_from_record, config_record

__all__ = ["RLLIB_ALGORITHMS", "RLlibTrainConfig", "canonical_rllib_algo", "check_sizes",
           "same_run", "env_record"]

RLLIB_ALGORITHMS = ("PPO", "APPO", "IMPALA")
"""The RLlib algorithms ``ipp-train rllib --algo`` trains (RLlib's spelling)."""


def canonical_rllib_algo(text: str) -> str:
    """``text`` in RLlib's spelling (any case); ValueError naming it otherwise."""
    if isinstance(text, str):
        for algo in RLLIB_ALGORITHMS:
            if text.strip().lower() == algo.lower():
                return algo
    raise ValueError(f"unknown RLlib algorithm {text!r}; supported: "
                     f"{', '.join(RLLIB_ALGORITHMS)}")


@dataclass(frozen=True)
class RLlibTrainConfig:
    """One ``ipp-train rllib`` run.

    Attributes:
        algo: ``PPO``, ``APPO`` or ``IMPALA`` (any case; stored in RLlib's spelling).
        iterations: RLlib training iterations (``algo.train()`` calls) of the whole run.
        seed: the run seed (missions, weights).
        n_agents, comm_range, resolution: the training world.
        width, features_dim, hidden: the network's sizes.
        num_env_runners: Ray actors that sample (0: the driver samples).
        envs_per_runner: env copies each runner steps.
        train_batch: team steps (joint steps of all UAVs) sampled per iteration (RLlib's
            ``train_batch_size_per_learner`` counts env steps): N times as many agent-steps.
        lr: learning rate.
        gamma: discount factor.
        checkpoint_every: iterations between checkpoints (and policy exports).
    """

    algo: str = "PPO"
    iterations: int = 10
    seed: int = 0
    n_agents: int = 4
    comm_range: float = 25.0
    resolution: float = 0.5
    width: int = 32
    features_dim: int = 128
    hidden: int = 64
    num_env_runners: int = 0
    envs_per_runner: int = 1
    train_batch: int = 512
    lr: float = 3e-4
    gamma: float = 0.99
    checkpoint_every: int = 5

    def __post_init__(self) -> None:
        object.__setattr__(self, "algo", canonical_rllib_algo(self.algo))
        minimum = {"iterations": 1, "seed": 0, "n_agents": 1, "width": 1, "features_dim": 1,
                   "hidden": 1, "num_env_runners": 0, "envs_per_runner": 1, "train_batch": 2,
                   "checkpoint_every": 1}
        check_integers(self, minimum, "invalid RLlib config: {name} must be an integer >= "
                       "{minimum}, got {value!r}", numpy=False)
        for name in ("comm_range", "resolution", "lr", "gamma"):
            value = getattr(self, name)
            if not is_real(value) or math.isnan(value) or value <= 0:
                raise ValueError(f"invalid RLlib config: {name} must be a number > 0, got "
                                 f"{value!r}")
        if not math.isfinite(self.lr) or self.gamma > 1:
            raise ValueError(f"invalid RLlib config: lr must be finite and gamma <= 1, got "
                             f"lr={self.lr!r}, gamma={self.gamma!r}")

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dict (an infinite comm_range becomes ``"inf"``)."""
        return config_record(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> RLlibTrainConfig:
        """Inverse of :meth:`to_dict`; unknown keys are refused."""
        return config_from_record(cls, values, "RLlib", "unknown RLlib config keys {keys}")

    def model_config(self) -> dict[str, int]:
        """The RLModule's ``model_config`` (the network's sizes)."""
        return {"width": self.width, "features_dim": self.features_dim, "hidden": self.hidden}


def check_sizes(config: RLlibTrainConfig, env_cfg: EnvConfig) -> None:
    """Refuse (LimitError, before any work and before Ray is needed) a run over a limit: the
    simulator copies stepped at once (every runner's, on one machine at worst), one
    iteration's batch of observations, or a network whose parameter count exceeds it."""
    check_mission(env_cfg, at_once=max(1, config.num_env_runners) * config.envs_per_runner)
    channels = len(actor_plane_names(env_cfg.features))
    check_rollout(float(config.train_batch) * env_cfg.team.n_agents, channels,
                  env_cfg.world.grid_points,
                  f"a train batch of {config.train_batch} team steps x {env_cfg.team.n_agents} "
                  "UAVs")
    check_policy_size(channels, env_cfg.world.grid_points, config.width, config.features_dim,
                      config.hidden, "an RLlib policy")



def same_run(config: RLlibTrainConfig, env_cfg: EnvConfig, record: dict[str, Any],
             where: str) -> None:
    """ValueError unless ``record`` (``checkpoint.json``) is a run of ``config`` (except its
    ``iterations``) on ``env_cfg``."""
    check_same_run(where, "RLlib", RLlibTrainConfig.from_dict(record["rllib_config"]), config,
                   "iterations", config_from_dict(record["env_config"]), env_cfg)


def env_record(env_cfg: EnvConfig) -> dict[str, Any]:
    """The env config as stored in the JSON records."""
    return config_to_dict(env_cfg)
