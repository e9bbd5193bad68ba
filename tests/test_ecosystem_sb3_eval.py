"""SB3 evaluation by missions (not UAV slots), VecNormalize statistics beside a zip, and
frame-stacked zips refused by name."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.vec_env import VecFrameStack, VecMonitor, VecNormalize

from baselines.sb3.evaluation import MissionEvalCallback, evaluate_missions, mission_means
from baselines.sb3.normalization import normalization_path, save_vec_normalize
from baselines.sb3.planner import SB3Planner
from ipp_toolkit import EnvConfig
from ipp_toolkit.io import CheckpointError
from ipp_toolkit.runs.evaluation import run_mission
from ipp_toolkit.vec import make_sb3_vec_env

SMALL = {"world": {"resolution": 1.0}, "team": {"n_agents": 2}}


def _tiny_ppo(env, **kwargs) -> PPO:
    torch.set_num_threads(1)
    return PPO("MlpPolicy", env, n_steps=32, batch_size=32, n_epochs=1, seed=0, device="cpu",
               policy_kwargs={"net_arch": [8]}, **kwargs)


def test_evaluate_missions_counts_missions_where_evaluate_policy_counts_uav_slots():
    vec = make_sb3_vec_env(SMALL)
    try:
        model = _tiny_ppo(vec).learn(64)
        # SB3's own helper: its two "episodes" are the two UAV slots of one mission.
        returns, _ = evaluate_policy(model, VecMonitor(vec),
                                     n_eval_episodes=2, deterministic=True,
                                     return_episode_rewards=True)
    finally:
        vec.close()
    assert returns[0] == returns[1]
    results = evaluate_missions(model, SMALL, missions=3, seed=5)
    assert [r.mission for r in results] == [0, 1, 2]
    assert len({r.final_entropy for r in results}) == 3
    assert all(0 < r.final_entropy < 1 and 0 <= r.final_f1 <= 1 for r in results)
    assert results == evaluate_missions(model, EnvConfig().replace(**SMALL), 3, seed=5)
    means = mission_means(results)
    assert means["team_return"] == pytest.approx(np.mean([r.team_return for r in results]))


def test_mission_eval_callback_logs_the_task_metrics(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    vec = make_sb3_vec_env(SMALL)
    callback = MissionEvalCallback(SMALL, missions=2, eval_freq=16)
    try:
        _tiny_ppo(vec, tensorboard_log=str(tmp_path)).learn(64, callback=callback)
    finally:
        vec.close()
    assert [steps for steps, _ in callback.evaluations] == [32, 64]
    events = EventAccumulator(str(next(tmp_path.iterdir())))
    events.Reload()
    tags = events.Tags()["scalars"]
    assert {"eval/team_return", "eval/final_entropy", "eval/final_f1"} <= set(tags)


def test_a_vec_normalize_zip_flies_only_with_its_statistics(tmp_path):
    vec = make_sb3_vec_env(SMALL)
    try:
        normalized = VecNormalize(vec)
        model = _tiny_ppo(normalized).learn(64)
    finally:
        vec.close()
    path = tmp_path / "norm.zip"
    model.save(path)
    with pytest.raises(CheckpointError, match=r"under VecNormalize.*norm\.vecnormalize\.json"
                                              r".*are missing.*save_vec_normalize"):
        SB3Planner(path)
    assert save_vec_normalize(normalized, path) == normalization_path(path)
    planner = SB3Planner(path)
    planes = np.random.default_rng(0).uniform(-1, 1, (2, 7, 11, 11)).astype(np.float32)
    np.testing.assert_allclose(planner.meta.normalization.apply(planes),
                               normalized.normalize_obs(planes), rtol=1e-5, atol=1e-6)
    rows = run_mission(EnvConfig().replace(**SMALL), planner, seed=0, mission=0)["rows"]
    assert len(rows) == 16


def test_a_frame_stacked_zip_is_refused_naming_frame_stacking(tmp_path):
    vec = make_sb3_vec_env(SMALL)
    try:
        model = _tiny_ppo(VecFrameStack(vec, 2)).learn(32)
    finally:
        vec.close()
    model.save(tmp_path / "stack.zip")
    with pytest.raises(CheckpointError, match=r"frame-stacked observations \(7, 11, 22\) "
                                              r"\(2 frames .*VecFrameStack"):
        SB3Planner(tmp_path / "stack.zip")
