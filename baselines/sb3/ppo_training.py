"""Training of the shared PPO policy: ``ipp-train ppo`` and :func:`train_ppo`.

Training runs sb3-contrib's ``MaskablePPO`` (default) or plain SB3 ``PPO`` on
:func:`ipp_toolkit.vec.make_sb3_vec_env`: every agent slot is one SB3 env, every agent gets
the team reward, and the policy sees only its own (C, 11, 11) actor planes. This module owns
the training mission (:func:`training_env_config`), the PPO run (:func:`train_ppo`: fresh or
resumed from ``checkpoint.pt``; the loop, its callbacks for progress, time limit and
checkpoints are :mod:`baselines.sb3.runner`'s, shared by every SB3 algorithm) and the command
line (:func:`main`). ``ipp-train ppo`` is the PPO case of ``ipp-train sb3``
(:mod:`baselines.sb3.training`): ``ipp-train sb3 --algo MaskablePPO`` runs the same code with
the same flags, ``--algo PPO`` adds ``--no-masked``. The policy's architecture and files, and
the planner that flies it, live in :mod:`baselines.sb3.ppo`.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

from ipp_toolkit.config.limits import check_mission, check_rollout
from ipp_toolkit.config.schema import EnvConfig, start_for_team_size
from ipp_toolkit.config.settings import build_env_config, setting_line
from ipp_toolkit.runs.cli_flags import comm_range, positive_float, positive_int
from ipp_toolkit.runs.cli_help import HelpFormatter, add_version
from ipp_toolkit.runs.progress import continue_hint, run_reporting
from ipp_toolkit.sim.features import actor_plane_names
from ipp_toolkit.sim.team import N_ACTIONS

# torch, SB3 and the simulator's SB3 view are imported where a run is built, not here: the
# flags, --help and a refused flag answer without them (ipp-train sb3 and rllib build their
# flags from this module too).
from .run_config import CHECKPOINT_KIND, CHECKPOINTS, TRAINING_KIND, PPOTrainConfig, SB3RunConfig

if TYPE_CHECKING:
    from .runner import RunFormat

__all__ = ["TrainingWorld", "training_env_config", "train_ppo", "check_training_memory",
           "add_mission_flags", "add_network_flags", "mission_config_from_args",
           "add_run_config_flags", "run_config_from_args", "add_run_flags", "main"]


class TrainingWorld(Protocol):
    """The training-world fields every trainer config has (PPOTrainConfig, SB3TrainConfig)."""

    n_agents: int
    comm_range: float
    resolution: float


def training_env_config(config: TrainingWorld, env_config: EnvConfig) -> EnvConfig:
    """``env_config`` with the training team size, range and resolution of ``config``."""
    start = start_for_team_size(env_config.team.start, int(config.n_agents), env_config.world)
    return env_config.replace(world={"resolution": float(config.resolution)},
                              team={"n_agents": int(config.n_agents),
                                    "comm_range": float(config.comm_range), "start": start})


# --------------------------------------------------------------------------------------------
# Training


def _ppo_run_format() -> RunFormat:
    from .ppo import policy_metadata
    from .runner import RunFormat

    return RunFormat(algo_label="PPO", policy_kind=CHECKPOINT_KIND, training_kind=TRAINING_KIND,
                     metadata=policy_metadata, tb_log_name="ppo")


def check_training_memory(env_cfg: EnvConfig, n_envs: int, n_steps: int,
                          buffer_size: int | None = None) -> None:
    """LimitError (a ValueError) when ``n_envs`` simulator copies, or a rollout of
    ``n_steps`` x ``n_envs`` x UAVs observations (a replay buffer of ``buffer_size``), would
    not fit its memory limit; checked before anything is built (``--n-envs 20000`` or
    ``--n-steps 10000000`` would otherwise allocate until the machine swaps)."""
    check_mission(env_cfg, at_once=n_envs)
    n_agents = env_cfg.team.n_agents
    what = f"a rollout of n_steps {n_steps} x n_envs {n_envs} x {n_agents} UAVs"
    transitions = float(n_steps) * n_envs * n_agents
    if buffer_size is not None:
        what, transitions = f"a replay buffer of {buffer_size} transitions", float(buffer_size)
    check_rollout(transitions, len(actor_plane_names(env_cfg.features)),
                  env_cfg.world.grid_points, what)


def train_ppo(config: PPOTrainConfig, env_config: EnvConfig, out_dir: str | Path,
              progress: bool = True, resume: bool = False,
              time_limit_s: float | None = None, command: str | None = None,
              announce: str = "") -> Path:
    """Train a shared PPO policy and write it to ``out_dir/policy.pt``.

    The PPO case of ``ipp-train sb3`` (:mod:`baselines.sb3.runner` runs it). The env is
    ``env_config`` with the team size, range and resolution of ``config``
    (:func:`training_env_config`). Plain PPO (``masked=False``) samples from the unmasked
    policy; the view holds a UAV whose sampled action is masked in place for the step
    (:func:`~ipp_toolkit.vec.make_sb3_vec_env`'s ``invalid_action="hold"``, minus
    ``config.invalid_penalty``), so the action PPO stores is the one executed.

    Args:
        config: hyper-parameters.
        env_config: the mission configuration to train on.
        out_dir: output folder (created).
        progress: show a tqdm bar.
        resume: continue from ``out_dir/checkpoint.pt`` (its configs must match).
        time_limit_s: stop after this many seconds of training (this call; a partial rollout
            is dropped) and save what was learnt; None trains for ``total_timesteps``.
        command: the command line that started the run, recorded in the JSON files.
        announce: a line printed to stderr once the run folder is checked, before any work
            (the command line's ``setting:`` line); nothing when empty.

    Returns:
        the path of the saved ``policy.pt``.

    Raises:
        ValueError: bad arguments, an existing run in ``out_dir`` without ``resume``, or a
            checkpoint whose configs differ from the given ones.
    """
    from ipp_toolkit.vec import make_sb3_vec_env

    from .ppo import model_payload, policy_class, policy_kwargs
    from .runner import run_sb3_training, same_run_check

    if not isinstance(config, PPOTrainConfig):
        raise ValueError(f"config must be a PPOTrainConfig, got {type(config).__name__}")
    if not isinstance(env_config, EnvConfig):
        raise ValueError(f"env_config must be an EnvConfig, got {type(env_config).__name__}")
    env_cfg = training_env_config(config, env_config)
    check_training_memory(env_cfg, config.n_envs, config.n_steps)

    check_resume = same_run_check(config, env_cfg, "ppo_config", "PPO")

    def make_env(env_seed: int) -> Any:
        return make_sb3_vec_env(env_cfg, config.n_envs, env_seed, num_cpus=config.num_cpus,
                                invalid_penalty=config.invalid_penalty)

    def make_model(env: Any, env_seed: int, tb_dir: str, done: int) -> Any:
        from sb3_contrib import MaskablePPO
        from stable_baselines3 import PPO

        cls = MaskablePPO if config.masked else PPO
        return cls(policy_class(config), env, learning_rate=config.lr, n_steps=config.n_steps,
                   batch_size=config.batch_size, n_epochs=config.n_epochs, gamma=config.gamma,
                   gae_lambda=config.gae_lambda, clip_range=config.clip_range,
                   ent_coef=config.ent_coef, vf_coef=config.vf_coef,
                   max_grad_norm=config.max_grad_norm, policy_kwargs=policy_kwargs(config, env_cfg),
                   tensorboard_log=tb_dir, seed=env_seed, device="cpu", verbose=0)

    extra: dict[str, Any] = {"n_actions": N_ACTIONS}
    if command is not None:
        extra["command"] = str(command)
    return run_sb3_training(
        out_dir=out_dir, run_format=_ppo_run_format(), seed=config.seed,
        total_timesteps=config.total_timesteps, checkpoint_every=config.checkpoint_every,
        make_env=make_env, make_model=make_model,
        payload=lambda model: model_payload(model, config, env_cfg),
        check_resume=check_resume, extra_record=extra, progress=progress, resume=resume,
        time_limit_s=time_limit_s, announce=announce, env_config=env_cfg)


# --------------------------------------------------------------------------------------------
# Command line


#: ``ipp-train ppo --preset NAME``: the flags that trained each shipped PPO policy
#: (``ppo=shipped:NAME``, from its JSON record). ``split`` (also ``shipped``, its first name)
#: asked for 3,000,000 transitions and was stopped by a 28-minute limit at 1,738,016;
#: ``learned-mixture`` ships a periodic checkpoint, with the env file bundled beside its
#: weights. Each recipe asks for what its policy trained.
_SPLIT_FLAGS: dict[str, Any] = {
    "timesteps": 1_738_016, "n_envs": 8, "n_steps": 64, "batch_size": 256, "seed": 0,
    "agents": 4, "comm": 25.0, "resolution": 0.5, "checkpoint_every": 100_000}
PPO_PRESETS: dict[str, dict[str, Any]] = {
    "default": {},
    "shipped": _SPLIT_FLAGS,
    "split": _SPLIT_FLAGS,
    # The run of the gain-prior PPO on the learned field prior's gain planes; ships its
    # checkpoint at 600,000 (the best on validation missions).
    "learned-mixture": {
        **_SPLIT_FLAGS, "timesteps": 600_000, "gain_prior": 20.0,
        "config": str(CHECKPOINTS / "ppo_learned_mixture_4agents_d25.yaml")},
}


def add_mission_flags(parser: argparse.ArgumentParser, defaults: SB3RunConfig | Any) -> None:
    """The mission flags every trainer shares (``ipp-train ppo``, ``sb3``, ``rllib``): the env
    file, the run seed and the training world (team size, range, resolution). ``defaults``
    has the fields ``seed``, ``n_agents``, ``comm_range`` and ``resolution``."""
    parser.add_argument("--config", help="env config YAML (default: none, the paper's world)")
    parser.add_argument("--seed", type=int, default=defaults.seed,
                        help="run seed: the policy's weights, its sampling, the missions")
    parser.add_argument("--agents", type=positive_int("agents"), default=None,
                        help=f"team size N (default: the --config file's, else "
                             f"{defaults.n_agents})")
    parser.add_argument("--comm", type=comm_range, default=None, metavar="METRES|inf",
                        help=f"communication range D in metres, inf allowed (default: the "
                             f"--config file's, else {defaults.comm_range:g})")
    parser.add_argument("--resolution", type=positive_float, default=None,
                        help=f"training map resolution in metres per cell (default: the "
                             f"--config file's, else {defaults.resolution:g})")


def add_network_flags(parser: argparse.ArgumentParser, defaults: SB3RunConfig | Any) -> None:
    """The network-size flags of the shared conv policy (``defaults``: ``width``,
    ``features_dim``, ``hidden``)."""
    parser.add_argument("--width", type=int, default=defaults.width,
                        help="conv channels of the features extractor")
    parser.add_argument("--features-dim", type=int, default=defaults.features_dim,
                        help="output size of the features extractor")
    parser.add_argument("--hidden", type=int, default=defaults.hidden,
                        help="hidden layer width of each head")


def mission_config_from_args(args: argparse.Namespace, defaults: SB3RunConfig | Any
                             ) -> EnvConfig:
    """The env config that :func:`add_mission_flags`' flags give (flag > ``--config`` file >
    ``defaults``)."""
    return build_env_config(
        args.config, agents=args.agents, comm=args.comm, resolution=args.resolution,
        defaults={"world": {"resolution": defaults.resolution},
                  "team": {"n_agents": defaults.n_agents, "comm_range": defaults.comm_range}})


def add_run_config_flags(parser: argparse.ArgumentParser, defaults: SB3RunConfig) -> None:
    """The flags of :class:`~baselines.sb3.ppo.SB3RunConfig`'s fields (every SB3 trainer): the
    mission flags (:func:`add_mission_flags`), the run's length and network sizes."""
    add_mission_flags(parser, defaults)
    parser.add_argument("--timesteps", type=int, default=defaults.total_timesteps,
                        help="agent-transitions to train for")
    parser.add_argument("--n-envs", type=int, default=defaults.n_envs,
                        help="simulator copies stepped together")
    add_network_flags(parser, defaults)
    parser.add_argument("--workers", "--num-cpus", dest="num_cpus", type=int,
                        default=defaults.num_cpus, metavar="N",
                        help="SuperSuit worker processes (0: none; --num-cpus is the old name)")
    parser.add_argument("--checkpoint-every", type=int, default=defaults.checkpoint_every,
                        help="agent-transitions between checkpoints")
    parser.add_argument("--invalid-penalty", type=float, default=defaults.invalid_penalty,
                        metavar="P", help="reward subtracted when a masked action is picked "
                                          "(the UAV holds for that step; never with "
                                          "MaskablePPO)")


