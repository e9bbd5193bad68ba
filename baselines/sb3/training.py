"""``ipp-train sb3 --algo ALGO``: train any supported SB3 algorithm with parameter sharing.

Every algorithm trains on :func:`ipp_toolkit.vec.make_sb3_vec_env` (one env slot per UAV, one
policy for all, the team reward for every slot) through the same run loop as
``ipp-train ppo`` (:func:`baselines.sb3.runner.run_sb3_training`: TensorBoard logs, atomic
checkpoints, ``--resume``, ``--time-limit``, a progress bar). Only MaskablePPO reads the
action masks; the others train with the view's ``invalid_action="hold"``: a masked action
holds the UAV for the step (minus ``invalid_penalty``), so the stored action is the executed
one.

* ``--algo PPO`` / ``--algo MaskablePPO`` are ``ipp-train ppo`` (``--no-masked`` /
  ``--masked``): the same code, flags, presets (``--preset shipped``) and files
  (``ipp-toolkit/ppo``).
* ``--algo A2C|DQN|QRDQN|RecurrentPPO|TRPO|ARS`` write ``OUT/policy.pt`` in the ``ipp-toolkit/sb3``
  format (:mod:`baselines.sb3.policies`): the policy's state dict with the algorithm, its
  hyper-parameters, the observation shape, the action count, the architecture and the env
  config; ``policy.json`` adds the exact command. Never a pickled SB3 zip (the ``sb3``
  planner flies SB3's own zips as well, without unpickling them).

Off-policy runs (DQN, QRDQN) resume without their replay buffer (it is not saved): a resumed
run collects ``learning_starts`` transitions again before it trains.
"""

from __future__ import annotations

import argparse
import math
import shlex
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ipp_toolkit.config.field_types import is_real
from ipp_toolkit.config.files import config_to_dict
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.config.settings import setting_line
from ipp_toolkit.io import save_checkpoint
from ipp_toolkit.runs.cli_help import HelpFormatter, add_version, version_line
from ipp_toolkit.runs.progress import continue_hint, run_reporting
from ipp_toolkit.sim.features import actor_plane_names

# The policies (torch), SB3 and the simulator's SB3 view are imported where a model is built:
# the flags, --help and a refused flag answer without them.
from .ppo_training import (
    add_run_config_flags,
    add_run_flags,
    check_training_memory,
    run_config_from_args,
    train_ppo,
    training_env_config,
)
from .ppo_training import main as ppo_main
from .run_config import (
    ALGORITHMS,
    PPOTrainConfig,
    SB3RunConfig,
    canonical_algo,
    check_policy_size,
    config_from_record,
    config_record,
)

if TYPE_CHECKING:
    from .policies import PolicyArchitecture

__all__ = ["SB3TrainConfig", "ALGORITHM_DEFAULTS", "PPO_ALGORITHMS", "algorithm_class",
           "coerce_hyperparameter", "sb3_model_payload", "make_sb3_model", "save_sb3_policy",
           "training_env_config", "train_sb3", "main"]

PPO_ALGORITHMS = ("PPO", "MaskablePPO")
"""The algorithms ``ipp-train ppo`` trains (``ipp-train sb3`` hands them over to it)."""

_PPO = PPOTrainConfig()
_PPO_HYPER = {"learning_rate": _PPO.lr, "gamma": _PPO.gamma, "n_steps": _PPO.n_steps,
              "batch_size": _PPO.batch_size, "n_epochs": _PPO.n_epochs,
              "gae_lambda": _PPO.gae_lambda, "clip_range": _PPO.clip_range,
              "ent_coef": _PPO.ent_coef, "vf_coef": _PPO.vf_coef,
              "max_grad_norm": _PPO.max_grad_norm}
_DQN_HYPER = {"learning_rate": 1e-4, "gamma": 0.99, "buffer_size": 20_000,
              "learning_starts": 1_000, "batch_size": 64, "tau": 1.0, "train_freq": 4,
              "gradient_steps": 1, "target_update_interval": 1_000,
              "exploration_fraction": 0.2, "exploration_initial_eps": 1.0,
              "exploration_final_eps": 0.05, "max_grad_norm": 10.0}
