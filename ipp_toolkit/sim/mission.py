"""The mission core: explicit state plus ``reset_mission`` and ``step_mission``.

Plain functions over a :class:`MissionState` (Gymnasium's functional-env style); the
PettingZoo shell in :mod:`ipp_toolkit.env` only holds a state and calls them. Maps are updated
in place and only inside the footprints a step touched.

Order inside ``reset_mission``: place UAVs, all measure, exchange at the start positions
(step s = 0). Inside ``step_mission``: check masks -> same-target rule -> move -> all measure
-> exchange at the new positions (latest measurement only, no relaying) -> fuse local and
global maps -> reward -> metrics. Measuring and fusing run in whole-step compiled kernels
where Numba is there (:func:`_measure_exchange_fuse_compiled`); the per-UAV, per-rectangle
code (:func:`_measure_exchange_fuse`) is their reference and the NumPy fallback, and both
give the same numbers to the last bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import accumulate
from typing import Any

import numpy as np

from .._native import kernels
from ..belief.block_grid import BlockGrid, Rect
from ..belief.mapping import BeliefMaps
from ..config.limits import check_mission
from ..config.schema import EnvConfig, fixed_start_waypoints
from ..world.seeding import MissionStreams, mission_streams
from ..world.sensor import Camera
from ..world.sensor_noise import entropy_prefix, fill_sensor_noise
from ..world.terrain import generate_terrain
from .team import (
    ACTION_NAMES,
    N_ACTIONS,
    action_masks,
    communication_matrix,
    positions_in_metres,
    resolve_moves,
)

__all__ = [
    "MissionGeometry",
    "MissionState",
    "Metrics",
    "InvalidActionError",
    "reset_mission",
    "step_mission",
    "compute_metrics",
    "agent_label",
]


class InvalidActionError(ValueError):
    """A masked or out-of-range action was passed to ``step``."""


def agent_label(index: int) -> str:
    """Name of agent ``index`` in the multi-agent API (``uav_0``, ``uav_1``, ...)."""
    return f"uav_{index}"


class MissionGeometry:
    """Everything about a world that does not change between missions: camera and blocks.

    Build it once per configuration and share it across missions (it is read-only).

    Attributes:
        whole_step: whether steps run in the whole-step kernels (planning blocks of at most
            129 cells; :func:`_measure_exchange_fuse_compiled`).
    """

    def __init__(self, config: EnvConfig):
        check_mission(config)  # an absurd size is refused before its tables are built
        world = config.world
        self.config = config
        self.camera = Camera(world, config.sensor)
        self.blocks = BlockGrid(world.map_cells, world.grid_points, world.resolution,
                                world.grid_spacing)
        self.grid_points = world.grid_points
        self.n_altitudes = len(world.altitudes)
        self.start_altitude_index = self.camera.altitude_index(config.team.start_altitude)
        # Footprint coverage of every planning block, per waypoint: (Z, G, G, G, G).
        self.coverage = self.blocks.coverage(self.camera.rects).astype(np.float32)
        # The whole-step kernels sum a reading's planes as np.add.reduceat does for blocks
        # of up to 129 cells (every world at r_M >= 0.04 m with waypoints 5 m apart).
        self.whole_step = bool(self.blocks.block_sizes.max() <= 129)
        # Per altitude, for the compiled step: the float32 accuracy a cell's noise is
        # compared with, and the weight W(z) H(z) of a 0 / a 1 reading (z = p(h) or
        # 1 - p(h), so H(z) is one number per altitude) in the measurement planes.
        self.accuracy32 = self.camera.accuracy.astype(np.float32)
        reward, entropy = config.reward, self.camera.reading_entropy
        self.reading_weights = np.stack([reward.weight_uninteresting * entropy,
                                         reward.weight_interesting * entropy], axis=1)

    def positions_m(self, positions: np.ndarray) -> np.ndarray:
        """(N, 3) metres of (N, 3) waypoint indices."""
        world = self.config.world
        return positions_in_metres(positions, world.grid_spacing, world.altitudes)


@dataclass
class Metrics:
    """Evaluation metrics of the global map at one step.

    Attributes:
        entropy: mean entropy in bits over ground-truth interesting cells (1.0 at the prior).
        f1: F1 of the interesting class over all cells, prediction p > 0.5.
        rmse: root mean squared error of p over ground-truth interesting cells.
    """

    entropy: float
    f1: float
    rmse: float

    def as_dict(self) -> dict[str, float]:
        return {"entropy": self.entropy, "f1": self.f1, "rmse": self.rmse}


@dataclass
class _GlobalStats:
    """Running sums over the global map, updated from the changed regions only."""

    n_interesting: int
    entropy_interesting: float  # sum of H(p) over ground-truth interesting cells
    squared_error_interesting: float  # sum of (1 - p)^2 over ground-truth interesting cells
    true_positive: int
    predicted_positive: int
    weighted_entropy: float  # sum of W(p) H(p) over all cells, the reward's H


@dataclass
class MissionState:
    """The full state of one mission; arrays are owned and updated in place.

    Attributes:
        config: the mission's configuration.
        geometry: the shared world geometry.
        ground_truth: (H, W) bool, 1 = interesting.
        positions: (N, 3) int waypoint indices (ix, iy, iz).
        step: steps taken so far (0 after the start measurements).
        maps: N local maps (index k) and the global map (index N).
        heard: (N, N) bool, ``heard[k, i]``: agent k received agent i's latest measurement.
        footprints: (N, 4) int, latest footprint rectangle of each agent.
        measurement_planes: (N, G, G) block-mean weighted entropy of each latest reading.
        last_actions: (N,) int, actions of the last step (-1 before the first step).
        blocked: (N,) bool, held back by the same-target rule at the last step.
        held_invalid: (N,) bool, held in place at the last step because its action was
            masked (only under ``team.invalid_action="hold"``).
        reward: team reward of the last step (0 after reset).
        alive: (N,) bool, UAVs still flying (``team.failures``): a failed one neither moves,
            senses nor communicates.
        failure_step: (N,) int, the step at which each UAV fails (budget + 1: never).
        history: metrics after every step, s = 0..step.
        gain_cache: the footprint gain cache of the local maps
            (:class:`ipp_toolkit.belief.gain.FootprintGainCache`), built on first use by
            :func:`ipp_toolkit.sim.features.footprint_gain`; None until then.
        false_positive_cache: the same for the false-positive objective
            (``features.gain_false_positive``); None until used.
        block_mean_cache: the local maps' block means of probability
            (:class:`ipp_toolkit.belief.interest.BlockMeanCache`), likewise.
    """

    config: EnvConfig
    geometry: MissionGeometry
    streams: MissionStreams
    ground_truth: np.ndarray
    positions: np.ndarray
    maps: BeliefMaps
    stats: _GlobalStats
    step: int = 0
    heard: np.ndarray = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))
    footprints: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), dtype=np.int64))
    measurement_planes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    last_actions: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    blocked: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    held_invalid: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    reward: float = 0.0
    alive: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    failure_step: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    history: list[Metrics] = field(default_factory=list)
    _drop_rng: np.random.Generator | None = None
    _noise_prefix: list[int] | None = field(default=None, repr=False, compare=False)
    gain_cache: Any = field(default=None, repr=False, compare=False)
    false_positive_cache: Any = field(default=None, repr=False, compare=False)
    block_mean_cache: Any = field(default=None, repr=False, compare=False)

    @property
    def n_agents(self) -> int:
        return len(self.positions)

    @property
    def budget(self) -> int:
        return self.config.team.budget

    @property
    def done(self) -> bool:
        """True once the budget of steps is spent."""
        return self.step >= self.budget

    @property
    def global_index(self) -> int:
        """Index of the global map in :attr:`maps`."""
        return self.n_agents

    def masks(self) -> np.ndarray:
        """(N, 6) int8 valid actions at the current positions (failed UAVs hold no cell)."""
        return action_masks(self.positions, self.geometry.grid_points, self.geometry.n_altitudes,
                            self.alive)

    def positions_m(self) -> np.ndarray:
        """(N, 3) float current positions in metres."""
        return self.geometry.positions_m(self.positions)

    def metrics(self) -> Metrics:
        """Metrics of the global map now (from the running sums)."""
        return _metrics_from_stats(self.stats)


def _metrics_from_stats(stats: _GlobalStats) -> Metrics:
    n = stats.n_interesting
    denominator = n + stats.predicted_positive
    return Metrics(
        entropy=stats.entropy_interesting / n,
        f1=2.0 * stats.true_positive / denominator if denominator else 0.0,
        rmse=math.sqrt(max(stats.squared_error_interesting, 0.0) / n),
    )


def compute_metrics(ground_truth: np.ndarray, prob: np.ndarray, entropy: np.ndarray) -> Metrics:
    """Metrics of a full map from scratch (the reference the running sums must match).

    Args:
        ground_truth: (H, W) bool.
        prob: (H, W) probabilities of the map.
        entropy: (H, W) per-cell entropy in bits of the map.
    """
    truth = np.asarray(ground_truth, dtype=bool)
    n = int(np.count_nonzero(truth))
    if n == 0:
        raise ValueError("the ground truth has no interesting cell: entropy and RMSE over "
                         "interesting cells are undefined")
    predicted = prob > 0.5
    tp = int(np.count_nonzero(truth & predicted))
    denominator = n + int(np.count_nonzero(predicted))
    return Metrics(
        entropy=float(entropy[truth].sum(dtype=np.float64) / n),
        f1=2.0 * tp / denominator if denominator else 0.0,
        rmse=float(np.sqrt(np.sum((1.0 - prob[truth].astype(np.float64)) ** 2) / n)),
    )


def _prior_stats(ground_truth: np.ndarray, maps: BeliefMaps) -> _GlobalStats:
    """The running sums of a map at the prior (every cell holds the prior's values).

    The same NumPy reductions over the same float32 values as :func:`compute_metrics` on the
    full map (so the same numbers to the last bit), without building the map's arrays.
    """
    n = int(np.count_nonzero(ground_truth))
    prior_prob = np.full(n, maps.prior_prob, dtype=np.float32)
    positive = bool(maps.prior_prob > 0.5)
    return _GlobalStats(
        n_interesting=n,
        entropy_interesting=float(np.full(n, maps.prior_entropy, dtype=np.float32)
                                  .sum(dtype=np.float64)),
        squared_error_interesting=float(np.sum((1.0 - prior_prob.astype(np.float64)) ** 2)),
        true_positive=n if positive else 0,
        predicted_positive=ground_truth.size if positive else 0,
        weighted_entropy=float(np.sum(np.full(ground_truth.shape, maps.prior_wentropy,
                                              dtype=np.float32), dtype=np.float64)),
    )


def _start_positions(config: EnvConfig, geometry: MissionGeometry,
                     streams: MissionStreams) -> np.ndarray:
    team, world = config.team, config.world
    n = team.n_agents
    positions = np.empty((n, 3), dtype=np.int64)
    positions[:, 2] = geometry.start_altitude_index
    if team.start == "fixed":
        waypoints = fixed_start_waypoints(world, n)
        if waypoints is None:  # EnvConfig refuses such a world; a guard, not a fallback
            raise ValueError(f"no fixed starts for {n} agents in this world")
        positions[:, :2] = waypoints
    else:
        g = geometry.grid_points
        cells = streams.generator("starts").choice(g * g, size=n, replace=False)
        positions[:, 0] = cells % g
        positions[:, 1] = cells // g
    return positions


def _failure_steps(config: EnvConfig, streams: MissionStreams) -> np.ndarray:
    """(N,) int step at which each UAV fails (``team.failures``), budget + 1 for never."""
    team = config.team
    steps = np.full(team.n_agents, team.budget + 1, dtype=np.int64)
    for agent, step in team.failures:
        steps[agent] = step
    if team.random_failures:
        rng = streams.generator("failures")
        spared = np.flatnonzero(steps > team.budget)
        chosen = rng.choice(spared, size=team.random_failures, replace=False)
        steps[chosen] = rng.integers(1, team.budget + 1, size=team.random_failures)
    return steps


def reset_mission(config: EnvConfig, seed: int, mission: int = 0, namespace: str = "train",
                  geometry: MissionGeometry | None = None,
                  ground_truth: np.ndarray | None = None,
                  raster: np.ndarray | None = None) -> MissionState:
    """Start mission ``mission`` of run ``seed``: terrain, starts, start measurements.

    Args:
        config: the mission configuration.
        seed: run seed; with ``namespace`` and ``mission`` it fixes every random stream.
        mission: index of the mission within the run.
        namespace: ``train``, ``validation`` or ``test`` (disjoint terrains).
        geometry: a prebuilt geometry for ``config`` (built when omitted).
        ground_truth: (H, W) bool terrain to use instead of the generated one.
        raster: (h, w) array for ``terrain.kind = "raster"`` instead of the file.

    Returns:
        the state at s = 0, after every UAV measured at its start and the exchange.
    """
    geometry = geometry if geometry is not None else MissionGeometry(config)
    if geometry.config != config:
        raise ValueError("geometry was built for another configuration")
    streams = mission_streams(namespace, seed, mission)
    size = config.world.map_cells
    if ground_truth is None:
        truth = generate_terrain(config.terrain, config.world, streams.generator("terrain"),
                                 raster=raster, namespace=namespace)
    else:
        truth = np.asarray(ground_truth)
        if truth.shape != (size, size):
            raise ValueError(f"ground_truth has shape {truth.shape}, expected {(size, size)}")
        # Any object is true: only booleans or numbers 0/1 say which cells are interesting.
        if truth.dtype.kind not in "biuf" or (truth.dtype.kind != "b"
                                             and not np.isin(truth, (0, 1)).all()):
            raise ValueError(f"ground_truth must hold booleans (or 0/1), got dtype "
                             f"{truth.dtype}")
        truth = truth.astype(bool)
    if not truth.any():
        raise ValueError("the ground truth has no interesting cell")
    n = config.team.n_agents
    maps = BeliefMaps(n + 1, geometry.blocks, config.world.prior,
                      config.reward.weight_interesting, config.reward.weight_uninteresting)
    state = MissionState(
        config=config,
        geometry=geometry,
        streams=streams,
        ground_truth=truth,
        positions=_start_positions(config, geometry, streams),
        maps=maps,
        stats=_prior_stats(truth, maps),
        last_actions=np.full(n, -1, dtype=np.int64),
        blocked=np.zeros(n, dtype=bool),
        held_invalid=np.zeros(n, dtype=bool),
        measurement_planes=np.zeros((n,) + geometry.blocks.block_area.shape),
        alive=np.ones(n, dtype=bool),
        failure_step=_failure_steps(config, streams),
        footprints=np.zeros((n, 4), dtype=np.int64),
        _drop_rng=streams.generator("drops"),
    )
    _measure_exchange_fuse(state)
    state.history.append(state.metrics())
    return state


def _check_actions(state: MissionState, actions: np.ndarray, alive: np.ndarray) -> np.ndarray:
    """Validate a joint action; returns (N,) bool, the agents that try to move.

    A UAV that is not ``alive`` (failed by this step) does not move; its action is ignored.
    """
    masks = state.masks()
    n = state.n_agents
    if actions.shape != (n,):
        raise InvalidActionError(f"expected one action per agent, shape ({n},), got shape "
                                 f"{actions.shape}")
    moving = alive.copy()
    for k, action in enumerate(actions.tolist()):
        if not 0 <= action < N_ACTIONS:
            raise InvalidActionError(f"agent {agent_label(k)!r}: action {action!r} is out of "
                                     f"range; valid indices are 0..{N_ACTIONS - 1} "
                                     f"{ACTION_NAMES}")
        if not alive[k]:
            continue
        if not masks[k, action]:
            if state.config.team.invalid_action == "hold":
                moving[k] = False
                continue
            x, y, z = state.positions_m()[k]
            raise InvalidActionError(
                f"agent {agent_label(k)!r}: action {action} ({ACTION_NAMES[action]}) is masked "
                f"at position (x={x:g}, y={y:g}, z={z:g}); valid actions: "
                f"{[ACTION_NAMES[a] for a in np.flatnonzero(masks[k])]}")
    return moving


def step_mission(state: MissionState, actions: np.ndarray | list[int]) -> float:
    """Advance the mission by one joint action, in place.

    Args:
        state: the mission; must not be done.
        actions: (N,) int joint action, indices into ``ACTION_NAMES``.

    Returns:
        the team reward of this step (also stored in ``state.reward``).

    Raises:
        InvalidActionError: an action is out of range, or masked while
            ``invalid_action="raise"``; the state is left unchanged.
    """
    if state.done:
        raise RuntimeError(f"the mission is over: all {state.budget} steps are spent; reset it")
    try:
        actions = np.asarray(actions)
        if actions.dtype.kind not in "iu":
            if actions.dtype.kind == "f" and np.all(np.isfinite(actions)) \
                    and np.all(actions == np.round(actions)):
                actions = actions.astype(np.int64)
            else:
                raise TypeError
    except (TypeError, ValueError):
        raise InvalidActionError(f"actions must be integers, got {actions!r}") from None
    alive = state.failure_step > state.step + 1  # a UAV failing at this step is out already
    moving = _check_actions(state, actions.astype(np.int64), alive)
    state.alive = alive
    state.held_invalid = alive & ~moving  # only a masked action under "hold" stops a live UAV
    state.positions, state.blocked = resolve_moves(state.positions, actions, moving, alive)
    state.last_actions = actions.astype(np.int64)
    state.step += 1
    state.reward = _measure_exchange_fuse(state)
    state.history.append(state.metrics())
    return state.reward


_FUSED_STEP = True
"""Run a step's sensing and fusion in the whole-step kernels when they are available (the
tests switch it off to compare them with the per-rectangle calls, which they must equal)."""


def _measure_exchange_fuse(state: MissionState) -> float:
    """All agents measure, exchange within range, fuse; returns the step's reward."""
    if _FUSED_STEP and kernels.AVAILABLE and state.geometry.whole_step:
        return _measure_exchange_fuse_compiled(state)
    geometry, camera, blocks = state.geometry, state.geometry.camera, state.geometry.blocks
    n = state.n_agents
    team = state.config.team
    rects: list[Rect | None] = [None] * n
    deltas: list[np.ndarray | None] = [None] * n
    flying = np.flatnonzero(state.alive).tolist()
    footprints = state.footprints.copy()  # a new array: snapshots may hold the old one
    for k in flying:
        ix, iy, iz = (int(v) for v in state.positions[k])
        rect = camera.footprint((ix, iy, iz))
        reading = camera.read(state.ground_truth, rect, iz, state.streams.sensor(state.step, k))
        rects[k] = rect
        deltas[k] = camera.reading_logodds(reading, iz)
        # (d): W(z) H(z) per cell; z is p(h) or 1 - p(h), so H(z) is one number per altitude.
        h = float(camera.reading_entropy[iz])
        weights = np.where(reading, state.maps.weight_interesting * h,
                           state.maps.weight_uninteresting * h)
        plane = np.zeros(blocks.block_area.shape)
        blocks.add_block_sums(plane, weights, rect)
        state.measurement_planes[k] = plane / blocks.block_area
        footprints[k] = rect
    state.footprints = footprints
    state.measurement_planes[~state.alive] = 0.0  # a failed UAV's last reading is gone
    state.heard = communication_matrix(geometry.positions_m(state.positions), team.comm_range,
                                       team.message_drop, state._drop_rng, state.alive)
    maps = state.maps
    for k in flying:
        senders = np.flatnonzero(state.heard[k]).tolist()  # flying ones only (heard says so)
        for i in senders:
            maps.add_evidence(k, rects[i], deltas[i])
        for i in senders:
            maps.refresh(k, rects[i])
    g = state.global_index
    for i in flying:
        maps.add_evidence(g, rects[i], deltas[i])
    numerator = 0.0
    denominator = state.stats.weighted_entropy
    for i in flying:
        r0, r1, c0, c1 = rects[i]
        sums = maps.refresh_with_stats(g, rects[i], state.ground_truth[r0:r1, c0:c1])
        gained, reweighted = _fold_region_stats(state.stats, sums)
        numerator += gained
        denominator += reweighted
    return _reward(state, numerator, denominator)