def run_config_from_args(args: argparse.Namespace, defaults: SB3RunConfig
                    ) -> tuple[EnvConfig, dict[str, Any]]:
    """The env config and the :class:`~baselines.sb3.ppo.SB3RunConfig` fields that
    :func:`add_run_config_flags`' flags give (flag > ``--config`` file > ``defaults``)."""
    env_config = mission_config_from_args(args, defaults)
    fields = {"total_timesteps": args.timesteps, "n_envs": args.n_envs, "seed": args.seed,
              "width": args.width, "features_dim": args.features_dim, "hidden": args.hidden,
              "resolution": env_config.world.resolution, "n_agents": env_config.team.n_agents,
              "comm_range": env_config.team.comm_range, "num_cpus": args.num_cpus,
              "checkpoint_every": args.checkpoint_every,
              "invalid_penalty": args.invalid_penalty}
    return env_config, fields


def add_run_flags(parser: argparse.ArgumentParser) -> None:
    """The run-control flags of every SB3 trainer: time limit, resume, progress."""
    parser.add_argument("--time-limit", type=float, default=None, metavar="MINUTES",
                        help="stop after this many minutes of training and save (default: none, "
                             "no limit)")
    parser.add_argument("--resume", action="store_true",
                        help="continue from OUT/checkpoint.pt")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


