"""RLlib as its docs use a custom env: the env's ``env_config`` (every key defaulted, unknown
keys refused) and the ``rllib`` observation layout without Ray; with ``ray[rllib]`` (marked
``rllib``; ``.ci/rllib`` runs them in their own venv): the registration at import, a relative
``--out``, ``Algorithm.from_checkpoint`` and RLlib's own action-masking RLModule."""

from __future__ import annotations

import json
import runpy
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test

from baselines.rllib.env_config import ENV_CONFIG_DEFAULTS, env_settings
from ipp_toolkit import EnvConfig, IPPEnv

REPO = Path(__file__).resolve().parents[1]
SMALL = {"world": {"resolution": 1.0}, "team": {"n_agents": 2}}


@pytest.fixture
def rllib() -> None:
    """Skip unless RLlib imports (its package may be there without its own dependencies)."""
    pytest.importorskip("ray.rllib.algorithms.ppo",
                        reason="needs ray[rllib] (pip install -c constraints-rllib.txt -e "
                               "'.[rllib]', or bash .ci/rllib)")


def test_every_env_config_key_has_a_default() -> None:
    for given in ({}, None):
        settings = env_settings(given)
        assert settings.env == EnvConfig() and settings.observation == "dict"
        assert (settings.base_seed, settings.envs_per_runner) == (0, 1)
        assert settings.invalid_action == "hold"
    assert set(ENV_CONFIG_DEFAULTS) == {"env", "observation", "base_seed", "envs_per_runner",
                                        "invalid_action"}
    # observation None follows the mission's features.observation; the key overrides it.
    settings = env_settings({"env": {**SMALL, "features": {"observation": "rllib"}}})
    assert settings.observation == "rllib" and settings.env.team.n_agents == 2
    assert env_settings({"env": {"features": {"observation": "box"}},
                         "observation": "dict"}).observation == "dict"


@pytest.mark.parametrize(("env_config", "named"), [
    ({"seed": 3, "bogus": 1}, "unknown env_config key(s) ['bogus', 'seed']"),
    ({"base_seed": -1}, "env_config['base_seed'] must be an integer >= 0, got -1"),
    ({"envs_per_runner": 0}, "env_config['envs_per_runner'] must be an integer >= 1, got 0"),
    ({"observation": "image"}, "env_config['observation'] must be one of"),
    ({"invalid_action": "skip"}, "env_config['invalid_action'] must be one of"),
    ({"env": {"team": {"bogus": 1}}}, "bogus"),
    ({"env": 3}, "env_config['env'] must be an EnvConfig"),
    ([("base_seed", 1)], "must be a dict, got list"),
])
def test_bad_env_config_is_refused_naming_the_value(env_config: object, named: str) -> None:
    with pytest.raises(ValueError) as error:
        env_settings(env_config)  # type: ignore[arg-type]
    assert named in str(error.value)


def test_the_rllib_observation_is_the_planes_flattened_and_the_mask() -> None:
    config = EnvConfig().replace(**SMALL, features={"observation": "rllib"})
    env = IPPEnv(config)
    space = env.observation_space("uav_0")
    assert set(space.spaces) == {"observations", "action_mask"}
    assert space["observations"].shape == (7 * 11 * 11,)
    assert space["observations"].dtype == np.float32 and space["action_mask"].dtype == np.int8
    reference = IPPEnv(config, observation="dict")
    observations, _ = env.reset(seed=0)
    expected, _ = reference.reset(seed=0)
    for _ in range(3):
        for agent in env.agents:
            assert space.contains(observations[agent])
            np.testing.assert_array_equal(observations[agent]["observations"],
                                          expected[agent]["observation"].reshape(-1))
            np.testing.assert_array_equal(observations[agent]["action_mask"],
                                          expected[agent]["action_mask"])
        actions = {a: int(np.flatnonzero(expected[a]["action_mask"])[0]) for a in env.agents}
        observations = env.step(actions)[0]
        expected = reference.step(actions)[0]
    with warnings.catch_warnings():  # the API test passes an unknown reset option on purpose
        warnings.simplefilter("ignore", UserWarning)
        parallel_api_test(IPPEnv(config), num_cycles=20)


# In a fresh process: a registration made by an earlier test's Ray would hide a missing one.
_REGISTERED = """
import ray
from ray.tune.registry import ENV_CREATOR, _global_registry
import baselines.rllib.module as module

def known():
    return _global_registry.contains(ENV_CREATOR, module.ENV_NAME)

assert known(), "not registered at import"
env = _global_registry.get(ENV_CREATOR, module.ENV_NAME)({})  # raised KeyError: 'base_seed'
observations, _ = env.reset()
assert list(observations) == [f"uav_{k}" for k in range(4)], list(observations)
assert set(observations["uav_0"]) == {"observation", "action_mask"}
env = module.IPPMultiAgentEnv({"env": {"team": {"n_agents": 2}}, "observation": "rllib"})
assert set(env.reset()[0]["uav_1"]) == {"observations", "action_mask"}
try:
    module.make_env({"seed": 1})
except ValueError as error:
    assert "unknown env_config key(s) ['seed']" in str(error), error
else:
    raise AssertionError("an unknown key was accepted")
# A Ray keeps a registration while it runs: a second ray.init() (a second run in the same
# process) must know the name too.
for _ in range(2):
    ray.init(num_cpus=1, include_dashboard=False, log_to_driver=False)
    assert known(), "not registered in a later Ray of this process"
    ray.shutdown()
print("ok")
"""


