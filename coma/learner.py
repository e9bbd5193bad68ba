"""COMA: counterfactual multi-agent policy gradients for the UAV team, top to bottom.

Read in order: the rollout (missions in lock-step, a shared actor sampling from the bounded
softmax), the critic update (TD(lambda) targets per episode from a target critic refreshed
every ``target_update_transitions``), the advantage (``coma.advantages``), the actor update
(the paper's ``-log pi(u) A``, or with ``clip_ratio > 0`` PPO's clipped surrogate), then
logging, evaluation and checkpoints. An optional warm start (``coma.warm_start``) imitates a
planner first. Hyper-parameters live in :class:`COMAConfig`; the mission in an
:class:`EnvConfig`. ``train`` is the Python entry point, ``main`` the ``ipp-train coma``
command.

Reproducibility: mission k of a run always has the same terrain and sensor noise
(``ipp_toolkit.seeding``); action sampling and mini-batch shuffling draw from one torch
Generator whose state is checkpointed, so an interrupted run resumed with ``resume=True``
continues exactly as if it had not stopped.
"""

from __future__ import annotations

import argparse
import copy
import csv
import io
import math
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from ipp_toolkit.config import EnvConfig, config_to_dict
from ipp_toolkit.evaluation import planner_seed
from ipp_toolkit.features import actor_observations, actor_plane_names
from ipp_toolkit.io import CheckpointError, atomic_write, write_json
from ipp_toolkit.mission import MissionGeometry, MissionState, reset_mission, step_mission
from ipp_toolkit.planners import Planner, agent_views
from ipp_toolkit.progress import progress_bar
from ipp_toolkit.settings import build_env_config
from ipp_toolkit.team import N_ACTIONS

from .advantages import central_value_advantage, counterfactual_advantage, td_lambda_targets
from .config import PRESETS, VARIANTS, COMAConfig, mission_settings, preset
from .inputs import critic_input, value_input
from .networks import GainPriorActor, bounded_softmax, epsilon_at, greedy_actions
from .persistence import (
    DEFAULT_SHIPPED,
    COMANetworks,
    build_networks,
    load_policy,
    load_state_into,
    resolve_policy,
    save_policy,
)
from .warm_start import WarmStartConfig

__all__ = ["TrainingDiverged", "TrainResult", "Rollout", "collect_rollout", "greedy_actions",
           "evaluate_greedy", "validate", "mission_settings", "setting_of_update", "train",
           "main", "TRAINING_DEFAULTS"]


class TrainingDiverged(RuntimeError):
    """A loss became NaN or infinite; the last good checkpoint is kept."""


# --------------------------------------------------------------------------------------------
# Rollout


@dataclass
class Rollout:
    """One update's data: E missions of T steps with N agents, in lock-step.

    Attributes:
        actor_obs: (E, N, T, C_actor, G, G) float32.
        critic_obs: (E, N, T, C_critic, G, G) float32.
        value_obs: (E, N, T, C_value, G, G) float32, or None unless ``central_qv``.
        masks: (E, N, T, 6) bool valid actions.
        actions: (E, N, T) int64.
        behaviour_probs: (E, N, T) probability of each action under the policy that chose
            it (1 for a demonstrator's actions).
        rewards: (E, T) float32 team rewards.
        returns: (E,) undiscounted return of each mission.
        final_entropy: (E,) entropy metric at the end of each mission.
    """

    actor_obs: torch.Tensor
    critic_obs: torch.Tensor
    value_obs: torch.Tensor | None
    masks: torch.Tensor
    actions: torch.Tensor
    behaviour_probs: torch.Tensor
    rewards: torch.Tensor
    returns: np.ndarray
    final_entropy: np.ndarray

    @property
    def transitions(self) -> int:
        """Agent-transitions in the rollout: E * N * T."""
        return int(np.prod(self.actions.shape))


def _stack_time(frames: list[np.ndarray]) -> torch.Tensor:
    """T frames of (E, N, ...) -> (E, N, T, ...)."""
    return torch.from_numpy(np.stack(frames, axis=2))


def _learning_masks(state: MissionState) -> np.ndarray:
    """(N, 6) bool masks the learner uses: the valid actions, or all actions in the no-mask
    ablation (``team.invalid_action = "hold"``: a masked choice holds the UAV in place)."""
    if state.config.team.invalid_action == "hold":
        return np.ones((state.n_agents, N_ACTIONS), dtype=bool)
    return state.masks().astype(bool)


