"""The segment grid of the lookahead: hand-sized cuts, discount and sums."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from baselines.heuristics.information_gain import InformationGainPlanner
from ipp_toolkit._native import kernels
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planning.segments import SegmentGrid, SegmentSums, objective_segment_values


def _grid() -> SegmentGrid:
    # one altitude, a 1 x 2 grid of waypoints: footprints rows [1, 5), columns [0, 3) and [2, 6)
    rects = np.array([[[[1, 5, 0, 3], [1, 5, 2, 6]]]])
    return SegmentGrid(rects, size=8, block=4)


def test_the_cuts_are_every_footprint_edge_and_every_block_edge():
    grid = _grid()
    np.testing.assert_array_equal(grid.layout.row_edges, [0, 1, 4, 5, 8])
    np.testing.assert_array_equal(grid.layout.col_edges, [0, 2, 3, 4, 6, 8])
    assert grid.shape == (4, 5)
    np.testing.assert_array_equal(grid.edge_index(np.array([1, 5, 2, 6])), [1, 3, 1, 4])
    weights = grid.block_weights(np.array([[1.0, 2.0], [3.0, 4.0]]))
    np.testing.assert_array_equal(weights[:, 0], [1, 1, 3, 3])
    np.testing.assert_array_equal(weights[0], [1, 1, 1, 2, 2])


def test_a_segment_two_footprints_cover_is_discounted_once():
    grid = _grid()
    values = np.ones(grid.shape)
    grid.discount(values, np.array([[1, 5, 0, 3], [1, 5, 2, 6]]), 0.5)
    want = np.ones(grid.shape)
    want[1:3, 0:4] = 0.5  # rows [1, 5), columns [0, 6): the overlap [2, 3) too, once
    np.testing.assert_array_equal(values, want)
    box_values = np.ones((2, 2))  # segments rows 2..3, columns 3..4 of the grid
    grid.discount(box_values, np.array([[1, 5, 2, 6]]), 0.5, box=(2, 4, 3, 5))
    np.testing.assert_array_equal(box_values, [[0.5, 1.0], [1.0, 1.0]])


def test_constant_sums_are_the_layouts_sums_of_a_constant_map_bit_for_bit():
    grid = _grid()
    value = np.float32(0.1)
    cells = np.full((8, 8), value, dtype=np.float32)
    np.testing.assert_array_equal(grid.constant_sums(value), grid.layout.segment_sums(cells))
    sums = grid.layout.segment_sums(np.arange(64, dtype=np.float32).reshape(8, 8))
    assert sums[1, 0] == 8 + 9 + 16 + 17 + 24 + 25  # rows [1, 4), columns [0, 2)


def test_objective_values_weight_the_gain_and_the_clean_up_term():
    sums = np.stack([np.full((2, 1, 3), 2.0), np.full((2, 1, 3), 10.0)])  # (T, Z, R, C)
    interest = np.array([[0.0, 0.5, 1.0]])
    np.testing.assert_array_equal(objective_segment_values(sums, 1, None), [[2.0] * 3])
    np.testing.assert_allclose(objective_segment_values(sums, 1, interest, 0.5),
                               [[5.0, 3.5, 2.0]])


def test_a_missions_grid_and_kept_sums_come_from_its_world_and_tables():
    """``for_world`` cuts by the world's ~0.5 m squares; ``of_tables`` keeps every altitude
    column of the tables, starting from the log-odds of the world's prior."""
    world = EnvConfig().replace(world={"resolution": 0.25, "prior": 0.3}).world
    planner = InformationGainPlanner()
    planner.reset(EnvConfig().replace(world={"resolution": 0.25, "prior": 0.3}), seed=0)
    grid = SegmentGrid.for_world(planner.camera.rects, world)
    assert grid.block == 2 and grid.size == world.map_cells  # 0.5 m: two cells of 0.25 m
    assert grid.key == planner.segment_grid.key
    kept = SegmentSums.of_tables(grid, planner._segment_tables(), world.prior)
    assert kept.columns == ["altitude_0", "altitude_1", "altitude_2"]
    assert kept.start == np.float32(np.log(0.3 / 0.7))


