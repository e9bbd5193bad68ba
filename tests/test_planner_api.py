import types

import numpy as np
import pytest
from helpers import small_config

from ipp_toolkit.planning import (
    Planner,
    agent_views,
    available_planners,
    make_planner,
    planner_views,
    register_planner,
)
from ipp_toolkit.sim.mission import reset_mission, step_mission


@register_planner("test-first-valid")
class FirstValid(Planner):
    needs_observations = False

    def act(self, views):
        return np.array([int(np.flatnonzero(v.mask)[0]) for v in views])


def test_registered_planner_is_found_and_flies():
    assert "test-first-valid" in available_planners()
    planner = make_planner("test-first-valid")
    state = reset_mission(small_config(), seed=0)
    planner.reset(state.config, seed=0)
    while not state.done:
        step_mission(state, planner.act(agent_views(state, planner.needs_observations)))
    assert state.step == state.budget


def test_views_are_read_only_and_local():
    config = small_config(comm_range=0.0)
    state = reset_mission(config, seed=0)
    views = agent_views(state)
    assert len(views) == 4
    with pytest.raises(ValueError):
        views[0].local_prob[0, 0] = 1.0
    with pytest.raises(ValueError):
        views[0].mask[0] = 1
    # D = 0: nobody is heard; the local map is the agent's own, not the global one.
    assert views[0].teammates.size == 0
    assert not np.array_equal(views[0].local_prob, state.maps.prob[state.global_index])
    assert views[2].observation.shape == (7, 11, 11)
    assert agent_views(state, with_observations=False)[0].observation.shape[0] == 0


def test_planners_without_local_maps_get_empty_ones_and_the_maps_stay_unbuilt():
    from ipp_toolkit._native import kernels
    from ipp_toolkit.runs.evaluation import run_mission

    state = reset_mission(small_config(), seed=0)
    views = agent_views(state, with_observations=False, with_local_maps=False)
    assert all(v.local_prob.shape == (0, 0) and v.local_logodds.size == 0 for v in views)
    seen = []

    class Watching(FirstValid):
        needs_local_maps = False

        def act(self, views):
            seen.append(self.state.maps._arrays is None)
            return super().act(views)

    planner = Watching()
    planner.state = None

    def observe(mission_state):
        planner.state = mission_state

    rows = run_mission(small_config(), planner, seed=0, mission=0, observer=observe)["rows"]
    assert len(rows) == small_config().team.budget + 1
    assert all(seen) or not kernels.AVAILABLE  # nobody built the per-cell arrays
    for name in ("random", "coverage"):
        assert not make_planner(name).needs_local_maps
    # planner_views reads what a planner needs; a duck-typed one gets the maps by default.
    state = reset_mission(small_config(), seed=0)
    assert planner_views(state, Watching())[0].local_prob.shape == (0, 0)
    duck = planner_views(state, types.SimpleNamespace(needs_observations=False))
    assert duck[0].local_prob.shape == state.maps.prob.shape[1:]
    assert duck[0].observation.shape[0] == 0
    assert make_planner("ig").needs_local_maps


def test_views_list_heard_teammates():
    state = reset_mission(small_config(comm_range=float("inf")), seed=0)
    view = agent_views(state)[1]
    assert view.teammates.tolist() == [0, 2, 3]
    assert view.teammate_positions.shape == (3, 3) and view.teammate_footprints.shape == (3, 4)


def test_square_means_of_views_are_block_means_to_the_bit():
    from ipp_toolkit.belief.interest import block_means, square_cells

    # 0.25 m cells: squares of 2 x 2 cells, summed again where a step touched them.
    config = small_config(comm_range=float("inf"), resolution=0.25, team={"budget": 6})
    block = square_cells(config.world.map_cells, config.world.resolution)
    assert block == 2
    state = reset_mission(config, seed=3)
    planner = make_planner("random")
    planner.reset(config, seed=3)
    kept = []
    while not state.done:
        views = agent_views(state, with_observations=False)
        assert views[0].team_squares is views[3].team_squares  # one per team and step
        for view in views:
            means = view.square_means(block)
            assert means.base is not None and not means.flags.writeable
            np.testing.assert_array_equal(means.view(np.uint32), block_means(
                view.local_prob, block).view(np.uint32))
        kept.append(views[1])
        step_mission(state, planner.act(views))
    assert state.block_mean_cache.incremental
    # A view asked after its step, or for another square size, sums its own map.
    stale = kept[0]
    assert stale.team_squares.means(block) is None
    np.testing.assert_array_equal(stale.square_means(block),
                                  block_means(stale.local_prob, block))
    assert kept[-1].team_squares.means(2 * block) is None
    # Views built without local maps, or by hand, carry none.
    assert agent_views(state, with_local_maps=False)[0].team_squares is None


def test_registry_errors():
    with pytest.raises(ValueError, match="unknown planner 'nope'; registered planners: .*"
                                         "test-first-valid"):
        make_planner("nope")
    with pytest.raises(ValueError, match="already registered"):
        register_planner("test-first-valid")(type("Other", (Planner,), {"act": None}))
    with pytest.raises(ValueError, match="invalid planner name"):
        register_planner("a,b")

    @register_planner("test-not-a-planner")
    def factory():
        return object()

    with pytest.raises(TypeError, match="not a Planner"):
        make_planner("test-not-a-planner")


#: Each planner module, and the training modules that acting with its planner must not load.
INFERENCE_ONLY = {
    "coma.planner": ("coma.learner", "coma.warm_start", "coma.rollout", "coma.run_files",
                     "coma.cli"),
    "baselines.sb3.ppo": ("baselines.sb3.ppo_training", "ipp_toolkit.vec"),
    "baselines.sb3.planner": ("baselines.sb3.training", "baselines.sb3.runner",
                              "baselines.sb3.ppo_training", "ipp_toolkit.vec"),
    "baselines.torchrl.planner": ("torchrl", "ipp_toolkit.torchrl_env"),
}


def test_inference_never_imports_training():
    import json
    import subprocess
    import sys

    # One fresh interpreter imports the modules in turn and lists, after each, its training
    # modules then loaded. Loaded modules stay loaded: none listed means that no module
    # imports any of its training modules on its own either (one interpreter, not three).
    code = ("import importlib, json, sys\n"
            f"found = {{}}\nfor module, training in {INFERENCE_ONLY!r}.items():\n"
            "    importlib.import_module(module)\n"
            "    found[module] = sorted(m for m in training if m in sys.modules)\n"
            "print(json.dumps(found))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip().splitlines()[-1]
    assert json.loads(out) == {module: [] for module in INFERENCE_ONLY}
