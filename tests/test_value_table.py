"""The interned value table and the compiled kernels (per rectangle and whole step, sensor noise)
against their NumPy reference."""

import numpy as np
import pytest
from helpers import random_valid_actions

from ipp_toolkit._native import kernels
from ipp_toolkit.belief import value_table
from ipp_toolkit.belief.block_grid import BlockGrid
from ipp_toolkit.belief.mapping import BELIEF_COLUMNS, LOGODDS_CLIP, belief_columns
from ipp_toolkit.belief.value_table import DerivedMemo, ValueTable
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.sim import mission
from ipp_toolkit.sim.mission import reset_mission, step_mission
from ipp_toolkit.world.seeding import mission_streams
from ipp_toolkit.world.sensor_noise import assembled_entropy, compiled_noise_ok

needs_numba = pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not importable")


def _square(values):
    return (values * values, values + 1)


@pytest.fixture(params=["compiled", "numpy"])
def path(request, monkeypatch):
    if request.param == "compiled" and not kernels.AVAILABLE:
        pytest.skip("numba is not importable")
    monkeypatch.setattr(kernels, "AVAILABLE", request.param == "compiled")
    return request.param


def test_equal_values_share_an_index_and_columns_are_derived_once(path):
    table = ValueTable(_square, ("square", "plus_one"), first=np.float32([0.0]))
    values = np.float32([[3.0, 0.0, -2.5], [3.0, 7.25, -2.5]])
    index = table.indices(values)
    assert index.shape == (2, 3) and index[0, 1] == 0  # the first value interned
    assert index[0, 0] == index[1, 0] and index[0, 2] == index[1, 2]
    assert len(set(index.ravel().tolist())) == 4 == len(table)
    np.testing.assert_array_equal(table.values[index], values)
    np.testing.assert_array_equal(table.column("square")[index], values * values)
    np.testing.assert_array_equal(table.column("plus_one")[index], values + 1)
    # -0.0 and 0.0 are different bit patterns but the same value: both are fine.
    again = table.indices(values[:, ::-1])  # a strided view
    np.testing.assert_array_equal(again, index[:, ::-1])


def test_growth_keeps_every_index(path):
    rng = np.random.default_rng(0)
    table = ValueTable(_square, ("square", "plus_one"))
    values = rng.normal(size=20_000).astype(np.float32)
    first = table.indices(values[:7_000])
    second = table.indices(values)  # grows and rehashes past the first capacity
    np.testing.assert_array_equal(second[:7_000], first)
    np.testing.assert_array_equal(table.values[second], values)
    np.testing.assert_array_equal(table.column("square")[second], values * values)
    assert len(table) == len(np.unique(values))


def test_bad_dtype_is_refused():
    table = ValueTable(_square, ("square", "plus_one"))
    with pytest.raises(TypeError, match="float32"):
        table.indices(np.zeros(3))


def test_belief_columns_are_the_cell_functions():
    logodds = np.linspace(-9, 9, 301).astype(np.float32)
    prob, entropy, weights, wentropy = belief_columns(logodds, 0.7, 0.2)
    assert len(BELIEF_COLUMNS) == 4
    np.testing.assert_allclose(prob, 1 / (1 + np.exp(-logodds.astype(np.float64))), rtol=1e-6)
    np.testing.assert_array_equal(wentropy, weights * entropy)
    assert set(np.unique(weights).tolist()) == {np.float32(0.2), np.float32(0.5),
                                                 np.float32(0.7)}


# Teams the whole-mission comparisons fly: the paper's, everyone in range, and a larger
# team with random starts, lost messages and failing UAVs.
_TEAMS = {
    "d25": {"comm_range": 25.0},
    "inf": {"comm_range": float("inf")},
    "drops": {"n_agents": 6, "start": "random", "comm_range": 15.0, "message_drop": 0.3,
              "random_failures": 2},
}