PPO_SET_NAMES = {"learning_rate": "lr", "gamma": "gamma", "n_steps": "n_steps",
                 "batch_size": "batch_size", "n_epochs": "n_epochs", "gae_lambda": "gae_lambda",
                 "clip_range": "clip_range", "ent_coef": "ent_coef", "vf_coef": "vf_coef",
                 "max_grad_norm": "max_grad_norm"}
"""``--set NAME=VALUE`` of PPO runs: SB3's name -> the :class:`PPOTrainConfig` field."""
_FLAG_OF = {"n_steps": "--n-steps", "batch_size": "--batch-size", "lr": "--lr",
            "ent_coef": "--ent-coef"}


def ppo_overrides(items: list[str], argv: list[str]) -> dict[str, int | float]:
    """The :class:`PPOTrainConfig` fields ``--set NAME=VALUE`` items give (the config checks
    the values).

    Raises:
        ValueError: a malformed item, an unknown name (the known ones listed), a name given
            twice or with its own flag (``--n-steps``, ``--batch-size``, ``--lr``,
            ``--ent-coef``), or a value that is not a number.
    """
    given: dict[str, int | float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"--set expects NAME=VALUE, got {item!r}")
        if name not in PPO_SET_NAMES:
            raise ValueError(f"--set {name}: not a PPO hyper-parameter; known: "
                             f"{', '.join(PPO_SET_NAMES)}")
        field = PPO_SET_NAMES[name]
        flag = _FLAG_OF.get(field)
        if field in given or (flag is not None and any(a == flag or a.startswith(flag + "=")
                                                       for a in argv)):
            raise ValueError(f"--set {name} is given twice (or with {flag})")
        try:
            given[field] = int(text) if field in ("n_steps", "batch_size", "n_epochs") \
                else float(text)
        except ValueError:
            raise ValueError(f"--set {name}={text}: not a "
                             f"{'whole ' if field in ('n_steps', 'batch_size', 'n_epochs') else ''}"
                             "number") from None
    return given