ALGORITHM_DEFAULTS: dict[str, dict[str, int | float]] = {
    "PPO": dict(_PPO_HYPER),
    "MaskablePPO": dict(_PPO_HYPER),
    "RecurrentPPO": {**_PPO_HYPER, "lstm_hidden_size": 64},
    "A2C": {"learning_rate": 7e-4, "gamma": 0.99, "n_steps": 8, "gae_lambda": 0.95,
            "ent_coef": 0.01, "vf_coef": 0.5, "max_grad_norm": 0.5},
    "DQN": dict(_DQN_HYPER),
    "QRDQN": {**_DQN_HYPER, "n_quantiles": 25},
    "TRPO": {"learning_rate": 1e-3, "gamma": 0.99, "n_steps": _PPO.n_steps,
             "batch_size": _PPO.batch_size, "gae_lambda": 0.95, "cg_max_steps": 15,
             "cg_damping": 0.1, "line_search_shrinking_factor": 0.8,
             "line_search_max_iter": 10, "n_critic_updates": 10, "target_kl": 0.01,
             "sub_sampling_factor": 1},
    "ARS": {"learning_rate": 0.02, "n_delta": 8, "delta_std": 0.05, "n_eval_episodes": 1},
}
"""Every hyper-parameter ``--set NAME=VALUE`` accepts per algorithm, with its default (the
SB3 constructor argument of that name; ``lstm_hidden_size`` and ``n_quantiles`` size the
policy). Sized for CPU training on the 11 x 11 planes."""
_POLICY_OPTIONS = ("lstm_hidden_size", "n_quantiles")
_INT_MIN = {"n_steps": 1, "batch_size": 2, "n_epochs": 1, "buffer_size": 1,
            "learning_starts": 0, "train_freq": 1, "gradient_steps": 1,
            "target_update_interval": 1, "lstm_hidden_size": 1, "n_quantiles": 1,
            "cg_max_steps": 1, "line_search_max_iter": 1, "n_critic_updates": 1,
            "sub_sampling_factor": 1, "n_delta": 1, "n_eval_episodes": 1}
_UNIT_INTERVAL = ("gamma", "gae_lambda", "tau", "exploration_fraction",
                  "exploration_initial_eps", "exploration_final_eps",
                  "line_search_shrinking_factor")
_POSITIVE = ("learning_rate", "clip_range", "max_grad_norm", "cg_damping", "target_kl",
             "delta_std")


def algorithm_class(algo: str) -> type:
    """The SB3 / sb3-contrib algorithm class of ``algo`` (any case)."""
    algo = canonical_algo(algo)
    if algo == "ARS":
        from .runner import ReportingARS

        return ReportingARS  # ARS that logs the task metrics
    if algo in ("MaskablePPO", "QRDQN", "RecurrentPPO", "TRPO"):
        import sb3_contrib

        return getattr(sb3_contrib, algo)
    import stable_baselines3

    return getattr(stable_baselines3, algo)


def _check_hyperparameter(algo: str, name: str, value: Any) -> int | float:
    """``value`` if it is a valid ``name`` of ``algo``; ValueError naming it otherwise."""
    known = ALGORITHM_DEFAULTS[algo]
    if name not in known:
        raise ValueError(f"unknown hyper-parameter {name!r} for {algo}; known: "
                         f"{', '.join(sorted(known))}")
    if not is_real(value):
        raise ValueError(f"{algo} hyper-parameter {name} must be a number, got {value!r}")
    if name in _INT_MIN:
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if not isinstance(value, int) or value < _INT_MIN[name]:
            raise ValueError(f"{algo} hyper-parameter {name} must be an integer >= "
                             f"{_INT_MIN[name]}, got {value!r}")
        return value
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{algo} hyper-parameter {name} must be finite, got {value!r}")
    if name in _UNIT_INTERVAL and not 0.0 <= value <= 1.0:
        raise ValueError(f"{algo} hyper-parameter {name} must lie in [0, 1], got {value!r}")
    if name in _POSITIVE and value <= 0:
        raise ValueError(f"{algo} hyper-parameter {name} must be > 0, got {value!r}")
    if value < 0:
        raise ValueError(f"{algo} hyper-parameter {name} must be >= 0, got {value!r}")
    return value


