"""Validation of a COMA actor during training, and which policy ``best.pt`` keeps.

This module owns how a run scores its actor: :func:`evaluate_greedy` flies held-out
``validation`` missions with the greedy policy, :func:`validate` averages that over the
validation settings (:func:`validation_settings`: every training setting on every validation
terrain) and, for ``selection = "worst_vs_ig"``, measures the gaps to a reference planner's
final entropy on the same missions (:func:`reference_scores`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from torch import nn

from ipp_toolkit.config import EnvConfig
from ipp_toolkit.features import actor_observations
from ipp_toolkit.mission import MissionGeometry, reset_mission, step_mission
from ipp_toolkit.team import N_ACTIONS

from .config import COMAConfig
from .networks import greedy_actions

__all__ = ["evaluate_greedy", "validate", "validation_settings", "reference_scores"]


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
