"""The paper authors' two baselines as named planners: ``ig_paper`` and ``coverage_paper``."""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import small_config
from test_planners import fly, hand_built_state

from baselines.heuristics.coverage import (
    CoveragePlanner,
    PaperCoveragePlanner,
    paper_lawnmower_paths,
)
from baselines.heuristics.information_gain import (
    InformationGainPlanner,
    PaperInformationGainPlanner,
)
from ipp_toolkit.belief.mapping import LOGODDS_CLIP, entropy_from_logodds, expected_gain
from ipp_toolkit.planning import agent_views, make_planner
from ipp_toolkit.sim.mission import MissionState, reset_mission
from ipp_toolkit.sim.team import ACTION_NAMES
from ipp_toolkit.world.sensor import Camera

UP, NORTH, EAST, SOUTH, WEST, DOWN = range(6)
LN3 = math.log(3.0)


def gain_of(p: float, accuracy: float, outcome_weighting: str) -> float:
    """expected_gain of one cell with probability p (weights 1 / 0), accuracy a."""
    logodds = np.array([[math.log(p / (1 - p))]], dtype=np.float32)
    prob = np.array([[p]], dtype=np.float32)
    entropy = entropy_from_logodds(logodds)
    delta = np.array([math.log((1 - accuracy) / accuracy), math.log(accuracy / (1 - accuracy))],
                     dtype=np.float32)
    return float(expected_gain(logodds, prob, entropy, accuracy, delta,
                               outcome_weighting=outcome_weighting)[0, 0])


# --- the outcome weighting ------------------------------------------------------------------


def test_belief_weighting_of_one_cell_by_hand():
    # p = 0.8, a = 0.75: reading 1 -> l = ln 4 + ln 3, p1 = 12/13; reading 0 -> p0 = 4/7
    # (both weight 1). H(0.8) = 0.7219281, H(12/13) = 0.3912436, H(4/7) = 0.9852281.
    # Authors: 0.8 (0.7219281 - 0.3912436) + 0.2 (0.7219281 - 0.9852281) = 0.2118876.
    # Predictive: q = 0.8 * 0.75 + 0.2 * 0.25 = 0.65 -> 0.65 * 0.3306845 - 0.35 * 0.2633
    # = 0.1227899.
    assert gain_of(0.8, 0.75, "belief") == pytest.approx(0.2118876, abs=2e-6)
    assert gain_of(0.8, 0.75, "predictive") == pytest.approx(0.1227899, abs=2e-6)
    # At p = 0.5 the reading is 1 with probability q = 0.5 whatever a: the two forms agree.
    # H(0.5) - H(0.75) = 1 - 0.8112781, both outcomes weighted 1/2 but p0 = 0.25 weighs 0.
    expected = 0.5 * (1 - 0.8112781)
    assert gain_of(0.5, 0.75, "belief") == pytest.approx(expected, abs=2e-6)
    assert gain_of(0.5, 0.75, "predictive") == pytest.approx(expected, abs=2e-6)


