"""Actor and critic feature planes on the 11 x 11 planning grid.

Every plane is G x G (one cell per waypoint). Map planes average the map cells of each
waypoint's 5 m x 5 m block (entropy planes average W H per cell, not H of the mean). Each
plane can be switched off in :class:`~ipp_toolkit.config.schema.FeatureConfig` for ablations.

Value ranges: the centred position plane lies in [-1, 1] (-1 marks out-of-area cells), every
other plane in [0, 1].
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..belief.field_prior import shared_prior
from ..belief.gain import FootprintGainCache
from ..belief.interest import BlockMeanCache, interest_smoother, square_cells
from ..belief.mapping import false_positive_term_applies
from ..config.schema import ACTOR_PLANES, GAIN_INTEREST_SMOOTHED, FeatureConfig, RewardConfig
from ..world.sensor import Camera
from .mission import MissionState
from .team import ACTION_DELTAS, N_ACTIONS

__all__ = [
    "GAIN_PLANES",
    "actor_plane_names",
    "gain_plane_channels",
    "option_gain_cells",
    "relative_option_gains",
    "footprint_gain",
    "gain_normaliser",
    "plane_objective",
    "square_means",
    "gain_planes",
    "state_plane_names",
    "critic_plane_names",
    "actor_observations",
    "global_state",
    "critic_observations",
    "other_action_planes",
]

_STATE_ONLY = ("all_positions", "global_map", "global_entropy", "all_footprints")


#: The planes of the ``gain`` switch, in channel order.
GAIN_PLANES = ("gain_level", "gain_up", "gain_down")


def actor_plane_names(features: FeatureConfig) -> list[str]:
    """Names of the actor's planes in channel order (``gain`` gives :data:`GAIN_PLANES`)."""
    names: list[str] = []
    for name in ACTOR_PLANES:
        if getattr(features, name):
            names += list(GAIN_PLANES) if name == "gain" else [name]
    return names


def gain_plane_channels(features: FeatureConfig) -> list[int]:
    """Channel indices of ``gain_level``, ``gain_up``, ``gain_down`` among the actor's planes.

    Raises:
        ValueError: the ``gain`` planes are switched off.
    """
    if not features.gain:
        raise ValueError("the gain planes are not among the actor's planes "
                         "(features.gain = false); switch them on with --feature gain=true")
    names = actor_plane_names(features)
    return [names.index(name) for name in GAIN_PLANES]


def option_gain_cells(gain_channels: Sequence[int], grid: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where each option's expected gain sits in the agent-centred ``gain`` planes.

    Option a's gain is ``planes[channel[a], row[a], col[a]]``: the horizontal moves read
    ``gain_level`` next to the centre, up and down read the centre of ``gain_up`` /
    ``gain_down``. Learned policies with a gain prior (COMA's ``GainPriorActor``, PPO's
    ``gain_prior``) read their prior here.

    Args:
        gain_channels: the three channels of :func:`gain_plane_channels`.
        grid: G, the side of the planes.

    Returns:
        (channel, row, col), each a (6,) int64 array indexed by action.
    """
    if len(gain_channels) != 3:
        raise ValueError(f"gain_channels = {list(gain_channels)!r} must name the three planes "
                         f"{', '.join(GAIN_PLANES)}")
    level, up, down = (int(c) for c in gain_channels)
    centre = grid // 2
    channel = np.array([up if dz > 0 else down if dz < 0 else level
                        for _, _, dz in ACTION_DELTAS], dtype=np.int64)
    # Window cell (v, u) shows waypoint (y + v - c, x + u - c): option (dx, dy) is at
    # (c + dy, c + dx).
    return channel, centre + ACTION_DELTAS[:, 1], centre + ACTION_DELTAS[:, 0]


def relative_option_gains(gains: Any) -> Any:
    """(B, 6) options' gains (a torch tensor, e.g. read at :func:`option_gain_cells`) -> the
    same over the best option's magnitude: the prior term of the gain-prior policies (COMA's
    ``GainPriorActor``, PPO's ``gain_prior``) before its weight. The best option reads 1, or
    -1 when every option's gain is negative (late in a mission, where only cells believed
    uninteresting are left), so the options keep the order of their gains either way."""
    return gains / (gains.amax(dim=1, keepdim=True).abs() + 1e-8)


def state_plane_names(features: FeatureConfig) -> list[str]:
    """Names of the planes of ``state()``: the budget plus the critic's global planes."""
    names = ["budget"] if features.budget else []
    return names + [name for name in _STATE_ONLY if getattr(features, name)]


