"""The whole UAV team as one Gymnasium agent, registered as ``ipp_toolkit/UAVTeam-v0``.

(``ipp_toolkit/UAV-v0``, :mod:`ipp_toolkit.uav_env`, is the other registered id: one shared
policy choosing one UAV's move at a time, whose SB3 zips the ``sb3`` planner flies.)

Single-agent tools (``gymnasium.make``, Gymnasium's and SB3's ``check_env``, any
single-agent learner) see the team of N UAVs as one agent that picks every UAV's move at
once. With ``team.n_agents = 1`` it is the single-UAV problem.

* action: ``MultiDiscrete([6] * N)``, one move per UAV (0 up, 1 north, 2 east, 3 south,
  4 west, 5 down);
* observation: ``Box(-1, 1, (N * C * G * G,), float32)``, every UAV's actor planes (what
  each UAV itself knows, as in :class:`~ipp_toolkit.env.IPPEnv`), flattened because SB3's
  checker and ``MlpPolicy`` expect a vector; ``obs.reshape(env.unwrapped.plane_shape)``
  gives the (N, C, G, G) planes back;
* masks: :meth:`IPPTeamEnv.action_masks` returns the flat (N * 6,) bool valid moves
  (sb3-contrib's ``MaskablePPO`` reads it for ``MultiDiscrete``), also in
  ``info["action_mask"]`` as (N, 6) int8. A masked move holds that UAV for the step and is
  flagged in ``info["invalid_action"]`` (``invalid_action="raise"`` makes it an error);
* reward: the team reward; after ``budget`` steps the episode terminates (a true terminal,
  never a truncation); a failed UAV (``team.failures``) stays, inert, until the end;
* seeding: ``reset(seed=s)`` starts mission 0 of run ``s``, later ``reset()`` calls fly
  missions 1, 2, ... (as in ``IPPEnv``).
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces

from .config.files import ConfigLike
from .env import IPPEnv
from .sim.team import N_ACTIONS

__all__ = ["ENV_ID", "UAV_ENV_ID", "IPPTeamEnv", "TeamShell", "register_envs"]

ENV_ID = "ipp_toolkit/UAVTeam-v0"
UAV_ENV_ID = "ipp_toolkit/UAV-v0"
"""The per-UAV id (:class:`ipp_toolkit.uav_env.IPPUAVEnv`), registered here with the team's."""


