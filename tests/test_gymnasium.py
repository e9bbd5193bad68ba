"""The team as one Gymnasium agent: registration, both env checkers, masks, MaskablePPO."""

import warnings

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from helpers import small_config
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import ipp_toolkit  # noqa: F401  (registers ipp_toolkit/UAVTeam-v0)
from ipp_toolkit.sim.mission import InvalidActionError
from ipp_toolkit.team_env import ENV_ID, IPPTeamEnv


def test_registered_env_passes_gymnasium_and_sb3_checkers():
    config = small_config(n_agents=2, resolution=1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # not even a warning from either checker
        env = gymnasium.make(ENV_ID, config=config)
        check_env(env.unwrapped)
        sb3_check_env(env.unwrapped)
    assert isinstance(env.unwrapped, IPPTeamEnv)
    assert env.action_space == gymnasium.spaces.MultiDiscrete([6, 6])
    assert env.unwrapped.plane_shape == (2, 7, 11, 11)
    env.close()


def test_one_episode_holds_masked_moves_and_terminates_at_the_budget():
    config = small_config(n_agents=2, resolution=1.0)
    env = gymnasium.make(ENV_ID, config=config)
    obs, info = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape and info["action_mask"].shape == (2, 6)
    env.action_space.seed(0)
    steps = held = 0
    terminated = False
    while not terminated:
        masks = env.unwrapped.action_masks().reshape(2, 6)
        action = env.action_space.sample()  # ignores the masks
        obs, reward, terminated, truncated, info = env.step(action)
        assert not truncated and env.observation_space.contains(obs)
        invalid = ~masks[np.arange(2), action]
        assert info["invalid_action"].tolist() == invalid.tolist()
        held += int(invalid.sum())
        steps += 1
    assert steps == config.team.budget and 0 < info["f1"] <= 1 and held > 0
    strict = IPPTeamEnv(config, invalid_action="raise")
    strict.reset(seed=0)
    with pytest.raises(InvalidActionError, match="is masked"):
        strict.step(np.array([0, 0]))  # both start at the top altitude: "up" is masked
    with pytest.raises(ValueError, match="one move per UAV"):
        strict.step(np.array([1, 1, 1]))


def test_maskable_ppo_trains_on_the_registered_env():
    from sb3_contrib import MaskablePPO

    config = small_config(n_agents=2, resolution=1.0)
    model = MaskablePPO("MlpPolicy", gymnasium.make(ENV_ID, config=config), n_steps=32,
                        batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(64)
    env = IPPTeamEnv(config, invalid_action="raise")  # the masked policy never picks one
    obs, _ = env.reset(seed=1)
    done = False
    while not done:
        action, _ = model.predict(obs, action_masks=env.action_masks(), deterministic=True)
        obs, _, done, _, _ = env.step(action)
