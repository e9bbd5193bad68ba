"""The run configs of SB3 training (:class:`SB3RunConfig`, :class:`PPOTrainConfig`), the
shipped PPO policies' names and the parameter count of the shared policy: what the command
lines of ``ipp-train ppo``, ``sb3`` and ``rllib`` need to build their flags and defaults.

Nothing here imports torch or SB3, so ``--help`` and a refused flag answer at once;
:mod:`baselines.sb3.ppo` (the network and its files) re-exports every name.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ipp_toolkit.config.field_types import check_integers, is_real
from ipp_toolkit.config.limits import check_layer_size, check_parameters
from ipp_toolkit.planning import resolve_shipped
from ipp_toolkit.sim.team import N_ACTIONS

__all__ = ["SB3RunConfig", "PPOTrainConfig", "config_record", "config_from_record",
           "check_policy_size", "CHECKPOINT_KIND", "TRAINING_KIND", "CHECKPOINTS",
           "SHIPPED_POLICIES", "DEFAULT_SHIPPED", "DEFAULT_CHECKPOINT", "resolve_policy",
           "ALGORITHMS", "canonical_algo"]

CHECKPOINT_KIND = "ipp-toolkit/ppo"
"""Format tag of ``policy.pt`` files."""
TRAINING_KIND = "ipp-toolkit/ppo-training"
"""Format tag of ``checkpoint.pt`` files (model + optimiser, for resuming)."""
CHECKPOINTS = Path(__file__).resolve().parent / "checkpoints"
"""Where the shipped PPO policies live."""
SHIPPED_POLICIES: dict[str, str] = {"split": "ppo_4agents_d25.pt",
                                   "learned-mixture": "ppo_learned_mixture_4agents_d25.pt"}
"""Shipped PPO policies by name, as in ``ppo=shipped:NAME`` (files in :data:`CHECKPOINTS`)."""
DEFAULT_SHIPPED = "learned-mixture"
"""The shipped policy the ``ppo`` planner flies by default (the best on validation missions)."""
DEFAULT_CHECKPOINT = CHECKPOINTS / SHIPPED_POLICIES[DEFAULT_SHIPPED]
"""Its file, used when the ``ppo`` planner gets no checkpoint."""


def resolve_policy(policy: str | os.PathLike[str]) -> Path:
    """A PPO policy as a user names it: ``shipped:NAME`` (:data:`SHIPPED_POLICIES`) or a path.

    Raises:
        ValueError: ``shipped:`` with an unknown name (the message lists the names).
    """
    return resolve_shipped(policy, {name: CHECKPOINTS / file
                                    for name, file in SHIPPED_POLICIES.items()}, "ppo")


# --------------------------------------------------------------------------------------------
# Configuration


def config_record(config: Any) -> dict[str, Any]:
    """A training-config dataclass as a JSON-safe dict (``comm_range`` inf as ``"inf"``)."""
    values = dataclasses.asdict(config)
    if math.isinf(values.get("comm_range", 0.0)):
        values["comm_range"] = "inf"
    return values


def config_from_record(cls: type, values: Mapping[str, Any], what: str,
                       unknown_keys: str = "invalid {what} config: unknown key(s) {keys}") -> Any:
    """Inverse of :func:`config_record` for dataclass ``cls``; unknown keys are rejected.

    Raises:
        ValueError: keys that are not fields of ``cls``: ``unknown_keys`` formatted with
            ``what`` and the sorted list of ``keys``.
    """
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(unknown_keys.format(what=what, keys=unknown))
    values = dict(values)
    if values.get("comm_range") == "inf":
        values["comm_range"] = math.inf
    return cls(**values)


def _check_integers(config: Any, what: str, names: tuple[str, ...], minimum: int) -> None:
    check_integers(config, dict.fromkeys(names, minimum),
                   f"invalid {what} config: {{name}} must be an integer >= {{minimum}}, "
                   "got {value!r}")


def _check_number(what: str, name: str, value: Any, positive: bool) -> None:
    if not is_real(value) or not math.isfinite(value) or (value <= 0 if positive else value < 0):
        raise ValueError(f"invalid {what} config: {name} must be "
                         f"{'a positive number' if positive else 'a number >= 0'}, "
                         f"got {value!r}")


@dataclass(frozen=True)
class SB3RunConfig:
    """What every SB3 training run shares: its length, seed, network sizes and world.

    :class:`PPOTrainConfig` (``ipp-train ppo``) and ``SB3TrainConfig`` (``ipp-train sb3``)
    extend it with their algorithm's hyper-parameters. SB3 timesteps are agent-transitions.

    Attributes:
        total_timesteps: agent-transitions to train for (one joint step of N agents counts N).
        n_envs: simulator copies stepped together; SB3 sees ``n_envs * n_agents`` envs.
        seed: seed of the policy, the sampling and the training missions.
        width: channels of the two 3x3 conv layers of :class:`SmallCNN`.
        features_dim: output size of :class:`SmallCNN` (its final linear layer).
        hidden: width of the one hidden layer of each head.
        resolution: map resolution (metres per cell) of the training world; coarser than the
            paper's 0.1 m so CPU training is fast (the 11 x 11 planes are resolution-free).
        n_agents: team size N during training.
        comm_range: communication range D (metres, inf allowed) during training.
        num_cpus: SuperSuit worker processes (0: everything in this process, fastest on two
            cores).
        checkpoint_every: agent-transitions between training checkpoints.
        invalid_penalty: reward subtracted from an agent slot whose (unmasked) action was
            masked; the UAV holds for that step (never happens with MaskablePPO).
    """

    total_timesteps: int = 200_000
    n_envs: int = 4
    seed: int = 0
    width: int = 32
    features_dim: int = 128
    hidden: int = 64
    resolution: float = 0.5
    n_agents: int = 4
    comm_range: float = 25.0
    num_cpus: int = 0
    checkpoint_every: int = 20_000
    invalid_penalty: float = 0.0

    def run_fields(self) -> dict[str, Any]:
        """The shared fields' values (to build another run config of the same run)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(SB3RunConfig)}

    def _check_run_fields(self, what: str) -> None:
        """Validate the shared fields; errors start with ``invalid {what} config``."""
        _check_integers(self, what, ("total_timesteps", "n_envs", "width", "features_dim",
                                     "hidden", "n_agents", "checkpoint_every"), 1)
        for name in ("width", "features_dim", "hidden"):
            check_layer_size(name, getattr(self, name), f"invalid {what} config")
        _check_integers(self, what, ("seed", "num_cpus"), 0)
        _check_number(what, "resolution", self.resolution, positive=True)
        _check_number(what, "invalid_penalty", self.invalid_penalty, positive=False)
        if not is_real(self.comm_range) or math.isnan(self.comm_range) or self.comm_range < 0:
            raise ValueError(f"invalid {what} config: comm_range must be >= 0 (inf allowed), "
                             f"got {self.comm_range!r}")

    def _check_rollout(self, what: str, batch_size: int, n_steps: int) -> None:
        rollout = n_steps * self.n_envs * self.n_agents
        if batch_size > rollout:
            raise ValueError(f"invalid {what} config: batch_size {batch_size} is larger than "
                             f"a rollout (n_steps * n_envs * n_agents = {rollout})")


