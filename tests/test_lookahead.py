"""The open-loop lookahead of the ig family: its path values against a per-cell count."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from baselines.field_prior.planner import LearnedPriorPlanner
from baselines.heuristics.information_gain import InformationGainPlanner
from baselines.heuristics.spatial_gain import SpatialGainPlanner
from ipp_toolkit._native import kernels
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planning import planner_views
from ipp_toolkit.planning.lookahead import continuation_values
from ipp_toolkit.planning.segments import SegmentSums
from ipp_toolkit.sim.driver import fly_missions, start_missions
from ipp_toolkit.sim.team import ACTION_DELTAS, N_ACTIONS


def _config(agents: int = 2, resolution: float = 1.0) -> EnvConfig:
    return EnvConfig().replace(world={"resolution": resolution}, team={"n_agents": agents},
                               terrain={"kind": "blobs"})


def _views_after(planner, config, steps: int):
    """The team's views after ``steps`` greedy steps of ``planner`` on validation mission 0."""
    state, = start_missions(config, 0, 0, 1, "validation")
    planner.reset(config, seed=0)
    flown = []

    def policy(states):
        views = planner_views(states[0], planner)
        if len(flown) == steps:
            raise StopIteration
        flown.append(1)
        return [planner.act(views)]

    try:
        fly_missions([state], policy)
    except StopIteration:
        pass
    return planner_views(state, planner)


def _brute_force(planner, view, first_target, depth, gamma, mate_rects):
    """The best continuation after ``first_target``, cell by cell: each later footprint
    counts the cells no earlier footprint of the path covered, at its altitude's value."""
    camera = planner.camera
    n_z, n_y, n_x = camera.rects.shape[:3]
    size = view.local_logodds.shape[0]
    whole = (slice(0, size), slice(0, size))
    values = {}
    for z in range(n_z):
        gain = planner.cell_gains(view, z, whole)
        planner._discount(gain, (0, size, 0, size), mate_rects)
        values[z] = gain.astype(np.float64)
    best = -np.inf
    for moves in itertools.product(range(N_ACTIONS), repeat=depth - 1):
        position = np.array(first_target)
        seen = np.zeros((size, size), dtype=bool)
        r0, r1, c0, c1 = camera.rects[position[2], position[1], position[0]]
        seen[r0:r1, c0:c1] = True
        total, ok = 0.0, True
        for t, move in enumerate(moves):
            position = position + ACTION_DELTAS[move]
            if not ((position >= 0).all() and position[0] < n_x and position[1] < n_y
                    and position[2] < n_z):
                ok = False
                break
            r0, r1, c0, c1 = camera.rects[position[2], position[1], position[0]]
            new = np.zeros_like(seen)
            new[r0:r1, c0:c1] = True
            new &= ~seen
            total += gamma ** t * values[position[2]][new].sum()
            seen |= new
        if ok:
            best = max(best, total)
    return best


class _OwnCellGains(SpatialGainPlanner):
    """A subclass that overrides ``cell_gains`` alone: its lookahead sums its own values."""

    def cell_gains(self, view, altitude, cells):
        return super().cell_gains(view, altitude, cells) * np.float32(1.0 + altitude)


