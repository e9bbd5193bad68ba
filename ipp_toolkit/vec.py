"""Single-policy (parameter-sharing) view of the simulator for Stable-Baselines3.

SuperSuit's ``pettingzoo_env_to_vec_env_v1`` turns one :class:`~ipp_toolkit.env.IPPEnv` into
a vector of N single-agent envs (one per UAV) and ``concat_vec_envs_v1`` stacks ``n_envs``
copies of it, so SB3 sees ``n_envs * N`` envs driven by one shared policy. SuperSuit's own SB3
wrapper is not used: it loses seeds, attribute access (so MaskablePPO crashes), the
termination/truncation split and per-env infos.
:class:`IPPVecEnv` is the project's own SB3 ``VecEnv`` over SuperSuit's gymnasium vector env:

* slot ``c * N + k`` is agent ``k`` of copy ``c``;
* observations are the (C, G, G) float32 actor planes only; the action mask is taken out of
  every observation (including ``info["terminal_observation"]``) and served by
  :meth:`IPPVecEnv.action_masks` as an (n_envs * N, 6) bool array, which sb3-contrib's
  ``MaskablePPO`` finds through ``env_method("action_masks")``;
* seeds: ``seed(s)`` (or ``PPO(seed=s)``) makes the next reset start copy ``c`` on run
  ``s + c`` (mission 0, then 1, 2, ... at every auto-reset), so copies differ and the same
  seed replays the same missions, with any ``num_cpus``;
* invalid actions: ``MaskablePPO`` never samples one (it reads the masks); an algorithm that
  cannot mask (A2C, PPO, DQN, QR-DQN, RecurrentPPO, ...) may. The view's default,
  ``invalid_action="hold"``, holds such a UAV in place for the step (it still measures), sets
  ``info["invalid_action"] = True`` for its slot and subtracts ``invalid_penalty`` (default
  0) from that slot's reward; the action stored by the algorithm is the one executed (a hold
  is what that action does), so no sample is rewritten behind its back.
  ``invalid_action="raise"`` makes it an error (the native env's ``invalid_action``, which
  holds by default too);
* a failed UAV (``team.failures``) keeps its slot, inert until the mission ends: zero planes,
  an all-valid mask, reward 0, its actions ignored (black death);
* the budget end is a true terminal: ``dones`` is True and
  ``info["TimeLimit.truncated"]`` is False, so PPO does not bootstrap past it; the infos of
  that step are the mission's last (``step`` = budget, its final ``entropy`` and ``f1``), the
  next mission's start is in ``reset_infos``;
* ``close()`` stops SuperSuit's worker processes; it also runs at interpreter exit, because
  those non-daemon workers otherwise make the interpreter hang there.
"""

from __future__ import annotations

import atexit
import weakref
from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from .config.files import ConfigLike, as_env_config
from .config.schema import check_int
from .env import INVALID_ACTION_POLICIES, IPPEnv, action_index
from .sim.team import N_ACTIONS
from .world.seeding import check_namespace

__all__ = ["IPPVecEnv", "INVALID_ACTION_POLICIES", "make_sb3_vec_env"]