def critic_plane_names(features: FeatureConfig) -> list[str]:
    """Names of the critic's planes: the actor's, the global ones, then 6 action planes."""
    names = actor_plane_names(features)
    names += [name for name in _STATE_ONLY if getattr(features, name)]
    if features.other_actions:
        names += [f"other_actions_{a}" for a in range(N_ACTIONS)]
    return names


def _altitude_code(state: MissionState) -> np.ndarray:
    """(N,) altitude of each agent as (iz + 1) / Z: 1/3, 2/3, 1 for three levels."""
    return (state.positions[:, 2] + 1) / state.geometry.n_altitudes


def _position_planes(state: MissionState, centred: bool) -> np.ndarray:
    """(N, G, G) plane (a): the agent and the teammates it hears, by altitude code."""
    g = state.geometry.grid_points
    n = state.n_agents
    codes = _altitude_code(state)
    x, y = state.positions[:, 0], state.positions[:, 1]
    planes = np.zeros((n, g, g))
    if centred:
        c = g // 2
        # Window cell (v, u) of agent k shows grid cell (y_k + v - c, x_k + u - c).
        offsets = np.arange(g) - c
        wy = y[:, None] + offsets[None, :]  # (N, G)
        wx = x[:, None] + offsets[None, :]
        outside = ((wy < 0) | (wy >= g))[:, :, None] | ((wx < 0) | (wx >= g))[:, None, :]
        planes[outside] = -1.0
        k_idx, i_idx = np.nonzero(state.heard)  # agent k hears i (including itself)
        v = y[i_idx] - y[k_idx] + c
        u = x[i_idx] - x[k_idx] + c
        inside = (v >= 0) & (v < g) & (u >= 0) & (u < g)
        planes[k_idx[inside], v[inside], u[inside]] = codes[i_idx[inside]]
    else:
        k_idx, i_idx = np.nonzero(state.heard)
        planes[k_idx, y[i_idx], x[i_idx]] = codes[i_idx]
    return planes


def _footprint_cover(state: MissionState, who: np.ndarray) -> np.ndarray:
    """(K, G, G) coverage of the blocks by the latest footprints selected by ``who`` (K, N).

    Sum over the selected footprints, clipped at 1 (exact where footprints do not overlap).
    """
    x, y, z = state.positions[:, 0], state.positions[:, 1], state.positions[:, 2]
    cover = state.geometry.coverage[z, y, x]  # (N, G, G)
    return np.minimum(np.tensordot(who.astype(np.float32), cover, axes=1), 1.0)


def actor_observations(state: MissionState, features: FeatureConfig) -> np.ndarray:
    """Observations of all agents.

    Returns:
        (N, C_actor, G, G) float32, channels in :func:`actor_plane_names` order.
    """
    n = state.n_agents
    g = state.geometry.grid_points
    maps = state.maps
    planes: list[np.ndarray] = []
    if features.budget:
        planes.append(np.full((n, g, g), (state.budget - state.step) / state.budget))
    if features.agent_id:
        ids = (np.arange(n) + 1) / features.agent_id_scale
        planes.append(np.broadcast_to(ids[:, None, None], (n, g, g)))
    if features.position:
        planes.append(_position_planes(state, features.centred))
    if features.own_position:
        own = np.zeros((n, g, g))
        own[np.arange(n), state.positions[:, 1], state.positions[:, 0]] = _altitude_code(state)
        planes.append(own)
    if features.local_map:
        planes.append(maps.prob_blocks[:n] / maps.blocks.block_area)
    if features.local_entropy:
        planes.append(maps.wentropy_blocks[:n] / maps.blocks.block_area)
    if features.measurement_entropy:
        planes.append(state.measurement_planes)
    if features.footprints:
        planes.append(_footprint_cover(state, state.heard))
    if features.gain:
        planes.extend(np.moveaxis(
            gain_planes(state, features.gain_smoothing, features.gain_interest,
                        features.gain_false_positive, features.gain_false_positive_steps),
            1, 0))
    return np.stack(planes, axis=1).astype(np.float32)