def test_belief_weighting_matches_the_formula_on_a_map():
    config = small_config()
    camera = Camera(config.world, config.sensor)
    rng = np.random.default_rng(1)
    logodds = rng.uniform(-LOGODDS_CLIP, LOGODDS_CLIP, size=(30, 40)).astype(np.float32)
    logodds[:4] = 0.0  # the prior: both weightings coincide there
    prob = (1 / (1 + np.exp(-logodds.astype(np.float64)))).astype(np.float32)
    entropy = entropy_from_logodds(logodds)
    for iz in range(3):
        a, delta = camera.accuracy[iz], camera.delta_logodds[iz]
        predictive = expected_gain(logodds, prob, entropy, a, delta)
        belief = expected_gain(logodds, prob, entropy, a, delta, outcome_weighting="belief")
        # Same per-outcome terms g1, g0: recover them from two weightings and check the third.
        q = prob * a + (1 - prob) * (1 - a)
        p1 = 1 / (1 + np.exp(-np.clip(logodds + delta[1], -LOGODDS_CLIP, LOGODDS_CLIP)))
        p0 = 1 / (1 + np.exp(-np.clip(logodds + delta[0], -LOGODDS_CLIP, LOGODDS_CLIP)))
        w1 = np.where(np.abs(p1 - 0.5) <= 1e-3, 0.5, (p1 > 0.5).astype(float))
        w0 = np.where(np.abs(p0 - 0.5) <= 1e-3, 0.5, (p0 > 0.5).astype(float))
        g1 = w1 * (entropy - entropy_from_logodds(logodds + delta[1]))
        g0 = w0 * (entropy - entropy_from_logodds(logodds + delta[0]))
        clipped = np.abs(logodds) > LOGODDS_CLIP - 2.0  # the clip changes H(p1) there
        np.testing.assert_allclose(belief[~clipped], (prob * g1 + (1 - prob) * g0)[~clipped],
                                   atol=2e-5)
        np.testing.assert_allclose(predictive[~clipped], (q * g1 + (1 - q) * g0)[~clipped],
                                   atol=2e-5)
        np.testing.assert_allclose(belief[:4], predictive[:4], atol=1e-7)
        assert np.abs(belief - predictive).max() > 1e-3  # the weighting does matter elsewhere


def test_unknown_outcome_weighting_is_refused():
    with pytest.raises(ValueError, match="outcome_weighting"):
        gain_of(0.8, 0.75, "posterior")
    with pytest.raises(ValueError, match="outcome_weighting"):
        InformationGainPlanner(outcome_weighting="paper")


def test_ig_paper_is_ig_with_the_belief_weighting():
    planner = make_planner("ig_paper", overlap_discount=0.25)
    assert isinstance(planner, PaperInformationGainPlanner)
    assert isinstance(planner, InformationGainPlanner)
    assert planner.outcome_weighting == "belief" and planner.overlap_discount == 0.25
    assert make_planner("ig").outcome_weighting == "predictive"
    assert isinstance(make_planner("coverage_paper"), PaperCoveragePlanner)


# --- ig_paper against ig --------------------------------------------------------------------


def leaning_state(regions: list[tuple[float, float, float, float, float]]) -> MissionState:
    """Agent 0 at (25 m, 25 m, 10 m), agent 1 far away; agent 0's map is certain (p ~ 0)
    except rectangles (x0, x1, y0, y1) in metres set to probability p."""
    state = hand_built_state(2, [(5, 5, 1), (0, 10, 0)], {}, comm_range=0.0)
    r, size = state.config.world.resolution, state.config.world.map_cells
    for x0, x1, y0, y1, p in regions:
        state.maps.logodds[0, round(y0 / r):round(y1 / r), round(x0 / r):round(x1 / r)] = (
            math.log(p / (1 - p)))
    state.maps.refresh(0, (0, size, 0, size))
    return state


def choices(name: str, state: MissionState) -> np.ndarray:
    planner = make_planner(name)
    planner.reset(state.config, 0)
    return planner.act(agent_views(state, with_observations=False))


def test_ig_paper_prefers_cells_that_already_lean_where_ig_does_not():
    # At 10 m (a = 0.735) one reading is worth 0.0829 bits on an unknown cell for both; on a
    # cell at p = 0.8 it is worth 0.1077 bits to ig but 0.1974 bits to the authors' form.
    # West footprint (x 14.2-25.8 m) sees A only: 88 unknown cells = 7.30 bits;
    # east footprint (x 24.2-35.8 m) sees B only: 48 cells at p = 0.8 = 5.17 / 9.48 bits.
    area_a = (14.5, 16.5, 19.5, 30.5, 0.5)
    area_b = (34.0, 35.5, 21.0, 29.0, 0.8)
    state = leaning_state([area_a, area_b])
    assert ACTION_NAMES[choices("ig", state)[0]] == "west"
    assert ACTION_NAMES[choices("ig_paper", state)[0]] == "east"
    # With B unknown too the weighting cannot matter: both go for the larger A.
    state = leaning_state([area_a, area_b[:4] + (0.5,)])
    assert choices("ig", state)[0] == choices("ig_paper", state)[0] == WEST