class IPPVecEnv(VecEnv):
    """SB3 ``VecEnv`` adapter over a SuperSuit vector of :class:`IPPEnv` copies.

    Build it with :func:`make_sb3_vec_env`; the constructor takes SuperSuit's gymnasium
    vector env (``ConcatVecEnv`` or ``ProcConcatVec``) as built there.

    Args:
        venv: SuperSuit's concatenated vector env with Dict observations
            ``{"observation": (C, G, G), "action_mask": (6,)}``.
        n_agents: agents per copy N.
        n_copies: copies of the simulator; ``venv.num_envs`` must be ``n_copies * N``.
        invalid_penalty: subtracted from the reward of a slot whose action was masked (only
            meaningful when the envs hold invalid actions, ``team.invalid_action="hold"``).
    """

    def __init__(self, venv: Any, n_agents: int, n_copies: int, invalid_penalty: float = 0.0):
        n_agents = check_int("n_agents", n_agents, 1)
        n_copies = check_int("n_copies", n_copies, 1)
        if venv.num_envs != n_agents * n_copies:
            raise ValueError(f"the vector env holds {venv.num_envs} agent slots, not "
                             f"{n_copies} copies x {n_agents} agents; one vec env must hold "
                             "one team size")
        space = venv.observation_space
        if not isinstance(space, spaces.Dict) or set(space.spaces) != {"observation",
                                                                       "action_mask"}:
            raise ValueError(f"expected Dict(observation, action_mask) observations, got {space}")
        if not np.isfinite(invalid_penalty) or invalid_penalty < 0:
            raise ValueError(f"invalid_penalty must be a finite number >= 0, got "
                             f"{invalid_penalty!r}")
        self.venv = venv
        self.n_agents = n_agents
        self.n_copies = n_copies
        self.invalid_penalty = float(invalid_penalty)
        self.render_mode = getattr(venv, "render_mode", None)
        super().__init__(n_agents * n_copies, space["observation"], venv.action_space)
        self._masks = np.ones((self.num_envs, N_ACTIONS), dtype=bool)
        self._actions: np.ndarray | None = None
        self._closed = False
        # SuperSuit's workers are not daemons: without close() the interpreter waits for them
        # forever at exit. Registered after the workers exist, so it runs before
        # multiprocessing's own exit handler joins them (atexit runs handlers LIFO).
        ref = weakref.ref(self)

        def _close_at_exit() -> None:
            env = ref()
            if env is not None:
                env.close()

        self._atexit = _close_at_exit
        atexit.register(_close_at_exit)

    # ---------------------------------------------------------------------------------------
    # Observations and masks

    def _split(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        """(num_envs, C, G, G) planes; caches the (num_envs, 6) masks."""
        self._masks = self._clean_masks(obs["action_mask"])
        return np.array(obs["observation"], dtype=np.float32, copy=True)

    @staticmethod
    def _clean_masks(masks: np.ndarray) -> np.ndarray:
        masks = np.asarray(masks).astype(bool)
        # An all-False row would give MaskablePPO NaN logits; no agent of IPPEnv has one, but
        # a row of a broken env must not poison the whole batch.
        masks[~masks.any(axis=1)] = True
        return masks

    def action_masks(self) -> np.ndarray:
        """(num_envs, 6) bool valid actions of every agent slot now."""
        return self._masks.copy()

    # ---------------------------------------------------------------------------------------
    # VecEnv API

    def _reset_venv(self, seed: int | None) -> tuple[dict[str, np.ndarray], list[dict]]:
        from supersuit.vector.multiproc_vec import ProcConcatVec, decompress_info

        venv = self.venv
        if not isinstance(venv, ProcConcatVec):
            # ConcatVecEnv resets copy c with seed + c.
            return venv.reset(seed=seed)
        # ProcConcatVec sends seed + worker index and each worker adds its local copy index,
        # so copies of different workers collide; send each worker seed + its first copy.
        for worker, pipe in enumerate(venv.pipes):
            first = venv.idx_starts[worker] // self.n_agents
            pipe.send(("reset", (None if seed is None else seed + first, None)))
        compressed = venv._receive_info()
        infos = decompress_info(self.num_envs, venv.idx_starts, compressed)
        observations = {key: np.array(value, copy=True)
                        for key, value in venv.observations_buffers.items()}
        return observations, infos

    def reset(self) -> VecEnvObs:
        """Reset every copy; the seed set by :meth:`seed` (if any) is used once.

        Returns:
            (num_envs, C, G, G) float32 observation planes.
        """
        seed = self._seeds[0] if self._seeds and self._seeds[0] is not None else None
        obs, infos = self._reset_venv(None if seed is None else int(seed))
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = [self._clean_info(info) for info in infos]
        return self._split(obs)

    def seed(self, seed: int | None = None) -> Sequence[None | int]:
        """Seed the next reset: copy c starts run ``seed + c`` (a random seed if None)."""
        if seed is None:
            seed = int(np.random.default_rng().integers(0, 2**31 - 1))
        seed = check_int("seed", seed, 0)
        # SB3 convention: one seed per env slot; the slots of copy c share seed + c.
        self._seeds = [seed + slot // self.n_agents for slot in range(self.num_envs)]
        return self._seeds

    def step_async(self, actions: np.ndarray) -> None:
        actions = np.asarray(actions)
        if actions.size != self.num_envs:
            raise ValueError(f"expected one action per agent slot ({self.num_envs}), got an "
                             f"array of shape {actions.shape}")
        actions = actions.reshape(self.num_envs)
        # Checked here, by slot: an out-of-range index would read past the masks below.
        for slot, action in enumerate(actions.tolist()):
            action_index(f"slot {slot}", action)
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        """Step every agent slot (auto-resetting finished copies).

        Returns:
            observations (num_envs, C, G, G) float32, rewards (num_envs,) float32,
            dones (num_envs,) bool and one info dict per slot.
        """
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        actions, self._actions = self._actions, None
        invalid = ~self._masks[np.arange(self.num_envs), np.asarray(actions, dtype=np.int64)]
        obs, rewards, terminated, truncated, infos = self.venv.step(actions)
        rewards = np.asarray(rewards, dtype=np.float32) - np.float32(self.invalid_penalty) * invalid
        terminated = np.asarray(terminated, dtype=bool)
        truncated = np.asarray(truncated, dtype=bool)
        dones = terminated | truncated
        clean = []
        for slot, info in enumerate(infos):
            info = self._clean_info(info)
            info["invalid_action"] = bool(invalid[slot])
            if dones[slot]:
                # The budget end is a true terminal, never a time-limit truncation.
                info["TimeLimit.truncated"] = bool(truncated[slot] and not terminated[slot])
            clean.append(info)
        return (self._split(obs), rewards, dones, clean)

    @staticmethod
    def _clean_info(info: dict[str, Any]) -> dict[str, Any]:
        # Copy: ProcConcatVec hands out one shared object for every empty info dict.
        info = dict(info)
        final = info.pop("terminal_info", None)
        if isinstance(final, dict):  # the mission's last step, not the next one's reset
            info.update(final)
        terminal = info.get("terminal_observation")
        if isinstance(terminal, dict):
            info["terminal_observation"] = np.array(terminal["observation"], dtype=np.float32)
        return info

    def close(self) -> None:
        """Stop SuperSuit's workers (idempotent)."""
        if self._closed:
            return
        self._closed = True
        atexit.unregister(self._atexit)
        self.venv.close()

    def render(self, mode: str | None = None) -> np.ndarray | None:
        """The first copy's RGB frame (rgb_array render mode only)."""
        return self.venv.render()

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [self.venv.render()]

    def _indices(self, indices: VecEnvIndices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int | np.integer):
            return [int(indices)]
        return [int(i) for i in indices]

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """Attributes the adapter itself answers (``render_mode``, ``n_agents``, ...)."""
        if not hasattr(self, attr_name):
            raise AttributeError(f"IPPVecEnv envs have no attribute {attr_name!r}")
        return [getattr(self, attr_name)] * len(self._indices(indices))

    def has_attr(self, attr_name: str) -> bool:
        return hasattr(self, attr_name)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise AttributeError(f"cannot set {attr_name!r} on the envs of an IPPVecEnv")

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        """Only ``action_masks`` is served: one (6,) bool row per requested slot."""
        if method_name != "action_masks":
            raise AttributeError(f"IPPVecEnv serves env_method('action_masks') only, "
                                 f"not {method_name!r}")
        return [self._masks[i].copy() for i in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: VecEnvIndices = None) -> list[bool]:
        return [False] * len(self._indices(indices))

    def __getstate__(self) -> dict[str, Any]:
        raise TypeError("IPPVecEnv cannot be pickled (it may own worker processes)")


class _SlotEnv(IPPEnv):
    """IPPEnv whose last step of a mission also carries its infos under ``terminal_info``:
    SuperSuit resets the copy inside the same step and overwrites the step's infos with the
    next mission's reset infos (same keys), so the final entropy and F1 would be lost."""

    def step(self, actions: dict[str, int]) -> tuple[dict, dict, dict, dict, dict]:
        observations, rewards, terminations, truncations, infos = super().step(actions)
        if not self.agents:
            for info in infos.values():
                info["terminal_info"] = dict(info)
        return observations, rewards, terminations, truncations, infos


def make_sb3_vec_env(config: ConfigLike, n_envs: int = 1, seed: int = 0, num_cpus: int = 0,
                     namespace: str = "train", invalid_action: str = "hold",
                     invalid_penalty: float = 0.0,
                     render_mode: str | None = None) -> IPPVecEnv:
    """SB3 vector env over ``n_envs`` copies of the simulator, one slot per agent.

    Args:
        config: the mission configuration (an ``EnvConfig``, a dict of sections or a YAML
            file's path); every copy has its team of N agents.
        n_envs: copies of the simulator (>= 1, default 1); SB3 sees ``n_envs * N`` envs.
        seed: run seed (>= 0, default 0); copy c starts on run ``seed + c`` at the first
            reset (an SB3 model's ``seed`` replaces it).
        num_cpus: worker processes (0 or 1: all copies in this process). More than
            ``n_envs`` is capped at ``n_envs``.
        namespace: random-stream namespace of the missions (``train`` for training).
        invalid_action: what a masked action does in this view: ``hold`` (default: the UAV
            stays and measures, counted in ``info["invalid_action"]``; every SB3 algorithm
            trains as is) or ``raise`` (an error, the native API's rule). A config that
            already says ``team.invalid_action="hold"`` holds either way.
        invalid_penalty: reward subtracted from a slot whose action was masked (>= 0).
        render_mode: ``None`` or ``"rgb_array"`` (``render()`` then returns the first
            copy's frame, for SB3's ``VecVideoRecorder``).

    Returns:
        an :class:`IPPVecEnv` with observations (C, G, G) float32, ``Discrete(6)`` actions and
        ``action_masks()``; close it (``finally``) when done.

    Raises:
        ValueError: config is not one EnvConfig (e.g. several team sizes), or a bad
            ``n_envs``, ``seed``, ``num_cpus`` or ``namespace``.
    """
    import supersuit as ss

    if isinstance(config, list | tuple):
        sizes = sorted({getattr(getattr(c, "team", None), "n_agents", None) for c in config},
                       key=str)
        raise ValueError(f"config must be one EnvConfig: one vec env holds one team size, got "
                         f"{len(config)} configs with n_agents {sizes}")
    config = as_env_config(config)
    n_envs = check_int("n_envs", n_envs, 1)
    seed = check_int("seed", seed, 0)
    num_cpus = check_int("num_cpus", num_cpus, 0)
    check_namespace(namespace)
    if invalid_action not in INVALID_ACTION_POLICIES:
        raise ValueError(f"invalid_action must be one of {INVALID_ACTION_POLICIES}, got "
                         f"{invalid_action!r}")
    # Fixed slots: a failed UAV stays as an inert agent (black death) until the mission ends.
    env = _SlotEnv(config, namespace=namespace, keep_failed=True, invalid_action=invalid_action,
                   render_mode=render_mode, observation="dict")  # the masks are read from it
    markov = ss.pettingzoo_env_to_vec_env_v1(env)
    # base_class "gymnasium" keeps terminations and truncations apart; IPPVecEnv is the SB3 side.
    venv = ss.concat_vec_envs_v1(markov, n_envs, num_cpus=min(num_cpus, n_envs),
                                 base_class="gymnasium")
    try:
        vec = IPPVecEnv(venv, config.team.n_agents, n_envs, invalid_penalty)
    except BaseException:
        venv.close()
        raise
    vec.render_mode = render_mode  # SuperSuit's worker processes lose it (None)
    vec.seed(seed)
    return vec