def footprint_gain(state: MissionState, smoothing: float | None = None,
                   interest: str | None = None,
                   false_positive: float | None = None,
                   false_positive_steps: int | None = None) -> np.ndarray:
    """Expected gain of a reading from every waypoint, on every agent's local map.

    The gain of one reading from waypoint (ix, iy, iz) is the sum over its footprint of
    :func:`~ipp_toolkit.belief.mapping.expected_gain` (the ``ig`` planner's objective), divided by
    the cell count of the largest footprint and by the larger class weight: it lies in
    [0, 1] whatever the map resolution, and it ranks the waypoints exactly as the sums do.
    The sums are kept on the state and updated only where the maps changed since the last
    call (:class:`~ipp_toolkit.belief.gain.FootprintGainCache`).

    With ``smoothing > 0`` (metres; None: the mission's ``features.gain_smoothing``, but a
    policy passes its own, as it may fly a mission configured otherwise) the sums are the
    ``ig_spatial`` objective instead:
    :func:`~ipp_toolkit.belief.mapping.interesting_gain` weighted by the smoothed probability of the
    interesting class (:mod:`ipp_toolkit.belief.interest`), divided by the same cell count (at most
    1; slightly negative where only cells believed uninteresting are left).

    With ``interest`` naming a learned field prior (``learned`` or a file; None: the mission's
    ``features.gain_interest``) the probability of interest is the prior's prediction from
    each agent's local map instead of the smoothing: ``ig_learned``'s objective
    (:mod:`ipp_toolkit.belief.field_prior`; one batched forward pass per call).

    With either, ``false_positive`` w > 0 (None: the mission's
    ``features.gain_false_positive``) adds w times
    :func:`~ipp_toolkit.belief.mapping.false_positive_gain` weighted by the probability that
    the cell is *not* interesting, as ``ig_learned(false_positive_weight=w)`` values cells;
    ``false_positive_steps`` k >= 1 (None: the mission's ``features.gain_false_positive_steps``)
    only when at most k steps are left, as ``false_positive_steps=k`` (0: at every step).

    Returns:
        (N, Z, G, G) float32.
    """
    reward = state.config.reward
    features = state.config.features
    smoothing = features.gain_smoothing if smoothing is None else smoothing
    interest = features.gain_interest if interest is None else interest
    false_positive = features.gain_false_positive if false_positive is None else false_positive
    if false_positive_steps is None:
        false_positive_steps = features.gain_false_positive_steps
    if not false_positive_term_applies(state.budget - state.step, false_positive_steps):
        false_positive = 0.0  # the clean-up of the last steps has not begun
    learned = interest != GAIN_INTEREST_SMOOTHED
    objective = plane_objective(smoothing, interest)
    cache = _footprint_cache(state, "gain_cache", objective)
    if objective == "interesting":
        world = state.config.world
        block = square_cells(world.map_cells, world.resolution)
        squares = square_means(state)
        if learned:
            weight = shared_prior(interest).square_values(squares, world.resolution,
                                                          world.map_cells)
        else:
            weight = interest_smoother(world.map_cells, world.resolution,
                                       smoothing).smooth(squares)
        sums = cache.weighted_sums(weight, block)
        if false_positive > 0:
            checking = _footprint_cache(state, "false_positive_cache", "false_positive")
            sums += false_positive * checking.weighted_sums(1.0 - weight, block)
    else:
        sums = cache.sums()
    return (sums / gain_normaliser(reward, state.geometry.camera, objective)).astype(np.float32)