@pytest.mark.parametrize(("agents", "positions", "uncertain", "comm"), [
    # test_planners' scenarios: every uncertain cell sits at p = 0.5 exactly.
    (2, [(2, 2, 2), (8, 8, 2)], {0: [(19.0, 23.0, 8.0, 12.0)]}, 0.0),
    (2, [(2, 2, 2), (8, 8, 2)], {0: [(8.0, 12.0, 8.0, 12.0)]}, 0.0),
    (2, [(4, 5, 0), (6, 5, 0)], {0: [(23.0, 27.0, 23.0, 27.0)], 1: [(23.0, 27.0, 23.0, 27.0)]},
     math.inf),
    (2, [(2, 5, 1), (5, 5, 0)], {0: [(17.5, 20.5, 19.5, 30.5)],
                                 1: [(17.5, 19.0, 23.0, 27.0), (31.0, 32.5, 24.0, 27.0)]},
     math.inf),
])
def test_ig_paper_equals_ig_where_the_weighting_cannot_matter(agents, positions, uncertain,
                                                              comm):
    # Same choices, including ig's coordination (claimed targets, discounted footprints).
    state = hand_built_state(agents, positions, uncertain, comm_range=comm)
    np.testing.assert_array_equal(choices("ig_paper", state), choices("ig", state))


def test_ig_paper_flies_other_paths_than_ig_on_a_mission():
    config = small_config(n_agents=4)
    _, ig_actions, _ = fly(make_planner("ig"), config, seed=2)
    _, paper_actions, _ = fly(make_planner("ig_paper"), config, seed=2)
    assert not np.array_equal(ig_actions, paper_actions)


# --- coverage_paper -------------------------------------------------------------------------


def test_paper_lawnmower_paths_are_the_documented_shapes():
    paths = paper_lawnmower_paths()
    assert paths.shape == (4, 15, 2)
    sweep = [10.0, 15.0, 20.0, 25.0, 30.0, 35.0, 40.0]
    path1 = [[x, 10.0] for x in sweep] + [[40.0, 15.0]] + [[x, 20.0] for x in sweep[::-1]]
    path2 = [[x, 30.0] for x in sweep] + [[40.0, 35.0]] + [[x, 40.0] for x in sweep[::-1]]
    path3 = [[10.0, y] for y in sweep] + [[15.0, 40.0]] + [[20.0, y] for y in sweep[::-1]]
    path4 = [[30.0, y] for y in sweep] + [[35.0, 40.0]] + [[40.0, y] for y in sweep[::-1]]
    assert paths.tolist() == [path1, path2, path3, path4]


def metres(xy: np.ndarray) -> list[tuple[float, float]]:
    return [(5.0 * x, 5.0 * y) for x, y in xy.tolist()]


def test_coverage_paper_flies_the_four_paths_from_the_fixed_starts():
    config = small_config(n_agents=4)
    planner = make_planner("coverage_paper")
    state, _, positions = fly(planner, config)
    paths = [set(map(tuple, p.tolist())) for p in paper_lawnmower_paths()]
    # Every UAV starts on a corner of the paths' square, so it descends there (15 -> 10 -> 5 m)
    # and then takes one path waypoint per step, each of the four paths by one UAV; the only
    # other waypoint is the one that closes a path's loop (its ends are 10 m apart).
    flown = []
    for k in range(4):
        assert positions[:3, k].tolist() == [positions[0, k, :2].tolist() + [z]
                                             for z in (2, 1, 0)]
        lane = planner.lanes[k]
        after = positions[2:, k]
        assert np.all(np.abs(np.diff(after, axis=0)).sum(axis=1) == 1)  # no wait, no detour
        on_lane = np.array([any(np.array_equal(p, w) for w in lane) for p in after])
        assert np.count_nonzero(~on_lane) <= 1
        np.testing.assert_array_equal(after[on_lane], lane[:np.count_nonzero(on_lane)])
        flown.append(paths.index(set(metres(lane[:, :2]))))
    assert sorted(flown) == [0, 1, 2, 3]
    # Agent 0 at (10, 10): path 1 from its first waypoint (east at y = 10, north, west at 20).
    assert metres(positions[2:, 0, :2]) == [
        (10.0, 10.0), (15.0, 10.0), (20.0, 10.0), (25.0, 10.0), (30.0, 10.0), (35.0, 10.0),
        (40.0, 10.0), (40.0, 15.0), (40.0, 20.0), (35.0, 20.0), (30.0, 20.0), (25.0, 20.0),
        (20.0, 20.0), (15.0, 20.0)]
    # Agent 1 at (40, 10): path 4 counter-clockwise, north along x = 40 m first.
    assert metres(positions[2:6, 1, :2]) == [(40.0, 10.0), (40.0, 15.0), (40.0, 20.0),
                                             (40.0, 25.0)]
    # Everything stays inside the paths' square: the 10 m border strips are never flown over.
    assert positions[..., :2].min() == 2 and positions[..., :2].max() == 8


