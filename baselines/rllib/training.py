"""``ipp-train rllib --algo PPO|APPO|IMPALA``: train the shared policy with RLlib, on a local
Ray or a cluster (``--address``).

Every UAV is one agent of an RLlib multi-agent env and all map to one policy (parameter
sharing, :mod:`baselines.rllib.module`); the RLModule reads the action mask from the
observation and masks the invalid logits, so a masked action is never sampled. The run folder
``OUT`` holds, as the other trainers' do:

* ``OUT/checkpoint/`` (RLlib's checkpoint of the whole algorithm, swapped in atomically:
  written beside, then renamed) and ``OUT/checkpoint.json`` (the configs, iterations,
  agent-steps, seconds); ``--resume`` carries on from it (same configs; only
  ``--iterations`` may change);
* ``OUT/policy.pt`` + ``policy.json``: the policy's plain weights for the ``rllib`` planner
  (``ipp-compare --planners rllib=OUT``), written atomically at every checkpoint and at the end;
* ``OUT/tb/``: TensorBoard: ``rollout/ep_rew_mean`` (the team return per mission, mean of the
  last 100 missions, as SB3's), ``rollout/final_entropy``, ``rollout/final_f1``,
  ``rollout/rllib_episode_return_mean`` (RLlib's own: the sum over the UAVs of an episode),
  throughput and the learner's losses, against agent-steps.

Ray is optional (``pip install -c constraints-rllib.txt -e ".[rllib]"``): this module
imports it only inside :func:`train_rllib`, so the command line checks its arguments without it.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.config.settings import setting_line
from ipp_toolkit.extras import install_command, require_extra
from ipp_toolkit.runs.cli_help import HelpFormatter, add_version
from ipp_toolkit.runs.progress import run_reporting

from ..sb3.ppo_training import (
    add_mission_flags,
    add_network_flags,
    add_run_flags,
    mission_config_from_args,
    training_env_config,
)
from .train_config import RLLIB_ALGORITHMS, RLlibTrainConfig, canonical_rllib_algo, check_sizes

__all__ = ["INSTALL_COMMAND", "RLlibUnavailableError", "RLlibTrainConfig", "require_rllib",
           "train_rllib", "main"]

INSTALL_COMMAND = install_command("rllib", "constraints-rllib.txt")
"""How to install the optional RLlib extra (docs/rllib.md)."""


class RLlibUnavailableError(ValueError):
    """``ray[rllib]`` cannot be imported here."""


def require_rllib() -> None:
    """Raise :class:`RLlibUnavailableError` (naming the install command) unless RLlib imports
    (:func:`~ipp_toolkit.extras.require_extra`)."""
    require_extra("ray.rllib", "ipp-train rllib", INSTALL_COMMAND, package="ray[rllib]",
                  error=RLlibUnavailableError)


def train_rllib(config: RLlibTrainConfig, env_config: EnvConfig, out_dir: str | Path,
                address: str | None = None, progress: bool = True, resume: bool = False,
                time_limit_s: float | None = None, command: str | None = None,
                announce: str = "") -> Path:
    """Train ``config.algo`` with one shared policy and write ``out_dir/policy.pt``.

    Args:
        config: algorithm, length, sizes and resources.
        env_config: the mission configuration (team size, range and resolution are
            ``config``'s).
        out_dir: the run folder (created); a relative one is taken from the working
            directory.
        address: a Ray cluster (``HOST:PORT`` as printed by ``ray start --head``, or
            ``auto``); None starts a local Ray with ``num_env_runners + 1`` CPUs.
        progress: show a progress bar over iterations.
        resume: continue from ``out_dir/checkpoint`` (same configs; only ``iterations`` may
            differ).
        time_limit_s: stop after the iteration that passes this many seconds, and save.
        command: the command line, recorded in the JSON files.
        announce: a line printed to stderr once the folder is checked (the ``setting:`` line).

    Returns:
        the path of ``policy.pt``.

    Raises:
        RLlibUnavailableError: ray[rllib] is not installed.
        ConnectionError: no Ray cluster answers at ``address``.
        ValueError: bad arguments, an existing run without ``resume``, nothing to resume, or
            a checkpoint of other configs.
    """
    if not isinstance(config, RLlibTrainConfig):
        raise ValueError(f"config must be an RLlibTrainConfig, got {type(config).__name__}")
    if not isinstance(env_config, EnvConfig):
        raise ValueError(f"env_config must be an EnvConfig, got {type(env_config).__name__}")
    if time_limit_s is not None and (isinstance(time_limit_s, bool)
                                     or not isinstance(time_limit_s, int | float)
                                     or not time_limit_s > 0):
        raise ValueError(f"time_limit_s must be a positive number or None, got {time_limit_s!r}")
    env_cfg = training_env_config(config, env_config)
    check_sizes(config, env_cfg)
    if address is not None:
        from ipp_toolkit.runs.ray_backend import probe

        probe(address)  # fails in seconds, naming the address, with or without Ray here
    require_rllib()
    from . import run as rllib_run  # imports Ray

    # Absolute from here on: RLlib takes a relative checkpoint path for a URI and refuses it
    # ("URI has empty scheme") at the first checkpoint, after the first iterations.
    out = Path(out_dir).expanduser().resolve()
    return rllib_run.run(config, env_cfg, out, address=address, progress=progress,
                         resume=resume, time_limit_s=time_limit_s, command=command,
                         announce=announce)


# --------------------------------------------------------------------------------------------
# Command line


def _parser() -> argparse.ArgumentParser:
    defaults = RLlibTrainConfig()
    parser = argparse.ArgumentParser(
        prog="ipp-train rllib",
        allow_abbrev=False,  # a prefix of another flag must not be taken for it
        description="Train a shared (parameter-sharing) policy with RLlib (PPO, APPO or "
                    "IMPALA) on a local Ray or a Ray cluster; the rllib planner flies it "
                    "(ipp-compare --planners rllib=OUT). Needs the optional extra: "
                    + INSTALL_COMMAND,
        formatter_class=HelpFormatter)
    add_version(parser)
    parser.add_argument("--algo", default="PPO", metavar="|".join(RLLIB_ALGORITHMS),
                        help="the RLlib algorithm (any case)")
    parser.add_argument("--iterations", type=int, default=defaults.iterations,
                        help="training iterations (each samples --train-batch team steps)")
    parser.add_argument("--out", default=None, help="output folder (default runs/rllib-ALGO)")
    parser.add_argument("--address", default=None,
                        help="a running Ray cluster (HOST:PORT as printed by `ray start "
                             "--head`, or auto); default: a local Ray for this run")
    parser.add_argument("--num-env-runners", type=int, default=defaults.num_env_runners,
                        metavar="K", help="Ray actors that sample (0: the driver samples)")
    parser.add_argument("--envs-per-runner", type=int, default=defaults.envs_per_runner,
                        help="simulator copies each sampler steps")
    parser.add_argument("--train-batch", type=int, default=defaults.train_batch,
                        help="team steps (joint steps of all UAVs) sampled per iteration; "
                             "agent-steps are N (--agents) times as many")
    parser.add_argument("--lr", type=float, default=defaults.lr, help="learning rate")
    parser.add_argument("--gamma", type=float, default=defaults.gamma, help="discount factor")
    parser.add_argument("--checkpoint-every", type=int, default=defaults.checkpoint_every,
                        help="iterations between checkpoints")
    add_mission_flags(parser, defaults)
    add_network_flags(parser, defaults)
    add_run_flags(parser)
    return parser


def _config_from_args(args: argparse.Namespace) -> tuple[RLlibTrainConfig, EnvConfig]:
    """The run's config and env config (ValueError naming a bad value)."""
    algo = canonical_rllib_algo(args.algo)
    env_config = mission_config_from_args(args, RLlibTrainConfig())
    config = RLlibTrainConfig(
        algo=algo, iterations=args.iterations, seed=args.seed,
        n_agents=env_config.team.n_agents, comm_range=env_config.team.comm_range,
        resolution=env_config.world.resolution, width=args.width,
        features_dim=args.features_dim, hidden=args.hidden,
        num_env_runners=args.num_env_runners, envs_per_runner=args.envs_per_runner,
        train_batch=args.train_batch, lr=args.lr, gamma=args.gamma,
        checkpoint_every=args.checkpoint_every)
    return config, env_config


def main(argv: list[str] | None = None) -> int:
    """``ipp-train rllib [options]``; 0 on success, 2 on bad input, 1 when Ray fails."""
    argv = list(sys.argv[1:] if argv is None else argv)
    command = shlex.join(["ipp-train", "rllib", *argv])
    args = _parser().parse_args(argv)  # exits with status 2 on malformed options
    folder = {"out": args.out or "runs/rllib-ALGO"}

    def work() -> int:
        config, env_config = _config_from_args(args)
        out = folder["out"] = args.out or f"runs/rllib-{config.algo.lower()}"
        path = train_rllib(config, env_config, out, address=args.address,
                           progress=not args.no_progress, resume=args.resume,
                           time_limit_s=None if args.time_limit is None
                           else args.time_limit * 60,
                           command=command, announce=setting_line(env_config, args.config))
        print(f"saved {path}")
        return 0

    return run_reporting("ipp-train rllib", work,
                         lambda: f"continue with the same command plus --resume --out "
                                 f"{folder['out']} (from the last checkpoint)",
                         errors=(ConnectionError,))


if __name__ == "__main__":
    sys.exit(main())