def _reward(state: MissionState, numerator: float, denominator: float) -> float:
    reward_cfg = state.config.reward
    if denominator <= 1e-9:
        return float(reward_cfg.beta)
    return float(reward_cfg.alpha * numerator / denominator + reward_cfg.beta)


def _measure_exchange_fuse_compiled(state: MissionState) -> float:
    """:func:`_measure_exchange_fuse` in the whole-step kernels, with the same numbers.

    The readings come from the same noise streams (:mod:`ipp_toolkit.world.sensor_noise`), their
    planes are summed as ``np.add.reduceat`` sums them, and :meth:`BeliefMaps.fuse_targets`
    fuses them into the local maps (each agent's heard readings, in agent order) and then
    the global one.
    """
    geometry, camera, blocks = state.geometry, state.geometry.camera, state.geometry.blocks
    flying = state.alive.nonzero()[0]
    n_flying = len(flying)
    positions = state.positions[flying]
    altitude = positions[:, 2]
    rects = camera.rects[altitude, positions[:, 1], positions[:, 0]]  # (F, 4)
    ends = list(accumulate((r1 - r0) * (c1 - c0) for r0, r1, c0, c1 in rects.tolist()))
    offsets = np.array([0] + ends, dtype=np.int64)  # each reading's first cell, and the end
    noise = np.empty(int(offsets[-1]), dtype=np.float32)
    if state._noise_prefix is None:
        state._noise_prefix = entropy_prefix(state.streams)
    fill_sensor_noise(state.streams, state.step, flying.tolist(), offsets, noise,
                      state._noise_prefix)
    readings = np.empty(len(noise), dtype=bool)
    planes = np.zeros((n_flying,) + blocks.block_area.shape)
    kernels.read_cells(state.ground_truth, rects, geometry.accuracy32[altitude], noise,
                       offsets, geometry.reading_weights[altitude], blocks.edges, readings,
                       planes)
    state.measurement_planes[flying] = planes / blocks.block_area
    if n_flying < state.n_agents:
        state.measurement_planes[~state.alive] = 0.0  # a failed UAV's last reading is gone
    footprints = state.footprints.copy()  # a new array: snapshots may hold the old one
    footprints[flying] = rects
    state.footprints = footprints
    team = state.config.team
    state.heard = communication_matrix(geometry.positions_m(state.positions), team.comm_range,
                                       team.message_drop, state._drop_rng, state.alive)
    # Targets: each flying agent's map with the readings it heard, senders in agent order
    # (heard already excludes failed UAVs), then the global map with all of them. Plain
    # Python: a handful of agents.
    flying_list = flying.tolist()
    slot_of = {k: f for f, k in enumerate(flying_list)}
    heard = state.heard.tolist()
    senders: list[int] = []
    target_offsets = [0]
    for k in flying_list:
        senders += [slot_of[i] for i, hears in enumerate(heard[k]) if hears]
        target_offsets.append(len(senders))
    senders += range(n_flying)
    target_offsets.append(len(senders))
    stats = state.maps.fuse_targets(
        rects, readings, offsets, camera.delta_logodds[altitude],
        np.array(flying_list + [state.n_agents], dtype=np.int64),
        np.array(target_offsets, dtype=np.int64), np.array(senders, dtype=np.int64),
        state.ground_truth)
    numerator = 0.0
    denominator = state.stats.weighted_entropy
    for sums in stats.tolist():
        gained, reweighted = _fold_region_stats(state.stats, sums)
        numerator += gained
        denominator += reweighted
    return _reward(state, numerator, denominator)


def _fold_region_stats(stats: _GlobalStats, sums: np.ndarray | list[float]
                       ) -> tuple[float, float]:
    """Fold one refreshed global region into the running sums.

    Args:
        sums: the region's changes, :data:`ipp_toolkit.belief.mapping.REGION_STATS`.

    Returns the region's share of the reward's numerator, sum W'(H - H'), and of the
    correction of its denominator, sum (W' - W) H, with W' the posterior weights.
    """
    (entropy_interesting, squared_error, true_positive, predicted_positive,
     reweighted_old, old_went, new_went) = sums.tolist() if isinstance(sums, np.ndarray) else sums
    stats.entropy_interesting += entropy_interesting
    stats.squared_error_interesting += squared_error
    stats.true_positive += int(true_positive)
    stats.predicted_positive += int(predicted_positive)
    stats.weighted_entropy += new_went - old_went
    return reweighted_old - new_went, reweighted_old - old_went