def coerce_hyperparameter(algo: str, name: str, text: str) -> int | float:
    """The value of ``--set NAME=TEXT`` for ``algo``, checked (ValueError naming it)."""
    algo = canonical_algo(algo)
    _check_hyperparameter(algo, name, ALGORITHM_DEFAULTS[algo].get(name, 0))  # unknown name
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"--set {name}={text}: not a number") from None
    return _check_hyperparameter(algo, name, value)


# --------------------------------------------------------------------------------------------
# Configuration


@dataclass(frozen=True)
class SB3TrainConfig(SB3RunConfig):
    """One ``ipp-train sb3`` run: :class:`~baselines.sb3.ppo.SB3RunConfig`'s fields (length, seed,
    network sizes, training world), the algorithm and its hyper-parameters.

    Attributes:
        algo: one of :data:`~baselines.sb3.policies.ALGORITHMS` (any case; stored in SB3's
            spelling).
        hyperparameters: the algorithm's hyper-parameters (:data:`ALGORITHM_DEFAULTS` keys);
            missing ones take the defaults, so the stored dict is complete.
    """

    algo: str = "MaskablePPO"
    hyperparameters: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        algo = canonical_algo(self.algo)
        object.__setattr__(self, "algo", algo)
        self._check_run_fields("SB3")
        if not isinstance(self.hyperparameters, Mapping):
            raise ValueError(f"invalid SB3 config: hyperparameters must be a mapping, got "
                             f"{self.hyperparameters!r}")
        merged = dict(ALGORITHM_DEFAULTS[algo])
        for name, value in self.hyperparameters.items():
            merged[name] = _check_hyperparameter(algo, name, value)
        object.__setattr__(self, "hyperparameters", merged)
        if "batch_size" in merged and "n_steps" in merged:
            self._check_rollout("SB3", merged["batch_size"], merged["n_steps"])
        self.architecture()  # validates the sizes
        if algo in PPO_ALGORITHMS:
            self.to_ppo_config()  # PPOTrainConfig's own checks, before any work

    def architecture(self) -> PolicyArchitecture:
        """The policy's network sizes."""
        from .policies import PolicyArchitecture

        options = {name: self.hyperparameters[name] for name in _POLICY_OPTIONS
                   if name in self.hyperparameters}
        return PolicyArchitecture(width=self.width, features_dim=self.features_dim,
                                  hidden=self.hidden, **options)

    def algorithm_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of the SB3 algorithm's constructor (hyper-parameters that do not
        size the policy)."""
        return {k: v for k, v in self.hyperparameters.items() if k not in _POLICY_OPTIONS}

    def to_ppo_config(self) -> PPOTrainConfig:
        """The same run as ``ipp-train ppo`` sees it (PPO and MaskablePPO only)."""
        if self.algo not in PPO_ALGORITHMS:
            raise ValueError(f"{self.algo} is not trained by ipp-train ppo")
        hyper = dict(self.hyperparameters)
        return PPOTrainConfig(**self.run_fields(), lr=hyper.pop("learning_rate"),
                              masked=self.algo == "MaskablePPO", **hyper)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dict (an infinite comm_range becomes the string ``"inf"``)."""
        values = config_record(self)
        values["hyperparameters"] = dict(self.hyperparameters)
        return values

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> SB3TrainConfig:
        """Inverse of :meth:`to_dict`; unknown keys are rejected."""
        return config_from_record(cls, values, "SB3")


# --------------------------------------------------------------------------------------------
# Training


def sb3_model_payload(model: Any, config: SB3TrainConfig,
                      env_config: EnvConfig) -> dict[str, Any]:
    """What an ``ipp-toolkit/sb3`` file holds of a model: its policy's state dict and records."""
    return {
        "policy": model.policy.state_dict(),
        "algo": config.algo,
        "obs_shape": [int(d) for d in model.observation_space.shape],
        "n_actions": int(model.action_space.n),  # type: ignore[union-attr]
        "architecture": config.architecture().to_dict(),
        "hyperparameters": dict(config.hyperparameters),
        "sb3_config": config.to_dict(),
        "env_config": config_to_dict(env_config),
        "num_timesteps": int(model.num_timesteps),
    }