@pytest.mark.parametrize("depth, gamma, steps, agent, kind, resolution", [
    (2, 1.0, 3, 1, SpatialGainPlanner, 1.0), (3, 0.5, 3, 1, SpatialGainPlanner, 1.0),
    (3, 0.5, 0, 0, SpatialGainPlanner, 1.0), (3, 0.5, 8, 0, SpatialGainPlanner, 1.0),
    (4, 0.7, 5, 1, SpatialGainPlanner, 1.0), (3, 0.5, 6, 1, InformationGainPlanner, 1.0),
    (3, 0.5, 4, 0, _OwnCellGains, 1.0),
    (3, 0.5, 9, 1, lambda: SpatialGainPlanner(false_positive_weight=0.5), 1.0),
    (3, 0.5, 5, 1, LearnedPriorPlanner, 0.25),  # probability of interest on 2 x 2 cells
])
def test_continuation_values_match_a_cell_by_cell_count(depth, gamma, steps, agent, kind,
                                                        resolution):
    config = _config(resolution=resolution)
    planner = kind()
    views = _views_after(planner, config, steps=steps)
    view = views[agent]
    candidates = view.position[None, :].astype(np.int64) + ACTION_DELTAS
    allowed = view.mask.astype(bool)
    # a teammate's next footprint where the agent is: its cells count half
    mate_rects = planner.camera.rects[view.position[2], view.position[1],
                                      view.position[0]][None]
    grid = planner.segment_grid

    def segment_values(altitude, box):
        values = planner.segment_values(view, altitude, box)
        grid.discount(values, mate_rects, planner.overlap_discount, box)
        return values

    got = continuation_values(planner.camera.rects, candidates, allowed, depth, gamma,
                              segment_values, grid)
    for action in range(N_ACTIONS):
        if allowed[action]:
            want = _brute_force(planner, view, candidates[action], depth, gamma, mate_rects)
            # per cell: float32 products summed; per segment: float64 sums times the weight
            assert got[action] == pytest.approx(want, rel=1e-6, abs=1e-9)
        else:
            assert got[action] == 0.0


def _path(planner, comm: float) -> np.ndarray:
    config = _config().replace(team={"comm_range": comm})
    views = _views_after(planner, config, steps=config.team.budget)
    return np.array([view.position for view in views])


def test_the_default_looks_ahead_with_communication_and_is_greedy_without():
    for comm, same in ((0.0, True), (25.0, False)):
        default = _path(LearnedPriorPlanner(), comm)
        greedy = _path(LearnedPriorPlanner(lookahead_steps=1), comm)
        assert np.array_equal(default, greedy) == same
    silent = _path(LearnedPriorPlanner(lookahead_silent=True), 0.0)
    assert not np.array_equal(silent, _path(LearnedPriorPlanner(lookahead_steps=1), 0.0))


@pytest.mark.parametrize("options, message", [
    ({"lookahead_steps": 0}, "lookahead_steps must be an integer in"),
    ({"lookahead_steps": 9}, "lookahead_steps must be an integer in"),
    ({"lookahead_discount": 1.5}, "lookahead_discount must be a number in"),
    ({"lookahead_discount": float("nan")}, "lookahead_discount must be a number in"),
])
def test_bad_lookahead_options_are_refused_naming_them(options, message):
    with pytest.raises(ValueError, match=message):
        SpatialGainPlanner(**options)


@pytest.mark.parametrize("comm", [25.0, math.inf])
def test_kept_segment_sums_equal_sums_from_scratch(comm):
    """The sums kept across steps (refreshed where the maps changed) are the sums of the
    current maps, bit for bit, for every agent, at every step, on two missions in a row;
    UAVs whose maps are the same (every one at D = inf) share one refresh."""
    config = _config(agents=4, resolution=0.25).replace(team={"comm_range": comm})
    planner = LearnedPriorPlanner()
    columns = [f"altitude_{z}" for z in range(3)]
    kept = None
    for mission in range(2):
        state, = start_missions(config, 0, mission, 1, "validation")
        planner.reset(config, seed=0)
        if kept is None:
            kept = SegmentSums(planner.segment_grid, planner._segment_tables(), columns, 0.0)
        checked: list[int] = []

        def policy(states, kept=kept, checked=checked):
            views = planner_views(states[0], planner)
            for view in views:
                fresh = SegmentSums(planner.segment_grid, planner._segment_tables(), columns,
                                    float(view.step))  # any start: the sums of the map
                np.testing.assert_array_equal(kept(view), fresh(view))
                box = (7, 90, 3, 41)  # a box's sums from its cells alone are the same
                np.testing.assert_array_equal(kept.box_sums(view, box, [2, 0]),
                                              kept(view)[:, [2, 0], 7:90, 3:41])
            shared = all(kept._sums[view.index] is kept._sums[0] for view in views)
            assert shared == (comm == math.inf)
            checked.append(1)
            return [planner.act(views)]

        fly_missions([state], policy)
        assert len(checked) == config.team.budget


