"""The interned value table and the compiled refresh kernels against their NumPy reference."""

import numpy as np
import pytest
from conftest import random_valid_actions

from ipp_toolkit import kernels
from ipp_toolkit.config import EnvConfig
from ipp_toolkit.mapping import BELIEF_COLUMNS, belief_columns
from ipp_toolkit.mission import reset_mission, step_mission
from ipp_toolkit.value_table import ValueTable

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


@needs_numba
@pytest.mark.parametrize("comm_range", [25.0, float("inf")])
def test_compiled_and_numpy_refresh_agree_over_whole_missions(monkeypatch, comm_range):
    config = EnvConfig().replace(world={"resolution": 0.5}, team={"comm_range": comm_range})
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
