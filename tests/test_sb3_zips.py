"""SB3's own ``model.save`` zips flown by the ``sb3`` planner (read without unpickling), and
models whose policy the toolkit's files cannot hold refused by name."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
import torch
from helpers import small_config
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.vec_env import VecMonitor

from baselines.sb3.planner import SB3Planner
from baselines.sb3.policies import greedy_actions
from baselines.sb3.training import SB3TrainConfig, save_sb3_policy
from ipp_toolkit.io import CheckpointError
from ipp_toolkit.runs.evaluation import run_mission
from ipp_toolkit.vec import make_sb3_vec_env
from reports.cli import compare_main

torch.set_num_threads(1)

#: Every algorithm on SB3's default policy of the view, with tiny settings.
ZIP_ALGOS = {
    "PPO": ("stable_baselines3", "MlpPolicy", {"n_steps": 16, "batch_size": 32, "n_epochs": 1}),
    "A2C": ("stable_baselines3", "MlpPolicy", {"n_steps": 8}),
    "DQN": ("stable_baselines3", "MlpPolicy", {"learning_starts": 16, "buffer_size": 200}),
    "MaskablePPO": ("sb3_contrib", "MlpPolicy", {"n_steps": 16, "batch_size": 32,
                                                 "n_epochs": 1}),
    "QRDQN": ("sb3_contrib", "MlpPolicy", {"learning_starts": 16, "buffer_size": 200}),
    "RecurrentPPO": ("sb3_contrib", "MlpLstmPolicy", {"n_steps": 16, "batch_size": 32,
                                                      "n_epochs": 1}),
    "TRPO": ("sb3_contrib", "MlpPolicy", {"n_steps": 16, "batch_size": 32}),
    "ARS": ("sb3_contrib", "MlpPolicy", {"n_delta": 2}),
}


def _train(algo: str, tmp_path, policy: str | None = None, **changes):
    module, default_policy, kwargs = ZIP_ALGOS[algo]
    cls = getattr(__import__(module), algo)
    config = small_config(n_agents=2, resolution=1.0)
    vec = make_sb3_vec_env(config)  # n_envs=1, seed=0
    try:
        model = cls(policy or default_policy, VecMonitor(vec), seed=0, device="cpu",
                    **{**kwargs, **changes})
        model.learn(64)
        observations = vec.reset()
    finally:
        vec.close()
    path = tmp_path / f"{algo}.zip"
    model.save(path)
    return model, path, config, observations


@pytest.mark.parametrize("algo", list(ZIP_ALGOS))
def test_an_sb3_zip_of_every_algorithm_flies_as_the_model_predicts(tmp_path, algo):
    model, path, config, observations = _train(algo, tmp_path)
    planner = SB3Planner(path)
    assert planner.algo == algo and planner.observation_features is None
    every = np.ones((len(observations), 6), dtype=bool)
    if algo == "RecurrentPPO":
        predicted, _ = model.predict(observations, state=None, deterministic=True,
                                     episode_start=np.ones(len(observations), dtype=bool))
    else:
        predicted, _ = model.predict(observations, deterministic=True)
    flown, _ = greedy_actions(planner.policy, algo, observations, every)
    np.testing.assert_array_equal(flown, predicted)
    # The mission keeps the simulator's rule (a masked action would raise): never masked.
    result = run_mission(config, planner, seed=0, mission=0)
    assert len(result["rows"]) == config.team.budget + 1


def test_ipp_compare_flies_a_zip_and_refuses_what_it_cannot_rebuild(tmp_path, capsys,
                                                                    placeholder_figures):
    _, path, _, _ = _train("PPO", tmp_path)
    out = tmp_path / "compare"
    assert compare_main(["--planners", f"ig,sb3={path}", "--agents", "2", "--resolution", "1",
                         "--trials", "1", "--budget", "2", "--workers", "1",
                         "--out", str(out)]) == 0
    assert "sb3" in (out / "summary.md").read_text()
    # Its training setting is unknown: ipp-compare says so once, before flying.
    err = capsys.readouterr().err
    assert "note: planner 'sb3' flies off its training setting: an SB3 zip records no " \
        "training setting" in err

    class MeanPool(BaseFeaturesExtractor):
        def __init__(self, observation_space):
            super().__init__(observation_space, observation_space.shape[0])

        def forward(self, observations):
            return observations.mean((2, 3))

    _, custom, _, _ = _train("A2C", tmp_path,
                             policy_kwargs={"features_extractor_class": MeanPool})
    with pytest.raises(CheckpointError, match="features extractor .*MeanPool"):
        SB3Planner(custom)
    assert compare_main(["--planners", f"ig,sb3={custom}", "--workers", "1", "--out",
                         str(tmp_path / "no")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()  # the setting line, then the error
    assert lines[-1].startswith("ipp-compare: error: planner 'sb3' cannot be built")
    assert "MeanPool" in lines[-1] and not any("Traceback" in line for line in lines)
    # A zip whose data record names a class the planner does not know: refused by name.
    forged = tmp_path / "forged.zip"
    with zipfile.ZipFile(path) as source, zipfile.ZipFile(forged, "w") as target:
        for name in source.namelist():
            blob = source.read(name)
            if name == "data":
                data = json.loads(blob)
                data["policy_class"]["__init__"] = "<function EvilPolicy.__init__ at 0x0>"
                blob = json.dumps(data).encode()
            target.writestr(name, blob)
    with pytest.raises(CheckpointError, match="holds a EvilPolicy policy"):
        SB3Planner(forged)


def test_save_sb3_policy_refuses_a_policy_its_file_could_not_hold(tmp_path):
    model, _, config, _ = _train("DQN", tmp_path)  # SB3's default MlpPolicy
    train_config = SB3TrainConfig(algo="DQN", n_agents=2, n_envs=1)
    with pytest.raises(ValueError, match="not the DQN policy make_sb3_model builds.*model.save"):
        save_sb3_policy(tmp_path / "policy.pt", model, train_config, config)
    assert not (tmp_path / "policy.pt").exists()


def test_ipp_train_sb3_lists_every_discrete_algorithm(capsys):
    from reports.cli import train_main

    assert train_main(["sb3", "--help"]) == 0
    usage = capsys.readouterr().out
    assert "PPO|MaskablePPO|A2C|DQN|QRDQN|RecurrentPPO|TRPO|ARS" in usage