def test_a_map_of_another_size_is_refused_naming_it():
    planner = InformationGainPlanner()
    planner.reset(EnvConfig().replace(world={"resolution": 1.0}), seed=0)
    kept = SegmentSums(planner.segment_grid, planner._segment_tables(), ["altitude_0"], 0.0)
    view = SimpleNamespace(index=0, step=0, local_logodds=np.zeros((7, 7), np.float32))
    with pytest.raises(ValueError, match=r"shape \(7, 7\)"):
        kept(view)


def test_changed_boxes_cover_every_changed_cell_compiled_or_not(monkeypatch):
    """The boxes of segments to sum again: one per run of changed segment rows, over the
    columns that changed in it; the compiled row scan finds the same boxes as NumPy."""
    grid = _grid()  # row cuts 0, 1, 4, 5, 8; column cuts 0, 2, 3, 4, 6, 8
    kept = SegmentSums(grid, [], [], 0.0)
    before = np.zeros((8, 8), dtype=np.float32)
    after = before.copy()
    after[2, 5] = 1.0  # row segment 1, column segment 3
    after[3, 0] = -0.0  # another bit pattern: changed too
    after[7, 7] = 2.0  # row segment 3, column segment 4
    want = [(1, 2, 0, 4), (3, 4, 4, 5)]
    assert kept._changed_boxes(before, after) == want
    assert kept._changed_boxes(before, before) == []
    if kernels.AVAILABLE:
        monkeypatch.setattr(kernels, "AVAILABLE", False)
        assert kept._changed_boxes(before, after) == want
        monkeypatch.setattr(kernels, "AVAILABLE", True)
        rng = np.random.default_rng(1)
        for _ in range(20):
            after = before.copy()
            after[rng.random((8, 8)) < 0.05] = 1.0
            compiled = kept._changed_boxes(before, after)
            monkeypatch.setattr(kernels, "AVAILABLE", False)
            assert kept._changed_boxes(before, after) == compiled
            monkeypatch.setattr(kernels, "AVAILABLE", True)


@pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not importable")
def test_same_bits_tells_maps_apart_by_their_bit_patterns():
    a = np.zeros((5, 7), dtype=np.float32)
    b = a.copy()
    assert kernels.same_bits(a.view(np.uint32), b.view(np.uint32))
    b[4, 6] = -0.0  # equal as numbers, not as bits
    assert not kernels.same_bits(a.view(np.uint32), b.view(np.uint32))
    assert not kernels.same_bits(b.view(np.uint32)[::-1], b.view(np.uint32))  # any strides


def test_teammates_with_the_same_map_share_sums_and_every_answer_stays_right():
    """Two UAVs with the same map share one refresh; when one's map moves on, the other's
    answers (this step's and an earlier view's) stay the sums of its own map."""
    planner = InformationGainPlanner()
    planner.reset(EnvConfig().replace(world={"resolution": 1.0}), seed=0)
    columns = ["altitude_0", "altitude_2"]
    kept = SegmentSums(planner.segment_grid, planner._segment_tables(), columns, 0.0)

    def fresh(view):  # the sums of the view's map from scratch
        return SegmentSums(planner.segment_grid, planner._segment_tables(), columns,
                           0.0)(SimpleNamespace(**{**view.__dict__, "index": 0}))

    def view(index, step, logodds, heard):
        return SimpleNamespace(index=index, step=step, local_logodds=logodds,
                               teammates=np.array(heard))

    rng = np.random.default_rng(0)
    size = planner.segment_grid.size
    first = np.zeros((size, size), np.float32)
    first[3:9, 4:12] = rng.standard_normal((6, 8)).astype(np.float32)
    a0, b0 = view(0, 1, first, [1]), view(1, 1, first.copy(), [0])
    np.testing.assert_array_equal(kept(a0), fresh(a0))
    assert kept(b0) is kept(a0)  # shared: one refresh for both
    second = first.copy()
    second[20:25, 30:40] = 1.5  # agent 1 alone reads more at the next step
    b1 = view(1, 2, second, [])
    np.testing.assert_array_equal(kept(b1), fresh(b1))
    np.testing.assert_array_equal(kept(a0), fresh(a0))  # asked again: its own map's sums
    a1 = view(0, 2, first, [])
    np.testing.assert_array_equal(kept(a1), fresh(a1))
    assert kept(a1) is not kept(b1)
    for old in (a0, b0):  # views of the step before: the sums of their maps, not others'
        np.testing.assert_array_equal(kept(old), fresh(old))
