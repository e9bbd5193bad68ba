"""COMA: counterfactual multi-agent policy gradients for the UAV team, top to bottom.

Read in order: the rollout (``coma.rollout``: missions in lock-step, a shared actor sampling
from the bounded softmax), the critic update (TD(lambda) targets per episode from a target
critic refreshed every ``target_update_transitions``), the advantage (``coma.advantages``),
the actor update (the paper's ``-log pi(u) A``, or with ``clip_ratio > 0`` PPO's clipped
surrogate), then logging, validation (``coma.validation``) and checkpoints. An optional warm
start (``coma.warm_start``) imitates a planner first. Hyper-parameters live in
:class:`COMAConfig`; the mission in an :class:`EnvConfig`. One COMA update is
:mod:`coma.update_step`'s :func:`update` (re-exported here); this module owns :func:`train`
(the run: start or resume, the update loop, logs, ``best.pt`` and ``last.pt``); ``coma.cli``
is the ``ipp-train coma`` command around it and ``coma.run_files`` keeps its progress log.

Reproducibility: mission k of a run always has the same terrain and sensor noise
(``ipp_toolkit.world.seeding``) and samples its actions from its own stream
(``coma.rollout.sampling_generator``); mini-batch shuffling draws from one torch Generator
whose state is checkpointed, so an interrupted run resumed with ``resume=True`` continues
exactly as if it had not stopped. The missions of an update may be flown by several workers
(``workers``, ``backend``: ``coma.parallel``) with the same result to the last bit; the update
runs in this process, on ``device`` (a GPU's numbers differ from the CPU's in rounding).
"""

from __future__ import annotations

import copy
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from ipp_toolkit.config.files import changed_fields, config_to_dict, env_config_changes
from ipp_toolkit.config.limits import check_rollout
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import CheckpointError, load_weights, write_json
from ipp_toolkit.runs.process_pool import limit_blas_threads, retain_freed_memory
from ipp_toolkit.runs.progress import progress_bar
from ipp_toolkit.runs.result_store import raster_digest
from ipp_toolkit.runs.run_folder import COMA_COMMAND, claim
from ipp_toolkit.sim.features import actor_plane_names, critic_plane_names
from ipp_toolkit.sim.mission import MissionGeometry

from .config import COMAConfig, mission_settings
from .networks import epsilon_at
from .parallel import (
    RunSpec,
    Workers,
    check_workers,
    make_workers,
    resolve_device,
    to_channels_last,
)
from .persistence import (
    COMANetworks,
    build_networks,
    check_network_size,
    load_policy,
    save_policy,
)
from .run_files import (
    TrainResult,
    check_counters,
    check_raster_record,
    read_progress,
    resume_fields,
    saved_update,
    write_progress,
)
from .update_step import TrainingDiverged, update
from .validation import reference_scores, validate, validation_settings
from .warm_start import WarmStartConfig
from .warm_start import warm_start as imitate

__all__ = ["TrainingDiverged", "update", "make_optimisers", "setting_of_update",
           "to_channels_last", "train"]


# --------------------------------------------------------------------------------------------
# Training run: state, checkpoints, logs


def setting_of_update(n_settings: int, seed: int, update: int) -> int:
    """Index of the mission setting that update ``update`` (0-based) trains on.

    Each block of ``n_settings`` consecutive updates visits every setting once, in an order
    drawn from ``(seed, block)``: balanced, reproducible and the same after a resume.
    """
    if n_settings == 1:
        return 0
    block, offset = divmod(update, n_settings)
    order = np.random.default_rng([seed, block, 0x5E77]).permutation(n_settings)
    return int(order[offset])