def collect_rollout(networks: COMANetworks, env_config: EnvConfig, geometry: MissionGeometry,
                    seed: int, first_mission: int, n_missions: int, eps: float,
                    generator: torch.Generator, namespace: str = "train",
                    demonstrators: Sequence[Planner] | None = None) -> Rollout:
    """Play ``n_missions`` missions in lock-step with the bounded-softmax policy.

    Missions ``first_mission ... first_mission + n_missions - 1`` of run ``seed`` are used, so
    consecutive updates see fresh terrains. The actor runs once per step for all agents of all
    missions; the critic inputs are built with the joint action just sampled.

    Args:
        demonstrators: one planner per mission that acts instead of the actor (demonstrations
            for a warm start, see ``coma.warm_start``); ``eps`` is then unused.
    """
    variant = networks.coma_config.variant
    features = env_config.features
    states = [reset_mission(env_config, seed, first_mission + e, namespace, geometry)
              for e in range(n_missions)]
    if demonstrators is not None:
        if len(demonstrators) != n_missions:
            raise ValueError(f"need one demonstrator per mission ({n_missions}), got "
                             f"{len(demonstrators)}")
        for e, planner in enumerate(demonstrators):
            planner.reset(env_config, planner_seed(seed, first_mission + e, namespace))
    actor_frames, critic_frames, value_frames, mask_frames, action_frames, reward_frames = \
        [], [], [], [], [], []
    behaviour_frames: list[np.ndarray] = []
    returns = np.zeros(n_missions)
    for _ in range(env_config.team.budget):
        obs = np.stack([actor_observations(s, features) for s in states])  # (E, N, C, G, G)
        masks = np.stack([_learning_masks(s) for s in states])  # (E, N, 6)
        if demonstrators is None:
            with torch.no_grad():
                logits = networks.actor(torch.from_numpy(obs).flatten(0, 1))
                probs = bounded_softmax(logits, torch.from_numpy(masks).flatten(0, 1), eps)
            chosen = torch.multinomial(probs, 1, generator=generator)
            behaviour = probs.gather(-1, chosen).view(n_missions, -1).numpy()
            actions = chosen.view(n_missions, -1).numpy()
        else:
            actions = np.stack([np.asarray(planner.act(agent_views(s, planner.needs_observations,
                                                                   planner.observation_features)),
                                           dtype=np.int64)
                                for planner, s in zip(demonstrators, states, strict=True)])
            behaviour = np.ones(actions.shape, dtype=np.float32)
        critic_frames.append(np.stack([critic_input(s, features, variant, actions[e], obs[e])
                                       for e, s in enumerate(states)]))
        if networks.value is not None:
            value_frames.append(np.stack([value_input(s, features, obs[e])
                                          for e, s in enumerate(states)]))
        rewards = np.array([step_mission(s, actions[e]) for e, s in enumerate(states)])
        returns += rewards
        actor_frames.append(obs)
        mask_frames.append(masks)
        action_frames.append(actions)
        behaviour_frames.append(behaviour)
        reward_frames.append(rewards)
    return Rollout(
        actor_obs=_stack_time(actor_frames),
        critic_obs=_stack_time(critic_frames),
        value_obs=_stack_time(value_frames) if value_frames else None,
        masks=_stack_time(mask_frames),
        actions=_stack_time(action_frames).long(),
        behaviour_probs=_stack_time(behaviour_frames).float(),
        rewards=torch.from_numpy(np.stack(reward_frames, axis=1)).float(),
        returns=returns,
        final_entropy=np.array([s.history[-1].entropy for s in states]),
    )


