"""The Ray side of ``ipp-train rllib``: the algorithm's config, the loop, checkpoints, logs.

Imported by :func:`baselines.rllib.training.train_rllib` once RLlib is known to import; see
that module for the run folder's files. Seeds: the run seed seeds RLlib (weights, sampling);
the env copies fly missions of runs ``seed + done + w * envs_per_runner + v``
(:class:`baselines.rllib.module.IPPMultiAgentEnv`), ``done`` being the agent-steps trained
before a resume (0 for a fresh run), so a resumed run flies new missions, reproducibly.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import sys
import time
from pathlib import Path
from typing import Any

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import temporary_path, write_json
from ipp_toolkit.runs.process_pool import limit_blas_threads
from ipp_toolkit.runs.progress import progress_bar
from ipp_toolkit.runs.ray_backend import session
from ipp_toolkit.runs.run_folder import claim

from .module import (
    ENV_NAME,
    SHARED_POLICY,
    IPPMaskedRLModule,
    TeamMetricsCallback,
    make_env,
)
from .policy import RLlibPolicyFile, save_rllib_policy
from .train_config import RLlibTrainConfig, env_record, same_run

__all__ = ["algorithm_config", "run"]

_STATE = "ipp_state.json"
"""The toolkit's record inside an RLlib checkpoint folder (configs, counts, seconds)."""


def algorithm_config(config: RLlibTrainConfig, env_cfg: EnvConfig, base_seed: int) -> Any:
    """The RLlib ``AlgorithmConfig`` of a run (new API stack, one shared RLModule)."""
    from ray.rllib.algorithms.appo import APPOConfig
    from ray.rllib.algorithms.impala import IMPALAConfig
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec
    from ray.tune.registry import register_env

    # Again, with Ray's public call: .module registers at import and at every ray.init()
    # through a private hook of Ray's, which a later Ray may lack.
    register_env(ENV_NAME, make_env)
    config_class = {"PPO": PPOConfig, "APPO": APPOConfig, "IMPALA": IMPALAConfig}[config.algo]
    rl_config = (
        config_class()
        # The Dict observation, whatever features.observation says: IPPMaskedRLModule reads
        # the planes and the mask from it.
        .environment(ENV_NAME, env_config={"env": env_record(env_cfg), "observation": "dict",
                                           "base_seed": base_seed,
                                           "envs_per_runner": config.envs_per_runner},
                     disable_env_checking=True)
        .framework("torch")
        .env_runners(num_env_runners=config.num_env_runners,
                     num_envs_per_env_runner=config.envs_per_runner,
                     num_cpus_per_env_runner=1, gym_env_vectorize_mode="sync")
        .learners(num_learners=0)
        .multi_agent(policies={SHARED_POLICY},
                     policy_mapping_fn=lambda agent_id, episode, **kwargs: SHARED_POLICY)
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={
            SHARED_POLICY: RLModuleSpec(module_class=IPPMaskedRLModule,
                                        model_config=config.model_config())}))
        .training(lr=config.lr, gamma=config.gamma,
                  train_batch_size_per_learner=config.train_batch)
        .callbacks(TeamMetricsCallback)
        # One iteration = one --train-batch of team steps for every algorithm: APPO and
        # IMPALA otherwise default to iterations of at least 10 s each (RLlib's
        # min_time_s_per_iteration), however little they sampled.
        .reporting(metrics_num_episodes_for_smoothing=100, min_time_s_per_iteration=0,
                   min_sample_timesteps_per_iteration=config.train_batch)
        .debugging(seed=config.seed, log_level="ERROR")
    )
    if config.algo == "PPO":
        rl_config.training(minibatch_size=min(256, config.train_batch), num_epochs=4)
    return rl_config


