"""The baseline planners: valid and deterministic actions, greedy choices, lanes, registry."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import small_config

from baselines.heuristics.coverage import CoveragePlanner, boustrophedon
from baselines.heuristics.information_gain import InformationGainPlanner, expected_gain
from baselines.heuristics.random_planner import RandomPlanner
from ipp_toolkit.belief.mapping import LOGODDS_CLIP, binary_entropy, class_weights
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planning import Planner, agent_views, available_planners, make_planner
from ipp_toolkit.sim.mission import MissionState, reset_mission, step_mission
from ipp_toolkit.sim.team import ACTION_NAMES
from ipp_toolkit.world.sensor import Camera

PLANNERS = ("random", "coverage", "ig")
UP, NORTH, EAST, SOUTH, WEST, DOWN = range(6)


def fly(planner: Planner, config: EnvConfig, seed: int = 0, mission: int = 0
        ) -> tuple[MissionState, np.ndarray, np.ndarray]:
    """One full mission; returns the final state, (B, N) actions and (B + 1, N, 3) positions."""
    state = reset_mission(config, seed=seed, mission=mission, namespace="test")
    planner.reset(config, seed)
    actions, positions = [], [state.positions.copy()]
    while not state.done:
        views = agent_views(state, with_observations=planner.needs_observations)
        joint = planner.act(views)
        assert joint.shape == (state.n_agents,) and joint.dtype == np.int64
        step_mission(state, joint)  # raises InvalidActionError on a masked action
        actions.append(joint)
        positions.append(state.positions.copy())
    return state, np.array(actions), np.array(positions)


# --- every planner --------------------------------------------------------------------------


@pytest.mark.parametrize("name", PLANNERS)
@pytest.mark.parametrize("n_agents", [2, 4, 8])
def test_planner_flies_full_missions_with_valid_actions(name, n_agents):
    config = small_config(n_agents=n_agents)
    assert config.team.invalid_action == "raise"
    planner = make_planner(name)
    for mission in range(2):
        state, actions, _ = fly(planner, config, seed=3, mission=mission)
        assert state.done and actions.shape == (config.team.budget, n_agents)


@pytest.mark.parametrize("name", PLANNERS)
def test_planner_is_deterministic_under_a_seed(name):
    config = small_config(n_agents=4)
    _, first, _ = fly(make_planner(name), config, seed=5)
    reused = make_planner(name)
    fly(reused, config, seed=9)  # a previous mission must not leak into the next one
    _, second, _ = fly(reused, config, seed=5)
    np.testing.assert_array_equal(first, second)


def test_random_planner_depends_on_its_seed():
    config = small_config(n_agents=4)
    planner = make_planner("random")
    state = reset_mission(config, seed=0)
    views = agent_views(state, with_observations=False)
    draws = []
    for seed in (0, 1):
        planner.reset(config, seed)
        draws.append(np.concatenate([planner.act(views) for _ in range(10)]))
    assert not np.array_equal(draws[0], draws[1])
    # Uniform over the valid actions only.
    masks = state.masks()
    planner.reset(config, 2)
    counts = np.zeros((4, 6))
    for _ in range(600):
        counts[np.arange(4), planner.act(views)] += 1
    assert np.all(counts[masks == 0] == 0)
    assert np.all(counts[masks == 1] > 600 / masks.sum(axis=1).max() * 0.6)


# --- registry -------------------------------------------------------------------------------


@pytest.mark.parametrize(("name", "cls"), [("random", RandomPlanner),
                                           ("coverage", CoveragePlanner),
                                           ("ig", InformationGainPlanner)])
def test_planners_are_found_by_name(name, cls):
    assert name in available_planners()
    planner = make_planner(name)
    assert type(planner) is cls and planner.name == name
    assert planner.needs_observations is False


def test_planner_options_and_unknown_name():
    assert make_planner("coverage", altitude_index=1).altitude_index == 1
    assert make_planner("ig", overlap_discount=0.25).overlap_discount == 0.25
    with pytest.raises(ValueError, match="unknown planner 'greedy'; registered planners: "
                                         ".*coverage, .*ig, .*random"):
        make_planner("greedy")
    with pytest.raises(ValueError, match="overlap_discount"):
        make_planner("ig", overlap_discount=1.5)
    with pytest.raises(ValueError, match="altitude_index"):
        make_planner("coverage", altitude_index=3).reset(small_config(), 0)


# --- information gain -----------------------------------------------------------------------


def test_expected_gain_matches_the_formula():
    config = small_config()
    camera = Camera(config.world, config.sensor)
    rng = np.random.default_rng(0)
    logodds = rng.uniform(-LOGODDS_CLIP, LOGODDS_CLIP, size=(40, 50)).astype(np.float32)
    logodds[:5] = 0.0  # the prior: the weights' tie band of p = 0.5
    logodds[5:10] = camera.delta_logodds[1, 0]  # one reading 0 at 10 m: l1 lands on 0
    logodds[10:12] = LOGODDS_CLIP  # clipped cells
    prob = (1 / (1 + np.exp(-logodds.astype(np.float64))))
    w1, w2 = 0.8, 0.3
    for iz in range(3):
        a = camera.accuracy[iz]
        d0, d1 = camera.delta_logodds[iz].astype(np.float64)
        q = prob * a + (1 - prob) * (1 - a)
        l1 = np.clip(logodds + d1, -LOGODDS_CLIP, LOGODDS_CLIP)
        l0 = np.clip(logodds + d0, -LOGODDS_CLIP, LOGODDS_CLIP)
        p1, p0 = 1 / (1 + np.exp(-l1)), 1 / (1 + np.exp(-l0))
        h = binary_entropy(prob)
        reference = (q * class_weights(p1, w1, w2) * (h - binary_entropy(p1))
                     + (1 - q) * class_weights(p0, w1, w2) * (h - binary_entropy(p0)))
        gain = expected_gain(logodds, prob.astype(np.float32), h.astype(np.float32), a,
                             camera.delta_logodds[iz], w1, w2)
        assert gain.dtype == np.float32 and gain.shape == logodds.shape
        np.testing.assert_allclose(gain, reference, atol=2e-5)


def hand_built_state(n_agents: int, positions: list[tuple[int, int, int]],
                     uncertain: dict[int, list[tuple[float, float, float, float]]],
                     comm_range: float = float("inf")) -> MissionState:
    """A mission whose local maps are certain everywhere except given regions.

    Args:
        n_agents: team size.
        positions: (ix, iy, iz) of every agent.
        uncertain: per agent, regions (x0, x1, y0, y1) in metres left at the prior;
            everything else is certainly uninteresting (zero expected gain).
        comm_range: D; inf = everyone hears everyone.
    """
    config = small_config(n_agents=n_agents, comm_range=comm_range)
    size, r = config.world.map_cells, config.world.resolution
    truth = np.zeros((size, size), dtype=bool)
    truth[: size // 2] = True
    state = reset_mission(config, seed=0, ground_truth=truth)
    state.positions = np.array(positions, dtype=np.int64)
    state.heard = np.full((n_agents, n_agents), comm_range > 0) | np.eye(n_agents, dtype=bool)
    for k in range(n_agents):
        state.maps.logodds[k] = -LOGODDS_CLIP
        for x0, x1, y0, y1 in uncertain.get(k, []):
            state.maps.logodds[k, round(y0 / r):round(y1 / r), round(x0 / r):round(x1 / r)] = 0.0
        state.maps.refresh(k, (0, size, 0, size))
    return state


@pytest.mark.parametrize(("region", "expected"), [
    ((19.0, 23.0, 8.0, 12.0), EAST),  # only the east footprint reaches x > 18.7 m
    ((8.0, 12.0, 19.0, 23.0), NORTH),
    ((0.0, 1.0, 8.0, 12.0), WEST),  # only the west footprint reaches x < 1.3 m
    ((8.0, 12.0, 0.0, 1.0), SOUTH),
    ((8.0, 12.0, 8.0, 12.0), DOWN),  # every footprint sees it; 10 m reads it best
])
def test_ig_picks_the_informative_action(region, expected):
    # Agent 0 at (10 m, 10 m, 15 m): footprints of the moves are 17.3 m wide (11.5 m down).
    state = hand_built_state(2, [(2, 2, 2), (8, 8, 2)], {0: [region]}, comm_range=0.0)
    planner = make_planner("ig")
    planner.reset(state.config, 0)
    actions = planner.act(agent_views(state, with_observations=False))
    assert ACTION_NAMES[actions[0]] == ACTION_NAMES[expected]
    # Agent 1's map holds no uncertainty: all gains are 0 -> its first valid action (north).
    assert actions[1] == NORTH


def test_ig_avoids_a_target_claimed_by_a_heard_teammate():
    # Both want waypoint (5, 5) at 5 m: agent 0 from the west, agent 1 from the east.
    region = (23.0, 27.0, 23.0, 27.0)
    positions = [(4, 5, 0), (6, 5, 0)]
    for comm_range, agent1 in [(0.0, WEST), (float("inf"), None)]:
        state = hand_built_state(2, positions, {0: [region], 1: [region]}, comm_range)
        planner = make_planner("ig")
        planner.reset(state.config, 0)
        actions = planner.act(agent_views(state, with_observations=False))
        assert actions[0] == EAST
        if agent1 is None:  # heard: the same-target rule would hold it back, so it avoids it
            assert actions[1] != WEST
        else:  # not heard: it cannot know
            assert actions[1] == agent1


@pytest.mark.parametrize(("discount", "expected"), [(0.0, EAST), (0.5, EAST), (1.0, WEST)])
def test_ig_discounts_cells_a_heard_teammate_will_see(discount, expected):
    # Agent 0 flies east at 10 m to (15 m, 25 m); its footprint (x 9.2-20.8 m) covers
    # region A of agent 1's map. Agent 1 at (25 m, 25 m, 5 m) sees A (24 cells) only by
    # flying west and the smaller B (18 cells) only by flying east.
    area_a, area_b = (17.5, 19.0, 23.0, 27.0), (31.0, 32.5, 24.0, 27.0)
    state = hand_built_state(2, [(2, 5, 1), (5, 5, 0)],
                             {0: [(17.5, 20.5, 19.5, 30.5)], 1: [area_a, area_b]})
    planner = make_planner("ig", overlap_discount=discount)
    planner.reset(state.config, 0)
    actions = planner.act(agent_views(state, with_observations=False))
    assert actions[0] == EAST
    assert ACTION_NAMES[actions[1]] == ACTION_NAMES[expected]


def test_ig_beats_random_on_final_entropy():
    config = small_config(n_agents=4, comm_range=float("inf"))
    entropies = {}
    for name in ("ig", "random"):
        planner = make_planner(name)
        entropies[name] = np.mean([fly(planner, config, seed=0, mission=m)[0].metrics().entropy
                                   for m in range(5)])
    assert entropies["ig"] < entropies["random"] - 0.1, entropies


# --- coverage -------------------------------------------------------------------------------


def test_boustrophedon_is_one_connected_lawnmower():
    path = boustrophedon(11)
    assert path.shape == (121, 2)
    assert len({tuple(p) for p in path.tolist()}) == 121
    assert np.all(np.abs(np.diff(path, axis=0)).sum(axis=1) == 1)
    assert path[:3].tolist() == [[0, 0], [1, 0], [2, 0]] and path[11].tolist() == [10, 1]


@pytest.mark.parametrize("n_agents", [2, 4, 8])
def test_coverage_lanes_partition_the_grid(n_agents):
    config = small_config(n_agents=n_agents)
    planner = make_planner("coverage", altitude_index=1)
    state = reset_mission(config, seed=0)
    planner.reset(config, 0)
    planner.act(agent_views(state, with_observations=False))
    lanes = planner.lanes
    assert len(lanes) == n_agents
    cells = np.concatenate(lanes)
    assert np.all(cells[:, 2] == 1)
    assert len({tuple(c) for c in cells[:, :2].tolist()}) == len(cells) == 121
    assert max(map(len, lanes)) - min(map(len, lanes)) <= 1
    for lane in lanes:  # each lane is a path of unit steps
        assert np.all(np.abs(np.diff(lane[:, :2], axis=0)).sum(axis=1) == 1)


def test_coverage_visits_its_lane_waypoints():
    config = small_config(n_agents=2)
    planner = make_planner("coverage")
    state, _, positions = fly(planner, config)
    budget = config.team.budget
    for k, lane in enumerate(planner.lanes):
        start = positions[0, k]
        transit = int(np.abs(lane[0] - start).sum())  # Manhattan steps to the lane entry
        assert transit < budget
        # Unobstructed (the two UAVs are far apart): after the transit, one waypoint per step.
        visited = positions[transit:, k]
        np.testing.assert_array_equal(visited, lane[:len(visited)])
        # The transit itself went down first, then flew straight to the entry.
        assert np.all(np.abs(np.diff(positions[:transit + 1, k], axis=0)).sum(axis=1) == 1)
        assert positions[start[2] - lane[0, 2], k, 2] == lane[0, 2]


@pytest.mark.parametrize(("blocker", "position", "expected"), [
    ((0, 1, 0), (1, 1, 0), SOUTH),  # west is masked: the other move towards the entry
    ((0, 0, 0), (1, 0, 0), UP),  # the only helpful move is masked: the first valid action
])
def test_coverage_takes_a_valid_action_when_its_move_is_masked(blocker, position, expected):
    config = small_config(n_agents=2)
    state = reset_mission(config, seed=0)
    planner = make_planner("coverage")
    planner.reset(config, 0)
    planner.act(agent_views(state, with_observations=False))  # plans from the fixed starts
    assert planner.lanes[0][0].tolist() == [0, 0, 0]  # agent 0 enters its lane at (0, 0)
    # Put agent 0 next to its entry and agent 1 in the way of its preferred move (west).
    state.positions = np.array([position, blocker], dtype=np.int64)
    views = agent_views(state, with_observations=False)
    actions = planner.act(views)
    assert views[0].mask[actions[0]] and views[1].mask[actions[1]]
    assert ACTION_NAMES[actions[0]] == ACTION_NAMES[expected]


def _trained_config(planner: Planner) -> EnvConfig:
    return getattr(planner, "trained_config", None) or planner.meta.env_config


@pytest.mark.parametrize("name", ["coma", "ppo"])
def test_learned_planners_avoid_targets_heard_teammates_chose(name):
    """The shipped learned planners decide in index order, like ``ig``: no agent moves to a
    2-D cell that a heard, lower-index teammate chose while another valid option is left;
    ``in_order=False`` gives each agent its own masked argmax instead."""
    import math

    from ipp_toolkit.planning import planner_views
    from ipp_toolkit.sim.team import ACTION_DELTAS, unclaimed_options

    planner = make_planner(name)
    config = _trained_config(planner).replace(team={"n_agents": 8, "comm_range": math.inf})
    planner.reset(config, 0)
    independent = make_planner(name, in_order=False) if name == "ppo" else None
    if independent is not None:
        independent.reset(config, 0)
    state = reset_mission(config, seed=0, mission=0)
    differed = 0
    while not state.done:
        views = planner_views(state, planner)
        actions = planner.act(views)
        targets = state.positions + ACTION_DELTAS[actions]
        for k, view in enumerate(views):
            mates = view.teammates[view.teammates < k]
            assert unclaimed_options(view.position, view.mask, targets[mates])[actions[k]]
        if independent is not None:
            own = independent.act(views)
            masks = np.stack([view.mask for view in views]).astype(bool)
            assert masks[np.arange(len(own)), own].all()
            differed += int((own != actions).any())
        step_mission(state, actions)
    if independent is not None:
        assert differed > 0  # the rule changed some choice of 8 UAVs over a mission