def make_sb3_model(config: SB3TrainConfig, env: Any, seed: int | None = None,
                   tensorboard_log: str | None = None) -> Any:
    """A fresh SB3 model of ``config.algo`` on ``env`` whose policy the ``sb3`` planner can
    rebuild (the policy class and sizes of :mod:`baselines.sb3.policies`).

    Args:
        config: algorithm, hyper-parameters and network sizes.
        env: the vec env (:func:`ipp_toolkit.vec.make_sb3_vec_env`, possibly wrapped).
        seed: the model's seed (default ``config.seed``); SB3 also seeds ``env`` with it.
        tensorboard_log: TensorBoard folder, or None.
    """
    from .policies import policy_class, sb3_policy_kwargs

    algo = config.algo
    return algorithm_class(algo)(
        policy_class(algo), env, policy_kwargs=sb3_policy_kwargs(algo, config.architecture()),
        tensorboard_log=tensorboard_log, seed=config.seed if seed is None else seed,
        device="cpu", verbose=0, **config.algorithm_kwargs())


def save_sb3_policy(path: str | Path, model: Any, config: SB3TrainConfig,
                    env_config: EnvConfig, **extra: Any) -> Path:
    """Write a model's policy for the ``sb3`` planner: ``path`` and its JSON record, atomically.

    PPO and MaskablePPO are written in ``ipp-train ppo``'s format, the others in
    ``ipp-toolkit/sb3``; ``extra`` (JSON-safe) goes into the JSON record only.

    Args:
        path: destination ``.pt`` file; the record is ``path.with_suffix(".json")``.
        model: a model made by :func:`make_sb3_model` (or with the same policy class and
            ``policy_kwargs``).
        config: its configuration.
        env_config: the env config it trained on (its features are the policy's planes).
    """
    from .policies import SB3_POLICY_KIND, sb3_policy_metadata
    from .ppo import save_policy

    _check_rebuildable(model, config)
    if config.algo in PPO_ALGORITHMS:
        return save_policy(path, model, config.to_ppo_config(), env_config, **extra)
    payload = sb3_model_payload(model, config, env_config)
    return save_checkpoint(path, payload, SB3_POLICY_KIND, sb3_policy_metadata(payload, **extra))


def _check_rebuildable(model: Any, config: SB3TrainConfig) -> None:
    """ValueError unless ``model``'s policy is the one the planner rebuilds from ``config``
    (same class, parameter names and shapes): a file of another policy would not load."""
    from .policies import build_policy, policy_class

    policy = getattr(model, "policy", None)
    shape = tuple(getattr(getattr(model, "observation_space", None), "shape", ()) or ())
    if policy is None or len(shape) != 3:
        raise ValueError(f"save_sb3_policy needs an SB3 model on the (C, G, G) planes of "
                         f"make_sb3_vec_env, got {type(model).__name__} with observations "
                         f"{shape or '?'}; save it with model.save(PATH) and fly sb3=PATH.zip")
    expected = build_policy(config.algo, config.architecture(), shape).state_dict()
    own = policy.state_dict()
    fits = (type(policy) is policy_class(config.algo) and own.keys() == expected.keys()
            and all(own[k].shape == expected[k].shape for k in own))
    if not fits:
        raise ValueError(f"the model's {type(policy).__name__} is not the {config.algo} policy "
                         f"make_sb3_model builds for this config (width {config.width}, "
                         f"features_dim {config.features_dim}, hidden {config.hidden}), so "
                         "its file could not be loaded; build the model with make_sb3_model, "
                         "or save it with model.save(PATH) and fly sb3=PATH.zip")