def test_coverage_paper_two_uavs_fly_paths_1_and_2():
    config = small_config(n_agents=2)
    planner = make_planner("coverage_paper")
    fly(planner, config)
    paths = [set(map(tuple, p.tolist())) for p in paper_lawnmower_paths()]
    assert [paths.index(set(metres(lane[:, :2]))) for lane in planner.lanes] == [0, 1]
    # Agent 1 starts at (40, 40), mid-path 2: the loop goes west along y = 40 m first, then on
    # from path 2's other end (10, 30) after the one closing waypoint (10, 35).
    assert metres(planner.lanes[1][:10, :2]) == [
        (40.0, 40.0), (35.0, 40.0), (30.0, 40.0), (25.0, 40.0), (20.0, 40.0), (15.0, 40.0),
        (10.0, 40.0), (10.0, 30.0), (15.0, 30.0), (20.0, 30.0)]


def test_coverage_paper_repeats_the_paths_for_eight_uavs():
    config = small_config(n_agents=8)
    planner = make_planner("coverage_paper")
    _, actions, positions = fly(planner, config)
    paths = [set(map(tuple, p.tolist())) for p in paper_lawnmower_paths()]
    flown = sorted(paths.index(set(metres(lane[:, :2]))) for lane in planner.lanes)
    assert flown == [0, 0, 1, 1, 2, 2, 3, 3]
    # One direction of travel for all: no two UAVs lock each other for good; every UAV
    # reaches at least 8 path waypoints at 5 m.
    for k, lane in enumerate(planner.lanes):
        visited = {tuple(p) for p in positions[:, k].tolist()}
        assert sum(tuple(w) in visited for w in lane.tolist()) >= 8


@pytest.mark.parametrize("name", ["ig_paper", "coverage_paper"])
@pytest.mark.parametrize("n_agents", [2, 3, 4, 8])
def test_paper_baselines_fly_valid_and_deterministic_missions(name, n_agents):
    config = small_config(n_agents=n_agents)  # invalid_action="raise": a masked action fails
    planner = make_planner(name)
    state, first, _ = fly(planner, config, seed=4, mission=1)
    assert state.done and first.shape == (config.team.budget, n_agents)
    fly(planner, config, seed=7, mission=0)  # a previous mission must not leak into the next
    _, second, _ = fly(planner, config, seed=4, mission=1)
    np.testing.assert_array_equal(first, second)


def test_coverage_paper_refuses_a_world_without_its_paths():
    config = small_config(n_agents=4).replace(world={"area_size": 35.0},
                                              team={"start": "random"})
    with pytest.raises(ValueError, match="coverage_paper"):
        make_planner("coverage_paper").reset(config, 0)
    CoveragePlanner().reset(config, 0)  # our own coverage adapts to any grid


def test_coverage_paper_ignores_terrain_and_noise():
    # Non-adaptive: the plan depends only on the starts, not on the terrain or the noise.
    config = small_config(n_agents=4)
    _, first, _ = fly(make_planner("coverage_paper"), config, seed=0, mission=0)
    _, other, _ = fly(make_planner("coverage_paper"), config, seed=11, mission=3)
    np.testing.assert_array_equal(first, other)
    assert reset_mission(config, seed=11, mission=3).positions.tolist() == \
        reset_mission(config, seed=0, mission=0).positions.tolist()