@dataclass(frozen=True)
class PPOTrainConfig(SB3RunConfig):
    """Hyper-parameters of a PPO run: :class:`SB3RunConfig`'s fields and PPO's own.

    Attributes:
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
        masked: train with sb3-contrib ``MaskablePPO`` (invalid actions never sampled) instead
            of plain ``PPO`` (a sampled masked action holds the UAV for the step, see
            :func:`baselines.sb3.ppo_training.train_ppo`).
        gain_prior: 0 for the plain policy; > 0 adds the ``gain`` planes' expected gain of each
            option to the logits (:class:`GainPriorExtractor`), starting at this weight with a
            zero learned part, so the untrained greedy policy flies the gain's argmax. Needs
            the ``gain`` planes among the observations (``features.gain = true``).
    """

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
    masked: bool = True
    gain_prior: float = 0.0

    def __post_init__(self) -> None:
        self._check_run_fields("PPO")
        _check_integers(self, "PPO", ("n_steps", "batch_size", "n_epochs"), 1)
        for name in ("lr", "clip_range", "max_grad_norm"):
            _check_number("PPO", name, getattr(self, name), positive=True)
        for name in ("gamma", "gae_lambda"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not 0.0 <= value <= 1.0:
                raise ValueError(f"invalid PPO config: {name} must lie in [0, 1], got {value!r}")
        for name in ("ent_coef", "vf_coef", "gain_prior"):
            _check_number("PPO", name, getattr(self, name), positive=False)
        if not isinstance(self.masked, bool):
            raise ValueError(f"invalid PPO config: masked must be a bool, got {self.masked!r}")
        self._check_rollout("PPO", self.batch_size, self.n_steps)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dict (an infinite comm_range becomes the string ``"inf"``)."""
        return config_record(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> PPOTrainConfig:
        """Inverse of :meth:`to_dict`; unknown keys are rejected."""
        return config_from_record(cls, values, "PPO")


def check_policy_size(channels: int, grid: int, width: int, features_dim: int, hidden: int,
                      where: str, extra: float = 0.0) -> None:
    """Refuse (LimitError) a shared policy over :class:`SmallCNN` whose parameters would exceed
    the limit, before it is built: the two convolutions, the linear layer and two heads of one
    hidden layer (``extra``: more, e.g. an LSTM). A float count, so absurd sizes cannot
    overflow."""
    side = (int(grid) + 1) // 2  # the stride-2 convolution's output side
    width, features, hidden = float(width), float(features_dim), float(hidden)
    count = ((channels * 9 + 1) * width + (width * 9 + 1) * width
             + (width * side * side + 1) * features
             + 2 * ((features + N_ACTIONS + 1) * hidden + hidden * N_ACTIONS) + extra)
    check_parameters(count, f"{where} (width {int(width)}, features_dim {int(features)}, "
                     f"hidden {int(hidden)})")


ALGORITHMS = ("PPO", "MaskablePPO", "A2C", "DQN", "QRDQN", "RecurrentPPO", "TRPO", "ARS")
"""Algorithms ``ipp-train sb3 --algo`` trains and the ``sb3`` planner flies (SB3 spelling):
every SB3 and sb3-contrib algorithm that takes a discrete action space."""


_CONTINUOUS_ONLY = ("SAC", "TD3", "DDPG", "TQC", "CROSSQ")


def canonical_algo(name: str) -> str:
    """The SB3 spelling of a supported algorithm name given in any case.

    Raises:
        ValueError: an unsupported name; the message lists the supported ones.
    """
    if isinstance(name, str):
        for algo in ALGORITHMS:
            if name.strip().lower() == algo.lower():
                return algo
    hint = ""
    if isinstance(name, str) and name.strip().upper() in _CONTINUOUS_ONLY:
        hint = f" ({name.strip()} needs continuous actions; the UAVs have 6 discrete ones)"
    raise ValueError(f"unsupported algorithm {name!r}{hint}; supported: "
                     f"{', '.join(ALGORITHMS)}")