def _initialise_from(networks: COMANetworks, path: str) -> None:
    """Copy the actor and critic(s) of the policy file ``path`` into ``networks``."""
    source, _ = load_policy(path)
    if source.coma_config.variant != networks.coma_config.variant:
        raise CheckpointError(f"init_policy {path!r} is a {source.coma_config.variant!r} "
                              f"policy, this run trains {networks.coma_config.variant!r}")
    planes = actor_plane_names(source.env_config.features)
    wanted = actor_plane_names(networks.env_config.features)
    if planes != wanted or source.env_config.world.grid_points != \
            networks.env_config.world.grid_points:
        raise CheckpointError(f"init_policy {path!r} observes {planes} on a "
                              f"{source.env_config.world.grid_points}-point grid; this run's "
                              f"mission has {wanted} on {networks.env_config.world.grid_points}")
    for name in ("actor", "critic", "value"):
        module = getattr(networks, name)
        if module is not None:
            load_weights(module, getattr(source, name).state_dict(), path,
                         f"cannot restore the {name}")


def _move(networks: COMANetworks, device: torch.device) -> None:
    """Put the networks on ``device`` (nothing moves on the CPU)."""
    for module in (networks.actor, networks.critic, networks.value):
        if module is not None:
            module.to(device)


def make_optimisers(networks: COMANetworks) -> dict[str, torch.optim.Optimizer]:
    """Adam for the actor (``lr_actor``) and for the critic(s) (``lr_critic``)."""
    cfg = networks.coma_config
    optimisers = {"actor": torch.optim.Adam(networks.actor.parameters(), lr=cfg.lr_actor),
                  "critic": torch.optim.Adam(networks.critic.parameters(), lr=cfg.lr_critic)}
    if networks.value is not None:
        optimisers["value"] = torch.optim.Adam(networks.value.parameters(), lr=cfg.lr_critic)
    return optimisers


# What a run leaves that a new run would overwrite: refused unless resuming.
_RUN_FILES = ("last.pt", "best.pt", "warm_start.pt", "progress.csv")
_PROGRESS_KEYS = frozenset({"update", "missions", "transitions", "since_target", "best_entropy",
                            "best_update", "wall_s"})


def _resumable(last_path: Path, coma_config: COMAConfig, env_config: EnvConfig
               ) -> tuple[COMANetworks, dict[str, Any]]:
    """The checkpoint ``last_path`` (networks and payload), checked to belong to the run
    ``coma_config`` and ``env_config`` describe (only ``missions`` may differ).

    Raises:
        CheckpointError: the checkpoint is corrupt or belongs to another run.
    """
    networks, data = load_policy(last_path)
    progress = data.get("progress")
    missing = [key for key in ("target_critic", "optimisers", "generator", "progress")
               if key not in data]
    if missing or not isinstance(progress, dict) or not _PROGRESS_KEYS <= set(progress):
        raise CheckpointError(f"{str(last_path)!r} is a policy file (like best.pt), not a "
                              "training checkpoint: it lacks the training state "
                              f"({', '.join(missing) or 'progress counters'}); it cannot be "
                              "resumed")
    stored, wanted = resume_fields(networks.coma_config), resume_fields(coma_config)
    if stored != wanted:
        changed = ", ".join(changed_fields(stored, wanted))
        raise CheckpointError(f"checkpoint {str(last_path)!r} belongs to a run with other "
                              f"COMA settings ({changed}); give the run's settings, or start "
                              "a new folder instead")
    changes = env_config_changes(networks.env_config, env_config)
    if changes:
        raise CheckpointError(f"checkpoint {str(last_path)!r} was trained on another "
                              f"mission config ({', '.join(changes)}); start a new folder "
                              "instead")
    check_counters(last_path, progress, max(coma_config.missions, networks.coma_config.missions),
                   coma_config.missions_per_update)
    # A damaged or missing history is refused now, before any worker starts.
    read_progress(last_path.parent / "progress.csv", int(progress["update"]))
    return networks, data