class TeamShell(gymnasium.Env):
    """What both registered Gymnasium envs share: an :class:`~ipp_toolkit.env.IPPEnv` whose
    failed UAVs keep their slots, inert (``keep_failed=True``), its rendering and closing.

    Args:
        config: the mission configuration: an ``EnvConfig``, a dict of sections or a YAML
            file's path (defaults reproduce the paper: 4 UAVs).
        render_mode: ``None``, ``"rgb_array"`` or ``"human"`` (a window, updated at every
            team step).
        namespace: random-stream namespace: ``train``, ``validation`` or ``test``.
        invalid_action: ``hold`` (default: a masked move holds that UAV) or ``raise``.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 2}

    def __init__(self, config: ConfigLike = None, *, render_mode: str | None = None,
                 namespace: str = "train", invalid_action: str = "hold"):
        # The Dict observation, whatever features.observation says: the mask is read from it.
        self._env = IPPEnv(config, render_mode=render_mode, namespace=namespace,
                           keep_failed=True, invalid_action=invalid_action, observation="dict")
        self.config = self._env.config
        self.render_mode = render_mode
        self.invalid_action = invalid_action

    def render(self) -> np.ndarray | None:
        """An RGB frame (h, w, 3) uint8 with ``render_mode="rgb_array"``, else None (``human``:
        shown in the window)."""
        return self._env.render()

    def close(self) -> None:
        """Nothing to release; may be called more than once."""
        self._env.close()


class IPPTeamEnv(TeamShell):
    """The UAV team of an :class:`~ipp_toolkit.env.IPPEnv` as one Gymnasium agent.

    Args: as :class:`TeamShell`'s. Fixed slots: a failed UAV stays in the joint action and
    observation, inert.
    """

    def __init__(self, config: ConfigLike = None, *, render_mode: str | None = None,
                 namespace: str = "train", invalid_action: str = "hold"):
        super().__init__(config, render_mode=render_mode, namespace=namespace,
                         invalid_action=invalid_action)
        n = self.config.team.n_agents
        planes = self._env.observation_space(self._env.possible_agents[0])["observation"]
        self.plane_shape: tuple[int, ...] = (n, *planes.shape)
        self.observation_space = spaces.Box(-1.0, 1.0, (int(np.prod(self.plane_shape)),),
                                            dtype=np.float32)
        self.action_space = spaces.MultiDiscrete(np.full(n, N_ACTIONS, dtype=np.int64))
        self._masks = np.ones((n, N_ACTIONS), dtype=np.int8)

    def _joint(self, observations: dict, infos: dict) -> tuple[np.ndarray, dict[str, Any]]:
        """(N * C * G * G,) planes and the team's info: metrics, (N,) flags, (N, 6) masks."""
        agents = self._env.possible_agents
        planes = np.stack([observations[a]["observation"] for a in agents]).astype(np.float32)
        planes = planes.reshape(-1)
        self._masks = np.stack([observations[a]["action_mask"] for a in agents])
        first = infos[agents[0]]
        info = {"step": first["step"], "entropy": first["entropy"], "f1": first["f1"],
                "rmse": first["rmse"],
                "blocked": np.array([infos[a]["blocked"] for a in agents]),
                "invalid_action": np.array([infos[a]["invalid_action"] for a in agents]),
                "action_mask": self._masks.copy()}
        return planes, info

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Start a mission (``options={"mission": k}`` replays mission k).

        Returns:
            (N * C * G * G,) float32 planes and the info dict.
        """
        super().reset(seed=seed)  # Gymnasium's own np_random, which its checker asks for
        observations, infos = self._env.reset(seed=seed, options=options)
        return self._joint(observations, infos)

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Move every UAV; ``action`` is (N,) ints in 0..5.

        Returns:
            planes (N * C * G * G,), team reward, terminated (budget spent), truncated (always
            False) and the info dict.
        """
        action = np.asarray(action)
        n = len(self._env.possible_agents)
        if action.shape != (n,):
            raise ValueError(f"expected one move per UAV, shape ({n},), got {action!r}")
        observations, _, terminations, _, infos = self._env.step(
            {agent: action[k] for k, agent in enumerate(self._env.possible_agents)})
        planes, info = self._joint(observations, infos)
        terminated = all(terminations.values())
        # The mission's team reward (a failed UAV's own reward is 0).
        return planes, float(self._env.mission.reward), terminated, False, info

    def action_masks(self) -> np.ndarray:
        """(N * 6,) bool valid moves now, UAV by UAV (MaskablePPO's MultiDiscrete layout)."""
        return self._masks.astype(bool).reshape(-1)

def register_envs() -> None:
    """Register ``ipp_toolkit/UAVTeam-v0`` and ``ipp_toolkit/UAV-v0`` with Gymnasium
    (idempotent).

    ``gymnasium.make(ENV_ID, config=..., render_mode=...)`` then builds an
    :class:`IPPTeamEnv`, ``gymnasium.make(UAV_ENV_ID, ...)`` an
    :class:`~ipp_toolkit.uav_env.IPPUAVEnv`; ``config`` is an ``EnvConfig``, a dict of
    sections or a YAML file's path. Importing :mod:`ipp_toolkit` calls this.
    """
    # No max_episode_steps: the budget end is the env's own true terminal.
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(ENV_ID, entry_point="ipp_toolkit.team_env:IPPTeamEnv")
    if UAV_ENV_ID not in gymnasium.registry:
        gymnasium.register(UAV_ENV_ID, entry_point="ipp_toolkit.uav_env:IPPUAVEnv")
