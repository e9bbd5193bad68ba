"""features.observation = "box": planes alone, the mask in the infos, so every SuperSuit
observation wrapper takes the env."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import supersuit as ss
from pettingzoo.test import parallel_api_test

from ipp_toolkit import EnvConfig, IPPEnv

BOX = {"world": {"resolution": 1.0}, "team": {"n_agents": 2, "failures": [[1, 4]]},
       "features": {"observation": "box"}}

WRAPPERS = {
    "black_death_v3": ss.black_death_v3,
    "frame_stack_v1": lambda env: ss.frame_stack_v1(env, 3),
    "normalize_obs_v0": lambda env: ss.normalize_obs_v0(env, env_min=0.0, env_max=1.0),
    "dtype_v0": lambda env: ss.dtype_v0(env, np.float16),
    "flatten_v0": ss.flatten_v0,
    "agent_indicator_v0": ss.agent_indicator_v0,
    "pad_observations_v0": ss.pad_observations_v0,
}


def test_the_box_observation_is_the_planes_with_the_mask_in_the_infos():
    env = IPPEnv(BOX)
    assert env.observation_space("uav_0") == env.observation_space("uav_1")
    assert env.observation_space("uav_0").shape == (7, 11, 11)
    observations, infos = env.reset(seed=0)
    planes = IPPEnv(EnvConfig().replace(**{**BOX, "features": {}})).reset(seed=0)[0]
    for agent in env.agents:
        np.testing.assert_array_equal(observations[agent], planes[agent]["observation"])
        np.testing.assert_array_equal(infos[agent]["action_mask"], env.action_mask(agent))
        np.testing.assert_array_equal(infos[agent]["action_mask"],
                                      planes[agent]["action_mask"])
    with warnings.catch_warnings():  # the test passes an unknown reset option on purpose
        warnings.simplefilter("ignore", UserWarning)
        parallel_api_test(IPPEnv(BOX), num_cycles=20)
    with pytest.raises(ValueError, match=r"features.observation = 'image'"):
        EnvConfig().replace(features={"observation": "image"})
    with pytest.raises(ValueError, match=r"observation must be one of \('dict', 'box', 'rllib'\)"):
        IPPEnv(BOX, observation="image")


@pytest.mark.parametrize("name", sorted(WRAPPERS))
def test_every_supersuit_observation_wrapper_takes_the_box_env(name):
    base = IPPEnv(BOX)
    env = WRAPPERS[name](base)
    observations, infos = env.reset(seed=0)
    steps = 0
    while env.agents:
        # Valid actions only: the masks come from the infos (or the env's action_mask()).
        actions = {agent: int(np.flatnonzero(infos[agent].get("action_mask",
                                                               base.action_mask(agent)))[0])
                   for agent in env.agents}
        observations, rewards, terminations, truncations, infos = env.step(actions)
        for agent, obs in observations.items():
            assert env.observation_space(agent).contains(obs), (name, agent)
            assert not infos[agent].get("invalid_action", False)
        steps += 1
    # SuperSuit's black death ends the episode only once every agent is terminated AND
    # truncated, or the env has none left: one empty step after the budget end.
    assert steps == (16 if name == "black_death_v3" else 15) and base.mission.done