def _resume(resumable: tuple[COMANetworks, dict[str, Any]], last_path: Path, csv_path: Path,
            coma_config: COMAConfig, generator: torch.Generator, device: torch.device
            ) -> tuple[COMANetworks, nn.Module, dict[str, torch.optim.Optimizer], dict[str, Any],
                       list[dict[str, Any]]]:
    """The run in ``last_path`` (loaded and checked by :func:`_resumable`) as it stopped:
    networks (in training mode, on ``device``), target critic, optimisers, progress counters
    and logged rows; ``generator`` gets its shuffling state. A run may resume on another
    device than it began on.

    Raises:
        CheckpointError: the checkpoint's target critic or optimisers cannot be restored.
    """
    networks, data = resumable
    to_channels_last(networks)
    networks.coma_config = coma_config
    for module in (networks.actor, networks.critic, networks.value):
        if module is not None:
            module.train()
    _move(networks, device)
    target_critic = copy.deepcopy(networks.critic)
    load_weights(target_critic, data["target_critic"], last_path,
                 "cannot restore the target critic")
    optimisers = make_optimisers(networks)
    for name, optimiser in optimisers.items():
        try:
            optimiser.load_state_dict(data["optimisers"][name])
        except (KeyError, ValueError) as error:
            raise CheckpointError(f"checkpoint {str(last_path)!r}: cannot restore the "
                                  f"{name} optimiser ({error})") from None
    generator.set_state(data["generator"])
    state = dict(data["progress"])
    return networks, target_critic, optimisers, state, read_progress(csv_path, state["update"])


def train(coma_config: COMAConfig, env_config: EnvConfig, out_dir: str | Path,
          resume: bool = False, progress: bool = True, tensorboard: bool = True,
          max_updates: int | None = None,
          warm_start: WarmStartConfig | None = None, workers: int = 1,
          backend: str = "local", address: str | None = None,
          device: str | torch.device = "cpu", announce: str = "") -> TrainResult:
    """Train COMA (or a variant) and write its run folder.

    The folder gets ``config.json`` (both configs, and the sha256 of a raster file the terrain
    reads, which a resume checks), ``progress.csv`` (one row per update),
    ``tb/`` (TensorBoard), ``last.pt`` (resumable training checkpoint, written every
    ``checkpoint_every`` updates and at the end) and ``best.pt`` (the policy with the lowest
    validation entropy so far).

    Args:
        coma_config: hyper-parameters.
        env_config: the training missions (use a coarse ``world.resolution`` for speed).
        out_dir: the run folder. A folder with a checkpoint is only continued with ``resume``.
        resume: continue from ``out_dir/last.pt``; the configs must match (``missions`` may
            grow).
        progress: show a tqdm bar.
        tensorboard: write TensorBoard event files.
        max_updates: stop after this many updates in this call (for tests and time slices).
        warm_start: on a fresh run, first imitate a planner (``coma.warm_start``; default:
            ``coma_config.warm_start``, if its planner is set); the imitated networks are saved as
            ``warm_start.pt`` and scored on validation missions (update 0). A run with
            ``coma_config.init_policy`` starts from that policy's networks instead (no warm
            start); they are scored and saved as ``best.pt`` at update 0 alike.
        workers: workers flying each update's missions and the validation missions
            (``coma.parallel``; 1: this process). The trained weights do not depend on it.
        backend: ``local`` (``workers`` spawned processes) or ``ray`` (``workers`` Ray
            actors of one CPU, on a local Ray or the cluster at ``address``).
        address: with the ray backend, the cluster's head (``HOST:PORT``); None starts a
            local Ray with ``workers`` CPUs (a process already connected to Ray keeps its
            connection).
        device: where the networks learn: ``cpu`` or ``cuda``; rollouts always fly on the
            CPU, with a CPU copy of the actor. The warm start imitates on the CPU.
        announce: a line printed to stderr once the run folder is checked, before any work
            (the command line's ``setting:`` line); nothing when empty.

    The calling process is set up as a trainer for good: one torch and BLAS thread, and
    (glibc) freed memory kept for reuse (:func:`~ipp_toolkit.runs.process_pool.retain_freed_memory`:
    an update's activations and a rollout's planes are tens of MB each, which glibc would
    otherwise hand back and fault in afresh, at least until its own threshold rises).

    With ``coma_config.team_sizes`` / ``comm_ranges``, each update trains on one setting of
    :func:`mission_settings` (:func:`setting_of_update`), and validation averages over all of
    them; ``progress.csv`` records each update's ``n_agents`` and ``comm_range``.

    Raises:
        TrainingDiverged: a loss became non-finite; ``last.pt`` and ``best.pt`` keep the last
            good state.
        CheckpointError: a checkpoint to resume is corrupt or belongs to another run, or the
            terrain's raster file was replaced since the run began.
        FileExistsError: ``out_dir`` holds a run and ``resume`` is false.
        ValueError: bad ``workers``, ``backend``, ``address`` or ``device`` (e.g. ``cuda``
            where there is none), before anything is written.
        ConnectionError: no Ray cluster answers at ``address``.
    """
    torch.set_num_threads(1)
    limit_blas_threads()
    retain_freed_memory()
    learner_device = resolve_device(device)
    check_workers(workers, backend, address)
    out = Path(out_dir)
    settings, checks, known = _check_missions(coma_config, env_config)
    raster_sha256 = raster_digest(env_config)  # recorded in config.json, checked on resume
    # Held for the whole run: a second run into the folder is refused, naming this process.
    with claim(out_dir, COMA_COMMAND):  # the given path: an empty one is refused
        if resume:
            check_raster_record(out, raster_sha256, env_config.terrain.raster)
        resumable = _check_folder(out, resume, coma_config, env_config)
        if announce:
            print(announce, file=sys.stderr)
        reference = _fly_reference(coma_config, checks, workers, address)
        spec = RunSpec(coma_config, env_config, tuple(settings), tuple(checks), coma_config.seed)
        with make_workers(spec, workers, backend, address, known) as pool:
            return _train_with(pool, coma_config, env_config, out, resumable, progress,
                               tensorboard, max_updates, warm_start, learner_device, settings,
                               checks, reference, raster_sha256)


