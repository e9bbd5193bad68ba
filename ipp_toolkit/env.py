"""PettingZoo ``ParallelEnv`` shell over the mission core.

Spaces per agent (G = 11 at the defaults, C = number of actor planes switched on, 7 by
default):

* observation: ``Dict(observation=Box(-1, 1, (C, G, G), float32),
  action_mask=Box(0, 1, (6,), int8))``; the mask is there only, not in the infos. With
  ``features.observation = "box"`` (or ``IPPEnv(observation="box")``) it is the
  ``Box(-1, 1, (C, G, G), float32)`` planes alone, which SuperSuit's observation wrappers
  (``black_death_v3``, ``frame_stack_v1``, ``normalize_obs_v0``, ``flatten_v0``, ...) take,
  and the mask is in ``info["action_mask"]`` ((6,) int8) and :meth:`IPPEnv.action_mask`.
  With ``features.observation = "rllib"`` it is the layout of RLlib's action-masking
  examples (its ``ActionMaskingTorchRLModule``): ``Dict(observations=Box(-1, 1, (C*G*G,),
  float32), action_mask=Box(0, 1, (6,), int8))``, the same planes flattened (RLlib's
  default encoders take a flat ``Box``) and the same mask (int8, as Gymnasium's masked
  ``sample`` and PettingZoo's API test want it; that module's log of it is a float).
* infos: flat, numeric and with the same keys at reset and at every step (so TorchRL's
  ``PettingZooWrapper`` and BenchMARL can turn them into tensors): ``step`` (int),
  ``blocked`` (bool, held back by the same-target rule this step), ``invalid_action`` (bool,
  held in place this step because its action was masked) and ``entropy``, ``f1``, ``rmse``
  (float, of the global map; the same for every agent).
* action: ``Discrete(6)``: 0 up, 1 north (+y), 2 east (+x), 3 south, 4 west, 5 down.
* invalid actions: by default (``invalid_action="hold"``) a masked action holds the UAV in
  place for the step (it still measures) and flags ``info["invalid_action"]``, so tools that
  sample without the mask (``action_space.sample()``, RLlib's pre-check, TorchRL transforms and
  batched envs, SuperSuit) run; ``invalid_action="raise"`` makes it an error, as the mission
  core does unless ``team.invalid_action="hold"``.
* ``state()``: ``Box(0, 1, (C_state, G, G), float32)``, the centralised critic's global planes.

Every agent gets the same team reward. After ``budget`` steps every agent is terminated (a
true terminal, not a truncation). A UAV that fails (``team.failures``) is terminated at the
step it fails (PettingZoo's convention for an agent leaving: its last observation and reward
come with the termination, then it is gone from ``agents``); the others fly on. With
``keep_failed=True`` (the SB3 view, which needs fixed slots) it stays instead, SuperSuit's
"black death": zero observation planes, an all-valid mask, reward 0, its actions ignored,
until the mission ends. Seeding: ``reset(seed=s)`` starts mission 0 of run ``s``;
later ``reset()`` calls without a seed run missions 1, 2, ... of the same run, and
``reset(options={"mission": k})`` jumps to mission k, so evaluations can replay a mission.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec, parallel_to_aec_wrapper

from .config.files import ConfigLike, as_env_config
from .config.schema import OBSERVATION_KINDS
from .sim.features import (
    actor_observations,
    actor_plane_names,
    critic_observations,
    global_state,
    state_plane_names,
)
from .sim.mission import (
    InvalidActionError,
    MissionGeometry,
    MissionState,
    agent_label,
    reset_mission,
    step_mission,
)
from .sim.team import ACTION_NAMES, N_ACTIONS
from .world.seeding import check_namespace

__all__ = ["INVALID_ACTION_POLICIES", "IPPEnv", "env", "parallel_env", "raw_env"]

INVALID_ACTION_POLICIES = ("hold", "raise")


def action_index(agent: str, action: Any) -> int:
    """``action`` as an action index 0..5 (InvalidActionError naming ``agent`` otherwise):
    an integer or a one-element array of one, not a bool, never wider than an index."""
    if isinstance(action, np.ndarray):
        if action.size != 1:
            raise InvalidActionError(f"agent {agent!r}: action {action!r} must be one integer")
        action = action.reshape(()).item()
    if isinstance(action, bool) or not isinstance(action, int | np.integer):
        raise InvalidActionError(f"agent {agent!r}: action {action!r} must be an integer in "
                                 f"0..{N_ACTIONS - 1}")
    if not 0 <= action < N_ACTIONS:
        raise InvalidActionError(f"agent {agent!r}: action {action!r} is out of range; valid "
                                 f"indices are 0..{N_ACTIONS - 1} {ACTION_NAMES}")
    return int(action)


class IPPEnv(ParallelEnv):
    """Multi-UAV informative path planning as a PettingZoo parallel environment.

    Args:
        config: the mission configuration (defaults reproduce the paper): an ``EnvConfig``, a
            plain dict of sections (``{"team": {"n_agents": 2}}``) or a YAML file's path.
        render_mode: ``None``, ``"rgb_array"`` (``render()`` returns the frame) or
            ``"human"`` (a matplotlib window shows it at reset and every step).
        namespace: random-stream namespace: ``train``, ``validation`` or ``test``.
        ground_truth: (H, W) bool terrain used for every mission instead of the generator.
        raster: (h, w) array for ``terrain.kind = "raster"`` instead of the file.
        keep_failed: keep failed UAVs as inert agents instead of terminating them (see the
            module docstring).
        invalid_action: what a masked action does: ``hold`` (default: the UAV stays for the
            step, ``info["invalid_action"]`` is True) or ``raise`` (an ``InvalidActionError``,
            for strict use). A config that says ``team.invalid_action="hold"`` holds either way.
        observation: ``dict``, ``box`` or ``rllib`` (see the module docstring); None
            (default): the config's ``features.observation``.
    """

    metadata = {"name": "ipp_v0", "render_modes": ["human", "rgb_array"],
                "is_parallelizable": True, "render_fps": 2}

    def __init__(self, config: ConfigLike = None, *, render_mode: str | None = None,
                 namespace: str = "train", ground_truth: np.ndarray | None = None,
                 raster: np.ndarray | None = None, keep_failed: bool = False,
                 invalid_action: str = "hold", observation: str | None = None):
        self.config = as_env_config(config)
        if invalid_action not in INVALID_ACTION_POLICIES:
            raise ValueError(f"invalid_action must be one of {INVALID_ACTION_POLICIES}, got "
                             f"{invalid_action!r}")
        self.invalid_action = invalid_action
        # self.config stays the caller's (COMA reads team.invalid_action="hold" as its no-mask
        # ablation); the missions run under the env's own rule for masked actions.
        self._mission_config = self.config.replace(team={"invalid_action": "hold"}) \
            if invalid_action == "hold" else self.config
        self.keep_failed = bool(keep_failed)
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode {render_mode!r} is not supported; "
                             f"choose from {self.metadata['render_modes']}")
        self.render_mode = render_mode
        self.namespace = check_namespace(namespace)
        self.geometry = MissionGeometry(self._mission_config)
        self._ground_truth = ground_truth
        self._raster = raster
        n = self.config.team.n_agents
        self.possible_agents = [agent_label(k) for k in range(n)]
        self.agents: list[str] = []
        self._index = {agent: k for k, agent in enumerate(self.possible_agents)}
        g = self.geometry.grid_points
        features = self.config.features
        self.observation_kind = features.observation if observation is None else observation
        if self.observation_kind not in OBSERVATION_KINDS:
            raise ValueError(f"observation must be one of {OBSERVATION_KINDS}, got "
                             f"{self.observation_kind!r}")
        planes = spaces.Box(-1.0, 1.0, (len(actor_plane_names(features)), g, g), dtype=np.float32)
        if self.observation_kind == "box":
            self._observation_space: spaces.Space = planes
        else:
            mask = spaces.Box(0, 1, (N_ACTIONS,), dtype=np.int8)
            self._observation_space = spaces.Dict({"observation": planes, "action_mask": mask}) \
                if self.observation_kind == "dict" else spaces.Dict({
                    "observations": spaces.Box(-1.0, 1.0, (int(np.prod(planes.shape)),),
                                               dtype=np.float32),
                    "action_mask": mask})
        self._action_space = spaces.Discrete(N_ACTIONS)
        self.state_space = spaces.Box(0.0, 1.0, (len(state_plane_names(features)), g, g),
                                      dtype=np.float32)
        self._window: Any = None  # the human render mode's FrameWindow
        self._seed: int | None = None
        self._mission_index = -1
        self.mission: MissionState | None = None

    # PettingZoo's tests assert the very same space object on every call: return the one built.
    def observation_space(self, agent: str) -> spaces.Space:
        self._agent_index(agent)
        return self._observation_space

    def action_space(self, agent: str) -> spaces.Space:
        self._agent_index(agent)
        return self._action_space

    def _agent_index(self, agent: str) -> int:
        try:
            return self._index[agent]
        except KeyError:
            raise ValueError(f"unknown agent {agent!r}; agents are {self.possible_agents}") \
                from None

    def reset(self, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[dict, dict]:
        """Start a mission; see the module docstring for the seeding rules.

        Args:
            seed: run seed; starts mission 0 of that run.
            options: ``{"mission": k}`` jumps to mission k of the current run.

        Returns:
            observations and infos per agent.
        """
        if seed is not None:
            if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
                raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
            self._seed = int(seed)
            self._mission_index = 0
        else:
            if self._seed is None:
                # Unseeded: fresh OS entropy, so copies of one env never replay each other.
                self._seed = int(np.random.SeedSequence().entropy % (2**63))
            self._mission_index += 1
        if options is not None and not isinstance(options, Mapping):
            raise TypeError(f"options must be a dict such as {{'mission': 3}} or None, got "
                            f"{type(options).__name__} {options!r:.80}")
        unknown = sorted(map(str, set(options or {}) - {"mission"}))
        if unknown:  # a warning, not an error: PettingZoo's API test passes other options
            warnings.warn(f"ignoring unknown reset option(s) {unknown}; the only option is "
                          "'mission'", UserWarning, stacklevel=2)
        if options and "mission" in options:
            mission = options["mission"]
            if isinstance(mission, bool) or not isinstance(mission, int | np.integer) \
                    or mission < 0:
                raise ValueError(f"options['mission'] must be a non-negative integer, "
                                 f"got {mission!r}")
            self._mission_index = int(mission)
        self.mission = reset_mission(self._mission_config, self._seed, self._mission_index,
                                     self.namespace, self.geometry, self._ground_truth,
                                     self._raster)
        self.agents = list(self.possible_agents)
        if self.render_mode == "human":
            self.render()
        return self._observe(self.agents), self._infos(self.agents)

    def step(self, actions: dict[str, int]) -> tuple[dict, dict, dict, dict, dict]:
        """Advance all agents by one step.

        Args:
            actions: one action index per live agent (failed ones kept by ``keep_failed``
                included; their actions are ignored).

        Returns:
            observations, rewards, terminations, truncations and infos per agent.

        Raises:
            ValueError: an agent is missing or unknown, an action is out of range, or (with
                ``invalid_action="raise"``) masked.
        """
        if not isinstance(actions, Mapping):
            raise TypeError(f"actions must be a dict of agent name -> action index, got "
                            f"{type(actions).__name__} {actions!r:.80}")
        if self.mission is None:
            raise RuntimeError("call reset() before step()")
        if not self.agents:
            if actions:
                raise RuntimeError("the mission is over; call reset()")
            return {}, {}, {}, {}, {}
        unknown = sorted(set(actions) - set(self.agents))
        if unknown:
            raise InvalidActionError(f"actions for unknown or finished agents {unknown}; "
                                     f"live agents are {self.agents}")
        missing = [agent for agent in self.agents if agent not in actions]
        if missing:
            raise InvalidActionError(f"no action for agent(s) {missing}")
        joint = np.zeros(len(self.possible_agents), dtype=np.int64)  # gone agents: ignored
        for agent in self.agents:
            joint[self._index[agent]] = action_index(agent, actions[agent])
        was_alive = self.mission.alive.copy()
        reward = step_mission(self.mission, joint)
        agents = list(self.agents)
        observations = self._observe(agents)
        done = self.mission.done
        alive = self.mission.alive
        rewards = {agent: reward if was_alive[self._index[agent]] else 0.0 for agent in agents}
        terminations = {agent: done or not (self.keep_failed or alive[self._index[agent]])
                        for agent in agents}
        truncations = dict.fromkeys(agents, False)
        infos = self._infos(agents)
        self.agents = [agent for agent in agents if not terminations[agent]]
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminations, truncations, infos

    def _observe(self, agents: list[str] | None = None) -> dict[str, dict[str, np.ndarray]]:
        agents = self.agents if agents is None else agents
        planes = actor_observations(self.mission, self.config.features)
        masks = self._masks()
        planes[~self.mission.alive] = 0.0  # a failed UAV observes nothing
        if self.observation_kind == "box":
            return {agent: planes[self._index[agent]] for agent in agents}
        if self.observation_kind == "rllib":
            return {agent: {"observations": planes[self._index[agent]].reshape(-1),
                            "action_mask": masks[self._index[agent]]}
                    for agent in agents}
        return {agent: {"observation": planes[self._index[agent]],
                        "action_mask": masks[self._index[agent]]} for agent in agents}

    def _masks(self) -> np.ndarray:
        """(N, 6) int8 valid actions now; a failed UAV's (ignored) action may be any."""
        masks = self.mission.masks()
        masks[~self.mission.alive] = 1
        return masks

    def _infos(self, agents: list[str]) -> dict[str, dict[str, Any]]:
        # Flat scalars with fixed keys: TorchRL builds its info spec from the reset infos and
        # writes every step's values into it (a nested dict or a key missing at reset breaks it).
        metrics = {key: float(value) for key, value in self.mission.history[-1].as_dict().items()}
        infos = {agent: {"step": int(self.mission.step),
                         "blocked": bool(self.mission.blocked[self._index[agent]]),
                         "invalid_action": bool(self.mission.held_invalid[self._index[agent]]),
                         **metrics}
                 for agent in agents}
        if self.observation_kind == "box":  # the mask is not in the observation: here
            masks = self._masks()
            for agent in agents:
                infos[agent]["action_mask"] = masks[self._index[agent]]
        return infos

    def state(self) -> np.ndarray:
        """(C_state, G, G) float32 global planes for the centralised critic, within
        ``state_space``."""
        if self.mission is None:
            raise RuntimeError("call reset() before state()")
        # The weighted-entropy plane can round to -6e-10; clip so state_space holds it.
        return np.clip(global_state(self.mission, self.config.features), 0.0, 1.0)

    def critic_observations(self, joint_action: dict[str, int] | np.ndarray) -> np.ndarray:
        """(N, C_critic, G, G) per-agent critic inputs for a joint action chosen now."""
        if self.mission is None:
            raise RuntimeError("call reset() before critic_observations()")
        if isinstance(joint_action, dict):
            missing = [a for a in self.possible_agents if a not in joint_action]
            if missing:
                raise InvalidActionError(f"no action for agent(s) {missing}")
            joint_action = [joint_action[a] for a in self.possible_agents]
        values = list(np.asarray(joint_action, dtype=object).reshape(-1)) \
            if not isinstance(joint_action, list | tuple) else list(joint_action)
        if len(values) != len(self.possible_agents):
            raise InvalidActionError(f"expected one action per agent "
                                     f"({len(self.possible_agents)}), got {len(values)}")
        joint = np.array([action_index(agent, action) for agent, action
                          in zip(self.possible_agents, values, strict=True)], dtype=np.int64)
        return critic_observations(self.mission, self.config.features, joint)

    def action_mask(self, agent: str) -> np.ndarray:
        """(6,) int8 valid actions of ``agent`` now (all valid for a failed UAV)."""
        if self.mission is None:
            raise RuntimeError("call reset() before action_mask()")
        return self._masks()[self._agent_index(agent)]

    def render(self) -> np.ndarray | None:
        """An RGB frame (h, w, 3) uint8 (``rgb_array``): terrain, global map, UAVs,
        footprints, local maps; ``human`` shows it in a window (and returns None), as reset
        and every step then do."""
        if self.render_mode is None:
            return None
        if self.mission is None:
            raise RuntimeError("call reset() before render()")
        from .sim.rendering import render_state

        frame = render_state(self.mission)
        if self.render_mode != "human":
            return frame
        if self._window is None:
            from .sim.window import FrameWindow

            self._window = FrameWindow(f"ipp-toolkit: {len(self.possible_agents)} UAVs",
                                       self.metadata["render_fps"])
        self._window.show(frame)
        return None

    def close(self) -> None:
        """Close the ``human`` window, if any (idempotent)."""
        if self._window is not None:
            self._window.close()


def parallel_env(config: ConfigLike = None, **kwargs: Any) -> IPPEnv:
    """PettingZoo-style factory: ``parallel_env(config, render_mode=...)``."""
    return IPPEnv(config, **kwargs)


def raw_env(config: ConfigLike = None, **kwargs: Any) -> AECEnv:
    """The env as a PettingZoo AEC env (agents act in turn), without the order-enforcing
    wrapper: PettingZoo's ``parallel_to_aec_wrapper`` over :class:`IPPEnv`; the arguments are
    :class:`IPPEnv`'s."""
    return parallel_to_aec_wrapper(IPPEnv(config, **kwargs))


def env(config: ConfigLike = None, **kwargs: Any) -> AECEnv:
    """PettingZoo-style AEC factory: ``env(config, render_mode=...)`` is
    ``pettingzoo.utils.parallel_to_aec(IPPEnv(config, ...))`` (agents act in turn, the team
    moves once every live agent has acted; the order is enforced)."""
    return parallel_to_aec(IPPEnv(config, **kwargs))
