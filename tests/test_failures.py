"""UAV failures (``team.failures``, ``team.random_failures``): the simulator and the planners."""

import numpy as np
import pytest
from conftest import random_valid_actions, small_config

from ipp_toolkit.env import IPPEnv
from ipp_toolkit.evaluation import evaluate
from ipp_toolkit.mission import reset_mission, step_mission


@pytest.mark.parametrize("team, match", [
    ({"failures": [[4, 3]]}, r"team.failures.*0..3"),
    ({"failures": [[1, 3], [1, 5]]}, r"team.failures.*distinct"),
    ({"failures": [[1, 0]]}, r"team.failures.*1..15"),
    ({"failures": [[1, 16]]}, r"team.failures.*1..15"),
    ({"failures": [1, 3]}, r"team.failures.*\[agent, step\] pairs"),
    ({"random_failures": -1}, r"team.random_failures = -1"),
    ({"failures": [[0, 2]], "random_failures": 3}, r"team.random_failures.*survive"),
])
def test_bad_failures_are_refused_naming_the_field(team, match):
    with pytest.raises(ValueError, match=match):
        small_config(team=team)


def test_a_failed_uav_stops_moving_sensing_and_communicating():
    config = small_config(comm_range=float("inf"), team={"failures": [[1, 3]]})
    state = reset_mission(config, seed=0, mission=0)
    rng = np.random.default_rng(0)
    for _ in range(2):
        step_mission(state, random_valid_actions(state.masks(), rng))
    assert state.alive.all()
    frozen_position = state.positions[1].copy()
    frozen_map = state.maps.logodds[1].copy()
    last_footprint = state.footprints[1].copy()
    while not state.done:
        global_before = state.maps.logodds[state.global_index].copy()
        step_mission(state, random_valid_actions(state.masks(), rng))
        assert not state.alive[1] and state.alive[[0, 2, 3]].all()
        np.testing.assert_array_equal(state.positions[1], frozen_position)
        np.testing.assert_array_equal(state.maps.logodds[1], frozen_map)
        np.testing.assert_array_equal(state.footprints[1], last_footprint)
        assert not state.heard[1, [0, 2, 3]].any() and not state.heard[[0, 2, 3], 1].any()
        assert not state.measurement_planes[1].any()
        # Only the three others' readings reach the global map: their footprints hold every
        # change.
        changed = state.maps.logodds[state.global_index] != global_before
        covered = np.zeros_like(changed)
        for r0, r1, c0, c1 in state.footprints[[0, 2, 3]].tolist():
            covered[r0:r1, c0:c1] = True
        assert not (changed & ~covered).any()


def test_a_failed_uav_holds_no_cell():
    from ipp_toolkit.team import ACTION_NAMES, action_masks, resolve_moves

    east = ACTION_NAMES.index("east")
    positions = np.array([[2, 2, 0], [3, 2, 0]])  # agent 0 next to agent 1, east of it
    assert action_masks(positions, 11, 3)[0, east] == 0
    assert action_masks(positions, 11, 3, active=np.array([True, False]))[0, east] == 1
    # Agent 1 (failed) does not move, and agent 0 enters its cell without a contest.
    actions = np.array([east, east])
    moved, blocked = resolve_moves(positions, actions, np.array([True, False]),
                                   np.array([True, False]))
    assert moved.tolist() == [[3, 2, 0], [3, 2, 0]] and not blocked.any()


def test_random_failures_follow_the_missions_own_stream():
    config = small_config(team={"random_failures": 2})
    first = reset_mission(config, seed=3, mission=7)
    again = reset_mission(config, seed=3, mission=7)
    other = [reset_mission(config, seed=3, mission=m).failure_step for m in range(8)]
    np.testing.assert_array_equal(first.failure_step, again.failure_step)
    assert np.count_nonzero(first.failure_step <= config.team.budget) == 2
    assert all(((s >= 1) & (s <= config.team.budget)).sum() == 2 for s in other)
    assert len({tuple(s) for s in other}) > 1
    # The terrain and the starts do not depend on the failures.
    plain = reset_mission(small_config(), seed=3, mission=7)
    np.testing.assert_array_equal(first.ground_truth, plain.ground_truth)
    np.testing.assert_array_equal(first.maps.logodds, plain.maps.logodds)


def test_every_planner_flies_with_failures():
    config = small_config(team={"budget": 5, "failures": [[0, 2]], "random_failures": 1})
    planners = "ig,ig_paper,ig_spatial,coverage,random,coma,ppo"
    result = evaluate(config, planners, missions=2, seed=0, progress=False)
    finals = [row for row in result.rows if row["step"] == 5]
    assert len(finals) == 7 * 2
    assert all(0.0 < row["entropy"] <= 1.0 for row in finals)


def test_the_multi_agent_views_refuse_failures_for_now():
    with pytest.raises(ValueError, match="team.failures.*not yet"):
        IPPEnv(small_config(team={"failures": [[1, 3]]}))