def _check_missions(coma_config: COMAConfig, env_config: EnvConfig
                    ) -> tuple[list[EnvConfig], list[EnvConfig],
                               dict[tuple[str, int], MissionGeometry]]:
    """The training settings, the validation checks and the workers' mission geometries
    (built once here), refused (ValueError) before any worker starts or file is written."""
    if env_config.team.has_failures:
        raise ValueError("team.failures / team.random_failures: COMA does not train with UAV "
                         "failures yet (a failed UAV's transitions would be recorded); "
                         "evaluate a trained policy on them with ipp-compare instead")
    settings = mission_settings(coma_config, env_config)
    check_network_size(coma_config, env_config)
    for setting in settings:  # one update's missions are held at once: actor and critic inputs
        check_rollout(float(coma_config.missions_per_update) * setting.team.budget
                      * setting.team.n_agents, len(actor_plane_names(setting.features))
                      + len(critic_plane_names(setting.features)), setting.world.grid_points,
                      f"an update of {coma_config.missions_per_update} missions of "
                      f"{setting.team.n_agents} UAVs and budget {setting.team.budget}")
    geometries = [MissionGeometry(config) for config in settings]
    checks = validation_settings(coma_config, settings)
    # The checks' geometries are the settings' own objects where the checks are the settings.
    check_geometries = geometries if checks == settings else [
        MissionGeometry(config) for config in checks]
    known = {**{("train", k): g for k, g in enumerate(geometries)},
             **{("check", k): g for k, g in enumerate(check_geometries)}}
    return settings, checks, known


def _check_folder(out: Path, resume: bool, coma_config: COMAConfig, env_config: EnvConfig
                  ) -> tuple[COMANetworks, dict[str, Any]] | None:
    """Refuse a folder the run cannot go into (CheckpointError, FileExistsError); with
    ``resume``, the checkpoint to continue from (:func:`_resumable`)."""
    last_path = out / "last.pt"
    if resume and not last_path.exists():
        raise CheckpointError(f"nothing to resume: {str(last_path)!r} does not exist "
                              "(drop --resume to start a new run)")
    existing = [name for name in _RUN_FILES if (out / name).exists()]
    if existing and not resume:
        how = ("pass resume=True (--resume) to continue it" if last_path.exists() else
               "it stopped before its first checkpoint (no last.pt), so it cannot be "
               "resumed; move those files away")
        raise FileExistsError(f"{str(out)!r} already holds a run ({', '.join(existing)}): "
                              f"{how}, or choose another folder")
    # A checkpoint of another run is refused before anything flies or any worker starts.
    return _resumable(last_path, coma_config, env_config) if resume else None


