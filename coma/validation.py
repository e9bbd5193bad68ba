"""Validation of a COMA actor during training, and which policy ``best.pt`` keeps.

This module owns how a run scores its actor: :func:`fly_greedy` flies held-out
``validation`` missions with the greedy policy and keeps each mission's record
(:class:`GreedyFlights`), :func:`evaluate_greedy` summarises them, :func:`validate` averages
that over the validation settings (:func:`validation_settings`: every training setting on every
validation terrain) and, for ``selection = "worst_vs_ig"``, measures the gaps to a reference
planner's final entropy on the same missions (:func:`reference_scores`). The missions of a
setting may be flown in blocks by several workers (``coma.parallel``): the records of the
blocks, joined in mission order, give the scores of one flight, to the last bit.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from torch import nn

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planning import agent_views
from ipp_toolkit.sim.driver import fly_missions, start_missions
from ipp_toolkit.sim.features import actor_observations
from ipp_toolkit.sim.mission import MissionGeometry, MissionState
from ipp_toolkit.sim.team import N_ACTIONS, choose_in_order

from .config import COMAConfig
from .networks import masked_logits
from .planner import choose_greedy, teammate_discount
from .rollout import actor_batches

__all__ = ["GreedyFlights", "fly_greedy", "evaluate_greedy", "validate", "validation_settings",
           "reference_scores"]


@dataclass
class GreedyFlights:
    """What the greedy policy did on E missions of B steps.

    Attributes:
        rewards: (E, B) float64 team reward of every step.
        entropy: (E, B + 1) entropy metric after every step (step 0: the start).
        f1: (E, B + 1) F1 score after every step.
    """

    rewards: np.ndarray
    entropy: np.ndarray
    f1: np.ndarray

    @classmethod
    def concatenate(cls, parts: Sequence[GreedyFlights]) -> GreedyFlights:
        """The records of consecutive blocks of missions, joined in mission order."""
        return cls(*(np.concatenate([getattr(p, name) for p in parts])
                     for name in ("rewards", "entropy", "f1")))

    def scores(self) -> dict[str, float]:
        """``entropy_s`` and ``f1_s`` for s = 0..B (means over the missions) and ``return``:
        the mean team return, summed step by step over the missions as a lock-step flight
        of all of them adds it up."""
        total = 0.0
        for column in self.rewards.T:
            total += sum(column.tolist())
        result = {"return": total / len(self.rewards)}
        for step in range(self.entropy.shape[1]):
            result[f"entropy_{step}"] = float(np.mean(self.entropy[:, step].tolist()))
            result[f"f1_{step}"] = float(np.mean(self.f1[:, step].tolist()))
        return result


def fly_greedy(actor: nn.Module, env_config: EnvConfig, geometry: MissionGeometry, seed: int,
               first_mission: int, n_missions: int, namespace: str = "validation"
               ) -> GreedyFlights:
    """Fly missions ``first_mission .. first_mission + n_missions - 1`` of run ``seed`` in
    lock-step (:func:`ipp_toolkit.sim.driver.fly_missions`) with the greedy policy and record
    each one (the actor scores the agents of each group of :func:`coma.rollout.actor_batches`
    together, so a mission's record does not depend on the missions flown beside it). The
    policy decides as the ``coma`` planner flies it (:func:`coma.planner.choose_greedy`)."""
    features = env_config.features
    groups = actor_batches(first_mission, n_missions)
    discount = teammate_discount(actor, env_config, features)

    def act(states: Sequence[MissionState]) -> np.ndarray:
        """(E, N) greedy actions of this step."""
        obs = np.stack([actor_observations(s, features) for s in states])
        masks = np.stack([s.masks() for s in states])
        logits = np.concatenate([
            masked_logits(actor, obs[a:b].reshape(-1, *obs.shape[2:]),
                          masks[a:b].reshape(-1, N_ACTIONS)).reshape(b - a, -1, N_ACTIONS)
            for a, b in groups])
        # As the coma planner flies: in agent order, avoiding heard teammates' targets and,
        # for a gain-prior actor, discounting their footprints.
        if discount is None:
            return np.stack([choose_in_order(scores, s.positions, mask, s.heard)
                             for scores, s, mask in zip(logits, states, masks, strict=True)])
        return np.stack([
            choose_greedy(actor, planes, mask, agent_views(s, with_observations=False),
                          discount, scores)
            for planes, scores, s, mask in zip(obs, logits, states, masks, strict=True)])

    flight = fly_missions(start_missions(env_config, seed, first_mission, n_missions,
                                         namespace, geometry), act)
    return GreedyFlights(rewards=flight.rewards, entropy=flight.curve("entropy"),
                         f1=flight.curve("f1"))


def evaluate_greedy(actor: nn.Module, env_config: EnvConfig, geometry: MissionGeometry,
                    seed: int, n_missions: int, namespace: str = "validation"
                    ) -> dict[str, float]:
    """Mean entropy and F1 of the greedy policy on held-out missions, after every step.

    Returns:
        ``entropy_s`` and ``f1_s`` for s = 0..B, and ``return``: the mean team return.
    """
    return fly_greedy(actor, env_config, geometry, seed, 0, n_missions, namespace).scores()


def validate(actor: nn.Module, settings: Sequence[EnvConfig],
             geometries: Sequence[MissionGeometry] | None, seed: int, n_missions: int,
             reference: Sequence[float] | None = None,
             fly: Callable[[int, int], GreedyFlights] | None = None) -> dict[str, float]:
    """:func:`evaluate_greedy` on every setting, averaged key by key over the settings.

    With ``reference`` (a planner's mean final entropy per setting, same missions) it also
    gives ``gap_worst`` and ``gap_mean``: the largest and the mean of the policy's mean final
    entropy minus the reference's over the settings. ``fly(k, n_missions)``, if given, flies
    the missions of setting ``k`` instead of this process (``coma.parallel``'s workers, with
    ``actor``'s weights; ``geometries`` may then be None); the scores are the same.
    """
    if fly is None:
        if geometries is None:
            raise ValueError("validate needs the settings' geometries or a fly function")

        def fly(k: int, count: int) -> GreedyFlights:
            return fly_greedy(actor, settings[k], geometries[k], seed, 0, count)

    scores = [fly(k, n_missions).scores() for k in range(len(settings))]
    result = {key: float(np.mean([s[key] for s in scores])) for key in scores[0]}
    if reference is not None:
        budget = settings[0].team.budget
        gaps = [s[f"entropy_{budget}"] - r for s, r in zip(scores, reference, strict=True)]
        result.update(gap_worst=float(max(gaps)), gap_mean=float(np.mean(gaps)))
    return result


def validation_settings(coma_config: COMAConfig, settings: Sequence[EnvConfig]
                        ) -> list[EnvConfig]:
    """The validation missions' configs: every training setting on every validation terrain
    (``coma_config.validation_terrains``) at every validation resolution
    (``coma_config.validation_resolutions``); none of either: the settings themselves."""
    checks = list(settings)
    if coma_config.validation_terrains:
        checks = [config.replace(terrain={"kind": kind}) for config in checks
                  for kind in coma_config.validation_terrains]
    if coma_config.validation_resolutions:
        checks = [config.replace(world={"resolution": float(metres)}) for config in checks
                  for metres in coma_config.validation_resolutions]
    return checks


def reference_scores(settings: Sequence[EnvConfig], seed: int, n_missions: int,
                     planner: str = "ig", workers: int = 1, backend: str = "local",
                     address: str | None = None) -> list[float]:
    """``planner``'s mean final entropy on the validation missions of each setting (the
    missions :func:`evaluate_greedy` flies), for ``selection = "worst_vs_ig"``; flown by
    :func:`ipp_toolkit.runs.evaluation.evaluate` with ``workers``, ``backend`` and ``address``
    (the same numbers on any)."""
    from ipp_toolkit.runs.evaluation import evaluate

    scores = []
    for config in settings:
        result = evaluate(config, [planner], missions=n_missions, seed=seed,
                          namespace="validation", progress=False, workers=workers,
                          backend=backend, address=address)
        budget = config.team.budget
        scores.append(float(np.mean([r["entropy"] for r in result.rows
                                     if int(r["step"]) == budget])))
    return scores
