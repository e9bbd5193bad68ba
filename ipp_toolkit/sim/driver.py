"""The mission driver: E missions of one run, flown in lock-step to the end of the budget.

One loop drives every whole-mission flight of the project: the evaluation's
:func:`ipp_toolkit.runs.evaluation.run_mission` (E = 1, a planner's timed ``act``), COMA's
rollouts (``coma.rollout.collect_rollout``: the sampled actor, or demonstrator planners for
the warm start) and its greedy validation flights (``coma.validation.fly_greedy``). The
driver owns what they share: the missions' reset (:func:`start_missions`), the budget and
the end of a mission, the stepping and the team rewards, and the final histories
(:class:`Flight`). The caller owns the decisions: per step, its ``policy`` is given the E
states at the decision point and returns their joint actions, building whatever it needs
from them (COMA its actor planes, the evaluation its planner views) and recording it (COMA
keeps its critic inputs, built from the state and the joint action just chosen).

:class:`ipp_toolkit.env.IPPEnv` does not use it: its ``step`` is a step-at-a-time API (the
agent loop is its user's: PettingZoo, SB3, TorchRL), it flies one mission with a terrain that
may be given (``ground_truth``, ``raster``), and it has its own conventions for failed UAVs
(terminated, or kept with zero planes); it calls the same :func:`reset_mission` and
:func:`step_mission`, so a mission flown with the same actions is the same mission
(``tests/test_driver.py`` checks that COMA's observations equal the env's).

Same seed, same numbers: the driver adds no randomness and visits the missions in index
order, so a mission flown through it is, to the last bit, the mission its caller flew with
its own loop before.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ..config.schema import EnvConfig
from .mission import MissionGeometry, MissionState, reset_mission, step_mission

__all__ = ["Flight", "JointPolicy", "Observer", "fly_missions", "start_missions"]

JointPolicy = Callable[[Sequence[MissionState]], Sequence[np.ndarray | Sequence[int]]]
"""``policy(states) -> actions``: given the E missions at a decision point (not to be
modified), the joint action of each, ``actions[e]`` of shape (N,) int (an (E, N) array
will do). Called once per step, before any mission is stepped."""

Observer = Callable[[Sequence[MissionState]], None]
"""``observer(states)``: called after the reset and after every step (not to modify them)."""


@dataclass
class Flight:
    """E missions flown to the end of their budget B.

    Attributes:
        states: the E finished missions (``states[e].history`` holds B + 1 metrics).
        rewards: (E, B) float64 team reward of every step.
    """

    states: list[MissionState]
    rewards: np.ndarray

    def returns(self) -> np.ndarray:
        """(E,) float64 undiscounted returns, added step by step (as a loop that adds each
        step's rewards as they come would, so the sums do not depend on how they are
        computed)."""
        total = np.zeros(len(self.states))
        for column in self.rewards.T:
            total += column
        return total

    def curve(self, metric: str) -> np.ndarray:
        """(E, B + 1) float64 metric of the global map after every step (step 0: the start):
        ``entropy``, ``f1`` or ``rmse``."""
        if metric not in ("entropy", "f1", "rmse"):
            raise ValueError(f"metric must be entropy, f1 or rmse, got {metric!r}")
        return np.array([[getattr(m, metric) for m in s.history] for s in self.states],
                        dtype=np.float64).reshape(len(self.states), -1)


def start_missions(config: EnvConfig, seed: int, first_mission: int, n_missions: int,
                   namespace: str = "train", geometry: MissionGeometry | None = None
                   ) -> list[MissionState]:
    """Reset missions ``first_mission .. first_mission + n_missions - 1`` of run ``seed``.

    Returns:
        E = ``n_missions`` states at step 0 (:func:`reset_mission` of each, in index order,
        sharing ``geometry``, built once when omitted).
    """
    geometry = geometry if geometry is not None else MissionGeometry(config)
    return [reset_mission(config, seed, first_mission + e, namespace, geometry)
            for e in range(n_missions)]


def fly_missions(states: Sequence[MissionState], policy: JointPolicy,
                 observer: Observer | None = None) -> Flight:
    """Fly E missions at step 0 in lock-step to the end of their (common) budget B.

    Per step: ``actions = policy(states)``, then every mission takes its joint action
    (``step_mission(states[e], actions[e])``, in mission order), then ``observer(states)``.

    Args:
        states: E missions from :func:`start_missions` (or :func:`reset_mission`), none
            stepped yet, all with the same budget.
        policy: the joint actions of every mission at each step (see :data:`JointPolicy`).
        observer: called with the states after the reset and after every step.

    Returns:
        the :class:`Flight`: the finished states and the (E, B) rewards.

    Raises:
        ValueError: no states, a state already stepped, budgets that differ, or a policy
            that returns a number of joint actions other than E.
        InvalidActionError: (from :func:`step_mission`) a masked or out-of-range action.
    """
    states = list(states)
    if not states:
        raise ValueError("fly_missions needs at least one mission")
    budget = states[0].budget
    if any(s.step != 0 for s in states) or any(s.budget != budget for s in states):
        raise ValueError("fly_missions flies missions from step 0 with one budget; got steps "
                         f"{[s.step for s in states]} and budgets {[s.budget for s in states]}")
    rewards = np.zeros((len(states), budget))
    if observer is not None:
        observer(states)
    for step in range(budget):
        actions = policy(states)
        if len(actions) != len(states):
            raise ValueError(f"the policy returned {len(actions)} joint actions for "
                             f"{len(states)} missions")
        for e, state in enumerate(states):
            rewards[e, step] = step_mission(state, actions[e])
        if observer is not None:
            observer(states)
    return Flight(states, rewards)