def square_means(state: MissionState) -> np.ndarray:
    """(N, H / s, W / s) float32 the agents' local maps' means over squares of s =
    :func:`~ipp_toolkit.belief.interest.square_cells` cells (about 0.5 m): ``block_means`` of
    the maps to the bit, kept on the state and summed again only where the maps changed
    (:class:`~ipp_toolkit.belief.interest.BlockMeanCache`). The array is the cache's own:
    the next call may change it in place."""
    world = state.config.world
    block = square_cells(world.map_cells, world.resolution)
    means = state.block_mean_cache
    if means is None or means.maps is not state.maps or means.block != block:
        means = state.block_mean_cache = BlockMeanCache(state.maps, state.n_agents, block)
    return means.means()


def plane_objective(smoothing: float, interest: str) -> str:
    """The per-cell objective (:data:`~ipp_toolkit.belief.gain.OBJECTIVES`) the ``gain`` planes
    sum: ``interesting`` weighted by a probability of interest when it is smoothed
    (``smoothing`` > 0 metres) or learned (``interest`` not ``smoothed``), else ``ig``."""
    return "interesting" if smoothing > 0 or interest != GAIN_INTEREST_SMOOTHED else "ig"


def gain_normaliser(reward: RewardConfig, camera: Camera, objective: str) -> float:
    """What :func:`footprint_gain` divides a footprint's sum of the per-cell ``objective`` by:
    the cell count of the largest footprint, times the larger class weight for ``ig``, so
    the gain lies in [0, 1] whatever the map resolution."""
    scale = 1.0
    if objective != "interesting":
        scale = max(reward.weight_interesting, reward.weight_uninteresting, 1e-12)
    return camera.largest_footprint_cells * scale


def _footprint_cache(state: MissionState, slot: str, objective: str) -> FootprintGainCache:
    """The :class:`~ipp_toolkit.belief.gain.FootprintGainCache` of ``objective`` kept in the
    state's attribute ``slot`` (``gain_cache`` or ``false_positive_cache``), built anew when
    the maps or the objective changed."""
    cache = getattr(state, slot)
    if cache is None or cache.maps is not state.maps or cache.objective != objective:
        reward = state.config.reward
        cache = FootprintGainCache(state.maps, state.n_agents, state.geometry.camera,
                                   (reward.weight_interesting, reward.weight_uninteresting),
                                   objective)
        setattr(state, slot, cache)
    return cache


def gain_planes(state: MissionState, smoothing: float | None = None,
                interest: str | None = None, false_positive: float | None = None,
                false_positive_steps: int | None = None) -> np.ndarray:
    """The ``gain`` planes: :func:`footprint_gain` (of ``smoothing``, ``interest``,
    ``false_positive`` and ``false_positive_steps``) at the
    agent's altitude, above and below, in an 11 x 11 window centred on the agent.

    Window cell (v, u) of agent k shows waypoint (y_k + v - c, x_k + u - c), c = G // 2, so the
    six options of every decision sit at the same cells: the four horizontal moves next to
    the centre of ``gain_level``, up and down at the centre of ``gain_up`` / ``gain_down``
    (an absolute-frame plane would make the network look the agent up first; imitating ``ig``
    from it reached 71 % agreement, as without the planes). Outside the area, and where the
    altitude above or below does not exist, the planes are 0.

    Returns:
        (N, 3, G, G) float32 in :data:`GAIN_PLANES` order.
    """
    gain = footprint_gain(state, smoothing, interest, false_positive, false_positive_steps)
    n, z, g = gain.shape[:3]
    c = g // 2
    level = state.positions[:, 2]
    agents = np.arange(n)
    padded = np.zeros((n, 3, g + 2 * c, g + 2 * c), dtype=np.float32)
    padded[:, 0, c:c + g, c:c + g] = gain[agents, level]
    up, down = level + 1 < z, level > 0
    padded[up, 1, c:c + g, c:c + g] = gain[agents[up], level[up] + 1]
    padded[down, 2, c:c + g, c:c + g] = gain[agents[down], level[down] - 1]
    # Window (v, u) of agent k = padded (y_k + v, x_k + u): one strided gather for all agents.
    rows = state.positions[:, 1, None] + np.arange(g)[None, :]  # (N, G)
    cols = state.positions[:, 0, None] + np.arange(g)[None, :]
    return padded[agents[:, None, None, None], np.arange(3)[None, :, None, None],
                  rows[:, None, :, None], cols[:, None, None, :]]