@needs_numba
@pytest.mark.parametrize("team", sorted(_TEAMS))
def test_compiled_and_numpy_refresh_agree_over_whole_missions(monkeypatch, team):
    config = EnvConfig().replace(world={"resolution": 0.5}, team=_TEAMS[team])
    states = {}
    for compiled in (True, False):
        monkeypatch.setattr(kernels, "AVAILABLE", compiled)
        state = reset_mission(config, seed=4, mission=1)
        rng = np.random.default_rng(2)
        rewards = []
        while not state.done:
            rewards.append(step_mission(state, random_valid_actions(state.masks(), rng)))
        states[compiled] = (state, rewards)
    (fast, fast_rewards), (reference, reference_rewards) = states[True], states[False]
    maps, expected = fast.maps, reference.maps
    for name in ("logodds", "prob", "entropy", "wentropy"):
        np.testing.assert_array_equal(getattr(maps, name), getattr(expected, name), err_msg=name)
    # The same values, possibly at other indices.
    np.testing.assert_array_equal(maps.table.values[maps.value_index],
                                  expected.table.values[expected.value_index])
    np.testing.assert_allclose(maps.prob_blocks, expected.prob_blocks, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(maps.wentropy_blocks, expected.wentropy_blocks, rtol=1e-12,
                               atol=1e-9)
    np.testing.assert_allclose(fast_rewards, reference_rewards, rtol=1e-9, atol=1e-12)
    for a, b in zip(fast.history, reference.history, strict=True):
        np.testing.assert_allclose(list(a.as_dict().values()), list(b.as_dict().values()),
                                   rtol=1e-9, atol=1e-12)


def _fly(config: EnvConfig, mission_index: int = 1, read_every_step: bool = False):
    state = reset_mission(config, seed=4, mission=mission_index)
    rng = np.random.default_rng(2)
    rewards = []
    while not state.done:
        rewards.append(step_mission(state, random_valid_actions(state.masks(), rng)))
        if read_every_step:
            state.maps.prob  # noqa: B018 (brings the per-cell arrays up to date)
    return state, rewards


@needs_numba
@pytest.mark.parametrize("case", ["d25", "inf", "drops", "fine", "small-table"])
def test_whole_step_kernels_equal_the_per_rectangle_kernels_bit_for_bit(monkeypatch, case):
    """The whole-step kernels (mission._FUSED_STEP) change nothing, to the last bit."""
    resolution = 0.1 if case == "fine" else 0.5
    team = _TEAMS.get(case, _TEAMS["d25"])
    if case == "inf":
        team = {**team, "n_agents": 8}
    if case == "small-table":  # the table fills in mid-pass and grows many times
        monkeypatch.setattr(value_table, "_MIN_SLOT_BITS", 3)
    config = EnvConfig().replace(world={"resolution": resolution}, team=team)
    flown = {}
    for fused in (True, False):
        monkeypatch.setattr(mission, "_FUSED_STEP", fused)
        flown[fused] = _fly(config)
    (fast, fast_rewards), (reference, reference_rewards) = flown[True], flown[False]
    assert fast_rewards == reference_rewards
    assert [h.as_dict() for h in fast.history] == [h.as_dict() for h in reference.history]
    assert fast.stats == reference.stats
    for name in ("logodds", "value_index", "prob", "entropy", "wentropy", "prob_blocks",
                 "wentropy_blocks"):
        np.testing.assert_array_equal(getattr(fast.maps, name).view(np.uint8),
                                      getattr(reference.maps, name).view(np.uint8),
                                      err_msg=name)
    np.testing.assert_array_equal(fast.maps.table.values.view(np.uint32),
                                  reference.maps.table.values.view(np.uint32))
    assert fast.maps.changes == reference.maps.changes
    for name in ("measurement_planes", "footprints", "heard", "positions", "alive"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(reference, name),
                                      err_msg=name)
    if case == "small-table":
        assert len(fast.maps.table) > 8


@needs_numba
def test_compiled_sensor_noise_is_numpys_stream():
    assert compiled_noise_ok()
    for namespace, seed, mission_index in (("train", 0, 0), ("test", 12345, 7),
                                           ("my-study", 2**33 + 5, 3)):
        streams = mission_streams(namespace, seed, mission_index)
        for step, agents in ((0, [0, 1, 2, 3]), (15, [2, 7]), (2**32 + 1, [1])):
            sizes = [1 + 37 * agent for agent in agents]  # odd counts: half-used outputs
            offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
            got = np.empty(offsets[-1], dtype=np.float32)
            kernels.sensor_noise(assembled_entropy(streams, step, agents), offsets, got)
            expected = np.concatenate([streams.sensor(step, agent).random(size,
                                                                          dtype=np.float32)
                                       for agent, size in zip(agents, sizes, strict=True)])
            np.testing.assert_array_equal(got.view(np.uint32), expected.view(np.uint32))


@needs_numba
def test_reading_planes_are_numpys_block_sums():
    """read_cells sums the planes as np.add.reduceat does, up to blocks of 129 cells."""
    rng = np.random.default_rng(5)
    for map_cells, grid_points, spacing in ((258, 3, 129.0), (100, 11, 10.0), (64, 4, 20.0)):
        blocks = BlockGrid(map_cells, grid_points, 1.0, spacing)
        truth = rng.random((map_cells, map_cells)) < 0.4
        rects = [(0, map_cells, 0, map_cells)]  # whole blocks: 128 rows after the first
        for _ in range(4):
            r0, c0 = rng.integers(0, map_cells - 1, 2)
            r1 = rng.integers(r0 + 1, map_cells + 1)
            c1 = rng.integers(c0 + 1, map_cells + 1)
            rects.append((r0, r1, c0, c1))
        rects = np.array(rects, dtype=np.int64)
        sizes = (rects[:, 1] - rects[:, 0]) * (rects[:, 3] - rects[:, 2])
        offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        noise = rng.random(offsets[-1], dtype=np.float32)
        thresholds = np.float32([0.99, 0.7, 0.6, 0.8, 0.65])
        weights = rng.random((5, 2))
        readings = np.empty(offsets[-1], dtype=bool)
        planes = np.zeros((5, grid_points, grid_points))
        kernels.read_cells(truth, rects, thresholds, noise, offsets, weights, blocks.edges,
                           readings, planes)
        for f, (r0, r1, c0, c1) in enumerate(rects.tolist()):
            cells = noise[offsets[f]:offsets[f + 1]].reshape(r1 - r0, c1 - c0)
            reading = truth[r0:r1, c0:c1] ^ (cells >= thresholds[f])
            np.testing.assert_array_equal(
                readings[offsets[f]:offsets[f + 1]].reshape(reading.shape), reading)
            expected = np.zeros((grid_points, grid_points))
            blocks.add_block_sums(expected, np.where(reading, weights[f, 1], weights[f, 0]),
                                  (r0, r1, c0, c1))
            np.testing.assert_array_equal(planes[f], expected)


@needs_numba
def test_worlds_with_larger_blocks_take_the_per_rectangle_path(monkeypatch):
    config = EnvConfig().replace(world={"area_size": 20.0, "grid_spacing": 10.0,
                                        "resolution": 0.05},
                                 team={"n_agents": 2, "start": "random"})
    geometry = mission.MissionGeometry(config)
    assert geometry.blocks.block_sizes.max() == 200 and not geometry.whole_step

    def refuse(*_):
        raise AssertionError("the whole-step kernels cannot sum blocks of 200 cells")

    monkeypatch.setattr(kernels, "fuse_evidence", refuse)
    state = reset_mission(config, seed=0, geometry=geometry)
    step_mission(state, random_valid_actions(state.masks(), np.random.default_rng(0)))
    assert state.step == 1 and mission.MissionGeometry(EnvConfig()).whole_step


@needs_numba
@pytest.mark.parametrize("case", ["d25", "inf"])
def test_per_cell_arrays_are_built_only_when_read_and_then_match_reading_every_step(case):
    """A step writes only the index array and the block sums; the log-odds and caches are
    looked up on demand, the same whether read once at the end or after every step."""
    team = _TEAMS[case] if case == "d25" else {**_TEAMS[case], "n_agents": 8}
    config = EnvConfig().replace(world={"resolution": 0.5}, team=team)
    (lazy, _), (eager, _) = _fly(config), _fly(config, read_every_step=True)
    assert lazy.maps._arrays is None  # nobody read them: never built
    np.testing.assert_array_equal(lazy.maps.value_index, eager.maps.value_index)
    table = lazy.maps.table
    expected = [table.values] + [table.column(name) for name in ("prob", "entropy",
                                                                 "wentropy")]
    for name, column in zip(("logodds", "prob", "entropy", "wentropy"), expected,
                            strict=True):
        got = getattr(lazy.maps, name)
        np.testing.assert_array_equal(got.view(np.uint32),
                                      getattr(eager.maps, name).view(np.uint32), err_msg=name)
        np.testing.assert_array_equal(got, column[lazy.maps.value_index], err_msg=name)


@needs_numba
def test_known_transitions_lead_to_the_sums_of_their_values():
    """Every transition the whole-step kernel remembered is the index of clip(value +
    increment): the float32 sum the per-rectangle path computes."""
    config = EnvConfig().replace(world={"resolution": 0.5}, team=_TEAMS["d25"])
    state, _ = _fly(config)
    maps = state.maps
    values, clip = maps.table.values, np.float32(LOGODDS_CLIP)
    assert len(maps._delta_slots) == len(config.world.altitudes)
    known = 0
    for (d0, d1), slot in maps._delta_slots.items():
        for reading, delta in enumerate((d0, d1)):
            targets = maps._transitions[:len(values), 2 * slot + reading]
            hit = np.flatnonzero(targets >= 0)
            known += len(hit)
            sums = np.clip(values[hit] + np.float32(delta), -clip, clip)
            np.testing.assert_array_equal(values[targets[hit]].view(np.uint32),
                                          sums.view(np.uint32))
    assert known > 50


def test_a_shared_memo_gives_the_columns_deriving_gives(path):
    """Tables sharing a DerivedMemo get, for every value, the columns their own derive
    gives; each value is derived once for all of them."""
    calls = []

    def counted(values):
        calls.append(len(values))
        return _square(values)

    memo = DerivedMemo(counted, 2)
    assert memo.exact()
    calls.clear()
    rng = np.random.default_rng(3)
    values = rng.normal(size=(3, 40)).astype(np.float32)
    values[1, :20] = values[0, :20]  # the second table meets half of the first one's values
    for row in values:
        table = ValueTable(counted, ("square", "plus_one"), memo=memo)
        index = table.indices(row)
        square, plus_one = _square(row)
        np.testing.assert_array_equal(table.column("square")[index].view(np.uint32),
                                      square.view(np.uint32))
        np.testing.assert_array_equal(table.column("plus_one")[index], plus_one)
    assert sum(calls) == len(np.unique(values))


def test_a_memo_whose_derive_depends_on_position_is_not_used():
    memo = DerivedMemo(lambda values: (values + np.arange(len(values), dtype=np.float32),),
                       1)
    assert not memo.exact()
    table = ValueTable(memo.derive, ("shifted",), memo=memo)
    assert table.memo is None