@pytest.mark.rllib
def test_importing_the_module_registers_the_env_for_every_ray_and_empty_env_config_works(
        rllib: None) -> None:
    done = subprocess.run([sys.executable, "-c", _REGISTERED], cwd=REPO, capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0 and done.stdout.strip().endswith("ok"), done.stderr[-3000:]


# In a fresh process, as a user's script: nothing of the toolkit imported before
# Algorithm.from_checkpoint (the checkpoint's RLModule class imports the env's module), then
# PPOConfig().environment(ENV_NAME) with RLlib's default env_config ({}).
_CLIENT = """
import json, sys
import numpy as np, torch
from ray.rllib.algorithms.algorithm import Algorithm

algo = Algorithm.from_checkpoint(sys.argv[1])
module = algo.get_module("shared")
from baselines.rllib.module import ENV_NAME, IPPMultiAgentEnv, IPPMaskedRLModule

env = IPPMultiAgentEnv({"env": {"team": {"n_agents": 2}}, "invalid_action": "raise"})
obs, _ = env.reset()
batch = {k: torch.from_numpy(np.stack([obs[a][k] for a in obs]))
         for k in ("observation", "action_mask")}
actions = module.forward_inference({"obs": batch})["action_dist_inputs"].argmax(-1).tolist()
env.step(dict(zip(obs, actions)))  # invalid_action="raise": a masked action would stop here
algo.stop()

from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
config = (PPOConfig().environment(ENV_NAME).env_runners(num_env_runners=0)
          .multi_agent(policies={"shared"}, policy_mapping_fn=lambda agent, episode, **kw: "shared")
          .rl_module(rl_module_spec=RLModuleSpec(module_class=IPPMaskedRLModule,
                     model_config={"width": 4, "features_dim": 8, "hidden": 8}))
          .training(train_batch_size_per_learner=64, minibatch_size=64, num_epochs=1))
fresh = config.build_algo()
result = fresh.train()
fresh.stop()
print(json.dumps({"actions": actions,
                  "sampled": int(result["env_runners"]["num_env_steps_sampled"])}))
"""


@pytest.mark.slow
@pytest.mark.rllib
def test_relative_out_trains_and_the_checkpoint_restores_in_a_fresh_process(
        rllib: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from reports.cli import train_main

    monkeypatch.chdir(tmp_path)
    # A relative --out failed at the first checkpoint ("URI has empty scheme").
    assert train_main(["rllib", "--iterations", "2", "--checkpoint-every", "1",
                       "--train-batch", "30", "--agents", "2", "--width", "4",
                       "--features-dim", "8", "--hidden", "8", "--no-progress",
                       "--out", "runs/rllib-ppo"]) == 0
    run = tmp_path / "runs" / "rllib-ppo"
    assert (run / "policy.pt").is_file() and (run / "checkpoint" / "ipp_state.json").is_file()
    assert json.loads((run / "checkpoint.json").read_text())["iteration"] == 2
    done = subprocess.run([sys.executable, "-c", _CLIENT, str(run / "checkpoint")],
                          cwd=REPO, capture_output=True, text=True, timeout=400)
    assert done.returncode == 0, done.stderr[-3000:]
    reply = json.loads(done.stdout.strip().splitlines()[-1])
    assert len(reply["actions"]) == 2 and reply["sampled"] >= 64


@pytest.mark.slow
@pytest.mark.rllib
def test_rllibs_action_masking_module_trains_saves_restores_and_flies(
        rllib: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    # The example trains with invalid_action="raise": one masked action sampled by RLlib's
    # ActionMaskingTorchRLModule (or taken by the restored module) would stop it.
    monkeypatch.setattr(sys, "argv", ["06_rllib_action_masking.py", "--quick",
                                      "--out", str(tmp_path)])
    runpy.run_path(str(REPO / "examples" / "06_rllib_action_masking.py"), run_name="__main__")
    out = capsys.readouterr().out
    assert len([line for line in out.splitlines() if line.startswith("iteration ")]) == 2
    assert (tmp_path / "checkpoint").is_dir()
    flown = next(line for line in out.splitlines() if line.startswith("restored and flew"))
    entropy = float(flown.split("final entropy ")[1].split(",")[0])
    assert 0 < entropy < 1
