"""UAV failures (``team.failures``, ``team.random_failures``): the simulator and the planners."""

import numpy as np
import pytest
from helpers import random_valid_actions, small_config

from ipp_toolkit.env import IPPEnv
from ipp_toolkit.runs.evaluation import evaluate
from ipp_toolkit.sim.mission import reset_mission, step_mission


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
    from ipp_toolkit.sim.team import ACTION_NAMES, action_masks, resolve_moves

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


def test_the_native_api_terminates_a_failed_uav_and_passes_pettingzoo_s_test():
    from pettingzoo.test import parallel_api_test

    config = small_config(resolution=1.0, team={"budget": 6, "failures": [[1, 3]]})
    parallel_api_test(IPPEnv(config), num_cycles=20)
    env = IPPEnv(config)
    observations, _ = env.reset(seed=0)
    assert len(observations) == 4
    for step in range(1, 7):
        actions = {agent: int(np.flatnonzero(obs["action_mask"])[0])
                   for agent, obs in observations.items() if agent in env.agents}
        observations, rewards, terminations, _, _ = env.step(actions)
        if step < 3:
            assert env.agents == ["uav_0", "uav_1", "uav_2", "uav_3"]
        elif step == 3:  # terminated with its last observation and the team reward
            assert terminations["uav_1"] and not terminations["uav_0"]
            assert rewards["uav_1"] == rewards["uav_0"]
            assert env.agents == ["uav_0", "uav_2", "uav_3"]
        elif step < 6:
            assert "uav_1" not in observations and env.agents == ["uav_0", "uav_2", "uav_3"]
    assert env.agents == []


def test_the_sb3_view_keeps_a_failed_uav_s_slot_inert():
    from ipp_toolkit.vec import make_sb3_vec_env

    config = small_config(resolution=1.0, team={"budget": 4, "failures": [[2, 2]]})
    vec = make_sb3_vec_env(config, n_envs=1, seed=0)
    try:
        obs = vec.reset()
        assert obs.shape[0] == 4
        for step in range(1, 5):
            actions = vec.action_masks().argmax(axis=1)
            obs, rewards, dones, _ = vec.step(actions)
            if 2 <= step < 4:  # (the last step's obs is already the next mission's)
                assert not obs[2].any() and vec.action_masks()[2].all()
            # The step it fails brings the team reward, as in the native API; then nothing.
            if step == 2:
                assert rewards[2] == rewards[0]
            if step == 3:
                assert rewards[2] == 0.0 and rewards[0] != 0.0
        assert dones.all()  # every slot ends with the mission
    finally:
        vec.close()


def test_coma_training_refuses_failures_for_now(tmp_path):
    from coma.config import preset
    from coma.learner import train

    with pytest.raises(ValueError, match="team.failures.*COMA"):
        train(preset("cpu", missions=1), small_config(team={"failures": [[1, 3]]}), tmp_path)


def test_stop_workers_ends_running_tasks_and_the_manager_thread_at_once():
    """An interrupt must not wait for running missions: the workers are terminated and the
    pool's manager thread has ended when stop_workers returns (else concurrent.futures' exit
    hook can race with its pipe close and print a traceback after the interrupt message)."""
    import concurrent.futures
    import multiprocessing
    import time

    from ipp_toolkit.runs.process_pool import stop_workers

    executor = concurrent.futures.ProcessPoolExecutor(
        max_workers=1, mp_context=multiprocessing.get_context("spawn"))
    running = executor.submit(time.sleep, 120)
    pending = executor.submit(time.sleep, 120)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not running.running():
        time.sleep(0.05)
    processes = list(executor._processes.values())
    manager = executor._executor_manager_thread
    start = time.monotonic()
    stop_workers(executor)
    assert time.monotonic() - start < 15
    assert pending.done() and running.done()
    assert not manager.is_alive()
    for process in processes:
        process.join(timeout=5)
        assert not process.is_alive()