def _swap_in(folder: Path, write: Any) -> None:
    """Write a checkpoint folder beside ``folder`` with ``write(tmp)``, then rename it into
    place (the old one is removed only once the new one is there)."""
    tmp = temporary_path(folder)
    old = folder.with_name(f"{folder.name}.old")
    try:
        write(tmp)
        if folder.exists():
            if old.exists():
                shutil.rmtree(old)
            os.replace(folder, old)
        os.replace(tmp, folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    shutil.rmtree(old, ignore_errors=True)


def _agent_steps(result: dict[str, Any]) -> int:
    """Agent-steps (UAV transitions) sampled in one iteration, from its ``train()`` result."""
    value = result.get("env_runners", {}).get("num_module_steps_sampled", {})
    if isinstance(value, dict):
        return int(sum(float(v) for v in value.values()))
    return int(value)


def _scalars(result: dict[str, Any]) -> dict[str, float]:
    """The TensorBoard scalars of one iteration's result (absent ones are left out)."""
    runners = result.get("env_runners", {})
    learner = result.get("learners", {}).get(SHARED_POLICY, {})
    wanted = {"rollout/ep_rew_mean": runners.get("team_return"),
              "rollout/final_entropy": runners.get("final_entropy"),
              "rollout/final_f1": runners.get("final_f1"),
              "rollout/rllib_episode_return_mean": runners.get("episode_return_mean"),
              "rollout/ep_len_mean": runners.get("episode_len_mean"),
              "train/policy_loss": learner.get("policy_loss"),
              "train/value_loss": learner.get("vf_loss"),
              "train/entropy": learner.get("entropy")}
    out = {}
    for key, value in wanted.items():
        with contextlib.suppress(TypeError, ValueError):
            out[key] = float(value)
    return out


def run(config: RLlibTrainConfig, env_cfg: EnvConfig, out_dir: Path, *, address: str | None,
        progress: bool, resume: bool, time_limit_s: float | None, command: str | None,
        announce: str) -> Path:
    """:func:`baselines.rllib.training.train_rllib` after its checks (see there)."""
    with claim(out_dir, f"ipp-train rllib --algo {config.algo}") as folder:
        out = folder.path
        ckpt = out / "checkpoint"
        record: dict[str, Any] | None = None
        if resume:
            if not (ckpt / _STATE).is_file():
                raise ValueError(f"nothing to resume: {str(ckpt)!r} does not exist (drop "
                                 "--resume to start a new run)")
            record = json.loads((ckpt / _STATE).read_text(encoding="utf-8"))
            same_run(config, env_cfg, record, str(ckpt))
        elif ckpt.exists() or (out / "policy.pt").exists():
            raise ValueError(f"{str(out)!r} already holds an RLlib run; pass --resume or "
                             "choose another output folder")
        if announce:
            print(announce, file=sys.stderr)
        with session(address, config.num_env_runners + 1):
            return _train(config, env_cfg, out, record, progress, time_limit_s, command)


def _train(config: RLlibTrainConfig, env_cfg: EnvConfig, out: Path,
           record: dict[str, Any] | None, progress: bool, time_limit_s: float | None,
           command: str | None) -> Path:
    """Build (or restore) the algorithm and run the iterations left."""
    import torch
    from torch.utils.tensorboard import SummaryWriter

    torch.set_num_threads(1)  # two shared cores: more intra-op threads collapse throughput
    limit_blas_threads()

    done_iters = int(record["iteration"]) if record else 0
    done_steps = int(record["agent_steps"]) if record else 0
    seconds_before = float(record["train_seconds"]) if record else 0.0
    algo = algorithm_config(config, env_cfg, config.seed + done_steps).build_algo()
    if record is not None:
        algo.restore_from_path(str(out / "checkpoint"))
    tb_root = out / "tb"
    runs = len(list(tb_root.glob(f"{config.algo.lower()}_*"))) if tb_root.is_dir() else 0
    writer = SummaryWriter(str(tb_root / f"{config.algo.lower()}_{runs + 1}"))
    started = time.perf_counter()
    extra = {} if command is None else {"command": command}
    state = {"iteration": done_iters, "agent_steps": done_steps}

    def save() -> None:
        seconds = seconds_before + time.perf_counter() - started
        mine = {"rllib_config": config.to_dict(), "env_config": env_record(env_cfg),
                "train_seconds": round(seconds, 1), **state, **extra}

        def write(tmp: Path) -> None:
            algo.save_to_path(str(tmp))
            write_json(tmp / _STATE, mine)

        _swap_in(out / "checkpoint", write)
        write_json(out / "checkpoint.json", mine)
        module = algo.get_module(SHARED_POLICY)
        save_rllib_policy(out / "policy.pt", module.net, RLlibPolicyFile(
            algo=config.algo, architecture=module.architecture, env_config=env_cfg,
            agent_steps=state["agent_steps"], iteration=state["iteration"]),
            train_seconds=round(seconds, 1), **extra)

    bar = progress_bar(config.iterations, f"rllib-{config.algo.lower()}", "it",
                       initial=done_iters, disable=not progress)
    try:
        while state["iteration"] < config.iterations:
            result = algo.train()
            state["iteration"] += 1
            state["agent_steps"] += _agent_steps(result)
            for key, value in _scalars(result).items():
                writer.add_scalar(key, value, state["agent_steps"])
            elapsed = time.perf_counter() - started
            writer.add_scalar("time/agent_steps_per_s",
                              (state["agent_steps"] - done_steps) / max(elapsed, 1e-9),
                              state["agent_steps"])
            writer.flush()
            bar.update(1)
            team = _scalars(result).get("rollout/ep_rew_mean")
            if team is not None and hasattr(bar, "set_postfix"):
                bar.set_postfix(agent_steps=state["agent_steps"], team_return=f"{team:.2f}")
            if state["iteration"] % config.checkpoint_every == 0:
                save()
            if time_limit_s is not None and elapsed >= time_limit_s:
                break
        save()
    finally:
        bar.close()
        writer.close()
        algo.stop()
    return out / "policy.pt"