def test_kept_path_terms_give_the_same_values_and_stay_bounded(monkeypatch):
    """A waypoint's path rectangles are kept: asked again, the same values; the oldest are
    dropped past the bound in bytes."""
    from ipp_toolkit.planning import lookahead

    planner = SpatialGainPlanner()
    views = _views_after(planner, _config(), steps=3)
    view, grid = views[0], planner.segment_grid
    allowed = view.mask.astype(bool)

    def values(position):
        return continuation_values(planner.camera.rects, position[None, :] + ACTION_DELTAS,
                                   allowed, 3, 0.5,
                                   lambda z, box: planner.segment_values(view, z, box), grid)

    kept = lookahead._KeptPaths()
    monkeypatch.setattr(lookahead, "_KEPT_PATHS", kept)
    first = values(view.position)
    size = kept.entries[next(reversed(kept.entries))].nbytes
    monkeypatch.setattr(lookahead, "PATH_TERMS_BYTES", 3 * size)  # room for three
    for dx in range(1, 5):  # four other waypoints push the first out
        values(view.position + np.array([dx, 0, 0]))
    assert len(kept.entries) == 3 and kept.nbytes <= 3 * size
    np.testing.assert_array_equal(values(view.position), first)  # computed again
    np.testing.assert_array_equal(values(view.position), first)  # kept


@pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not importable")
@pytest.mark.parametrize("depth", [2, 3, 4])
def test_compiled_path_values_are_the_numpy_references_bit_for_bit(monkeypatch, depth):
    """The compiled summed-area tables and path sums add in the NumPy code's order: the same
    continuation values to the last bit, for every agent, with some first moves left out."""
    planner = LearnedPriorPlanner()
    views = _views_after(planner, _config(agents=4, resolution=0.5), steps=2)
    grid, rects = planner.segment_grid, planner.camera.rects
    rng = np.random.default_rng(depth)
    for view in views:
        allowed = view.mask.astype(bool) & (rng.random(N_ACTIONS) < 0.8)
        mates = rects[0, :2, :2].reshape(-1, 4)[: view.index]  # some discounted footprints

        def segment_values(z, box, view=view, mates=mates):
            values = planner.segment_values(view, z, box)
            grid.discount(values, mates, 0.5, box)
            return values

        targets = view.position[None, :] + ACTION_DELTAS
        compiled = continuation_values(rects, targets, allowed, depth, 0.7, segment_values,
                                       grid)
        monkeypatch.setattr(kernels, "AVAILABLE", False)
        reference = continuation_values(rects, targets, allowed, depth, 0.7, segment_values,
                                        grid)
        monkeypatch.setattr(kernels, "AVAILABLE", True)
        np.testing.assert_array_equal(compiled, reference)
        assert (compiled[~allowed] == 0).all() and (compiled[allowed] > 0).any()


@pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not importable")
def test_compiled_summed_area_table_is_two_cumsums_bit_for_bit():
    rng = np.random.default_rng(0)
    values = rng.standard_normal((7, 9)) * 10.0 ** rng.uniform(-5, 5, (7, 9))
    table = np.full((12, 12), np.nan)
    kernels.summed_area(values, table[2:10, 1:11])
    want = np.zeros((8, 10))
    want[1:, 1:] = np.cumsum(np.cumsum(values, axis=0), axis=1)
    np.testing.assert_array_equal(table[2:10, 1:11], want)
    assert np.isnan(table[:2]).all() and np.isnan(table[:, 0]).all()  # nothing else written
