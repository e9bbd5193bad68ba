"""The open-loop lookahead of the ig family: its path values against a per-cell count."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from baselines.learned_prior import LearnedPriorPlanner
from baselines.spatial_gain import SpatialGainPlanner
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planners import planner_views
from ipp_toolkit.planners.lookahead import continuation_values
from ipp_toolkit.sim.driver import fly_missions, start_missions
from ipp_toolkit.sim.team import ACTION_DELTAS, N_ACTIONS


def _config(agents: int = 2) -> EnvConfig:
    return EnvConfig().replace(world={"resolution": 1.0}, team={"n_agents": agents},
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


@pytest.mark.parametrize("depth, gamma, steps, agent", [(2, 1.0, 3, 1), (3, 0.5, 3, 1),
                                                        (3, 0.5, 0, 0), (3, 0.5, 8, 0),
                                                        (4, 0.7, 5, 1)])
def test_continuation_values_match_a_cell_by_cell_count(depth, gamma, steps, agent):
    config = _config()
    planner = SpatialGainPlanner()
    views = _views_after(planner, config, steps=steps)
    view = views[agent]
    candidates = view.position[None, :].astype(np.int64) + ACTION_DELTAS
    allowed = view.mask.astype(bool)
    # a teammate's next footprint where the agent is: its cells count half
    mate_rects = planner.camera.rects[view.position[2], view.position[1],
                                      view.position[0]][None]

    def cell_values(altitude, box):
        gain = planner.cell_gains(view, altitude, (slice(box[0], box[1]), slice(box[2], box[3])))
        planner._discount(gain, box, mate_rects)
        return gain

    got = continuation_values(planner.camera.rects, candidates, allowed, depth, gamma,
                              cell_values)
    for action in range(N_ACTIONS):
        if allowed[action]:
            want = _brute_force(planner, view, candidates[action], depth, gamma, mate_rects)
            assert got[action] == pytest.approx(want, rel=1e-9, abs=1e-9)
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