def train_sb3(config: SB3TrainConfig, env_config: EnvConfig, out_dir: str | Path,
              progress: bool = True, resume: bool = False, time_limit_s: float | None = None,
              command: str | None = None, announce: str = "") -> Path:
    """Train ``config.algo`` with parameter sharing and write ``out_dir/policy.pt``.

    PPO and MaskablePPO are handed to :func:`baselines.sb3.ppo_training.train_ppo` (the
    ``ipp-toolkit/ppo`` files); the other algorithms write ``ipp-toolkit/sb3`` files. The env
    is ``env_config`` with the team size, range and resolution of ``config``.

    Args:
        config: algorithm and hyper-parameters.
        env_config: the mission configuration to train on.
        out_dir: output folder (created).
        progress: show a tqdm bar.
        resume: continue from ``out_dir/checkpoint.pt`` (its configs must match; only
            ``total_timesteps`` may change).
        time_limit_s: stop after this many seconds of this call and save what was learnt.
        command: the command line that started the run, recorded in the JSON files.
        announce: a line printed to stderr once the run folder is checked, before any work
            (the command line's ``setting:`` line); nothing when empty.

    Returns:
        the path of the saved ``policy.pt``.

    Raises:
        ValueError: bad arguments, an existing run without ``resume``, or a checkpoint of
            other configs.
    """
    from ipp_toolkit.vec import make_sb3_vec_env

    from .policies import SB3_POLICY_KIND, SB3_TRAINING_KIND, sb3_policy_metadata
    from .runner import RunFormat, run_sb3_training, same_run_check

    if not isinstance(config, SB3TrainConfig):
        raise ValueError(f"config must be an SB3TrainConfig, got {type(config).__name__}")
    if not isinstance(env_config, EnvConfig):
        raise ValueError(f"env_config must be an EnvConfig, got {type(env_config).__name__}")
    if config.algo in PPO_ALGORITHMS:
        return train_ppo(config.to_ppo_config(), env_config, out_dir, progress=progress,
                         resume=resume, time_limit_s=time_limit_s, command=command,
                         announce=announce)
    env_cfg = training_env_config(config, env_config)
    algo = config.algo
    architecture = config.architecture()
    check_policy_size(len(actor_plane_names(env_cfg.features)), env_cfg.world.grid_points,
                      architecture.width, architecture.features_dim, architecture.hidden,
                      f"an {algo} policy")
    # An on-policy rollout holds n_steps per slot; an off-policy replay buffer, buffer_size
    # transitions in all.
    hyper = config.hyperparameters
    check_training_memory(env_cfg, config.n_envs, int(hyper.get("n_steps", 1)),
                          hyper.get("buffer_size"))

    check_resume = same_run_check(config, env_cfg, "sb3_config", "SB3")

    def make_env(env_seed: int) -> Any:
        # Only MaskablePPO reads the masks; every algorithm here holds masked actions.
        return make_sb3_vec_env(env_cfg, config.n_envs, env_seed, num_cpus=config.num_cpus,
                                invalid_action="hold", invalid_penalty=config.invalid_penalty)

    def make_model(env: Any, env_seed: int, tb_dir: str, done: int) -> Any:
        model = make_sb3_model(config, env, seed=env_seed, tensorboard_log=tb_dir)
        if done and "learning_starts" in config.hyperparameters:
            # The replay buffer is not saved: refill it before training again.
            model.learning_starts = done + int(config.hyperparameters["learning_starts"])
        return model

    run_format = RunFormat(algo_label=algo, policy_kind=SB3_POLICY_KIND,
                           training_kind=SB3_TRAINING_KIND, metadata=sb3_policy_metadata,
                           tb_log_name=algo.lower())
    return run_sb3_training(
        out_dir=out_dir, run_format=run_format, seed=config.seed,
        total_timesteps=config.total_timesteps, checkpoint_every=config.checkpoint_every,
        make_env=make_env, make_model=make_model,
        payload=lambda model: sb3_model_payload(model, config, env_cfg),
        check_resume=check_resume,
        extra_record={} if command is None else {"command": str(command)},
        progress=progress, resume=resume, time_limit_s=time_limit_s, announce=announce,
        env_config=env_cfg)


# --------------------------------------------------------------------------------------------
# Command line


