"""The ``ig_spatial`` planner: ``ig``'s rules with a neighbourhood-aware objective."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ipp_toolkit.belief.mapping import entropy_from_logodds
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planning import AgentView, make_planner
from ipp_toolkit.runs.evaluation import evaluate, run_mission
from ipp_toolkit.sim.team import ACTION_NAMES
from ipp_toolkit.world.sensor import Camera

CONFIG = EnvConfig().replace(world={"resolution": 0.5})


def lone_view(config: EnvConfig, position: tuple[int, int, int], logodds: np.ndarray,
              mask: np.ndarray) -> AgentView:
    logodds = logodds.astype(np.float32)
    empty = np.zeros((0,), dtype=np.int64)
    return AgentView(index=0, step=0, budget=15, position=np.array(position),
                     local_logodds=logodds, local_prob=1 / (1 + np.exp(-logodds)),
                     local_entropy=entropy_from_logodds(logodds), mask=mask,
                     teammates=empty, teammate_positions=np.zeros((0, 3), dtype=np.int64),
                     teammate_footprints=np.zeros((0, 4), dtype=np.int64),
                     footprint=np.zeros(4, dtype=np.int64), observation=None)


def test_a_found_region_draws_ig_spatial_but_not_ig():
    camera = Camera(CONFIG.world, CONFIG.sensor)
    position = (5, 5, 0)
    south = camera.rects[0, 4, 5]  # footprint of the south move's waypoint (row0, row1, ...)
    logodds = np.zeros((CONFIG.world.map_cells,) * 2)
    logodds[south[0] - 6:south[0], south[2]:south[3]] = 4.0  # measured interesting, just south
    mask = np.array([0, 1, 1, 1, 1, 0], dtype=np.int8)  # horizontal moves only
    view = lone_view(CONFIG, position, logodds, mask)
    ig, spatial = make_planner("ig"), make_planner("ig_spatial")
    ig.reset(CONFIG, 0)
    spatial.reset(CONFIG, 0)
    # The four horizontal footprints hold only prior cells: ig ties them and takes the first.
    assert ACTION_NAMES[int(ig.act([view])[0])] == "north"
    assert ACTION_NAMES[int(spatial.act([view])[0])] == "south"


def test_uninteresting_surroundings_push_ig_spatial_away():
    camera = Camera(CONFIG.world, CONFIG.sensor)
    north = camera.rects[0, 6, 5]
    logodds = np.zeros((CONFIG.world.map_cells,) * 2)
    logodds[north[1]:north[1] + 6, north[2]:north[3]] = -4.0  # measured empty, just north
    mask = np.array([0, 1, 1, 1, 1, 0], dtype=np.int8)
    spatial = make_planner("ig_spatial")
    spatial.reset(CONFIG, 0)
    action = ACTION_NAMES[int(spatial.act([lone_view(CONFIG, (5, 5, 0), logodds, mask)])[0])]
    assert action != "north"


def test_ig_spatial_flies_valid_deterministic_missions_and_refuses_bad_sigma():
    config = CONFIG.replace(team={"n_agents": 2, "comm_range": 25.0}, terrain={"kind": "blobs"})
    runs = [evaluate(config, "ig_spatial", missions=2, seed=4, progress=False) for _ in range(2)]
    assert [r["entropy"] for r in runs[0].rows] == [r["entropy"] for r in runs[1].rows]
    finals = [r["entropy"] for r in runs[0].rows if r["step"] == config.team.budget]
    assert len(finals) == 2 and all(e < 1.0 for e in finals)
    with pytest.raises(ValueError, match="sigma"):
        make_planner("ig_spatial", sigma=-1.0)


def test_the_false_positive_term_changes_choices_and_is_validated():
    from baselines.heuristics.spatial_gain import SpatialGainPlanner

    """w > 0 draws UAVs to check cells held above 0.5 that the smoothing doubts; w = 0 is the
    plain objective, and a bad w is refused naming it."""
    config = EnvConfig().replace(world={"resolution": 0.5})
    plain = SpatialGainPlanner()
    zero = SpatialGainPlanner(false_positive_weight=0.0)
    checking = SpatialGainPlanner(false_positive_weight=2.0)
    runs = {}
    for label, planner in (("plain", plain), ("zero", zero), ("checking", checking)):
        rows = [run_mission(config, planner, seed=1, mission=m, namespace="validation")["rows"]
                for m in range(3)]
        runs[label] = [(r["entropy"], r["f1"]) for mission in rows for r in mission]
    assert runs["zero"] == runs["plain"]
    assert runs["checking"] != runs["plain"]
    for bad in (-1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match="false_positive_weight"):
            SpatialGainPlanner(false_positive_weight=bad)


def test_false_positive_steps_applies_the_term_only_in_the_last_steps():
    """With k steps the values are the plain objective's until k steps are left, then those
    of the term at every step; a bad k is refused naming it."""
    from dataclasses import replace

    from baselines.heuristics.spatial_gain import SpatialGainPlanner

    camera = Camera(CONFIG.world, CONFIG.sensor)
    box = camera.rects[1, 5, 5]
    cells = (slice(int(box[0]), int(box[1])), slice(int(box[2]), int(box[3])))
    logodds = np.zeros((CONFIG.world.map_cells,) * 2)
    logodds[cells] = 1.0  # one noisy positive reading: held above 0.5, doubted by the smoothing
    view = lone_view(CONFIG, (5, 5, 1), logodds, np.ones(6, dtype=np.int8))
    planners = {label: SpatialGainPlanner(false_positive_weight=w, false_positive_steps=k)
                for label, w, k in (("plain", 0.0, None), ("always", 0.5, None),
                                    ("late", 0.5, 4))}
    for planner in planners.values():
        planner.reset(CONFIG, 0)
    for step, like in ((0, "plain"), (10, "plain"), (11, "always"), (14, "always")):
        at_step = replace(view, step=step)
        gains = {label: p.cell_gains(at_step, 1, cells) for label, p in planners.items()}
        assert not np.array_equal(gains["always"], gains["plain"])
        np.testing.assert_array_equal(gains["late"], gains[like])
    for bad in (0, -2, 2.5, True, "3"):
        with pytest.raises(ValueError, match="false_positive_steps"):
            SpatialGainPlanner(false_positive_weight=0.2, false_positive_steps=bad)