def _parser(preset: str = "default", prog: str = "ipp-train ppo") -> argparse.ArgumentParser:
    defaults = PPOTrainConfig()
    parser = argparse.ArgumentParser(
        prog=prog,
        allow_abbrev=False,  # a prefix of another flag must not be taken for it
        description="Train a shared (parameter-sharing) PPO policy on the simulator.",
        formatter_class=HelpFormatter)
    add_version(parser)
    parser.add_argument("--preset", choices=sorted(PPO_PRESETS), default="default",
                        help="start from these flags: NAME retrains the shipped policy "
                             "ppo=shipped:NAME ('shipped' is 'split'; flags given explicitly "
                             "win); the defaults shown below are the 'default' preset's")
    parser.add_argument("--out", default="runs/ppo", help="output folder (default runs/ppo)")
    parser.add_argument("--n-steps", type=int, default=defaults.n_steps,
                        help="rollout steps per agent slot")
    parser.add_argument("--batch-size", type=int, default=defaults.batch_size,
                        help="mini-batch of each update, in agent-transitions")
    parser.add_argument("--lr", type=float, default=defaults.lr, help="learning rate (Adam)")
    parser.add_argument("--ent-coef", type=float, default=defaults.ent_coef,
                        help="weight of the entropy bonus")
    add_run_config_flags(parser, defaults)
    parser.add_argument("--gain-prior", type=float, default=defaults.gain_prior, metavar="BETA",
                        help="> 0: add the gain planes' expected gain of each option to the "
                             "logits, starting at this weight (needs `features: {gain: true}` "
                             "in --config); 0: the plain policy")
    parser.add_argument("--masked", action=argparse.BooleanOptionalAction,
                        default=defaults.masked, help="MaskablePPO (default) or plain PPO")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="any PPO hyper-parameter by its SB3 name: "
                             f"{', '.join(PPO_SET_NAMES)} (each once; not with its own flag)")
    add_run_flags(parser)
    parser.set_defaults(**PPO_PRESETS[preset])
    return parser