def evaluate_greedy(actor: nn.Module, env_config: EnvConfig, geometry: MissionGeometry,
                    seed: int, n_missions: int, namespace: str = "validation"
                    ) -> dict[str, float]:
    """Mean entropy and F1 of the greedy policy on held-out missions, after every step.

    Returns:
        ``entropy_s`` and ``f1_s`` for s = 0..B, and ``return``: the mean team return.
    """
    states = [reset_mission(env_config, seed, m, namespace, geometry) for m in range(n_missions)]
    total_return = 0.0
    features = env_config.features
    for _ in range(env_config.team.budget):
        obs = np.stack([actor_observations(s, features) for s in states])
        masks = np.stack([s.masks() for s in states])
        actions = greedy_actions(actor, obs.reshape(-1, *obs.shape[2:]),
                                 masks.reshape(-1, N_ACTIONS)).reshape(n_missions, -1)
        total_return += sum(step_mission(s, actions[e]) for e, s in enumerate(states))
    result = {"return": total_return / n_missions}
    for step in range(env_config.team.budget + 1):
        result[f"entropy_{step}"] = float(np.mean([s.history[step].entropy for s in states]))
        result[f"f1_{step}"] = float(np.mean([s.history[step].f1 for s in states]))
    return result


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
    optimiser and its diagnostics are left alone.

    Raises:
        TrainingDiverged: a loss is not finite (the networks may be damaged: do not save).
    """
    cfg = networks.coma_config
    e, n, t = rollout.actions.shape
    # TD(lambda) targets per agent and episode from the target critic.
    with torch.no_grad():
        q_target = target_critic(rollout.critic_obs.flatten(0, 2)).view(e, n, t, N_ACTIONS)
        q_target_taken = q_target.gather(-1, rollout.actions.unsqueeze(-1)).squeeze(-1)
        next_values = torch.roll(q_target_taken, shifts=-1, dims=-1)  # Q'(s_{t+1}, u_{t+1})
        terminal = torch.zeros(e, n, t, dtype=torch.bool)
        terminal[..., -1] = True
        rewards = rollout.rewards.unsqueeze(1).expand(e, n, t)
        targets = td_lambda_targets(rewards, next_values, terminal, cfg.gamma, cfg.td_lambda)

    actor_obs = rollout.actor_obs.flatten(0, 2)
    critic_obs = rollout.critic_obs.flatten(0, 2)
    value_obs = rollout.value_obs.flatten(0, 2) if rollout.value_obs is not None else None
    masks = rollout.masks.flatten(0, 2)
    actions = rollout.actions.flatten()
    behaviour = rollout.behaviour_probs.flatten()
    targets = targets.flatten()
    samples = len(actions)
    logs: dict[str, list[float]] = {k: [] for k in (
        "critic_loss", "value_loss", "actor_loss", "advantage_std", "policy_entropy",
        "critic_grad_norm", "actor_grad_norm")}
    for _ in range(cfg.epochs):
        order = torch.randperm(samples, generator=generator)
        for start in range(0, samples, cfg.minibatch_size):
            batch = order[start:start + cfg.minibatch_size]
            q = networks.critic(critic_obs[batch])
            q_taken = q.gather(-1, actions[batch].unsqueeze(-1)).squeeze(-1)
            critic_loss = torch.mean((q_taken - targets[batch]) ** 2)
            _check_finite("critic loss", critic_loss)
            logs["critic_grad_norm"].append(_clip_step(optimisers["critic"], networks.critic,
                                                       critic_loss, cfg.max_grad_norm))
            logs["critic_loss"].append(critic_loss.item())
            if networks.value is not None:
                v = networks.value(value_obs[batch]).squeeze(-1)
                value_loss = torch.mean((v - targets[batch]) ** 2)
                _check_finite("value loss", value_loss)
                _clip_step(optimisers["value"], networks.value, value_loss, cfg.max_grad_norm)
                logs["value_loss"].append(value_loss.item())
            if not train_actor:
                continue

            penalty = None
            if cfg.residual_penalty > 0 and isinstance(networks.actor, GainPriorActor):
                residual, prior = networks.actor.parts(actor_obs[batch])
                logits = residual + prior
                valid = masks[batch].to(residual.dtype)
                centred = residual - (residual * valid).sum(-1, keepdim=True) / valid.sum(
                    -1, keepdim=True)
                penalty = (centred ** 2 * valid).sum() / valid.sum()
            else:
                logits = networks.actor(actor_obs[batch])
            probs = bounded_softmax(logits, masks[batch], eps)
            # The critic's pre-step Q serves the actor: one forward pass fewer per mini-batch.
            q = q.detach()
            with torch.no_grad():
                if cfg.variant == "central_qv":
                    v = networks.value(value_obs[batch]).squeeze(-1)
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


CSV_COLUMNS = ["update", "missions", "transitions", "eps", "return_mean", "final_entropy_mean",
               "critic_loss", "value_loss", "actor_loss", "advantage_std", "policy_entropy",
               "critic_grad_norm", "actor_grad_norm", "transitions_per_s", "wall_s",
               "eval_return", "eval_entropy_final", "eval_f1_final", "eval_gap_worst",
               "n_agents", "comm_range"]


@dataclass
class TrainResult:
    """Where a run left its files and how it ended.

    Attributes:
        out_dir: the run folder.
        best_policy: path of the policy with the lowest validation entropy (``best.pt``).
        last_checkpoint: path of the resumable training checkpoint (``last.pt``).
        updates: updates done in total.
        missions: training missions played in total.
        best_entropy: validation final entropy of the best policy.
        history: one dict per update (the CSV rows).
    """

    out_dir: Path
    best_policy: Path
    last_checkpoint: Path
    updates: int
    missions: int
    best_entropy: float
    history: list[dict[str, Any]] = field(default_factory=list)


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


def validate(actor: nn.Module, settings: Sequence[EnvConfig],
             geometries: Sequence[MissionGeometry], seed: int, n_missions: int,
             reference: Sequence[float] | None = None) -> dict[str, float]:
    """:func:`evaluate_greedy` on every setting, averaged key by key over the settings.

    With ``reference`` (a planner's mean final entropy per setting, same missions) it also
    gives ``gap_worst`` and ``gap_mean``: the largest and the mean of the policy's mean final
    entropy minus the reference's over the settings.
    """
    scores = [evaluate_greedy(actor, config, geometry, seed, n_missions)
              for config, geometry in zip(settings, geometries, strict=True)]
    result = {key: float(np.mean([s[key] for s in scores])) for key in scores[0]}
    if reference is not None:
        budget = settings[0].team.budget
        gaps = [s[f"entropy_{budget}"] - r for s, r in zip(scores, reference, strict=True)]
        result.update(gap_worst=float(max(gaps)), gap_mean=float(np.mean(gaps)))
    return result


def validation_settings(coma_config: COMAConfig, settings: Sequence[EnvConfig]
                        ) -> list[EnvConfig]:
    """The validation missions' configs: every training setting on every validation terrain
    (``coma_config.validation_terrains``; none: the settings themselves)."""
    if not coma_config.validation_terrains:
        return list(settings)
    return [config.replace(terrain={"kind": kind}) for config in settings
            for kind in coma_config.validation_terrains]


def reference_scores(settings: Sequence[EnvConfig], seed: int, n_missions: int,
                     planner: str = "ig") -> list[float]:
    """``planner``'s mean final entropy on the validation missions of each setting (the
    missions :func:`evaluate_greedy` flies), for ``selection = "worst_vs_ig"``."""
    from ipp_toolkit.evaluation import evaluate

    scores = []
    for config in settings:
        result = evaluate(config, [planner], missions=n_missions, seed=seed,
                          namespace="validation", progress=False)
        budget = config.team.budget
        scores.append(float(np.mean([r["entropy"] for r in result.rows
                                     if int(r["step"]) == budget])))
    return scores


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


def _make_optimisers(networks: COMANetworks) -> dict[str, torch.optim.Optimizer]:
    cfg = networks.coma_config
    optimisers = {"actor": torch.optim.Adam(networks.actor.parameters(), lr=cfg.lr_actor),
                  "critic": torch.optim.Adam(networks.critic.parameters(), lr=cfg.lr_critic)}
    if networks.value is not None:
        optimisers["value"] = torch.optim.Adam(networks.value.parameters(), lr=cfg.lr_critic)
    return optimisers


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=CSV_COLUMNS, extrasaction="ignore")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in CSV_COLUMNS})
    data = buffer.getvalue().encode("utf-8")
    atomic_write(path, lambda handle: handle.write(data))


def _comparable(config: COMAConfig) -> dict[str, Any]:
    """Fields that must match to resume a run (the total length may be extended)."""
    values = config.to_dict()
    values.pop("missions")
    return values


def train(coma_config: COMAConfig, env_config: EnvConfig, out_dir: str | Path,
          resume: bool = False, progress: bool = True, tensorboard: bool = True,
          max_updates: int | None = None,
          warm_start: WarmStartConfig | None = None) -> TrainResult:
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
            built from ``coma_config.warm_start``); the imitated networks are saved as
            ``warm_start.pt`` and scored on validation missions (update 0). A run with
            ``coma_config.init_policy`` starts from that policy's networks instead (no warm
            start); they are scored and saved as ``best.pt`` at update 0 alike.

    With ``coma_config.team_sizes`` / ``comm_ranges``, each update trains on one setting of
    :func:`mission_settings` (:func:`setting_of_update`), and validation averages over all of
    them; ``progress.csv`` records each update's ``n_agents`` and ``comm_range``.

    Raises:
        TrainingDiverged: a loss became non-finite; ``last.pt`` and ``best.pt`` keep the last
            good state.
        CheckpointError: a checkpoint to resume is corrupt or belongs to another run.
        FileExistsError: ``out_dir`` holds a run and ``resume`` is false.
    """
    torch.set_num_threads(1)
    out = Path(out_dir)
    last_path, best_path, csv_path = out / "last.pt", out / "best.pt", out / "progress.csv"
    settings = mission_settings(coma_config, env_config)
    geometries = [MissionGeometry(config) for config in settings]
    checks = validation_settings(coma_config, settings)
    check_geometries = geometries if checks == settings else [
        MissionGeometry(config) for config in checks]
    reference = (reference_scores(checks, coma_config.seed, coma_config.eval_missions)
                 if coma_config.selection == "worst_vs_ig" else None)
    budget = env_config.team.budget

    def criterion(scores: dict[str, float]) -> float:
        """What best.pt minimises: the mean final entropy, or the worst gap to IG."""
        return scores["gap_worst"] if reference is not None else scores[f"entropy_{budget}"]

    if resume and not last_path.exists():
        raise CheckpointError(f"nothing to resume: {str(last_path)!r} does not exist (drop "
                              "--resume to start a new run)")
    if last_path.exists() and not resume:
        raise FileExistsError(f"{str(out)!r} already holds a run (last.pt): pass resume=True "
                              "(--resume) to continue it, or choose another folder")
    generator = torch.Generator().manual_seed(coma_config.seed)
    history: list[dict[str, Any]] = []
    if resume and last_path.exists():
        networks, data = load_policy(last_path)
        if _comparable(networks.coma_config) != _comparable(coma_config):
            raise CheckpointError(f"checkpoint {str(last_path)!r} belongs to a run with other "
                                  "COMA settings; start a new folder instead")
        if config_to_dict(networks.env_config) != config_to_dict(env_config):
            raise CheckpointError(f"checkpoint {str(last_path)!r} was trained on another "
                                  "mission config; start a new folder instead")
        networks.coma_config = coma_config
        for module in (networks.actor, networks.critic, networks.value):
            if module is not None:
                module.train()
        target_critic = copy.deepcopy(networks.critic)
        load_state_into(target_critic, data["target_critic"], "the target critic",
                        str(last_path))
        optimisers = _make_optimisers(networks)
        for name, optimiser in optimisers.items():
            try:
                optimiser.load_state_dict(data["optimisers"][name])
            except (KeyError, ValueError) as error:
                raise CheckpointError(f"checkpoint {str(last_path)!r}: cannot restore the "
                                      f"{name} optimiser ({error})") from None
        generator.set_state(data["generator"])
        state = dict(data["progress"])
        if csv_path.exists():
            with open(csv_path, newline="") as handle:
                history = [{k: _parse(v) for k, v in row.items()}
                           for row in csv.DictReader(handle)]
            history = [row for row in history if row["update"] <= state["update"]]
    else:
        torch.manual_seed(coma_config.seed)
        networks = build_networks(coma_config, env_config)
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
            networks.actor.eval()
            validation = validate(networks.actor, checks, check_geometries, coma_config.seed,
                                  coma_config.eval_missions, reference)
            networks.actor.train()
            state["best_entropy"] = criterion(validation)
            save_policy(best_path, networks, {"validation": validation, "update": 0})
            return {"validation_entropy": validation[f"entropy_{budget}"],
                    "validation_f1": validation[f"f1_{budget}"]}

        if warm_start is None and coma_config.warm_start:
            warm_start = WarmStartConfig(planner=coma_config.warm_start,
                                         missions=coma_config.warm_start_missions,
                                         epochs=coma_config.warm_start_epochs)
        if coma_config.init_policy:
            _initialise_from(networks, coma_config.init_policy)
            run_info["init_policy"] = {"path": coma_config.init_policy, **score_start()}
        elif warm_start is not None:
            from .warm_start import warm_start as imitate

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
        target_critic = copy.deepcopy(networks.critic)
        optimisers = _make_optimisers(networks)
        write_json(out / "config.json", run_info)

    def save_checkpoint() -> None:
        save_policy(last_path, networks, {
            "target_critic": target_critic.state_dict(),
            "optimisers": {k: o.state_dict() for k, o in optimisers.items()},
            "generator": generator.get_state(),
            "progress": dict(state),
        })
        _write_csv(csv_path, history)

    writer = None
    if tensorboard:
        from torch.utils.tensorboard import SummaryWriter

        writer = SummaryWriter(str(out / "tb"), purge_step=state["update"] + 1)

    per_update = coma_config.missions_per_update
    total_updates = math.ceil(coma_config.missions / per_update)
    bar = progress_bar(total_updates, f"COMA ({coma_config.variant})", "updates",
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
            rollout = collect_rollout(networks, settings[setting], geometries[setting],
                                      coma_config.seed, state["missions"], per_update, eps,
                                      generator)
            try:
                losses = update(networks, target_critic, optimisers, rollout, eps, generator,
                                train_actor=state["update"] >= coma_config.critic_warmup_updates)
            except TrainingDiverged as error:
                raise TrainingDiverged(
                    f"{error} at update {state['update'] + 1}; training stopped. The last "
                    f"good checkpoint is kept: {str(last_path)!r} (update "
                    f"{_saved_update(last_path)}); lower the learning rates or check the "
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
                networks.actor.eval()
                scores = validate(networks.actor, checks, check_geometries, coma_config.seed,
                                  coma_config.eval_missions, reference)
                networks.actor.train()
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


def _saved_update(path: Path) -> str:
    if not path.exists():
        return "none yet"
    try:
        _, data = load_policy(path)
        return str(data["progress"]["update"])
    except (CheckpointError, KeyError):
        return "unreadable"


def _parse(text: str) -> Any:
    if text == "":
        return None
    number = float(text)
    return int(number) if number.is_integer() and "." not in text and "e" not in text \
        else number


# --------------------------------------------------------------------------------------------
# Command line: ipp-train coma


TRAINING_DEFAULTS = {"world": {"resolution": 0.5}, "features": {"own_position": True}}
"""``ipp-train coma``'s defaults over the paper's mission: training at r_M = 0.5 m (the policy
flies at any resolution) with the own-position plane (docs/departures.md). A ``--config`` file
wins over them, an explicit flag over the file."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ipp-train coma",
        description="Train COMA (or a credit-assignment variant) on the UAV mapping missions.")
    parser.add_argument("--preset", choices=sorted(PRESETS), default="cpu",
                        help="hyper-parameter preset (default: cpu)")
    parser.add_argument("--variant", choices=VARIANTS, help="credit-assignment variant")
    parser.add_argument("--config", help="YAML mission config (world, team, features, ...) "
                             "over the training defaults (the paper's mission at r_M 0.5 m "
                             "with features.own_position on); explicit flags win over it")
    parser.add_argument("--seed", type=int, help="run seed")
    parser.add_argument("--out", required=True, help="run folder")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out")
    parser.add_argument("--missions", type=int, help="training missions in total")
    parser.add_argument("--width", type=int, help="convolution channels")
    parser.add_argument("--agents", type=int, help="team size (default: from --config, 4)")
    parser.add_argument("--comm", type=float, help="communication range in metres")
    parser.add_argument("--terrain", metavar="KIND",
                        help="terrain kind of the training missions, e.g. mixture (default: "
                             "the --config file's, else split)")
    parser.add_argument("--resolution", type=float, default=None,
                        help="map resolution for training in metres (default: the --config "
                             "file's, else 0.5)")
    parser.add_argument("--warm-start", metavar="PLANNER",
                        help="first imitate this registered planner (e.g. ig; 'none' to "
                             "switch the preset's off); not in the paper")
    parser.add_argument("--team-sizes", metavar="N,N,...",
                        help="train on these team sizes, one per update, e.g. 2,4,8 (domain "
                             "randomisation; not in the paper)")
    parser.add_argument("--comm-ranges", metavar="D,D,...",
                        help="train on these communication ranges in metres, e.g. 0,25,inf")
    parser.add_argument("--init", metavar="POLICY",
                        help="start from this COMA policy file instead of a warm start "
                             "(fine-tuning), or a shipped one: --init shipped:NAME "
                             "(paper-actor, prior, mixed; plain 'shipped': coma's default)")
    parser.add_argument("--feature", action="append", default=[], metavar="NAME=BOOL",
                        help="switch a feature plane of the mission config, e.g. "
                             "--feature own_position=true (repeatable)")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="any COMAConfig field, e.g. --set lr_actor=1e-4 (repeatable)")
    parser.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    return parser


def _coerce(text: str) -> Any:
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _int_list(flag: str, text: str) -> list[int]:
    try:
        return [int(item) for item in text.split(",")]
    except ValueError:
        raise ValueError(f"{flag} expects integers separated by commas, got {text!r}") from None


def _float_list(flag: str, text: str) -> list[float]:
    try:
        return [float(item) for item in text.split(",")]
    except ValueError:
        raise ValueError(f"{flag} expects numbers (or inf) separated by commas, got "
                         f"{text!r}") from None


def configs_from_args(args: argparse.Namespace) -> tuple[COMAConfig, EnvConfig]:
    """The configs a parsed ``ipp-train coma`` command asks for (ValueError on bad input)."""
    changes: dict[str, Any] = {}
    for item in args.set:
        name, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--set expects FIELD=VALUE, got {item!r}")
        changes[name.strip()] = _coerce(value.strip())
    for name in ("variant", "seed", "missions", "width"):
        if getattr(args, name) is not None:
            changes[name] = getattr(args, name)
    if args.warm_start is not None:
        changes["warm_start"] = "" if args.warm_start == "none" else args.warm_start
    if args.team_sizes is not None:
        changes["team_sizes"] = _int_list("--team-sizes", args.team_sizes)
    if args.comm_ranges is not None:
        changes["comm_ranges"] = _float_list("--comm-ranges", args.comm_ranges)
    if args.init is not None:
        init = f"shipped:{DEFAULT_SHIPPED}" if args.init == "shipped" else args.init
        changes["init_policy"] = str(resolve_policy(init))
        if not Path(changes["init_policy"]).is_file():
            raise ValueError(f"--init {args.init!r}: no such policy file")
    coma_config = preset(args.preset, **changes)
    switches: dict[str, bool] = {}
    for item in args.feature:
        name, sep, value = item.partition("=")
        if not sep or value.strip().lower() not in ("true", "false", "1", "0", "on", "off"):
            raise ValueError(f"--feature expects NAME=true|false, got {item!r}")
        switches[name.strip()] = value.strip().lower() in ("true", "1", "on")
    env_config = build_env_config(args.config, defaults=TRAINING_DEFAULTS, agents=args.agents,
                                  comm=args.comm, resolution=args.resolution,
                                  terrain=args.terrain, features=switches)
    return coma_config, env_config


def main(argv: Sequence[str] | None = None) -> int:
    """``ipp-train coma``: returns 0 on success, 1 on divergence, 2 on bad input."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        coma_config, env_config = configs_from_args(args)
        # An invalid team, range or validation terrain fails here, before anything is written.
        validation_settings(coma_config, mission_settings(coma_config, env_config))
        if coma_config.warm_start:
            from ipp_toolkit.planners import planner_factory

            planner_factory(coma_config.warm_start)  # an unknown name fails before training
    except ValueError as error:
        print(f"ipp-train coma: error: {error}", file=sys.stderr)
        return 2
    try:
        result = train(coma_config, env_config, args.out, resume=args.resume,
                       progress=not args.no_progress)
    except (FileExistsError, CheckpointError) as error:
        print(f"ipp-train coma: error: {error}", file=sys.stderr)
        return 2
    except TrainingDiverged as error:
        print(f"ipp-train coma: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"\nipp-train coma: interrupted; continue with --resume --out {args.out} "
              "(from the last checkpoint)", file=sys.stderr)
        return 130
    criterion = ("worst gap to IG's final entropy" if coma_config.selection == "worst_vs_ig"
                 else "final entropy")
    print(f"trained {result.updates} updates ({result.missions} missions); best validation "
          f"{criterion} {result.best_entropy:+.3f}; policy: {result.best_policy}")
    return 0



