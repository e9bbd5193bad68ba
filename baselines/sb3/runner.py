"""The training run every SB3 algorithm shares: files, resume, callbacks and the learn loop.

:func:`run_sb3_training` is the one loop behind ``ipp-train ppo``
(:mod:`baselines.sb3.ppo_training`) and ``ipp-train sb3`` (:mod:`baselines.sb3.training`). A
caller says how to build the vec env and the model and what a policy file holds; this module
does the rest, identically for every algorithm:

* ``OUT/checkpoint.pt`` (+ ``.json``): the policy's state dict, its optimiser state, the step
  and episode counts and the training seconds, written atomically every
  ``checkpoint_every`` agent-transitions and at the end; ``resume=True`` carries on from it
  (its configs must match the given ones, and a raster file the terrain reads must be the
  one it began on: its sha256 is recorded in every checkpoint and policy);
* ``OUT/policy.pt`` (+ ``.json``): the final policy (state dict + records), written atomically;
* ``OUT/tb/``: TensorBoard logs: SB3's own (``rollout/ep_rew_mean`` counts one episode per
  UAV slot) and the task's, ``rollout/final_entropy`` and ``rollout/final_f1`` of the
  missions flown;
* progress (tqdm on a terminal, a short line every few percent in a log), and a time limit
  that stops training and saves what was learnt.

Seeds: a fresh run starts copy c of the simulator on run ``seed + c``; a run resumed after
``done`` transitions uses ``seed + done`` (new missions, reproducible). Nothing here is
imported by the planners.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from sb3_contrib import ARS
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv, VecMonitor

from ipp_toolkit.config.files import check_same_run, config_from_dict
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import load_torch, save_checkpoint
from ipp_toolkit.runs.process_pool import limit_blas_threads, retain_freed_memory
from ipp_toolkit.runs.progress import progress_bar
from ipp_toolkit.runs.result_store import check_raster_unchanged, raster_digest
from ipp_toolkit.runs.run_folder import claim

__all__ = ["RunFormat", "run_sb3_training", "progress_callback", "task_metrics_callback",
           "time_limit_callback",
           "checkpoint_callback"]


# --------------------------------------------------------------------------------------------
# Callbacks


def progress_callback(total: int, initial: int, desc: str = "ppo") -> BaseCallback:
    """Progress over agent-transitions: a tqdm bar on a terminal, a short line every few
    percent in a log (:func:`ipp_toolkit.runs.progress.progress_bar`; SB3's own bar needs
    ``rich``)."""

    class TqdmCallback(BaseCallback):
        def _on_training_start(self) -> None:
            self.bar = progress_bar(total, desc, "steps", initial=initial)

        def _on_step(self) -> bool:
            self.bar.update(self.model.num_timesteps - self.bar.n)
            return True

        def _on_training_end(self) -> None:
            self.bar.close()

    return TqdmCallback()


def task_metrics_callback() -> BaseCallback:
    """Logs the task's own scores of every finished training mission to TensorBoard (as COMA
    does): ``rollout/final_entropy`` and ``rollout/final_f1``, means over the missions that
    ended since the last dump. SB3's ``rollout/ep_rew_mean`` counts one episode per UAV slot
    (each slot gets the team reward); these count each mission's global map once per slot as
    well, which leaves the mean unchanged."""

    class TaskMetrics(BaseCallback):
        def _on_step(self) -> bool:
            infos, dones = self.locals.get("infos"), self.locals.get("dones")
            if infos is None or dones is None:  # ARS: one slot's (info, done) at a time
                info, done = self.locals.get("info"), self.locals.get("done")
                infos, dones = ([], []) if info is None else ([info], [done])
            for info, done in zip(infos, dones, strict=False):
                if done and "entropy" in info:
                    self.logger.record_mean("rollout/final_entropy", float(info["entropy"]))
                    self.logger.record_mean("rollout/final_f1", float(info["f1"]))
            return True

    return TaskMetrics()


class ReportingARS(ARS):
    """sb3-contrib's ARS whose candidate evaluations hand each step's locals (the slot's
    ``info`` and ``done``) to the callbacks, as the other algorithms' rollouts do, so
    :func:`task_metrics_callback` logs ARS's final entropy and F1 too (ARS alone steps its
    callbacks without them)."""

    def _trigger_callback(self, _locals: dict[str, Any], _globals: dict[str, Any],
                          callback: BaseCallback, n_envs: int) -> None:
        callback.update_locals(_locals)
        super()._trigger_callback(_locals, _globals, callback, n_envs)


def time_limit_callback(deadline: float) -> BaseCallback:
    """Stops training once ``deadline`` (a ``time.perf_counter`` time) has passed.

    Returning False from a step ends SB3's rollout (on-policy: the partial rollout is not
    trained on; off-policy: the collection) and ``learn``.
    """

    class TimeLimitCallback(BaseCallback):
        def _on_step(self) -> bool:
            return time.perf_counter() < deadline

    return TimeLimitCallback()


def checkpoint_callback(every: int, save: Callable[[], None]) -> BaseCallback:
    """Calls ``save`` every ``every`` agent-transitions."""

    class CheckpointCallback(BaseCallback):
        def _on_training_start(self) -> None:
            self.next_save = (self.model.num_timesteps // every + 1) * every

        def _on_step(self) -> bool:
            if self.model.num_timesteps >= self.next_save:
                save()
                self.next_save = (self.model.num_timesteps // every + 1) * every
            return True

    return CheckpointCallback()


# --------------------------------------------------------------------------------------------
# The run


@dataclass(frozen=True)
class RunFormat:
    """How one trainer names and tags its files.

    Attributes:
        algo_label: the algorithm in messages ("already holds a PPO run") and the progress bar.
        policy_kind: format tag of ``policy.pt`` (``ipp_toolkit.io.save_checkpoint``).
        training_kind: format tag of ``checkpoint.pt``.
        metadata: ``(payload, extra) -> JSON record`` of a file (the payload without weights).
        tb_log_name: TensorBoard run name under ``OUT/tb``.
    """

    algo_label: str
    policy_kind: str
    training_kind: str
    metadata: Callable[..., dict[str, Any]]
    tb_log_name: str

    @property
    def command(self) -> str:
        """The command recorded in the run folder (``ipp_toolkit.runs.run_folder``)."""
        return ("ipp-train ppo" if self.algo_label == "PPO"
                else f"ipp-train sb3 --algo {self.algo_label}")


def same_run_check(config: Any, env_config: EnvConfig, key: str, what: str
                   ) -> Callable[[dict[str, Any], Path], None]:
    """The ``check_resume`` of a trainer whose config dataclass is stored under ``key``.

    A checkpoint resumes only a run of the same config (``total_timesteps`` may change) on the
    same env config; otherwise ValueError naming the file.
    """
    def check(state: dict[str, Any], ckpt_path: Path) -> None:
        check_same_run(str(ckpt_path), what, type(config).from_dict(state[key]), config,
                       "total_timesteps", config_from_dict(state["env_config"]), env_config)
    return check


def run_sb3_training(
    *,
    out_dir: str | Path,
    run_format: RunFormat,
    seed: int,
    total_timesteps: int,
    checkpoint_every: int,
    make_env: Callable[[int], VecEnv],
    make_model: Callable[[VecEnv, int, str, int], Any],
    payload: Callable[[Any], dict[str, Any]],
    check_resume: Callable[[dict[str, Any], Path], None],
    extra_record: dict[str, Any] | None = None,
    progress: bool = True,
    resume: bool = False,
    time_limit_s: float | None = None,
    announce: str = "",
    env_config: EnvConfig | None = None,
) -> Path:
    """Train (fresh, or resumed from ``out_dir/checkpoint.pt``) and write ``out_dir/policy.pt``.

    The calling process is set up as a trainer for good: one torch and BLAS thread, and
    (glibc) freed memory kept for reuse
    (:func:`~ipp_toolkit.runs.process_pool.retain_freed_memory`).

    Args:
        out_dir: the run folder (created).
        run_format: file tags and names of this trainer.
        seed: the run seed; copy c starts on run ``seed + done + c``.
        total_timesteps: agent-transitions of the whole run (a resumed run trains the rest).
        checkpoint_every: agent-transitions between checkpoints.
        make_env: ``env_seed -> vec env`` (an :class:`ipp_toolkit.vec.IPPVecEnv`; closed here).
        make_model: ``(env, env_seed, tensorboard folder, done) -> SB3 model`` on that env.
        payload: ``model -> dict`` of what a policy file holds (weights under ``"policy"``).
        check_resume: ``(checkpoint payload, path)``; raises ValueError when the stored
            configs differ from the given ones.
        extra_record: JSON-safe fields added to both JSON records (e.g. the command line).
        progress: show a tqdm bar.
        resume: continue from ``out_dir/checkpoint.pt``.
        time_limit_s: stop after this many seconds of this call and save what was learnt.
        announce: a line printed to stderr once the run folder is checked, before any work
            (the command line's ``setting:`` line); nothing when empty.
        env_config: the missions the run trains on: the sha256 of a raster file their terrain
            reads is recorded in every file (``raster_sha256``) and checked on a resume.

    Returns:
        the path of ``policy.pt``.

    Raises:
        ValueError: a bad time limit, an existing run without ``resume``, nothing to resume,
            a checkpoint whose configs differ (from ``check_resume``), or a raster file
            replaced since the run began (named with both digests).
        ipp_toolkit.io.CheckpointError: a corrupt or foreign ``checkpoint.pt``.
    """
    if time_limit_s is not None and (isinstance(time_limit_s, bool)
                                     or not isinstance(time_limit_s, int | float)
                                     or not time_limit_s > 0):
        raise ValueError(f"time_limit_s must be a positive number or None, got {time_limit_s!r}")
    torch.set_num_threads(1)  # two shared cores: more intra-op threads collapse throughput
    limit_blas_threads()
    retain_freed_memory()  # large freed buffers are reused, not faulted in anew
    raster = _Raster(None, None) if env_config is None else \
        _Raster(env_config.terrain.raster, raster_digest(env_config))
    # Held for the whole run: a second run into the folder is refused, naming this process.
    with claim(out_dir, run_format.command) as run:
        return _run_claimed(run.path, run_format, seed, total_timesteps, checkpoint_every,
                            make_env, make_model, payload, check_resume, extra_record,
                            progress, resume, time_limit_s, announce, raster)


@dataclass(frozen=True)
class _Raster:
    """The raster file a run's terrain reads and its sha256 (None, None: none)."""

    path: str | None
    sha256: str | None


def _restore(model: Any, state: dict[str, Any]) -> None:
    """Put a checkpoint's weights, optimizer and counters back into a fresh SB3 model."""
    model.policy.load_state_dict(state["policy"])
    if "optimizer" in state:  # ARS has none: it perturbs the weights directly
        model.policy.optimizer.load_state_dict(state["optimizer"])
    if isinstance(getattr(model, "weights", None), torch.Tensor):
        # ARS searches around its own flat copy of the weights: refresh it.
        model.weights = torch.nn.utils.parameters_to_vector(model.policy.parameters()).detach()
    model.num_timesteps = int(state["num_timesteps"])
    model._episode_num = int(state.get("episodes", 0))


def _resume_state(out_dir: Path, run_format: RunFormat,
                  check_resume: Callable[[dict[str, Any], Path], None], resume: bool,
                  raster: _Raster) -> dict[str, Any] | None:
    """The checkpoint to go on from (None: a new run), refused (ValueError) when there is
    none to resume, when a new run would overwrite one, or when it belongs to another run:
    other configs (``check_resume``), or another content of the raster file."""
    ckpt_path = out_dir / "checkpoint.pt"
    if not resume:
        if ckpt_path.exists() or (out_dir / "policy.pt").exists():
            raise ValueError(f"{str(out_dir)!r} already holds a {run_format.algo_label} run; "
                             "pass resume=True (--resume) or choose another output folder")
        return None
    if not ckpt_path.is_file():
        raise ValueError(f"nothing to resume: {str(ckpt_path)!r} does not exist (drop "
                         "--resume to start a new run)")
    state = load_torch(ckpt_path, run_format.training_kind)
    check_resume(state, ckpt_path)
    check_raster_unchanged(state.get("raster_sha256"), raster.sha256, raster.path,
                           f"checkpoint {str(ckpt_path)!r}")
    return state


def _run_claimed(out_dir: Path, run_format: RunFormat, seed: int, total_timesteps: int,
                 checkpoint_every: int, make_env: Callable[[int], VecEnv],
                 make_model: Callable[[VecEnv, int, str, int], Any],
                 payload: Callable[[Any], dict[str, Any]],
                 check_resume: Callable[[dict[str, Any], Path], None],
                 extra_record: dict[str, Any] | None, progress: bool, resume: bool,
                 time_limit_s: float | None, announce: str, raster: _Raster) -> Path:
    """:func:`run_sb3_training` once ``out_dir`` is claimed."""
    ckpt_path = out_dir / "checkpoint.pt"
    extra_record = dict(extra_record or {})
    state = _resume_state(out_dir, run_format, check_resume, resume, raster)

    def file_payload(model: Any) -> dict[str, Any]:
        """What a checkpoint or policy file holds: the trainer's payload and the raster's
        digest (in the payload, which a resume reads; so in every JSON record too)."""
        data = payload(model)
        if raster.sha256 is not None:
            data["raster_sha256"] = raster.sha256
        return data

    if announce:
        print(announce, file=sys.stderr)

    done = int(state["num_timesteps"]) if state is not None else 0
    # A resumed run starts new missions: copy c continues on run seed + done + c.
    env_seed = seed + done
    venv = make_env(env_seed)
    model = None
    try:
        model = make_model(VecMonitor(venv), env_seed, str(out_dir / "tb"), done)
        if state is not None:
            _restore(model, state)
        started = time.perf_counter()
        elapsed_before = float(state.get("train_seconds", 0.0)) if state is not None else 0.0

        def seconds() -> float:
            return elapsed_before + time.perf_counter() - started

        def checkpoint_now() -> None:
            data = file_payload(model)
            optimizer = getattr(model.policy, "optimizer", None)
            if optimizer is not None:
                data["optimizer"] = optimizer.state_dict()
            data["episodes"] = int(model._episode_num)
            data["train_seconds"] = seconds()
            save_checkpoint(ckpt_path, data, run_format.training_kind,
                            run_format.metadata(data, train_seconds=data["train_seconds"],
                                                **extra_record))

        callbacks = [checkpoint_callback(checkpoint_every, checkpoint_now),
                     task_metrics_callback()]
        if progress:
            callbacks.append(progress_callback(total_timesteps, done,
                                               run_format.tb_log_name))
        if time_limit_s is not None:
            callbacks.append(time_limit_callback(started + time_limit_s))
        remaining = total_timesteps - done
        if remaining > 0:
            model.learn(total_timesteps=remaining, callback=callbacks,
                        reset_num_timesteps=state is None, tb_log_name=run_format.tb_log_name)
        checkpoint_now()
        final = file_payload(model)
        policy_path = out_dir / "policy.pt"
        return save_checkpoint(policy_path, final, run_format.policy_kind,
                               run_format.metadata(final, train_seconds=round(seconds(), 1),
                                                   **extra_record))
    finally:
        # SB3 leaves its TensorBoard writer (a thread with an open file) running after learn.
        if getattr(model, "_logger", None) is not None:
            model.logger.close()
        venv.close()
