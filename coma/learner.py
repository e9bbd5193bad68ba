"""COMA: counterfactual multi-agent policy gradients for the UAV team, top to bottom.

Read in order: the rollout (``coma.rollout``: missions in lock-step, a shared actor sampling
from the bounded softmax), the critic update (TD(lambda) targets per episode from a target
critic refreshed every ``target_update_transitions``), the advantage (``coma.advantages``),
the actor update (the paper's ``-log pi(u) A``, or with ``clip_ratio > 0`` PPO's clipped
surrogate), then logging, validation (``coma.validation``) and checkpoints. An optional warm
start (``coma.warm_start``) imitates a planner first. Hyper-parameters live in
:class:`COMAConfig`; the mission in an :class:`EnvConfig`. This module owns :func:`update`
(one COMA update) and :func:`train` (the run: start or resume, the update loop, logs,
``best.pt`` and ``last.pt``); ``coma.cli`` is the ``ipp-train coma`` command around it and
``coma.run_files`` keeps its progress log.

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
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from ipp_toolkit.config.files import config_to_dict
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import CheckpointError, write_json
from ipp_toolkit.runs.process_pool import limit_blas_threads, retain_freed_memory
from ipp_toolkit.runs.progress import progress_bar
from ipp_toolkit.runs.run_folder import COMA_COMMAND, claim
from ipp_toolkit.sim.features import actor_plane_names
from ipp_toolkit.sim.mission import MissionGeometry
from ipp_toolkit.sim.team import N_ACTIONS

from .advantages import central_value_advantage, counterfactual_advantage, td_lambda_targets
from .config import COMAConfig, mission_settings
from .networks import (
    GainPriorActor,
    bounded_softmax,
    epsilon_at,
    in_input_layout,
    learning_forward,
    mixed_precision,
)
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
    load_state_into,
    save_policy,
)
from .rollout import Rollout
from .run_files import (
    TrainResult,
    read_progress,
    resume_fields,
    saved_update,
    write_progress,
)
from .validation import reference_scores, validate, validation_settings
from .warm_start import WarmStartConfig
from .warm_start import warm_start as imitate

__all__ = ["TrainingDiverged", "update", "make_optimisers", "setting_of_update",
           "to_channels_last", "train"]


class TrainingDiverged(RuntimeError):
    """A loss became NaN or infinite; the last good checkpoint is kept."""


# --------------------------------------------------------------------------------------------
# One update: critic(s) on TD(lambda) targets, then the actor on the advantage


def _clip_step(optimiser: torch.optim.Optimizer, module: nn.Module, loss: torch.Tensor,
               max_norm: float) -> float:
    optimiser.zero_grad(set_to_none=True)
    loss.backward()
    norm = nn.utils.clip_grad_norm_(module.parameters(), max_norm)
    optimiser.step()
    return float(norm)


def update(networks: COMANetworks, target_critic: nn.Module, optimisers: dict[str, Any],
           rollout: Rollout, eps: float, generator: torch.Generator,
           train_actor: bool = True) -> dict[str, float]:
    """One COMA update on a rollout; returns the mean losses and diagnostics.

    ``train_actor=False`` fits only the critic(s) (a critic warm-up): the actor, its
    optimiser and its diagnostics are left alone. The update runs where the networks are: a
    CPU rollout is moved to their device (on the CPU it is used as it is); ``generator``
    (shuffling) is a CPU generator either way. The forward passes run in the config's
    ``precision`` (:func:`~coma.networks.mixed_precision`); losses, advantages and targets
    are float32.

    Raises:
        TrainingDiverged: a loss is not finite (the networks may be damaged: do not save).
    """
    cfg = networks.coma_config
    precision = cfg.precision
    device = next(networks.critic.parameters()).device
    rollout = rollout.to(device)
    e, n, t = rollout.actions.shape
    actor_obs = in_input_layout(networks.actor, rollout.actor_obs.flatten(0, 2))
    critic_obs = in_input_layout(networks.critic, rollout.critic_obs.flatten(0, 2))
    value_obs = None
    if rollout.value_obs is not None and networks.value is not None:
        value_obs = in_input_layout(networks.value, rollout.value_obs.flatten(0, 2))
    # TD(lambda) targets per agent and episode from the target critic.
    with torch.no_grad():
        q_target = learning_forward(target_critic, critic_obs, precision).view(e, n, t, N_ACTIONS)
        q_target_taken = q_target.gather(-1, rollout.actions.unsqueeze(-1)).squeeze(-1)
        next_values = torch.roll(q_target_taken, shifts=-1, dims=-1)  # Q'(s_{t+1}, u_{t+1})
        terminal = torch.zeros(e, n, t, dtype=torch.bool, device=device)
        terminal[..., -1] = True
        rewards = rollout.rewards.unsqueeze(1).expand(e, n, t)
        targets = td_lambda_targets(rewards, next_values, terminal, cfg.gamma, cfg.td_lambda)

    masks = rollout.masks.flatten(0, 2)
    actions = rollout.actions.flatten()
    behaviour = rollout.behaviour_probs.flatten()
    targets = targets.flatten()
    samples = len(actions)
    logs: dict[str, list[float]] = {k: [] for k in (
        "critic_loss", "value_loss", "actor_loss", "advantage_std", "policy_entropy",
        "critic_grad_norm", "actor_grad_norm")}
    for _ in range(cfg.epochs):
        order = torch.randperm(samples, generator=generator).to(device)
        for start in range(0, samples, cfg.minibatch_size):
            batch = order[start:start + cfg.minibatch_size]
            q = learning_forward(networks.critic, critic_obs[batch], precision)
            q_taken = q.gather(-1, actions[batch].unsqueeze(-1)).squeeze(-1)
            critic_loss = torch.mean((q_taken - targets[batch]) ** 2)
            _check_finite("critic loss", critic_loss)
            logs["critic_grad_norm"].append(_clip_step(optimisers["critic"], networks.critic,
                                                       critic_loss, cfg.max_grad_norm))
            logs["critic_loss"].append(critic_loss.item())
            if networks.value is not None:
                v = learning_forward(networks.value, value_obs[batch], precision).squeeze(-1)
                value_loss = torch.mean((v - targets[batch]) ** 2)
                _check_finite("value loss", value_loss)
                _clip_step(optimisers["value"], networks.value, value_loss, cfg.max_grad_norm)
                logs["value_loss"].append(value_loss.item())
            if not train_actor:
                continue

            penalty = None
            if cfg.residual_penalty > 0 and isinstance(networks.actor, GainPriorActor):
                with mixed_precision(precision, device):  # both parts float32 (the heads)
                    residual, prior = networks.actor.parts(actor_obs[batch])
                logits = residual + prior
                valid = masks[batch].to(residual.dtype)
                centred = residual - (residual * valid).sum(-1, keepdim=True) / valid.sum(
                    -1, keepdim=True)
                penalty = (centred ** 2 * valid).sum() / valid.sum()
            else:
                logits = learning_forward(networks.actor, actor_obs[batch], precision)
            probs = bounded_softmax(logits, masks[batch], eps)
            # The critic's pre-step Q serves the actor: one forward pass fewer per mini-batch.
            q = q.detach()
            with torch.no_grad():
                if cfg.variant == "central_qv":
                    v = learning_forward(networks.value, value_obs[batch],
                                         precision).squeeze(-1)
                    advantage = central_value_advantage(q, actions[batch], v)
                else:
                    advantage = counterfactual_advantage(q, actions[batch], probs.detach(),
                                                         masks[batch])
            raw_std = float(advantage.std()) if len(batch) > 1 else 0.0
            if cfg.normalise_advantage and len(batch) > 1:
                advantage = (advantage - advantage.mean()) / (advantage.std() + 1e-8)
            taken = probs.gather(-1, actions[batch].unsqueeze(-1)).squeeze(-1)
            if cfg.clip_ratio > 0:
                ratio = taken / behaviour[batch].clamp_min(1e-12)
                clipped = ratio.clamp(1.0 - cfg.clip_ratio, 1.0 + cfg.clip_ratio)
                actor_loss = -torch.mean(torch.min(ratio * advantage, clipped * advantage))
            else:
                actor_loss = -torch.mean(torch.log(taken.clamp_min(1e-12)) * advantage)
            if cfg.entropy_coef > 0:
                entropy = -(probs * torch.log(probs.clamp_min(1e-12))).sum(-1).mean()
                actor_loss = actor_loss - cfg.entropy_coef * entropy
            if penalty is not None:
                actor_loss = actor_loss + cfg.residual_penalty * penalty
            _check_finite("actor loss", actor_loss)
            logs["actor_grad_norm"].append(_clip_step(optimisers["actor"], networks.actor,
                                                      actor_loss, cfg.max_grad_norm))
            logs["actor_loss"].append(actor_loss.item())
            logs["advantage_std"].append(raw_std)
            with torch.no_grad():
                p = probs.clamp_min(1e-12)
                logs["policy_entropy"].append(float(-(probs * torch.log(p)).sum(-1).mean()))
    return {k: float(np.mean(v)) for k, v in logs.items() if v}


def _check_finite(what: str, value: torch.Tensor) -> None:
    if not torch.isfinite(value):
        raise TrainingDiverged(f"{what} is {value.item()}")


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
            load_state_into(module, getattr(source, name).state_dict(), f"the {name}", path)


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
        changed = ", ".join(f"{name} = {stored.get(name)!r} in the run, {wanted.get(name)!r} now"
                            for name in sorted(set(stored) | set(wanted))
                            if stored.get(name) != wanted.get(name))
        raise CheckpointError(f"checkpoint {str(last_path)!r} belongs to a run with other "
                              f"COMA settings ({changed}); give the run's settings, or start "
                              "a new folder instead")
    if config_to_dict(networks.env_config) != config_to_dict(env_config):
        raise CheckpointError(f"checkpoint {str(last_path)!r} was trained on another "
                              "mission config; start a new folder instead")
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
    load_state_into(target_critic, data["target_critic"], "the target critic",
                    str(last_path))
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

    The folder gets ``config.json`` (both configs), ``progress.csv`` (one row per update),
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
        CheckpointError: a checkpoint to resume is corrupt or belongs to another run.
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
    last_path = out / "last.pt"
    if env_config.team.has_failures:
        raise ValueError("team.failures / team.random_failures: COMA does not train with UAV "
                         "failures yet (a failed UAV's transitions would be recorded); "
                         "evaluate a trained policy on them with ipp-compare instead")
    settings = mission_settings(coma_config, env_config)
    check_network_size(coma_config, env_config)  # before any worker starts or file is written
    geometries = [MissionGeometry(config) for config in settings]
    checks = validation_settings(coma_config, settings)
    check_geometries = geometries if checks == settings else [
        MissionGeometry(config) for config in checks]
    # Held for the whole run: a second run into the folder is refused, naming this process.
    with claim(out_dir, COMA_COMMAND):  # the given path: an empty one is refused
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
        resumable = _resumable(last_path, coma_config, env_config) if resume else None
        if announce:
            print(announce, file=sys.stderr)
        # IG's reference flies before the actors exist (they hold their CPUs for the whole run):
        # on the cluster at --address, else in local processes (a local Ray of the run is not
        # started yet, and would cost its start-up twice).
        reference = None
        if coma_config.selection == "worst_vs_ig":
            # check_workers has refused an address without the ray backend.
            reference = reference_scores(
                checks, coma_config.seed, coma_config.eval_missions,
                workers=workers if address is not None else min(workers, os.cpu_count() or 1),
                backend="local" if address is None else "ray", address=address)
        spec = RunSpec(coma_config, env_config, tuple(settings), tuple(checks), coma_config.seed)
        known = {**{("train", k): g for k, g in enumerate(geometries)},
                 **{("check", k): g for k, g in enumerate(check_geometries)}}
        with make_workers(spec, workers, backend, address, known) as pool:
            return _train_with(pool, coma_config, env_config, out, resumable, progress,
                               tensorboard, max_updates, warm_start, learner_device, settings,
                               checks, reference)


def _train_with(pool: Workers, coma_config: COMAConfig, env_config: EnvConfig, out: Path,
                resumable: tuple[COMANetworks, dict[str, Any]] | None, progress: bool,
                tensorboard: bool, max_updates: int | None,
                warm_start: WarmStartConfig | None, device: torch.device,
                settings: list[EnvConfig], checks: list[EnvConfig],
                reference: list[float] | None) -> TrainResult:
    """The run of :func:`train` once its inputs are checked: ``pool`` flies the missions of
    the training ``settings`` and the validation ``checks``, the networks learn on
    ``device``; ``resumable`` is the checkpoint to continue from (:func:`_resumable`), if any."""
    last_path, best_path, csv_path = out / "last.pt", out / "best.pt", out / "progress.csv"
    budget = env_config.team.budget

    def criterion(scores: dict[str, float]) -> float:
        """What best.pt minimises: the mean final entropy, or the worst gap to IG."""
        return scores["gap_worst"] if reference is not None else scores[f"entropy_{budget}"]

    def validate_now(networks: COMANetworks) -> dict[str, float]:
        """The actor's validation scores, its missions flown by the pool's workers."""
        networks.actor.eval()
        try:
            return validate(networks.actor, checks, None, coma_config.seed,
                            coma_config.eval_missions, reference,
                            fly=lambda k, n: pool.greedy(networks, k, n))
        finally:
            networks.actor.train()

    generator = torch.Generator().manual_seed(coma_config.seed)
    history: list[dict[str, Any]] = []
    if resumable is not None:
        networks, target_critic, optimisers, state, history = _resume(
            resumable, last_path, csv_path, coma_config, generator, device)
    else:
        torch.manual_seed(coma_config.seed)
        networks = build_networks(coma_config, env_config)
        to_channels_last(networks)
        state = {"update": 0, "missions": 0, "transitions": 0, "since_target": 0,
                 "best_entropy": math.inf, "best_update": 0, "wall_s": 0.0}
        run_info: dict[str, Any] = {"coma": coma_config.to_dict(),
                                    "env": config_to_dict(env_config)}
        if reference is not None:
            run_info["validation_reference"] = {
                "planner": "ig", "terrains": [c.terrain.kind for c in checks],
                "final_entropy": reference}

        def score_start() -> dict[str, float]:
            """Validate the starting networks; they are ``best.pt`` at update 0."""
            validation = validate_now(networks)
            state["best_entropy"] = criterion(validation)
            save_policy(best_path, networks, {"validation": validation, "update": 0})
            return {"validation_entropy": validation[f"entropy_{budget}"],
                    "validation_f1": validation[f"f1_{budget}"]}

        if warm_start is None and coma_config.warm_start.enabled:
            warm_start = coma_config.warm_start
        if coma_config.init_policy:
            _initialise_from(networks, coma_config.init_policy)
            run_info["init_policy"] = {"path": coma_config.init_policy, **score_start()}
        elif warm_start is not None:
            tick = time.perf_counter()
            scores = imitate(networks, env_config, warm_start, coma_config.seed, generator,
                             progress)
            scores["seconds"] = time.perf_counter() - tick
            scores.update(score_start())
            save_policy(out / "warm_start.pt", networks, {"warm_start": scores})
            run_info["warm_start"] = {**warm_start.to_dict(), "result": scores}
        elif coma_config.gain_prior > 0:
            # The gain-prior actor starts as a planner worth scoring (ig's choice).
            run_info["gain_prior_start"] = score_start()
        _move(networks, device)  # the warm start imitated on the CPU
        target_critic = copy.deepcopy(networks.critic)
        optimisers = make_optimisers(networks)
        write_json(out / "config.json", run_info)

    def save_checkpoint() -> None:
        save_policy(last_path, networks, {
            "target_critic": target_critic.state_dict(),
            "optimisers": {k: o.state_dict() for k, o in optimisers.items()},
            "generator": generator.get_state(),
            "progress": dict(state),
        })
        write_progress(csv_path, history)

    writer = None
    if tensorboard:
        from torch.utils.tensorboard import SummaryWriter

        writer = SummaryWriter(str(out / "tb"), purge_step=state["update"] + 1)

    per_update = coma_config.missions_per_update
    total_updates = math.ceil(coma_config.missions / per_update)
    label = coma_config.variant + ("" if coma_config.precision == "float32"
                                   else f", {coma_config.precision}")
    bar = progress_bar(total_updates, f"COMA ({label})", "updates",
                       initial=state["update"], disable=not progress)
    updates_this_call = 0
    try:
        while state["update"] < total_updates and (max_updates is None
                                                   or updates_this_call < max_updates):
            tick = time.perf_counter()
            eps = epsilon_at(state["missions"], coma_config.eps_start, coma_config.eps_end,
                             coma_config.eps_anneal_missions)
            if state["since_target"] >= coma_config.target_update_transitions:
                target_critic.load_state_dict(networks.critic.state_dict())
                state["since_target"] = 0
            setting = setting_of_update(len(settings), coma_config.seed, state["update"])
            rollout = pool.rollout(networks, setting, state["missions"], per_update, eps)
            try:
                losses = update(networks, target_critic, optimisers, rollout, eps, generator,
                                train_actor=state["update"] >= coma_config.critic_warmup_updates)
            except TrainingDiverged as error:
                raise TrainingDiverged(
                    f"{error} at update {state['update'] + 1}; training stopped. The last "
                    f"good checkpoint is kept: {str(last_path)!r} (update "
                    f"{saved_update(last_path)}); lower the learning rates or check the "
                    "rewards") from None
            elapsed = time.perf_counter() - tick
            state["update"] += 1
            state["missions"] += per_update
            state["transitions"] += rollout.transitions
            state["since_target"] += rollout.transitions
            state["wall_s"] += elapsed
            row: dict[str, Any] = {
                "update": state["update"], "missions": state["missions"],
                "transitions": state["transitions"], "eps": eps,
                "return_mean": float(rollout.returns.mean()),
                "final_entropy_mean": float(rollout.final_entropy.mean()),
                **losses, "transitions_per_s": rollout.transitions / elapsed,
                "wall_s": state["wall_s"], "n_agents": settings[setting].team.n_agents,
                "comm_range": settings[setting].team.comm_range}
            last_update = state["update"] == total_updates
            if state["update"] % coma_config.eval_every == 0 or last_update:
                scores = validate_now(networks)
                row.update(eval_return=scores["return"],
                           eval_entropy_final=scores[f"entropy_{budget}"],
                           eval_f1_final=scores[f"f1_{budget}"],
                           eval_gap_worst=scores.get("gap_worst"))
                if criterion(scores) < state["best_entropy"]:
                    state["best_entropy"] = criterion(scores)
                    state["best_update"] = state["update"]
                    save_policy(best_path, networks, {"validation": scores,
                                                      "update": state["update"]})
            history.append(row)
            if writer is not None:
                for key, value in row.items():
                    if key != "update" and value is not None:
                        writer.add_scalar(f"coma/{key}", value, state["update"])
            updates_this_call += 1
            if state["update"] % coma_config.checkpoint_every == 0 or last_update:
                save_checkpoint()
            bar.update(1)
            bar.set_postfix(ret=f"{row['return_mean']:.2f}", eps=f"{eps:.2f}",
                            val_H=f"{state['best_entropy']:.3f}")
        if updates_this_call and (state["update"] % coma_config.checkpoint_every):
            save_checkpoint()
    finally:
        bar.close()
        if writer is not None:
            writer.close()
    return TrainResult(out, best_path, last_path, state["update"], state["missions"],
                       state["best_entropy"], history)