def main(argv: list[str] | None = None, prog: str = "ipp-train ppo",
         command: str | None = None) -> int:
    """``ipp-train ppo [options]``; returns 0 on success, 2 on bad input.

    Args:
        argv: the options (default ``sys.argv[1:]``).
        prog: the command's name in help and error messages (``ipp-train sb3`` runs the PPO
            case through here).
        command: the command line recorded in the run's JSON files (default: ``prog`` and
            ``argv``).
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    if command is None:
        command = shlex.join([*prog.split(), *argv])
    known, _ = _parser(prog=prog).parse_known_args(argv)  # exits 2 on malformed options
    args = _parser(known.preset, prog).parse_args(argv)
    from .ppo import policy_kwargs

    def work() -> int:
        env_config, run_fields = run_config_from_args(args, PPOTrainConfig())
        hyper = {"n_steps": args.n_steps, "batch_size": args.batch_size, "lr": args.lr,
                 "ent_coef": args.ent_coef, **ppo_overrides(args.set, argv)}
        config = PPOTrainConfig(**run_fields, **hyper, masked=args.masked,
                                gain_prior=args.gain_prior)
        env_cfg = training_env_config(config, env_config)
        # The missions' size first: an absurd area or resolution is named by this estimate,
        # not by the network it would also make too large.
        check_training_memory(env_cfg, config.n_envs, config.n_steps)
        policy_kwargs(config, env_cfg)  # validate before work
        path = train_ppo(config, env_config, args.out, progress=not args.no_progress,
                         resume=args.resume, announce=setting_line(env_config, args.config),
                         time_limit_s=None if args.time_limit is None else args.time_limit * 60,
                         command=command)
        print(f"saved {path}")
        return 0

    return run_reporting(prog, work, continue_hint(
        args.out, "checkpoint.pt", f"continue with --resume --out {args.out} (from the last "
        "checkpoint)"))


if __name__ == "__main__":
    sys.exit(main())