def _parser() -> argparse.ArgumentParser:
    defaults = SB3RunConfig()  # SB3TrainConfig's run fields, without building a policy
    parser = argparse.ArgumentParser(
        prog="ipp-train sb3",
        allow_abbrev=False,  # a prefix of another flag must not be taken for it
        description="Train a shared (parameter-sharing) policy of any supported SB3 algorithm "
                    "on the simulator. --algo PPO and --algo MaskablePPO run ipp-train ppo "
                    "and take its options (ipp-train sb3 --algo PPO --help).",
        formatter_class=HelpFormatter)
    add_version(parser)
    parser.add_argument("--algo", required=True, metavar="|".join(ALGORITHMS),
                        help="the algorithm (any case)")
    parser.add_argument("--out", default=None,
                        help="output folder (default runs/sb3-ALGO, lower case)")
    parser.add_argument("--lr", type=float, default=None,
                        help="learning rate (default: the algorithm's, see --set)")
    parser.add_argument("--gamma", type=float, default=None,
                        help="discount factor (default: the algorithm's, see --set)")
    add_run_config_flags(parser, defaults)
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="an algorithm hyper-parameter (repeatable): "
                             + "; ".join(f"{algo}: {', '.join(sorted(values))}"
                                         for algo, values in ALGORITHM_DEFAULTS.items()
                                         if algo not in PPO_ALGORITHMS))
    add_run_flags(parser)
    return parser


def _hyperparameters(algo: str, args: argparse.Namespace) -> dict[str, int | float]:
    """The hyper-parameters given by ``--lr``, ``--gamma`` and ``--set`` (each name once)."""
    given: dict[str, int | float] = {}
    items = [f"learning_rate={args.lr!r}"] if args.lr is not None else []
    items += [f"gamma={args.gamma!r}"] if args.gamma is not None else []
    for item in [*items, *args.set]:
        name, sep, text = (part.strip() for part in item.partition("="))
        if not sep or not name:
            raise ValueError(f"--set expects NAME=VALUE, got {item!r}")
        if name in given:
            raise ValueError(f"hyper-parameter {name!r} is given twice")
        given[name] = coerce_hyperparameter(algo, name, text)
    return given


def main(argv: list[str] | None = None) -> int:
    """``ipp-train sb3 --algo ALGO [options]``; returns 0 on success, 2 on bad input."""
    argv = list(sys.argv[1:] if argv is None else argv)
    command = shlex.join(["ipp-train", "sb3", *argv])
    pre = argparse.ArgumentParser(add_help=False, allow_abbrev=False)
    pre.add_argument("--algo")
    known, rest = pre.parse_known_args(argv)
    if known.algo is None:
        if "--version" in argv:
            print(version_line("ipp-train sb3"))
            return 0
        if "-h" in argv or "--help" in argv:
            _parser().print_help()
            return 0
        print(f"ipp-train sb3: error: --algo is required; supported: {', '.join(ALGORITHMS)}",
              file=sys.stderr)
        return 2
    try:
        algo = canonical_algo(known.algo)
    except ValueError as error:
        print(f"ipp-train sb3: error: --algo: {error}", file=sys.stderr)
        return 2
    if algo in PPO_ALGORITHMS:
        if any(item.split("=")[0] in ("--masked", "--no-masked") for item in rest):
            print(f"ipp-train sb3: error: --masked/--no-masked are ipp-train ppo's; here "
                  f"--algo {algo} chooses (MaskablePPO or PPO)", file=sys.stderr)
            return 2
        masked = ["--masked"] if algo == "MaskablePPO" else ["--no-masked"]
        return ppo_main(rest + masked, prog=f"ipp-train sb3 --algo {algo}", command=command)
    args = _parser().parse_args(argv)  # exits with status 2 on malformed options
    out = args.out or f"runs/sb3-{algo.lower()}"

    def work() -> int:
        env_config, run_fields = run_config_from_args(args, SB3TrainConfig(algo=algo))
        config = SB3TrainConfig(algo=algo, **run_fields,
                                hyperparameters=_hyperparameters(algo, args))
        training_env_config(config, env_config)  # validate before any work
        path = train_sb3(config, env_config, out, progress=not args.no_progress,
                         resume=args.resume, announce=setting_line(env_config, args.config),
                         time_limit_s=None if args.time_limit is None else args.time_limit * 60,
                         command=command)
        print(f"saved {path}")
        return 0

    return run_reporting("ipp-train sb3", work, continue_hint(
        out, "checkpoint.pt", f"continue with the same command plus --resume --out {out} (from "
        "the last checkpoint)"))


if __name__ == "__main__":
    sys.exit(main())