def _fly_reference(coma_config: COMAConfig, checks: list[EnvConfig], workers: int,
                   address: str | None) -> list[float] | None:
    """IG's final entropies on the validation missions, with ``selection = worst_vs_ig``.

    IG's reference flies before the actors exist (they hold their CPUs for the whole run): on
    the cluster at ``address``, else in local processes (a local Ray of the run is not started
    yet, and would cost its start-up twice). check_workers has refused an address without
    the ray backend.
    """
    if coma_config.selection != "worst_vs_ig":
        return None
    return reference_scores(
        checks, coma_config.seed, coma_config.eval_missions,
        workers=workers if address is not None else min(workers, os.cpu_count() or 1),
        backend="local" if address is None else "ray", address=address)


def _train_with(pool: Workers, coma_config: COMAConfig, env_config: EnvConfig, out: Path,
                resumable: tuple[COMANetworks, dict[str, Any]] | None, progress: bool,
                tensorboard: bool, max_updates: int | None,
                warm_start: WarmStartConfig | None, device: torch.device,
                settings: list[EnvConfig], checks: list[EnvConfig],
                reference: list[float] | None, raster_sha256: str | None) -> TrainResult:
    """The run of :func:`train` once its inputs are checked: ``pool`` flies the missions of
    the training ``settings`` and the validation ``checks``, the networks learn on
    ``device``; ``resumable`` is the checkpoint to continue from (:func:`_resumable`), if any."""
    run = _Run(pool, coma_config, env_config, out, settings, checks, reference, raster_sha256)
    generator = torch.Generator().manual_seed(coma_config.seed)
    if resumable is not None:
        learning = _Learning(*_resume(resumable, run.last_path, run.csv_path, coma_config,
                                      generator, device), generator)
    else:
        learning = run.start(warm_start, generator, device, progress)
    writer = None
    if tensorboard:
        from torch.utils.tensorboard import SummaryWriter

        writer = SummaryWriter(str(out / "tb"), purge_step=learning.state["update"] + 1)
    total_updates = math.ceil(coma_config.missions / coma_config.missions_per_update)
    label = coma_config.variant + ("" if coma_config.precision == "float32"
                                   else f", {coma_config.precision}")
    bar = progress_bar(total_updates, f"COMA ({label})", "updates",
                       initial=learning.state["update"], disable=not progress)
    try:
        run.loop(learning, total_updates, max_updates, writer, bar)
    finally:
        bar.close()
        if writer is not None:
            writer.close()
    state = learning.state
    return TrainResult(out, run.best_path, run.last_path, state["update"], state["missions"],
                       state["best_entropy"], learning.history)


@dataclass
class _Learning:
    """What the run carries from update to update; ``last.pt`` holds all of it but the
    ``history`` (``progress.csv``'s rows)."""

    networks: COMANetworks
    target_critic: nn.Module
    optimisers: dict[str, torch.optim.Optimizer]
    state: dict[str, Any]  # the progress counters
    history: list[dict[str, Any]]
    generator: torch.Generator  # mini-batch shuffling


