"""The optional ``gain`` planes: the ig planner's objective, per waypoint, on each local map."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_valid_actions, small_config

from ipp_toolkit.belief.mapping import expected_gain
from ipp_toolkit.sim.features import (
    GAIN_PLANES,
    actor_observations,
    actor_plane_names,
    footprint_gain,
    gain_planes,
)
from ipp_toolkit.sim.mission import reset_mission, step_mission


def _mid_mission(config, steps: int = 4, seed: int = 3):
    state = reset_mission(config, seed=seed, mission=1, namespace="test")
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        step_mission(state, random_valid_actions(state.masks(), rng))
    return state


@pytest.fixture
def gain_config():
    return small_config().replace(features={"gain": True}, team={"comm_range": 0.0})


def test_gain_planes_are_named_and_appended_last(gain_config):
    names = actor_plane_names(gain_config.features)
    assert names[-3:] == list(GAIN_PLANES)
    without = actor_plane_names(gain_config.replace(features={"gain": False}).features)
    assert names[:-3] == without


@pytest.mark.parametrize("comm_range", [0.0, 25.0, float("inf")])
def test_footprint_gain_is_the_mean_expected_gain_over_each_footprint(gain_config, comm_range):
    # D = inf: every map is the same, computed once and shared; D = 25 m: some are shared.
    state = _mid_mission(gain_config.replace(team={"comm_range": comm_range}))
    gain = footprint_gain(state)
    camera, maps, reward = state.geometry.camera, state.maps, state.config.reward
    n, z, g, _ = gain.shape
    assert (n, z, g) == (state.n_agents, len(camera.accuracy), state.geometry.grid_points)
    largest = max((r[1] - r[0]) * (r[3] - r[2]) for r in camera.rects.reshape(-1, 4))
    rng = np.random.default_rng(0)
    for _ in range(40):
        k, iz, iy, ix = (int(rng.integers(n)), int(rng.integers(z)), int(rng.integers(g)),
                         int(rng.integers(g)))
        r0, r1, c0, c1 = camera.rects[iz, iy, ix]
        cells = (k, slice(r0, r1), slice(c0, c1))
        direct = expected_gain(maps.logodds[cells], maps.prob[cells], maps.entropy[cells],
                               camera.accuracy[iz], camera.delta_logodds[iz],
                               reward.weight_interesting, reward.weight_uninteresting)
        assert gain[k, iz, iy, ix] == pytest.approx(direct.sum() / largest, rel=1e-4,
                                                    abs=1e-7)
    assert gain.min() >= 0.0 and gain.max() <= 1.0
    if comm_range == 0.0:  # agents that measured different places: different gains
        assert not np.allclose(gain[0], gain[1])
    if comm_range == float("inf"):
        assert all(np.array_equal(gain[0], gain[k]) for k in range(n))


def test_gain_planes_are_centred_on_the_agent_at_its_level_and_its_neighbours(gain_config):
    state = _mid_mission(gain_config)
    state.positions[0] = (0, 0, 0)  # corner, lowest level: nothing below, south or west
    state.positions[1, 2] = len(state.geometry.camera.accuracy) - 1  # top: nothing above
    gain, planes = footprint_gain(state), gain_planes(state)
    g = state.geometry.grid_points
    c = g // 2
    assert planes.shape == (state.n_agents, 3, g, g)
    for k in range(state.n_agents):
        x, y, z = state.positions[k]
        for v in range(g):
            for u in range(g):
                gy, gx = y + v - c, x + u - c
                inside = 0 <= gy < g and 0 <= gx < g
                for plane, dz in enumerate((0, 1, -1)):
                    exists = inside and 0 <= z + dz < gain.shape[1]
                    expected = gain[k, z + dz, gy, gx] if exists else 0.0
                    assert planes[k, plane, v, u] == expected, (k, plane, v, u)
    assert not planes[0, 2].any() and not planes[1, 1].any()
    assert not planes[0, 0, :c].any() and not planes[0, 0, :, :c].any()


def test_gain_planes_rank_moves_like_the_ig_planner(gain_config):
    """Without teammates to discount, ig's choice is the best move by the planes' gain."""
    from baselines.heuristics.information_gain import InformationGainPlanner
    from ipp_toolkit.planning import agent_views
    from ipp_toolkit.sim.team import ACTION_DELTAS

    planner = InformationGainPlanner()
    planner.reset(gain_config, 0)
    state = _mid_mission(gain_config, steps=5)
    choice = planner.act(agent_views(state, with_observations=False))
    obs = actor_observations(state, gain_config.features)[:, -3:]  # (N, 3, G, G)
    c = state.geometry.grid_points // 2
    checked = 0
    for k in range(state.n_agents):
        values = np.full(6, -np.inf)
        for action in np.flatnonzero(state.masks()[k]):
            dx, dy, dz = ACTION_DELTAS[action]
            # The six options sit at fixed window cells around the centre.
            values[action] = obs[k, {0: 0, 1: 1, -1: 2}[int(dz)], c + dy, c + dx]
        best = np.sort(values)[::-1]
        if best[0] - best[1] > 1e-3 * best[0]:  # a clear winner: no tie-break question
            assert choice[k] == int(np.argmax(values))
            checked += 1
    assert checked >= 1
