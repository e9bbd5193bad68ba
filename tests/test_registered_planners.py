"""Every registered planner that builds without arguments passes the basic checks.

The list comes from the registry (decorator and entry points), so a new planner is tested
here without editing a list: its actions are valid under the masks, a mission flown twice
with one seed gives the same actions, and one planner flies two missions after two resets.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from ipp_toolkit import EnvConfig, reset_mission, step_mission
from ipp_toolkit.planning import Planner, available_planners, make_planner, planner_views

#: A tiny mission: 2 UAVs, 1 m cells (a 50 x 50 map), 3 steps.
CONFIG = EnvConfig().replace(world={"resolution": 1.0}, team={"n_agents": 2, "budget": 3})


def _build(name: str) -> Planner:
    """The planner ``name`` with its defaults, or a skip (its reason shown with ``-rs``) when
    it needs arguments (a policy file, a run folder) or an optional dependency that is not
    installed."""
    try:
        with warnings.catch_warnings():  # a deprecated alias says so: still a planner to test
            warnings.simplefilter("ignore", DeprecationWarning)
            return make_planner(name)
    except (TypeError, ValueError, ImportError, OSError) as err:
        pytest.skip(f"planner {name!r} cannot be built without arguments here: {err}")


def _fly(planner: Planner, seed: int, mission: int = 0) -> list[list[int]]:
    """The joint actions of one mission, each checked against its views' masks."""
    planner.reset(CONFIG, seed)
    state = reset_mission(CONFIG, seed, mission)
    flown = []
    for _ in range(CONFIG.team.budget):
        views = planner_views(state, planner)
        actions = np.asarray(planner.act(views))
        assert actions.shape == (len(views),)
        for view, action in zip(views, actions.tolist(), strict=True):
            assert 0 <= action < len(view.mask) and view.mask[action], (
                f"{planner.name}: agent {view.index} took masked action {action} at step "
                f"{view.step}")
        flown.append([int(a) for a in actions])
        step_mission(state, actions)
    return flown


@pytest.mark.parametrize("name", available_planners())
def test_a_registered_planner_flies_valid_repeatable_missions(name):
    planner = _build(name)
    first = _fly(planner, seed=3)
    second = _fly(planner, seed=4, mission=1)  # a second reset, another mission
    assert _fly(planner, seed=3) == first, f"{name}: a third reset does not replay the first"
    assert _fly(_build(name), seed=3) == first, f"{name}: not deterministic given the seed"
    assert len(second) == CONFIG.team.budget


def test_a_removed_name_is_refused_with_the_note_its_package_declared(monkeypatch):
    from ipp_toolkit.planning import REMOVED_NAMES, register_removed_name

    monkeypatch.setattr("ipp_toolkit.planning.REMOVED_NAMES", dict(REMOVED_NAMES))
    register_removed_name("old-greedy", "removed 2030-01-01: use ig")
    with pytest.raises(ValueError, match="planner 'old-greedy' was removed 2030-01-01: use ig"):
        make_planner("old-greedy")
    assert "old-greedy" not in available_planners()