def _global_planes(state: MissionState, features: FeatureConfig) -> list[np.ndarray]:
    g = state.geometry.grid_points
    planes: list[np.ndarray] = []
    if features.all_positions:
        plane = np.zeros((g, g))
        plane[state.positions[:, 1], state.positions[:, 0]] = _altitude_code(state)
        planes.append(plane)
    if features.global_map:
        planes.append(state.maps.prob_plane(state.global_index))
    if features.global_entropy:
        planes.append(state.maps.wentropy_plane(state.global_index))
    if features.all_footprints:
        planes.append(_footprint_cover(state, np.ones((1, state.n_agents), dtype=bool))[0])
    return planes


def global_state(state: MissionState, features: FeatureConfig) -> np.ndarray:
    """The centralised critic's global input (``env.state()``).

    Returns:
        (C_state, G, G) float32, channels in :func:`state_plane_names` order.
    """
    g = state.geometry.grid_points
    planes = _global_planes(state, features)
    if features.budget:
        planes.insert(0, np.full((g, g), (state.budget - state.step) / state.budget))
    if not planes:
        return np.zeros((0, g, g), dtype=np.float32)
    return np.stack(planes).astype(np.float32)


def other_action_planes(positions: np.ndarray, joint_action: np.ndarray,
                        grid_points: int) -> np.ndarray:
    """Plane (j): for each agent, six planes marking the cells of the *other* agents.

    Args:
        positions: (N, 3) int waypoint indices at which the joint action was chosen.
        joint_action: (N,) int actions.
        grid_points: G.

    Returns:
        (N, 6, G, G) float32: ``out[i, a, y, x] = 1`` iff another agent j at (x, y) chose a.
    """
    positions = np.asarray(positions)
    joint_action = np.asarray(joint_action, dtype=np.int64)
    n = len(positions)
    one_agent = np.zeros((n, N_ACTIONS, grid_points, grid_points), dtype=np.float32)
    one_agent[np.arange(n), joint_action, positions[:, 1], positions[:, 0]] = 1.0
    everyone = one_agent.sum(axis=0, keepdims=True)
    return everyone - one_agent


def critic_observations(state: MissionState, features: FeatureConfig,
                        joint_action: np.ndarray | None = None,
                        actor_obs: np.ndarray | None = None) -> np.ndarray:
    """Per-agent critic input: the actor's planes, the global planes and plane (j).

    Args:
        state: the mission at the time the joint action is chosen.
        features: which planes.
        joint_action: (N,) int actions of all agents; required when ``other_actions`` is on.
        actor_obs: (N, C_actor, G, G) actor observations of this state, if already built.

    Returns:
        (N, C_critic, G, G) float32, channels in :func:`critic_plane_names` order.
    """
    n = state.n_agents
    g = state.geometry.grid_points
    if actor_obs is None:
        actor_obs = actor_observations(state, features)
    parts = [actor_obs]
    shared = _global_planes(state, features)
    if shared:
        parts.append(np.broadcast_to(np.stack(shared).astype(np.float32),
                                     (n, len(shared), g, g)))
    if features.other_actions:
        if joint_action is None:
            raise ValueError("critic_observations needs the joint action when the "
                             "other_actions planes are on")
        parts.append(other_action_planes(state.positions, joint_action, g))
    return np.concatenate(parts, axis=1)
