import numpy as np
import pytest
from helpers import random_valid_actions, small_config

from ipp_toolkit.belief.mapping import binary_entropy, class_weights
from ipp_toolkit.sim.mission import (
    InvalidActionError,
    compute_metrics,
    reset_mission,
    step_mission,
)


def run_mission(config, seed=0, mission=0, action_seed=0):
    state = reset_mission(config, seed, mission)
    rng = np.random.default_rng(action_seed)
    positions, rewards = [state.positions.copy()], []
    while not state.done:
        rewards.append(step_mission(state, random_valid_actions(state.masks(), rng)))
        positions.append(state.positions.copy())
    return state, np.array(positions), np.array(rewards)


def test_reset_places_fixed_starts_and_measures(config):
    state = reset_mission(config, seed=0)
    xy = state.positions_m()[:, :2].tolist()
    assert xy == [[10, 10], [40, 10], [40, 40], [10, 40]]
    assert (state.positions_m()[:, 2] == 15).all()
    assert state.step == 0 and len(state.history) == 1
    # The start measurements already reduced the entropy of interesting cells.
    assert state.history[0].entropy < 1.0


def test_same_seed_same_trajectory_and_metrics(config):
    a, pos_a, rew_a = run_mission(config, seed=3)
    b, pos_b, rew_b = run_mission(config, seed=3)
    assert (pos_a == pos_b).all() and (rew_a == rew_b).all()
    assert [m.as_dict() for m in a.history] == [m.as_dict() for m in b.history]
    assert (a.maps.logodds == b.maps.logodds).all()
    c, _, _ = run_mission(config, seed=4)
    assert not (a.ground_truth == c.ground_truth).all()


def test_missions_and_namespaces_differ(config):
    base = reset_mission(config, 0, 0, "train").ground_truth
    assert not (reset_mission(config, 0, 1, "train").ground_truth == base).all()
    assert not (reset_mission(config, 0, 0, "test").ground_truth == base).all()


def test_running_metrics_match_full_recompute(config):
    state, _, _ = run_mission(config.replace(team={"comm_range": float("inf")}), seed=1)
    g = state.global_index
    full = compute_metrics(state.ground_truth, state.maps.prob[g], state.maps.entropy[g])
    assert state.metrics().entropy == pytest.approx(full.entropy, abs=1e-5)
    assert state.metrics().f1 == pytest.approx(full.f1, abs=1e-9)
    assert state.metrics().rmse == pytest.approx(full.rmse, abs=1e-5)
    assert len(state.history) == state.budget + 1
    assert state.history[-1].entropy < state.history[0].entropy
    assert state.history[-1].f1 > state.history[0].f1


def test_reward_matches_full_map_formula(config):
    state = reset_mission(config, seed=2)
    rng = np.random.default_rng(5)
    for _ in range(4):
        g = state.global_index
        before = state.maps.prob[g].astype(np.float64).copy()
        reward = step_mission(state, random_valid_actions(state.masks(), rng))
        after = state.maps.prob[g].astype(np.float64)
        w_after = class_weights(after)
        reduction = np.sum(w_after * (binary_entropy(before) - binary_entropy(after)))
        expected = 22 * reduction / np.sum(w_after * binary_entropy(before)) - 0.5
        assert reward == pytest.approx(expected, rel=1e-3, abs=1e-4)


def test_reward_sign_rewards_reduction():
    # Fully interesting terrain: descending to sharper measurements reduces entropy.
    config = small_config(n_agents=2)
    truth = np.ones((100, 100), dtype=bool)
    state = reset_mission(config, seed=0, ground_truth=truth)
    step_mission(state, [5, 5])
    assert state.reward > config.reward.beta + 0.5
    bigger_alpha = config.replace(reward={"alpha": 44.0})
    state2 = reset_mission(bigger_alpha, seed=0, ground_truth=truth)
    step_mission(state2, [5, 5])
    assert state2.reward - bigger_alpha.reward.beta == pytest.approx(
        2 * (state.reward - config.reward.beta))


def test_last_step_measurement_counts(config):
    state, _, rewards = run_mission(config, seed=0)
    assert len(rewards) == config.team.budget
    # Metrics after the last step differ from the step before: its measurements were fused.
    assert state.history[-1].entropy != state.history[-2].entropy


def test_collision_rule_in_step():
    config = small_config(n_agents=2)
    state = reset_mission(config, seed=0)
    state.positions[:] = [[4, 5, 2], [6, 5, 2]]
    step_mission(state, [2, 4])  # both move into (5, 5)
    assert state.positions.tolist() == [[5, 5, 2], [6, 5, 2]]
    assert state.blocked.tolist() == [False, True]


def test_masked_action_raises_and_keeps_state(config):
    state = reset_mission(config, seed=0)
    before = state.positions.copy()
    with pytest.raises(InvalidActionError, match=r"uav_0.*action 0 \(up\) is masked"):
        step_mission(state, [0, 1, 1, 1])  # everyone starts at the top level
    with pytest.raises(InvalidActionError, match="uav_2.*action 9 is out of range"):
        step_mission(state, [1, 1, 9, 1])
    with pytest.raises(InvalidActionError, match="one action per agent"):
        step_mission(state, [1, 1])
    assert (state.positions == before).all() and state.step == 0


def test_hold_mode_keeps_position_and_measures():
    config = small_config(n_agents=2).replace(team={"invalid_action": "hold"})
    state = reset_mission(config, seed=0)
    before = state.positions.copy()
    step_mission(state, [0, 0])  # up at the top level: both hold
    assert (state.positions == before).all() and state.step == 1


def test_done_mission_refuses_steps(config):
    state, _, _ = run_mission(config)
    with pytest.raises(RuntimeError, match="mission is over"):
        step_mission(state, [1, 1, 1, 1])


@pytest.mark.parametrize("n_agents", [3, 12])
def test_random_starts_are_distinct(n_agents):
    state = reset_mission(small_config(n_agents=n_agents), seed=0)
    cells = {(x, y) for x, y, _ in state.positions.tolist()}
    assert len(cells) == n_agents


def test_no_two_agents_share_a_cell_over_missions():
    config = small_config(n_agents=8, comm_range=float("inf"))
    for seed in range(3):
        state = reset_mission(config, seed=seed)
        rng = np.random.default_rng(seed)
        while not state.done:
            step_mission(state, random_valid_actions(state.masks(), rng))
            assert len({(x, y) for x, y, _ in state.positions.tolist()}) == 8


def test_local_maps_follow_communication():
    # D = 0: agent 0's local map only changes inside its own footprints.
    config = small_config(comm_range=0.0)
    state = reset_mission(config, seed=0)
    r0, r1, c0, c1 = state.footprints[1]
    assert (state.maps.prob[0, r0:r1, c0:c1] == 0.5).all()
    assert (state.maps.prob[1, r0:r1, c0:c1] != 0.5).any()
    # D = inf: everyone holds every start measurement, identical to the global map.
    state = reset_mission(config.replace(team={"comm_range": float("inf")}), seed=0)
    for k in range(4):
        np.testing.assert_allclose(state.maps.logodds[k], state.maps.logodds[4])
