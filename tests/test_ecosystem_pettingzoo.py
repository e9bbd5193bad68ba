"""PettingZoo's conventions: the AEC factories ``env()`` / ``raw_env()`` and the ``human``
render mode."""

from __future__ import annotations

import warnings

import matplotlib

matplotlib.use("Agg")  # headless: the window is drawn, not shown

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from pettingzoo import AECEnv  # noqa: E402
from pettingzoo.test import api_test  # noqa: E402
from pettingzoo.utils.conversions import parallel_to_aec_wrapper  # noqa: E402

from ipp_toolkit import IPPEnv  # noqa: E402
from ipp_toolkit import env as env_module  # noqa: E402
from ipp_toolkit.sim.rendering import render_state  # noqa: E402
from ipp_toolkit.team_env import IPPTeamEnv  # noqa: E402

SMALL = {"world": {"resolution": 1.0}, "team": {"n_agents": 2}}


def test_aec_factories_pass_pettingzoo_api_test_and_fly_a_mission():
    aec = env_module.env(SMALL)
    assert isinstance(aec, AECEnv) and aec.metadata["name"] == "ipp_v0"
    with warnings.catch_warnings():  # the test's own notes: a Dict space, an unknown option
        warnings.simplefilter("ignore", UserWarning)
        api_test(aec, num_cycles=40)
    raw = env_module.raw_env(SMALL)
    assert isinstance(raw, parallel_to_aec_wrapper)
    aec = env_module.env(SMALL, invalid_action="raise")
    aec.reset(seed=0)
    moves = 0
    for _agent in aec.agent_iter():
        observation, _, terminated, truncated, _ = aec.last()
        action = None if terminated or truncated else \
            int(np.flatnonzero(observation["action_mask"])[0])
        aec.step(action)
        moves += action is not None
    assert moves == 2 * 15


def test_human_render_mode_shows_every_step_in_one_window():
    env = IPPEnv(SMALL, render_mode="human")
    env.reset(seed=0)
    window = env._window
    assert window is not None and plt.fignum_exists(window.figure.number)
    env.step({agent: int(np.flatnonzero(env.action_mask(agent))[0]) for agent in env.agents})
    assert env.render() is None
    np.testing.assert_array_equal(window._image.get_array(), render_state(env.mission))
    number = window.figure.number
    env.close()
    assert not plt.fignum_exists(number)
    team = IPPTeamEnv(SMALL, render_mode="human")
    team.reset(seed=0)
    assert team.render() is None
    team.close()
