"""The incremental footprint-gain cache equals a full recomputation at every step."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ipp_toolkit._native import kernels
from ipp_toolkit.belief.box_sums import BoxLayout
from ipp_toolkit.belief.gain import (
    FootprintGainCache,
    _overlap_matrix,
    footprint_sums,
    recomputed_footprint_sums,
)
from ipp_toolkit.belief.interest import BlockMeanCache, InterestSmoother, block_means
from ipp_toolkit.belief.mapping import (
    false_positive_gain,
    false_positive_term_applies,
    interesting_gain,
)
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.sim.features import footprint_gain, gain_planes
from ipp_toolkit.sim.mission import MissionGeometry, reset_mission, step_mission
from ipp_toolkit.sim.team import ACTION_NAMES


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


def test_missions_of_one_geometry_share_gains_and_overlaps_which_stay_exact(monkeypatch):
    """The per-value gains (a process-wide memo) and the footprint overlaps of refreshed
    regions (per camera, bounded) are shared by missions; the sums still equal a full
    recomputation, also when the bounded overlap cache is cleared mid-mission."""
    import ipp_toolkit.belief.gain as gain

    monkeypatch.setattr(gain, "_OVERLAP_CACHE_BYTES", 200_000)  # a few dozen regions
    config = EnvConfig().replace(world={"resolution": 0.5})
    geometry = MissionGeometry(config)
    rng = np.random.default_rng(11)
    caches = []
    for mission in range(2):
        state = reset_mission(config, seed=4, mission=mission, namespace="validation",
                              geometry=geometry)
        while True:
            footprint_gain(state)
            np.testing.assert_allclose(
                state.gain_cache.sums(),
                full_footprint_gain(state) * geometry.camera.largest_footprint_cells,
                rtol=1e-9, atol=1e-9)
            overlaps = state.gain_cache._overlap_cache
            assert overlaps.nbytes <= gain._OVERLAP_CACHE_BYTES
            if state.done:
                break
            step_mission(state, [rng.choice(np.flatnonzero(m)) for m in state.masks()])
        caches.append(state.gain_cache)
    assert caches[0]._overlap_cache is caches[1]._overlap_cache
    assert caches[0].table.memo is not None and caches[0].table.memo is caches[1].table.memo


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


def test_totals_of_the_interesting_objective_are_summed_when_first_asked_for_then_kept():
    config = EnvConfig().replace(world={"resolution": 0.5})
    state = reset_mission(config, seed=4, mission=0)
    camera = state.geometry.camera
    cache = FootprintGainCache(state.maps, state.n_agents, camera, (1.0, 0.0), "interesting")
    assert not cache.keeps_totals  # its readers take weighted_sums
    rng = np.random.default_rng(6)
    for step in range(4):
        if step >= 2:
            full = recomputed_footprint_sums(state.maps, state.n_agents, camera, (1.0, 0.0),
                                             objective="interesting")
            np.testing.assert_allclose(cache.sums(), full, rtol=1e-12, atol=1e-9)
            assert cache.keeps_totals
        step_mission(state, [rng.choice(np.flatnonzero(m)) for m in state.masks()])


def test_gain_planes_centre_shows_the_footprint_gain_of_the_own_waypoint():
    state = reset_mission(EnvConfig().replace(world={"resolution": 0.5}), seed=0)
    planes = gain_planes(state)
    gain = full_footprint_gain(state)
    c = state.geometry.grid_points // 2
    for k, (x, y, z) in enumerate(state.positions):
        assert planes[k, 0, c, c] == pytest.approx(gain[k, z, y, x], abs=1e-6)


@pytest.mark.parametrize("agents, comm, resolution", [(4, 25.0, 0.5), (4, math.inf, 0.5),
                                                     (2, 0.0, 0.5), (2, 25.0, 0.25)])
def test_smoothed_gain_planes_equal_a_full_recomputation(agents, comm, resolution):
    # At r_M = 0.25 m the smoothing blocks hold 2 x 2 cells: the weight is broadcast over them.
    config = EnvConfig().replace(world={"resolution": resolution},
                                 team={"n_agents": agents, "comm_range": comm},
                                 features={"gain": True, "gain_smoothing": 4.0})
    smoother = InterestSmoother(config.world.map_cells, resolution, 4.0)
    rng = np.random.default_rng(3)
    state = reset_mission(config, seed=2, mission=0, namespace="validation")
    camera_cells = state.geometry.camera.largest_footprint_cells
    while True:
        weight = smoother(state.maps.prob[:agents])
        full = recomputed_footprint_sums(state.maps, agents, state.geometry.camera, (1.0, 0.0),
                                         objective="interesting", cell_weight=weight)
        np.testing.assert_allclose(footprint_gain(state), full / camera_cells, rtol=0, atol=2e-6)
        if state.done:
            break
        step_mission(state, [rng.choice(np.flatnonzero(m)) for m in state.masks()])


def test_interesting_gain_on_a_hand_sized_case():
    # Prior cell (l = 0, H = 1 bit), accuracy 0.8: l1 = log 4, l0 = -log 4, H(0.8) = H(0.2).
    a = 0.8
    d = np.array([-math.log(4.0), math.log(4.0)], dtype=np.float32)
    zero = np.zeros((1, 1), dtype=np.float32)
    gain = interesting_gain(zero, zero + 0.5, zero + 1.0, a, d)
    h = -(0.8 * math.log2(0.8) + 0.2 * math.log2(0.2))
    assert gain[0, 0] == pytest.approx(1.0 - h, abs=1e-6)
    # A cell believed uninteresting (p = 0.2): a correct reading of 1 brings it to 0.5.
    low = np.full((1, 1), -math.log(4.0), dtype=np.float32)
    gain = interesting_gain(low, low * 0 + 0.2, low * 0 + h, a, d)
    h_001 = -(1 / 17 * math.log2(1 / 17) + 16 / 17 * math.log2(16 / 17))  # l = -log 16
    assert gain[0, 0] == pytest.approx(0.8 * (h - 1.0) + 0.2 * (h - h_001), abs=1e-5)
    assert gain[0, 0] < 0


def test_false_positive_gain_on_a_hand_sized_case():
    # Accuracy 0.8, d = +-log 4. A cell believed interesting (p = 0.8) that is not: a correct
    # reading of 0 brings it back to 0.5 (H = 1), a wrong one to l = log 16.
    a = 0.8
    d = np.array([-math.log(4.0), math.log(4.0)], dtype=np.float32)
    h = -(0.8 * math.log2(0.8) + 0.2 * math.log2(0.2))
    h_16 = -(1 / 17 * math.log2(1 / 17) + 16 / 17 * math.log2(16 / 17))
    high = np.full((1, 1), math.log(4.0), dtype=np.float32)
    gain = false_positive_gain(high, high * 0 + 0.8, high * 0 + h, a, d)
    assert gain[0, 0] == pytest.approx(0.8 * (h - 1.0) + 0.2 * (h - h_16), abs=1e-5)
    # p = 0.99 (l = log 99): a correct reading brings it to l = log(99 / 4), lower entropy.
    sure = np.full((1, 1), math.log(99.0), dtype=np.float32)
    h_99 = -(0.99 * math.log2(0.99) + 0.01 * math.log2(0.01))
    p_down = 99 / 103
    h_down = -(p_down * math.log2(p_down) + (1 - p_down) * math.log2(1 - p_down))
    p_up = 396 / 397
    h_up = -(p_up * math.log2(p_up) + (1 - p_up) * math.log2(1 - p_up))
    gain = false_positive_gain(sure, sure * 0 + 0.99, sure * 0 + h_99, a, d)
    assert gain[0, 0] == pytest.approx(0.8 * (h_99 - h_down) + 0.2 * (h_99 - h_up), abs=1e-5)
    # At or below 0.5 there is no false positive to check.
    cells = np.array([[0.0, -1.0, -5.0]], dtype=np.float32)
    entropy = np.array([[1.0, 0.8, 0.05]], dtype=np.float32)
    np.testing.assert_array_equal(false_positive_gain(cells, cells, entropy, a, d), 0.0)


def test_interest_smoother_keeps_constants_and_spreads_a_hotspot():
    smoother = InterestSmoother(100, 0.5, 3.0)
    assert smoother.block == 1
    flat = np.full((2, 100, 100), 0.3, dtype=np.float32)
    np.testing.assert_allclose(smoother(flat), 0.3, atol=1e-6)  # the border is renormalised
    spot = np.zeros((100, 100), dtype=np.float32)
    spot[50, 50] = 1.0
    smooth = smoother(spot)
    assert smooth.sum() == pytest.approx(1.0, abs=1e-3)  # mass kept away from the border
    assert smooth[50, 50] == smooth.max() and smooth[50, 56] > smooth[50, 62] > 0
    fine = InterestSmoother(500, 0.1, 3.0)  # 0.5 m blocks of 5 x 5 cells
    assert fine.block == 5
    big = np.zeros((500, 500), dtype=np.float32)
    big[100:400, 100:400] = 1.0  # 30 m square: its centre is 5 sigma inside
    out = fine(big)
    assert out.shape == (500, 500) and out[250, 250] > 0.99 and out[0, 0] < 1e-5
    with pytest.raises(ValueError, match="sigma"):
        InterestSmoother(100, 0.5, 0.0)
    with pytest.raises(ValueError, match="100 x 100"):
        smoother(np.zeros((50, 50), dtype=np.float32))


def test_gain_smoothing_is_validated():
    with pytest.raises(ValueError, match="gain_smoothing"):
        EnvConfig().replace(features={"gain_smoothing": -1.0})
    with pytest.raises(ValueError, match="gain_smoothing"):
        EnvConfig().replace(features={"gain_smoothing": math.inf})


def test_a_policy_gets_its_own_gain_smoothing_on_any_mission():
    from ipp_toolkit.sim.features import actor_observations

    plain = EnvConfig().replace(world={"resolution": 0.5}, features={"gain": True})
    smoothed = plain.replace(features={"gain": True, "gain_smoothing": 5.0})
    state = reset_mission(plain, seed=0, mission=0)
    reference = reset_mission(smoothed, seed=0, mission=0)
    for _ in range(3):  # the same valid moves on both (the same starts and terrain)
        actions = [int(np.flatnonzero(m)[-1]) for m in state.masks()]
        step_mission(state, actions)
        step_mission(reference, actions)
    planes = actor_observations(state, smoothed.features)[:, -3:]
    np.testing.assert_array_equal(planes, gain_planes(reference))
    assert not np.array_equal(planes, actor_observations(state, plain.features)[:, -3:])


def test_interest_window_equals_the_full_map_slice():
    smoother = InterestSmoother(500, 0.1, 5.0)
    prob = np.random.default_rng(0).random((500, 500), dtype=np.float32)
    blocks = smoother.block_values(prob)
    rows, cols = slice(37, 212), slice(0, 499)
    np.testing.assert_array_equal(smoother.window(blocks, rows, cols), smoother(prob)[rows, cols])


@pytest.mark.parametrize("block", [1, 2, 3, 5, 7, 8, 10])
def test_block_means_are_numpys_means_to_the_bit(block):
    # Values over six orders of magnitude: any other order of the additions shows at once.
    rng = np.random.default_rng(block)
    for shape in [(4, 20 * block, 20 * block), (1, 2 * block, 2 * block), (2, block, block)]:
        prob = (rng.standard_normal(shape) * 10.0 ** rng.uniform(-3, 3, shape)
                ).astype(np.float32)
        n = shape[-1] // block
        expected = prob.reshape(shape[:-2] + (n, block, n, block)).mean(axis=(-3, -1),
                                                                       dtype=np.float32)
        np.testing.assert_array_equal(block_means(prob, block), expected)


@pytest.mark.parametrize("block", [1, 2, 4, 5, 7, 8])
def test_block_sums_are_numpys_sums_to_the_bit(block):
    from ipp_toolkit.belief.interest import block_sums

    rng = np.random.default_rng(block)
    for shape in [(4, 25 * block, 25 * block), (3, 4 * block, 2 * block), (1, block, block)]:
        values = (rng.standard_normal(shape) * 10.0 ** rng.uniform(-3, 3, shape)
                  ).astype(np.float32)
        n, rows, cols = shape[0], shape[1] // block, shape[2] // block
        expected = values.reshape(n, rows * block, cols, block).sum(axis=3).reshape(
            n, rows, block, cols).sum(axis=2)
        np.testing.assert_array_equal(block_sums(values, block), expected)
        wide = block_sums(values.astype(np.float64), block)  # other dtypes: NumPy's own sums
        assert wide.dtype == np.float64
        np.testing.assert_array_equal(wide, values.astype(np.float64).reshape(
            n, rows * block, cols, block).sum(axis=3).reshape(n, rows, block, cols).sum(axis=2))


def test_block_means_take_the_ordered_sums_on_the_default_maps():
    import ipp_toolkit.belief.interest as interest

    prob = np.random.default_rng(0).random((4, 500, 500), dtype=np.float32)
    block_means(prob, 5)
    # This NumPy adds a block's cells in the order the whole-array sums copy (else they fall
    # back to its mean: the same numbers, five times slower).
    assert interest._ORDER_CHECKED[((4, 500, 500), 5, False)]


def test_box_layout_on_a_hand_sized_map():
    # A 6 x 6 map, weights on 2 x 2 squares. Footprint rows [0, 3) and [1, 4); columns [0, 1)
    # and [4, 6): rows 4-5 and columns 1-3 lie under no footprint.
    layout = BoxLayout(np.array([[0, 3], [1, 4]]), np.array([[0, 1], [4, 6]]), 6, block=2)
    assert layout.row_edges.tolist() == [0, 1, 2, 3, 4, 6]  # the bounds and the squares' edges
    assert layout.row_segments.tolist() == [[0, 3], [1, 4]]
    assert layout.row_block.tolist() == [0, 0, 1, 1, 2]
    assert layout.col_edges.tolist() == [0, 1, 2, 4, 6]
    assert layout.col_segments.tolist() == [[0, 1], [3, 4]]
    assert layout.col_block.tolist() == [0, 0, 1, 2]
    cells = np.arange(36, dtype=np.float32).reshape(6, 6)
    segment_sums = layout.segment_sums(cells)
    assert segment_sums[2].tolist() == [12, 13, 14 + 15, 16 + 17]
    assert segment_sums[4, 3] == 28 + 29 + 34 + 35
    weight = np.full((3, 3), 0.5, dtype=np.float32)
    weight[1, 2] = 2.0  # rows 2-3, columns 4-5
    expected = [[(0 + 6 + 12) / 2, (4 + 5 + 10 + 11) / 2 + (16 + 17) * 2],
                [(6 + 12 + 18) / 2, (10 + 11) / 2 + (16 + 17 + 22 + 23) * 2]]
    assert layout.sums(cells, weight).tolist() == expected
    assert layout.reference_weighted(layout.reference_segment_sums(cells, 0, 5, 0, 4),
                                     weight).tolist() == expected


def test_box_layout_sums_again_only_the_segments_a_region_overlaps():
    layout = BoxLayout(np.array([[0, 3], [1, 4]]), np.array([[0, 1], [4, 6]]), 6, block=2)
    cells = np.arange(36, dtype=np.float32).reshape(6, 6)
    kept = layout.segment_sums(cells)
    cells[3, 1] = 100.0  # inside row segment 3 ([3, 4)) and column segment 1 ([1, 2))
    stale = kept.copy()
    layout.segment_sums(cells, out=kept, region=(3, 4, 1, 2))
    assert np.array_equal(kept, layout.segment_sums(cells))
    assert np.flatnonzero((kept != stale).ravel()).tolist() == [3 * 4 + 1]
    # A region across segment edges reaches every segment it overlaps, whole.
    cells[1:5, 0:3] += 1.0
    layout.segment_sums(cells, out=kept, region=(1, 5, 0, 3))
    assert np.array_equal(kept, layout.segment_sums(cells))


def test_box_layout_refuses_a_block_that_does_not_divide_the_map():
    with pytest.raises(ValueError, match="block = 4 must be a positive divisor"):
        BoxLayout(np.array([[0, 1]]), np.array([[0, 1]]), 6, block=4)


def test_box_layout_refuses_bounds_outside_the_map_or_reversed():
    for bounds in ([[0, 6]], [[-1, 2]], [[3, 2]]):
        with pytest.raises(ValueError, match=r"footprint bounds must be ordered and lie within "
                                             r"\[0, 5\]"):
            BoxLayout(np.array(bounds), np.array([[0, 1]]), 5)


@pytest.mark.parametrize("block", [1, 5])
def test_weighted_sums_equal_float64_sums_in_a_fixed_order(block):
    config = EnvConfig().replace(features={"gain": True, "gain_smoothing": 5.0})
    state = reset_mission(config, seed=1, mission=0)
    rng = np.random.default_rng(2)
    for _ in range(2):
        step_mission(state, [rng.choice(np.flatnonzero(m)) for m in state.masks()])
    n, size = state.n_agents, state.maps.value_index.shape[-1]
    cache = FootprintGainCache(state.maps, n, state.geometry.camera, (1.0, 0.0), "interesting")
    weight = rng.random((n, size // block, size // block), dtype=np.float32)
    cells = np.repeat(np.repeat(weight, block, axis=-2), block, axis=-1).astype(np.float64)
    got = cache.weighted_sums(weight, block)
    # The float64 reference: every product exact, summed by matrix products.
    rows = np.stack([_overlap_matrix(b, 0, size) for b in cache.row_bounds])
    cols = np.stack([_overlap_matrix(b, 0, size).T for b in cache.col_bounds])
    expected = rows @ (cache.cells[cache.owner].astype(np.float64) * cells[:, None]) @ cols
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    # The compiled kernels and their NumPy references add in the same order: the same bits.
    layouts, _ = cache.segments[block]
    for k in range(n):
        for iz, layout in enumerate(layouts):
            rows, columns = layout.shape
            segment_sums = layout.reference_segment_sums(cache.cells[cache.owner[k], iz], 0,
                                                         rows, 0, columns)
            np.testing.assert_array_equal(
                got[k, iz], layout.reference_weighted(segment_sums, weight[k]))


@pytest.mark.parametrize("agents, comm", [(4, 25.0), (4, math.inf), (2, 0.0)])
def test_kept_segment_sums_equal_sums_from_scratch_at_every_step(agents, comm):
    """A segment is summed again, whole and in the same order, whenever a step changed the
    map under it: the kept sums are the whole maps' sums to the bit, whatever the path."""
    config = EnvConfig().replace(world={"resolution": 0.25},
                                 team={"n_agents": agents, "comm_range": comm},
                                 features={"gain": True, "gain_smoothing": 4.0})
    state = reset_mission(config, seed=3, mission=2)
    cache = FootprintGainCache(state.maps, agents, state.geometry.camera, (1.0, 0.0),
                               "interesting")
    size = state.maps.value_index.shape[-1]
    weight = np.ones((agents, size // 2, size // 2), dtype=np.float32)
    rng = np.random.default_rng(5)
    while True:
        cache.weighted_sums(weight, 2)
        layouts, kept = cache.segments[2]
        for k in np.unique(cache.owner).tolist():
            for iz, layout in enumerate(layouts):
                assert np.array_equal(kept[iz][k], layout.segment_sums(cache.cells[k, iz]))
        if state.done:
            break
        step_mission(state, [rng.choice(np.flatnonzero(m)) for m in state.masks()])


@pytest.mark.parametrize("agents, comm, resolution", [(4, 25.0, 0.1), (8, math.inf, 0.25),
                                                     (2, 0.0, 0.5)])
def test_block_mean_cache_equals_the_full_maps_block_means_at_every_step(agents, comm,
                                                                         resolution):
    """Only the blocks under refreshed rectangles are summed again, from the table's
    probabilities: the same numbers as the whole maps' block means, to the bit."""
    config = EnvConfig().replace(world={"resolution": resolution},
                                 team={"n_agents": agents, "comm_range": comm})
    block = InterestSmoother(config.world.map_cells, resolution, 4.0).block
    state = reset_mission(config, seed=5, mission=1)
    cache = BlockMeanCache(state.maps, agents, block)
    assert cache.incremental
    rng = np.random.default_rng(4)
    while True:
        got = cache.means().copy()
        # The per-cell arrays were not needed (the NumPy path of a step builds them).
        assert state.maps._arrays is None or not kernels.AVAILABLE
        expected = block_means(state.maps.prob[:agents], block)
        state.maps._arrays = None  # forget them again (they are rebuilt from the log)
        np.testing.assert_array_equal(got.view(np.uint32), expected.view(np.uint32))
        if state.done:
            break
        step_mission(state, [rng.choice(np.flatnonzero(m)) for m in state.masks()])


def test_block_mean_cache_takes_the_whole_maps_where_the_order_is_unchecked(monkeypatch):
    import ipp_toolkit.belief.interest as interest

    config = EnvConfig().replace(world={"resolution": 0.5})
    state = reset_mission(config, seed=0)
    monkeypatch.setattr(interest, "_ORDER_CHECKED", {((4, 100, 100), 1, False): False})
    cache = BlockMeanCache(state.maps, 4, 1)
    assert not cache.incremental
    np.testing.assert_array_equal(cache.means(), state.maps.prob[:4])


def test_the_false_positive_term_applies_in_the_last_steps_only_when_limited():
    assert false_positive_term_applies(15, None) and false_positive_term_applies(15, 0)
    assert not false_positive_term_applies(11, 10)
    assert false_positive_term_applies(10, 10) and false_positive_term_applies(1, 10)