class _Run:
    """The steps of a run whose inputs are checked: start, validate, update, checkpoint.

    ``pool`` flies the missions of the training ``settings`` and the validation ``checks``;
    ``reference`` is IG's validation scores with ``selection = worst_vs_ig``, else None;
    ``raster_sha256`` the digest of the terrain's raster file that ``config.json`` records.
    """

    def __init__(self, pool: Workers, coma_config: COMAConfig, env_config: EnvConfig,
                 out: Path, settings: list[EnvConfig], checks: list[EnvConfig],
                 reference: list[float] | None, raster_sha256: str | None = None) -> None:
        self.pool, self.coma_config, self.env_config = pool, coma_config, env_config
        self.out = out
        self.settings, self.checks, self.reference = settings, checks, reference
        self.last_path, self.best_path = out / "last.pt", out / "best.pt"
        self.csv_path = out / "progress.csv"
        self.budget = env_config.team.budget
        self.raster_sha256 = raster_sha256  # of the raster file the terrain reads, if any

    def criterion(self, scores: dict[str, float]) -> float:
        """What best.pt minimises: the mean final entropy, or the worst gap to IG."""
        return (scores["gap_worst"] if self.reference is not None
                else scores[f"entropy_{self.budget}"])

    def validate(self, networks: COMANetworks) -> dict[str, float]:
        """The actor's validation scores, its missions flown by the pool's workers."""
        cfg = self.coma_config
        networks.actor.eval()
        try:
            return validate(networks.actor, self.checks, None, cfg.seed, cfg.eval_missions,
                            self.reference, fly=lambda k, n: self.pool.greedy(networks, k, n))
        finally:
            networks.actor.train()

    def start(self, warm_start: WarmStartConfig | None,
              generator: torch.Generator, device: torch.device, progress: bool) -> _Learning:
        """A fresh run: new networks, started from ``init_policy``, a warm start or the
        gain prior as the config asks, on ``device``; writes ``config.json``."""
        cfg, env_config = self.coma_config, self.env_config
        torch.manual_seed(cfg.seed)
        networks = build_networks(cfg, env_config)
        to_channels_last(networks)
        state = {"update": 0, "missions": 0, "transitions": 0, "since_target": 0,
                 "best_entropy": math.inf, "best_update": 0, "wall_s": 0.0}
        run_info: dict[str, Any] = {"coma": cfg.to_dict(), "env": config_to_dict(env_config)}
        if self.raster_sha256 is not None:
            run_info["raster_sha256"] = self.raster_sha256
        if self.reference is not None:
            run_info["validation_reference"] = {
                "planner": "ig", "terrains": [c.terrain.kind for c in self.checks],
                "resolutions": [c.world.resolution for c in self.checks],
                "final_entropy": self.reference}
        if warm_start is None and cfg.warm_start.enabled:
            warm_start = cfg.warm_start
        if cfg.init_policy:
            _initialise_from(networks, cfg.init_policy)
            run_info["init_policy"] = {"path": cfg.init_policy,
                                       **self.score_start(networks, state)}
        elif warm_start is not None:
            tick = time.perf_counter()
            scores = imitate(networks, env_config, warm_start, cfg.seed, generator, progress)
            scores["seconds"] = time.perf_counter() - tick
            scores.update(self.score_start(networks, state))
            save_policy(self.out / "warm_start.pt", networks, {"warm_start": scores})
            run_info["warm_start"] = {**warm_start.to_dict(), "result": scores}
        elif cfg.gain_prior > 0:
            # The gain-prior actor starts as a planner worth scoring (ig's choice).
            run_info["gain_prior_start"] = self.score_start(networks, state)
        _move(networks, device)  # the warm start imitated on the CPU
        target_critic = copy.deepcopy(networks.critic)
        optimisers = make_optimisers(networks)
        write_json(self.out / "config.json", run_info)
        return _Learning(networks, target_critic, optimisers, state, [], generator)

    def score_start(self, networks: COMANetworks, state: dict[str, Any]) -> dict[str, float]:
        """Validate the starting networks; they are ``best.pt`` at update 0."""
        validation = self.validate(networks)
        state["best_entropy"] = self.criterion(validation)
        save_policy(self.best_path, networks, {"validation": validation, "update": 0})
        return {"validation_entropy": validation[f"entropy_{self.budget}"],
                "validation_f1": validation[f"f1_{self.budget}"]}

    def loop(self, learning: _Learning, total_updates: int, max_updates: int | None,
             writer: Any, bar: Any) -> None:
        """Update until ``total_updates`` (or ``max_updates`` in this call), validating every
        ``eval_every`` and checkpointing every ``checkpoint_every`` updates and at the end."""
        cfg, state = self.coma_config, learning.state
        updates_this_call = 0
        while state["update"] < total_updates and (max_updates is None
                                                   or updates_this_call < max_updates):
            row = self.one_update(learning)
            last_update = state["update"] == total_updates
            if state["update"] % cfg.eval_every == 0 or last_update:
                self.validate_update(learning, row)
            learning.history.append(row)
            if writer is not None:
                for key, value in row.items():
                    if key != "update" and value is not None:
                        writer.add_scalar(f"coma/{key}", value, state["update"])
            updates_this_call += 1
            if state["update"] % cfg.checkpoint_every == 0 or last_update:
                self.save_checkpoint(learning)
            bar.update(1)
            bar.set_postfix(ret=f"{row['return_mean']:.2f}", eps=f"{row['eps']:.2f}",
                            val_H=f"{state['best_entropy']:.3f}")
        if updates_this_call and (state["update"] % cfg.checkpoint_every):
            self.save_checkpoint(learning)

    def one_update(self, learning: _Learning) -> dict[str, Any]:
        """Fly one update's missions and learn on them; its ``progress.csv`` row."""
        cfg, state, networks = self.coma_config, learning.state, learning.networks
        tick = time.perf_counter()
        eps = epsilon_at(state["missions"], cfg.eps_start, cfg.eps_end, cfg.eps_anneal_missions)
        # The authors' targets come from the critic's random start, never refreshed.
        if state["since_target"] >= cfg.target_update_transitions \
                and cfg.critic_targets != "reference":
            learning.target_critic.load_state_dict(networks.critic.state_dict())
            state["since_target"] = 0
        setting = setting_of_update(len(self.settings), cfg.seed, state["update"])
        rollout = self.pool.rollout(networks, setting, state["missions"],
                                    cfg.missions_per_update, eps)
        try:
            losses = update(networks, learning.target_critic, learning.optimisers, rollout, eps,
                            learning.generator,
                            train_actor=state["update"] >= cfg.critic_warmup_updates)
        except TrainingDiverged as error:
            raise TrainingDiverged(
                f"{error} at update {state['update'] + 1}; training stopped. The last "
                f"good checkpoint is kept: {str(self.last_path)!r} (update "
                f"{saved_update(self.last_path)}); lower the learning rates or check the "
                "rewards") from None
        elapsed = time.perf_counter() - tick
        state["update"] += 1
        state["missions"] += cfg.missions_per_update
        state["transitions"] += rollout.transitions
        state["since_target"] += rollout.transitions
        state["wall_s"] += elapsed
        return {"update": state["update"], "missions": state["missions"],
                "transitions": state["transitions"], "eps": eps,
                "return_mean": float(rollout.returns.mean()),
                "final_entropy_mean": float(rollout.final_entropy.mean()),
                **losses, "transitions_per_s": rollout.transitions / elapsed,
                "wall_s": state["wall_s"], "n_agents": self.settings[setting].team.n_agents,
                "comm_range": self.settings[setting].team.comm_range}

    def validate_update(self, learning: _Learning, row: dict[str, Any]) -> None:
        """Score the actor into ``row``; a new best is saved as ``best.pt``."""
        state = learning.state
        scores = self.validate(learning.networks)
        row.update(eval_return=scores["return"],
                   eval_entropy_final=scores[f"entropy_{self.budget}"],
                   eval_f1_final=scores[f"f1_{self.budget}"],
                   eval_gap_worst=scores.get("gap_worst"))
        if self.criterion(scores) < state["best_entropy"]:
            state["best_entropy"] = self.criterion(scores)
            state["best_update"] = state["update"]
            save_policy(self.best_path, learning.networks, {"validation": scores,
                                                            "update": state["update"]})

    def save_checkpoint(self, learning: _Learning) -> None:
        """``progress.csv``, then ``last.pt`` (networks, target critic, optimisers, shuffling
        state, counters). In this order a run stopped between the two writes leaves rows
        ahead of the checkpoint, which a resume drops (:func:`coma.run_files.read_progress`),
        never a checkpoint ahead of its rows."""
        write_progress(self.csv_path, learning.history)
        save_policy(self.last_path, learning.networks, {
            "target_critic": learning.target_critic.state_dict(),
            "optimisers": {k: o.state_dict() for k, o in learning.optimisers.items()},
            "generator": learning.generator.get_state(),
            "progress": dict(learning.state),
        })
