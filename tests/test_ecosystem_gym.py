"""Gymnasium ids a generic tool can train on and the toolkit can fly: ``ipp_toolkit/UAV-v0``
(one shared policy, one UAV's move at a time) and configs given as dicts or YAML files."""

from __future__ import annotations

import warnings

import gymnasium
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env
from helpers import small_config

import ipp_toolkit  # noqa: F401  (registers the ids)
from ipp_toolkit import EnvConfig, IPPEnv, save_config
from ipp_toolkit.io import CheckpointError
from ipp_toolkit.runs.evaluation import evaluate
from ipp_toolkit.sim.mission import InvalidActionError
from ipp_toolkit.team_env import ENV_ID, IPPTeamEnv
from ipp_toolkit.uav_env import UAV_ENV_ID, IPPUAVEnv

SMALL = {"world": {"resolution": 1.0}, "team": {"n_agents": 2}}


@pytest.mark.parametrize("env_id", [ENV_ID, UAV_ENV_ID])
def test_both_ids_take_a_config_dict_a_yaml_path_or_an_envconfig(env_id, tmp_path):
    config = EnvConfig().replace(**SMALL)
    save_config(config, tmp_path / "small.yaml")
    for given in (config, SMALL, str(tmp_path / "small.yaml"), tmp_path / "small.yaml"):
        env = gymnasium.make(env_id, config=given)
        assert env.unwrapped.config == config
        env.close()
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['agents'\]"):
        gymnasium.make(env_id, config={"team": {"agents": 2}})
    with pytest.raises(ValueError, match="config must be an EnvConfig, a dict .* got int"):
        gymnasium.make(env_id, config=3)


def test_uav_env_passes_gymnasium_checker_and_returns_the_team_return():
    env = gymnasium.make(UAV_ENV_ID, config=SMALL)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_env(env.unwrapped)
    assert env.action_space == gymnasium.spaces.Discrete(6)
    assert env.observation_space.shape == (7, 11, 11)
    team = IPPEnv(SMALL)
    observations, _ = team.reset(seed=3)
    obs, info = env.reset(seed=3)
    total = team_total = 0.0
    moves = terminated = 0
    while not terminated:
        joint = {}
        for k, agent in enumerate(team.possible_agents):
            assert info["uav"] == k
            np.testing.assert_array_equal(obs, observations[agent]["observation"])
            np.testing.assert_array_equal(info["action_mask"], observations[agent]["action_mask"])
            joint[agent] = int(np.flatnonzero(env.unwrapped.action_masks())[-1])
            obs, reward, terminated, truncated, info = env.step(joint[agent])
            assert not truncated and (reward == 0.0 or k == 1)
            total += reward
            moves += 1
        observations, rewards, _, _, _ = team.step(joint)
        team_total += rewards["uav_0"]
    assert moves == 2 * 15 and total == pytest.approx(team_total)
    assert info["step"] == 15 and info["f1"] == team.mission.history[-1].f1


def test_uav_env_holds_or_raises_on_masked_moves_and_skips_failed_uavs():
    env = IPPUAVEnv(SMALL, invalid_action="raise")
    env.reset(seed=0)
    with pytest.raises(InvalidActionError, match="is masked"):
        env.step(0)  # both start at the top altitude: "up" is masked
    env = IPPUAVEnv(SMALL)
    env.reset(seed=0)
    _, _, _, _, info = env.step(0)
    assert info["invalid_action"] and info["uav"] == 1
    failing = IPPUAVEnv({**SMALL, "team": {"n_agents": 2, "failures": [[1, 3]]}})
    _, info = failing.reset(seed=0)
    moves = terminated = 0
    while not terminated:
        _, _, terminated, _, info = failing.step(int(np.flatnonzero(failing.action_masks())[0]))
        moves += 1
    assert moves == 2 * 2 + 13  # UAV 1 chooses in steps 1 and 2 only


def test_ppo_trained_through_gym_make_flies_as_an_sb3_zip(tmp_path):
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    env = gymnasium.make(UAV_ENV_ID, config=SMALL)
    model = PPO("MlpPolicy", env, n_steps=128, batch_size=64, n_epochs=1, seed=0,
                device="cpu", policy_kwargs={"net_arch": [16]})
    model.learn(256)
    model.save(tmp_path / "uav.zip")
    result = evaluate(EnvConfig().replace(**SMALL), f"sb3={tmp_path / 'uav.zip'}", missions=2,
                      seed=0, progress=False)
    final = [row for row in result.rows if row["step"] == 15]
    assert len(final) == 2 and all(0 < row["entropy"] < 1 for row in final)


def test_a_team_zip_is_refused_naming_the_per_uav_id(tmp_path):
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", IPPTeamEnv(small_config(n_agents=2, resolution=1.0)), n_steps=16,
                batch_size=16, seed=0, device="cpu", policy_kwargs={"net_arch": [8]})
    model.save(tmp_path / "team.zip")
    from baselines.sb3.planner import SB3Planner

    with pytest.raises(CheckpointError, match="MultiDiscrete action space.*ipp_toolkit/UAV-v0"):
        SB3Planner(tmp_path / "team.zip")
