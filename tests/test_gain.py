"""The incremental footprint-gain cache equals a full recomputation at every step."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ipp_toolkit.config import EnvConfig
from ipp_toolkit.features import footprint_gain, gain_planes
from ipp_toolkit.gain import FootprintGainCache, footprint_sums, recomputed_footprint_sums
from ipp_toolkit.mission import reset_mission, step_mission
from ipp_toolkit.team import ACTION_NAMES


def full_footprint_gain(state) -> np.ndarray:
    """(N, Z, G, G) normalised footprint gain recomputed from the whole maps."""
    reward = state.config.reward
    camera = state.geometry.camera
    sums = recomputed_footprint_sums(state.maps, state.n_agents, camera,
                                     (reward.weight_interesting, reward.weight_uninteresting))
    scale = max(reward.weight_interesting, reward.weight_uninteresting)
    return sums / (camera.largest_footprint_cells * scale)


def test_footprint_sums_on_a_hand_sized_map():
    cells = np.arange(16, dtype=np.float32).reshape(1, 4, 4)
    rects = np.array([[[0, 2, 0, 2], [0, 2, 1, 4]], [[1, 4, 0, 1], [3, 4, 3, 4]]])
    sums = footprint_sums(cells, rects)
    assert sums.tolist() == [[[0 + 1 + 4 + 5, 1 + 2 + 3 + 5 + 6 + 7], [4 + 8 + 12, 15]]]


@pytest.mark.parametrize("agents, comm, drop", [(4, 25.0, 0.0), (4, math.inf, 0.0),
                                                (2, 0.0, 0.0), (8, 25.0, 0.3)])
def test_cache_equals_full_recomputation_over_whole_missions(agents, comm, drop):
    config = EnvConfig().replace(world={"resolution": 0.5},
                                 team={"n_agents": agents, "comm_range": comm,
                                       "message_drop": drop})
    rng = np.random.default_rng(7)
    for mission in range(2):
        state = reset_mission(config, seed=3, mission=mission, namespace="validation")
        while True:
            cached = footprint_gain(state)
            full = full_footprint_gain(state)
            assert cached.shape == full.shape
            np.testing.assert_allclose(cached, full, rtol=0, atol=1e-6)  # float32 output
            np.testing.assert_allclose(state.gain_cache.sums(),
                                       full * state.geometry.camera.largest_footprint_cells,
                                       rtol=1e-9, atol=1e-9)
            if state.done:
                break
            masks = state.masks()
            step_mission(state, [rng.choice(np.flatnonzero(m)) for m in masks])


def test_cache_follows_steps_it_was_not_asked_about():
    config = EnvConfig().replace(world={"resolution": 0.5})
    state = reset_mission(config, seed=0, mission=0)
    footprint_gain(state)
    for _ in range(2):  # several steps between two reads
        step_mission(state, [ACTION_NAMES.index("down")] * 4)
    np.testing.assert_allclose(footprint_gain(state), full_footprint_gain(state), atol=1e-6)


def test_shared_maps_split_when_their_beliefs_part():
    config = EnvConfig().replace(world={"resolution": 0.5},
                                 team={"comm_range": math.inf, "message_drop": 0.5})
    state = reset_mission(config, seed=1, mission=0)
    cache = FootprintGainCache(state.maps, state.n_agents, state.geometry.camera, (1.0, 0.0))
    state.gain_cache = cache
    saw_shared = saw_split = False
    for _ in range(state.budget):
        footprint_gain(state)
        owners = cache.owner
        saw_shared |= len(set(owners.tolist())) < len(owners)
        saw_split |= len(set(owners.tolist())) > 1
        for k, owner in enumerate(owners):  # sharing only between identical beliefs
            assert np.array_equal(state.maps.logodds[k], state.maps.logodds[owner])
        np.testing.assert_allclose(footprint_gain(state), full_footprint_gain(state), atol=1e-6)
        step_mission(state, [int(np.flatnonzero(m)[-1]) for m in state.masks()])
    assert saw_shared and saw_split


def test_gain_planes_centre_shows_the_footprint_gain_of_the_own_waypoint():
    state = reset_mission(EnvConfig().replace(world={"resolution": 0.5}), seed=0)
    planes = gain_planes(state)
    gain = full_footprint_gain(state)
    c = state.geometry.grid_points // 2
    for k, (x, y, z) in enumerate(state.positions):
        assert planes[k, 0, c, c] == pytest.approx(gain[k, z, y, x], abs=1e-6)
