"""One UAV's decisions as a Gymnasium env, registered as ``ipp_toolkit/UAV-v0``.

The parameter-sharing problem for single-agent tools: one policy flies every UAV of the team,
one UAV at a time. Each ``step`` is one UAV's move; once every flying UAV of the team has
chosen, the team moves together (as in :class:`~ipp_toolkit.env.IPPEnv`) and the next UAV to
choose is the first of the next step. So ``gymnasium.make`` and any single-agent learner
(SB3's PPO, DQN, ..., sb3-contrib's MaskablePPO through :meth:`IPPUAVEnv.action_masks`) train
one shared policy on the very observations and actions the SB3 per-UAV view
(:func:`ipp_toolkit.vec.make_sb3_vec_env`) gives, and its ``model.save`` zips fly with
``ipp-compare --planners sb3=PATH.zip``.

* observation: ``Box(-1, 1, (C, G, G), float32)``, the actor planes of the UAV whose turn it
  is (``info["uav"]``), taken when the team last moved: a UAV does not see its teammates'
  choices of the same step;
* action: ``Discrete(6)``, that UAV's move (0 up, 1 north, 2 east, 3 south, 4 west, 5 down);
* masks: :meth:`IPPUAVEnv.action_masks` (6,) bool of that UAV, also ``info["action_mask"]``
  (6,) int8. A masked move holds the UAV for the step (``info["invalid_action"]`` of the move
  just made); ``invalid_action="raise"`` makes it an ``InvalidActionError`` at once;
* reward: the team reward of a step comes with the move that completes it (the last UAV's),
  0 with the others, so an episode's return is the team's return over the mission;
* episode: one mission, about ``N * budget`` moves, terminated (never truncated) after the
  ``budget``-th team step; a failed UAV (``team.failures``) is skipped (its turns are gone);
* seeding: ``reset(seed=s)`` starts mission 0 of run ``s``, later ``reset()`` calls fly
  missions 1, 2, ... (as in ``IPPEnv``), so SB3's ``evaluate_policy`` on this env counts
  missions as episodes.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from .config.files import ConfigLike
from .env import action_index
from .sim.mission import InvalidActionError
from .sim.team import ACTION_NAMES, N_ACTIONS
from .team_env import UAV_ENV_ID, TeamShell

__all__ = ["UAV_ENV_ID", "IPPUAVEnv"]


class IPPUAVEnv(TeamShell):
    """One UAV at a time of an :class:`~ipp_toolkit.env.IPPEnv` team (module docstring).

    Args: as :class:`~ipp_toolkit.team_env.TeamShell`'s: ``config`` (an ``EnvConfig``, a dict
    of sections or a YAML file's path), ``render_mode``, ``namespace``, ``invalid_action``
    (``hold`` or ``raise``). A failed UAV's turns are skipped.
    """

    def __init__(self, config: ConfigLike = None, *, render_mode: str | None = None,
                 namespace: str = "train", invalid_action: str = "hold"):
        super().__init__(config, render_mode=render_mode, namespace=namespace,
                         invalid_action=invalid_action)
        self.observation_space = self._env.observation_space(
            self._env.possible_agents[0])["observation"]
        self.action_space = spaces.Discrete(N_ACTIONS)
        self._observations: dict[str, dict[str, np.ndarray]] = {}
        self._order: list[int] = []   # the UAVs choosing in this team step, in index order
        self._turn = 0                # index into _order of the UAV choosing now
        self._joint = np.zeros(len(self._env.possible_agents), dtype=np.int64)

    @property
    def uav(self) -> int:
        """Index of the UAV whose move the next ``step`` takes."""
        return self._order[self._turn]

    def _start_step(self, observations: dict[str, dict[str, np.ndarray]]) -> None:
        self._observations = observations
        mission = self._env.mission
        # The UAVs that fly the coming step (one failing at it is out already, as in the core).
        self._order = np.flatnonzero(mission.failure_step > mission.step + 1).tolist()
        if not self._order:  # the mission is over: the last observer stays UAV 0
            self._order = [0]
        self._turn = 0
        self._joint[:] = 0  # a failed UAV's action is ignored

    def _observe(self, invalid: bool) -> tuple[np.ndarray, dict[str, Any]]:
        """(C, G, G) planes of the UAV choosing now and the info (its mask, the metrics)."""
        agent = self._env.possible_agents[self.uav]
        seen = self._observations[agent]
        metrics = self._env.mission.history[-1]
        info = {"uav": self.uav, "step": int(self._env.mission.step),
                "entropy": float(metrics.entropy), "f1": float(metrics.f1),
                "rmse": float(metrics.rmse), "invalid_action": bool(invalid),
                "action_mask": seen["action_mask"].copy()}
        return np.array(seen["observation"], dtype=np.float32, copy=True), info

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a mission (``options={"mission": k}`` replays mission k).

        Returns:
            the (C, G, G) float32 planes of the first UAV to choose and the info dict.
        """
        super().reset(seed=seed)  # Gymnasium's own np_random, which its checker asks for
        observations, _ = self._env.reset(seed=seed, options=options)
        self._start_step(observations)
        return self._observe(False)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """The move of UAV :attr:`uav` (an integer 0..5); the team moves after the last UAV.

        Returns:
            the next UAV's (C, G, G) planes, the reward (the team's when the team moved, else
            0), terminated (the budget is spent), truncated (always False) and the info dict.

        Raises:
            InvalidActionError: an action that is not one integer in 0..5, or a masked one
                with ``invalid_action="raise"`` (nothing changes).
            RuntimeError: ``step`` before ``reset`` or after the mission ended.
        """
        if self._env.mission is None or not self._order:
            raise RuntimeError("call reset() before step()")
        if self._env.mission.done:
            raise RuntimeError("the mission is over; call reset()")
        agent = self._env.possible_agents[self.uav]
        move = action_index(agent, action)
        mask = self._observations[agent]["action_mask"]
        invalid = not mask[move]
        if invalid and self.invalid_action == "raise":
            valid = [ACTION_NAMES[a] for a in np.flatnonzero(mask)]
            raise InvalidActionError(f"agent {agent!r}: action {move} ({ACTION_NAMES[move]}) "
                                     f"is masked; valid actions are {valid}")
        self._joint[self.uav] = move
        if self._turn + 1 < len(self._order):
            self._turn += 1
            planes, info = self._observe(invalid)
            return planes, 0.0, False, False, info
        observations, _, _, _, _ = self._env.step(
            {a: int(self._joint[k]) for k, a in enumerate(self._env.possible_agents)})
        reward = float(self._env.mission.reward)  # the team's (a failed UAV's own is 0)
        self._start_step(observations)
        planes, info = self._observe(invalid)
        return planes, reward, bool(self._env.mission.done), False, info

    def action_masks(self) -> np.ndarray:
        """(6,) bool valid moves of UAV :attr:`uav` now (what MaskablePPO reads)."""
        if not self._order:
            return np.ones(N_ACTIONS, dtype=bool)
        return self._observations[self._env.possible_agents[self.uav]]["action_mask"] \
            .astype(bool)
