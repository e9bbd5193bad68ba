"""Training of the shared PPO policy: ``ipp-train ppo`` and :func:`train_ppo`.

Training runs sb3-contrib's ``MaskablePPO`` (default) or plain SB3 ``PPO`` on
:func:`ipp_toolkit.vec.make_sb3_vec_env`: every agent slot is one SB3 env, every agent gets
the team reward, and the policy sees only its own (C, 11, 11) actor planes. This module owns
the training mission (:func:`training_env_config`), the run (:func:`train_ppo`: fresh or
resumed from ``checkpoint.pt``, its SB3 callbacks for progress, time limit and checkpoints)
and the command line (:func:`main`). The policy's
architecture and files, and the planner that flies it, live in :mod:`baselines.ppo`.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path
from typing import Any

import torch
from sb3_contrib import MaskablePPO
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecMonitor
from tqdm.auto import tqdm

from ipp_toolkit.config import EnvConfig, config_from_dict, start_for_team_size
from ipp_toolkit.io import CheckpointError, load_torch, save_torch, write_json
from ipp_toolkit.progress import report_interrupt
from ipp_toolkit.settings import build_env_config
from ipp_toolkit.vec import make_sb3_vec_env

from .ppo import (
    TRAINING_KIND,
    PPOTrainConfig,
    model_payload,
    policy_kwargs,
    policy_metadata,
    save_policy,
)

__all__ = ["training_env_config", "train_ppo", "main"]


def training_env_config(config: PPOTrainConfig, env_config: EnvConfig) -> EnvConfig:
    """``env_config`` with the training team size, range and resolution of ``config``."""
    start = start_for_team_size(env_config.team.start, int(config.n_agents), env_config.world)
    return env_config.replace(world={"resolution": float(config.resolution)},
                              team={"n_agents": int(config.n_agents),
                                    "comm_range": float(config.comm_range), "start": start})


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
    policy; the view holds a UAV whose sampled action is masked in place for the step
    (:func:`~ipp_toolkit.vec.make_sb3_vec_env`'s ``invalid_action="hold"``), so the action PPO
    stores is the one executed.

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
                    max_grad_norm=config.max_grad_norm, policy_kwargs=policy_kwargs(config),
                    tensorboard_log=str(out_dir / "tb"), seed=env_seed, device="cpu",
                    verbose=0)
        if state is not None:
            model.policy.load_state_dict(state["policy"])
            model.policy.optimizer.load_state_dict(state["optimizer"])
            model.num_timesteps = done
            model._episode_num = int(state.get("episodes", 0))
        started = time.perf_counter()
        elapsed_before = float(state.get("train_seconds", 0.0)) if state is not None else 0.0

        def save_checkpoint() -> None:
            payload = model_payload(model, config, env_cfg)
            payload["optimizer"] = model.policy.optimizer.state_dict()
            payload["episodes"] = int(model._episode_num)
            payload["train_seconds"] = elapsed_before + time.perf_counter() - started
            save_torch(ckpt_path, payload, TRAINING_KIND)
            write_json(ckpt_path.with_suffix(".json"),
                       policy_metadata(payload, train_seconds=payload["train_seconds"]))

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


# --------------------------------------------------------------------------------------------
# Command line


#: ``ipp-train ppo --preset NAME``: the flags that trained each shipped PPO policy (from its
#: JSON record). The shipped run asked for 3,000,000 transitions and was stopped by a
#: 28-minute limit at 1,738,016; the recipe asks for what it trained.
PPO_PRESETS: dict[str, dict[str, Any]] = {
    "default": {},
    "shipped": {"timesteps": 1_738_016, "n_envs": 8, "n_steps": 64, "batch_size": 256,
                "seed": 0, "agents": 4, "comm": 25.0, "resolution": 0.5,
                "checkpoint_every": 100_000},
}


def _parser(preset: str = "default") -> argparse.ArgumentParser:
    defaults = PPOTrainConfig()
    parser = argparse.ArgumentParser(
        prog="ipp-train ppo",
        description="Train a shared (parameter-sharing) PPO policy on the simulator.")
    parser.add_argument("--preset", choices=sorted(PPO_PRESETS), default="default",
                        help="start from these flags: 'shipped' retrains the shipped policy "
                             "(flags given explicitly win)")
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
    parser.add_argument("--workers", "--num-cpus", dest="num_cpus", type=int,
                        default=defaults.num_cpus, metavar="N",
                        help="SuperSuit worker processes (0: none; --num-cpus is the old name)")
    parser.add_argument("--checkpoint-every", type=int, default=defaults.checkpoint_every,
                        help="agent-transitions between checkpoints")
    parser.add_argument("--masked", action=argparse.BooleanOptionalAction,
                        default=defaults.masked, help="MaskablePPO (default) or plain PPO")
    parser.add_argument("--time-limit", type=float, default=None, metavar="MINUTES",
                        help="stop after this many minutes of training and save")
    parser.add_argument("--resume", action="store_true",
                        help="continue from OUT/checkpoint.pt")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(**PPO_PRESETS[preset])
    return parser


def main(argv: list[str] | None = None) -> int:
    """``ipp-train ppo [options]``; returns 0 on success, 2 on bad input."""
    known, _ = _parser().parse_known_args(argv)  # exits with status 2 on malformed options
    args = _parser(known.preset).parse_args(argv)
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
    except KeyboardInterrupt:
        return report_interrupt("ipp-train ppo", f"continue with --resume --out {args.out} "
                                "(from the last checkpoint)")
    print(f"saved {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
