"""Every supported SB3 algorithm on the parameter-sharing view: training, files, the ``sb3``
planner, masks, the SB3 ecosystem (monitor, normalisation, callbacks, evaluation, custom
extractors) and bad input."""

from __future__ import annotations

import json
import shlex
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import small_config
from stable_baselines3.common.vec_env import VecEnvWrapper, VecMonitor

from baselines.sb3.loading import load_sb3_policy
from baselines.sb3.planner import SB3Planner
from baselines.sb3.policies import (
    ALGORITHMS,
    SB3_POLICY_KIND,
    greedy_actions,
)
from baselines.sb3.training import (
    SB3TrainConfig,
    make_sb3_model,
    save_sb3_policy,
    train_sb3,
    training_env_config,
)
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import CheckpointError, save_torch
from ipp_toolkit.planning import agent_views
from ipp_toolkit.runs.evaluation import run_mission
from ipp_toolkit.sim.mission import reset_mission
from ipp_toolkit.vec import make_sb3_vec_env
from reports.cli import compare_main, train_main

torch.set_num_threads(1)

#: Tiny, fast settings per algorithm (a few hundred agent-transitions at r_M = 0.5 m).
TINY_HYPER = {
    "PPO": {"n_steps": 32, "batch_size": 64, "n_epochs": 1},
    "MaskablePPO": {"n_steps": 32, "batch_size": 64, "n_epochs": 1},
    "A2C": {"n_steps": 8},
    "DQN": {"buffer_size": 500, "learning_starts": 64, "batch_size": 32,
            "target_update_interval": 64},
    "QRDQN": {"buffer_size": 500, "learning_starts": 64, "batch_size": 32,
              "target_update_interval": 64, "n_quantiles": 5},
    "RecurrentPPO": {"n_steps": 32, "batch_size": 64, "n_epochs": 1, "lstm_hidden_size": 8},
    "TRPO": {"n_steps": 32, "batch_size": 64, "n_critic_updates": 1, "cg_max_steps": 3},
    "ARS": {"n_delta": 2},
}
TINY_NET = dict(n_envs=1, n_agents=2, width=8, features_dim=16, hidden=16,
                checkpoint_every=128)


def tiny_config(algo: str, **changes) -> SB3TrainConfig:
    return SB3TrainConfig(algo=algo, total_timesteps=changes.pop("total_timesteps", 256),
                          hyperparameters=TINY_HYPER[algo], **{**TINY_NET, **changes})


def _batch(vec, steps: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """(B, C, G, G) observations and (B, 6) masks of a few random valid steps."""
    rng = np.random.default_rng(0)
    observations, masks = [vec.reset()], [vec.action_masks()]
    for _ in range(steps):
        now = masks[-1]
        observations.append(vec.step((rng.random(now.shape) * now).argmax(1))[0])
        masks.append(vec.action_masks())
    return np.concatenate(observations), np.concatenate(masks)


class TrainedRuns:
    """256-transition runs through the trainer, one per algorithm, trained when first asked."""

    def __init__(self, folder):
        self.folder = folder
        self.trained: dict[str, tuple[SB3TrainConfig, object]] = {}

    def __getitem__(self, algo: str) -> tuple[SB3TrainConfig, object]:
        if algo not in self.trained:
            config = tiny_config(algo)
            path = train_sb3(config, EnvConfig(), self.folder / algo, progress=False,
                             command=f"test {algo}")
            self.trained[algo] = (config, path)
        return self.trained[algo]


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> TrainedRuns:
    return TrainedRuns(tmp_path_factory.mktemp("sb3"))


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_each_algorithm_trains_records_and_flies(runs, algo):
    config, path = runs[algo]
    record = json.loads(path.with_suffix(".json").read_text())
    assert record["num_timesteps"] >= 256 and record["command"] == f"test {algo}"
    assert record["obs_shape"] == [7, 11, 11] and record["n_actions"] == 6
    assert record["env_config"]["team"]["n_agents"] == 2
    if algo in ("PPO", "MaskablePPO"):  # ipp-train ppo's files: the PPO case of sb3
        assert record["format"] == "ipp-toolkit/ppo"
        assert record["algo"] == {"PPO": "ppo", "MaskablePPO": "maskable_ppo"}[algo]
        assert record["ppo_config"]["n_steps"] == 32
    else:
        assert record["format"] == SB3_POLICY_KIND and record["algo"] == algo
        assert record["hyperparameters"] == dict(config.hyperparameters)
    # Plain state dicts only, never an SB3 zip.
    assert not list(path.parent.glob("*.zip"))
    assert isinstance(torch.load(path, weights_only=True)["policy"], dict)
    assert (path.parent / "checkpoint.pt").is_file()
    assert any((path.parent / "tb").rglob("events.out.tfevents.*"))
    planner = SB3Planner(path)
    assert planner.algo == algo
    # The mission keeps the simulator's rule: a masked action would raise.
    result = run_mission(small_config(n_agents=2), planner, seed=0, mission=0)
    assert len(result["rows"]) == small_config().team.budget + 1


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_save_load_round_trip_gives_the_models_greedy_valid_actions(tmp_path, algo):
    config = tiny_config(algo)
    env_config = training_env_config(config, EnvConfig())
    vec = make_sb3_vec_env(env_config, n_envs=1, seed=0)
    try:
        model = make_sb3_model(config, VecMonitor(vec), seed=1)
        model.learn(96)
        observations, masks = _batch(vec)
    finally:
        vec.close()
    path = save_sb3_policy(tmp_path / "policy.pt", model, config, env_config)
    policy, meta = load_sb3_policy(path)
    assert meta.algo == algo and meta.obs_shape == (7, 11, 11)
    expected, _ = greedy_actions(model.policy, algo, observations, masks)
    loaded, _ = greedy_actions(policy, algo, observations, masks)
    np.testing.assert_array_equal(loaded, expected)
    assert masks[np.arange(len(loaded)), loaded].all()
    # With every action valid the greedy action is SB3's own deterministic prediction.
    every = np.ones_like(masks)
    if algo == "RecurrentPPO":
        states, starts = None, np.ones(len(observations), dtype=bool)
        predicted, _ = model.predict(observations, state=states, episode_start=starts,
                                     deterministic=True)
    elif algo == "MaskablePPO":
        predicted, _ = model.predict(observations, deterministic=True, action_masks=every)
    else:
        predicted, _ = model.predict(observations, deterministic=True)
    np.testing.assert_array_equal(greedy_actions(policy, algo, observations, every)[0],
                                  predicted)
    # Masking the unmasked favourite of each row moves the choice to a valid action.
    favourite = predicted
    masks_without = every.copy()
    masks_without[np.arange(len(favourite)), favourite] = False
    chosen, _ = greedy_actions(policy, algo, observations, masks_without)
    assert masks_without[np.arange(len(chosen)), chosen].all()
    # The planner (one batched forward over the team) agrees with the model.
    state = reset_mission(env_config, seed=0, mission=0, namespace="test")
    views = agent_views(state)
    planner = SB3Planner(path)
    planner.reset(env_config, seed=0)
    team_obs = np.stack([v.observation for v in views])
    team_masks = np.stack([v.mask for v in views])
    np.testing.assert_array_equal(planner.act(views),
                                  greedy_actions(model.policy, algo, team_obs, team_masks)[0])


def test_recurrent_planner_keeps_lstm_state_per_agent_and_resets_per_mission(runs):
    _, path = runs["RecurrentPPO"]
    planner = SB3Planner(path)
    config = small_config(n_agents=2)
    state = reset_mission(config, seed=0, mission=0)
    planner.reset(config, seed=0)
    views = agent_views(state, features=planner.observation_features)
    planner.act(views)
    first = planner._lstm_states
    assert first is not None and first[0].shape == (1, 2, 8)
    assert float(first[0].abs().sum()) > 0
    # The same planes from the carried state give another hidden state than from zeros.
    planner.act(views)
    assert not torch.equal(planner._lstm_states[0], first[0])
    planner.reset(config, seed=0)
    assert planner._lstm_states is None
    planner.act(views)
    torch.testing.assert_close(planner._lstm_states[0], first[0])


class MaskAudit(VecEnvWrapper):
    """Counts mask requests and the masked actions the algorithm sends."""

    def __init__(self, venv):
        super().__init__(venv)
        self.mask_requests = self.steps = self.invalid = 0

    def env_method(self, method_name, *args, indices=None, **kwargs):
        self.mask_requests += method_name == "action_masks"
        return self.venv.env_method(method_name, *args, indices=indices, **kwargs)

    def step_async(self, actions):
        actions = np.asarray(actions)
        self.steps += actions.size
        self.invalid += int((~self.venv.action_masks()[np.arange(actions.size),
                                                       actions]).sum())
        self.venv.step_async(actions)

    def reset(self):
        return self.venv.reset()

    def step_wait(self):
        return self.venv.step_wait()


def test_masks_reach_maskable_ppo_and_no_masked_action_is_executed():
    config = tiny_config("MaskablePPO")
    env_config = training_env_config(config, EnvConfig())
    # invalid_action="raise": a masked action would stop training with an error.
    vec = make_sb3_vec_env(env_config, n_envs=2, seed=0, invalid_action="raise")
    audit = MaskAudit(vec)
    try:
        make_sb3_model(config, VecMonitor(audit)).learn(256)
    finally:
        vec.close()
    assert audit.mask_requests >= 256 // 4 and audit.steps >= 256 and audit.invalid == 0


def test_algorithms_that_cannot_mask_hold_masked_actions_and_pay_the_penalty():
    config = tiny_config("A2C", invalid_penalty=0.25)
    env_config = training_env_config(config, EnvConfig())
    vec = make_sb3_vec_env(env_config, n_envs=1, seed=0, invalid_penalty=0.25)
    held: list[float] = []

    class Spy(VecEnvWrapper):
        def reset(self):
            return self.venv.reset()

        def step_wait(self):
            obs, rewards, dones, infos = self.venv.step_wait()
            held.extend(float(r) for r, info in zip(rewards, infos, strict=True)
                        if info["invalid_action"])
            return obs, rewards, dones, infos

    try:
        make_sb3_model(config, VecMonitor(Spy(vec))).learn(256)
    finally:
        vec.close()
    assert held, "an untrained A2C policy samples masked actions"


# --------------------------------------------------------------------------------------------
# SB3 ecosystem pieces on the view


def test_vec_monitor_and_vec_normalize(tmp_path):
    from stable_baselines3.common.vec_env import VecNormalize

    config = tiny_config("MaskablePPO")
    env_config = training_env_config(config, EnvConfig())
    vec = make_sb3_vec_env(env_config, n_envs=1, seed=0)
    try:
        monitor = VecMonitor(vec)
        monitor.reset()
        budget = env_config.team.budget
        for _ in range(budget):
            _, _, dones, infos = monitor.step(vec.action_masks().argmax(1))
        assert dones.all() and all(info["episode"]["l"] == budget for info in infos)
        normalized = VecNormalize(monitor, norm_obs=True, norm_reward=True)
        model = make_sb3_model(config, normalized)  # masks still reach MaskablePPO
        model.learn(128)
        assert normalized.obs_rms.count > 1 and normalized.obs_rms.mean.shape == (7, 11, 11)
    finally:
        vec.close()


def test_eval_and_checkpoint_callbacks_and_evaluate_policy(tmp_path):
    from stable_baselines3.common.callbacks import CheckpointCallback, EvalCallback
    from stable_baselines3.common.evaluation import evaluate_policy

    config = tiny_config("DQN")
    env_config = training_env_config(config, EnvConfig())
    vec = make_sb3_vec_env(env_config, n_envs=1, seed=0)
    eval_vec = make_sb3_vec_env(env_config, n_envs=1, seed=1000)
    try:
        model = make_sb3_model(config, VecMonitor(vec))
        evaluation = EvalCallback(VecMonitor(eval_vec), n_eval_episodes=2, eval_freq=64,
                                  log_path=str(tmp_path / "eval"), deterministic=True)
        saving = CheckpointCallback(save_freq=64, save_path=str(tmp_path / "zips"))
        model.learn(192, callback=[evaluation, saving])
        assert (tmp_path / "eval" / "evaluations.npz").is_file()
        assert np.isfinite(evaluation.last_mean_reward)
        assert list((tmp_path / "zips").glob("*.zip"))  # SB3's own files, the user's choice
        mean, std = evaluate_policy(model, VecMonitor(eval_vec), n_eval_episodes=2)
        assert np.isfinite(mean) and np.isfinite(std)
    finally:
        vec.close(), eval_vec.close()


def test_maskable_evaluation_uses_the_masks():
    from sb3_contrib.common.maskable.evaluation import evaluate_policy

    config = tiny_config("MaskablePPO")
    env_config = training_env_config(config, EnvConfig())
    vec = make_sb3_vec_env(env_config, n_envs=1, seed=3, invalid_action="raise")
    try:
        model = make_sb3_model(config, VecMonitor(vec))
        mean, _ = evaluate_policy(model, VecMonitor(vec), n_eval_episodes=2, use_masking=True)
        assert np.isfinite(mean)
    finally:
        vec.close()


def test_a_custom_features_extractor_trains_on_the_view():
    from sb3_contrib import RecurrentPPO
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

    class MeanPool(BaseFeaturesExtractor):
        """(B, C, G, G) -> (B, 2C): the mean and max of every plane."""

        def __init__(self, observation_space):
            super().__init__(observation_space, 2 * observation_space.shape[0])

        def forward(self, observations):
            return torch.cat([observations.mean((2, 3)), observations.amax((2, 3))], dim=1)

    vec = make_sb3_vec_env(small_config(n_agents=2), n_envs=1, seed=0)
    try:
        model = RecurrentPPO("MlpLstmPolicy", VecMonitor(vec), n_steps=16, batch_size=32,
                             n_epochs=1, seed=0,
                             policy_kwargs={"features_extractor_class": MeanPool,
                                            "lstm_hidden_size": 8, "net_arch": [8]})
        model.learn(64)
    finally:
        vec.close()
    assert isinstance(model.policy.features_extractor, MeanPool)


# --------------------------------------------------------------------------------------------
# Command line and bad input


def test_command_line_trains_any_algorithm_case_insensitively(tmp_path, capsys):
    out = tmp_path / "qrdqn"
    argv = ["sb3", "--algo", "qrdqn", "--timesteps", "128", "--n-envs", "1", "--agents", "2",
            "--width", "8", "--features-dim", "16", "--hidden", "16", "--lr", "1e-3",
            "--set", "buffer_size=300", "--set", "learning_starts=32",
            "--set", "n_quantiles=3", "--out", str(out), "--no-progress"]
    assert train_main(argv) == 0
    assert "setting: 2 UAVs (fixed starts), D = 25 m" in capsys.readouterr().err  # printed first
    record = json.loads((out / "policy.json").read_text())
    assert record["algo"] == "QRDQN" and record["command"] == shlex.join(["ipp-train", *argv])
    assert record["hyperparameters"]["learning_rate"] == 1e-3
    assert record["architecture"]["n_quantiles"] == 3
    # Resume: further with the same flags; other hyper-parameters are refused.
    more = [*argv[:4], "256", *argv[5:]]
    assert train_main([*more, "--resume"]) == 0
    assert json.loads((out / "policy.json").read_text())["num_timesteps"] >= 256
    assert train_main([*more, "--set", "batch_size=16", "--resume"]) == 2
    assert "cannot resume" in capsys.readouterr().err
    # The PPO case is ipp-train ppo, with its flags and files.
    ppo_out = tmp_path / "ppo"
    assert train_main(["sb3", "--algo", "PPO", "--timesteps", "64", "--n-envs", "1",
                       "--n-steps", "32", "--batch-size", "64", "--agents", "2",
                       "--out", str(ppo_out), "--no-progress"]) == 0
    assert "setting: 2 UAVs" in capsys.readouterr().err
    record = json.loads((ppo_out / "policy.json").read_text())
    assert record["format"] == "ipp-toolkit/ppo" and record["algo"] == "ppo"
    assert record["command"].startswith("ipp-train sb3 --algo PPO")


def test_time_limit_stops_and_saves(tmp_path):
    config = tiny_config("A2C", total_timesteps=100_000)
    path = train_sb3(config, EnvConfig(), tmp_path, progress=False, time_limit_s=0.3)
    assert json.loads(path.with_suffix(".json").read_text())["num_timesteps"] < 100_000
    SB3Planner(path)


@pytest.mark.parametrize("argv, message", [
    (["--algo", "SAC"], "SAC needs continuous actions; the UAVs have 6 discrete ones); "
                        "supported: PPO, MaskablePPO, A2C, DQN, QRDQN, RecurrentPPO"),
    (["--algo", "CrossQ"], "CrossQ needs continuous actions"),
    ([], "--algo is required; supported: PPO"),
    (["--algo", "a2c", "--set", "buffer_size=10"], "unknown hyper-parameter 'buffer_size' for "
                                                    "A2C"),
    (["--algo", "dqn", "--set", "gamma=2"], "gamma must lie in [0, 1], got 2.0"),
    (["--algo", "dqn", "--set", "train_freq=many"], "--set train_freq=many: not a number"),
    (["--algo", "MaskablePPO", "--no-masked"], "--masked/--no-masked are ipp-train ppo's"),
    (["--algo", "PPO", "--timesteps", "0"], "total_timesteps must be an integer >= 1, got 0"),
    (["--algo", "MaskablePPO", "--preset", "shipped", "--resume"], "nothing to resume"),
    (["--algo", "recurrentppo", "--resume"], "nothing to resume"),
])
def test_bad_command_lines_exit_2_with_one_line(tmp_path, capsys, argv, message):
    out = tmp_path / "run"
    assert train_main(["sb3", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not (out / "policy.pt").exists()


def test_planner_refuses_bad_files_naming_both_shapes(runs, tmp_path, capsys):
    _, path = runs["DQN"]
    payload = torch.load(path, weights_only=True)
    five = dict(payload, n_actions=5)
    save_torch(tmp_path / "five.pt", {k: v for k, v in five.items() if k != "format"},
               SB3_POLICY_KIND)
    with pytest.raises(CheckpointError, match="trained for 5 actions; the simulator has 6"):
        SB3Planner(tmp_path / "five.pt")
    six_planes = dict(payload, obs_shape=[6, 11, 11])
    save_torch(tmp_path / "six.pt", {k: v for k, v in six_planes.items() if k != "format"},
               SB3_POLICY_KIND)
    with pytest.raises(CheckpointError, match=r"\(6, 11, 11\).*\(7, 11, 11\)"):
        SB3Planner(tmp_path / "six.pt")
    planner = SB3Planner(path)
    with pytest.raises(CheckpointError, match=r"\(7, 11, 11\); missions of this config give "
                                              r"\(7, 9, 9\)"):
        planner.reset(small_config(world={"area_size": 40.0}), seed=0)
    with pytest.raises(CheckpointError, match="needs a policy file"):
        SB3Planner()
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes(path.read_bytes()[:500])
    foreign = tmp_path / "coma.pt"
    save_torch(foreign, {"actor": {}}, "ipp-toolkit/coma")
    for bad, message in ((corrupt, "is corrupt"), (foreign, "format tag: 'ipp-toolkit/coma'")):
        with pytest.raises(CheckpointError, match=message):
            SB3Planner(bad)
        out = tmp_path / f"out-{bad.stem}"
        assert compare_main(["--planners", f"ig,sb3={bad}", "--out", str(out)]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert lines[-1].startswith("ipp-compare: error: planner 'sb3' cannot be built")
        assert message in lines[-1] and str(bad) in lines[-1]
        assert not any("Traceback" in line for line in lines) and not out.exists()


def test_compare_flies_sb3_beside_ppo(runs):
    from reports.compare import compare

    _, dqn = runs["DQN"]
    _, ppo = runs["MaskablePPO"]
    comparison = compare(planners=f"ig,sb3={dqn},ppo={ppo},mine:sb3={ppo}", trials=1,
                         workers=1, config=small_config(team={"budget": 2}), progress=False)
    assert {"ig", "sb3", "ppo", "mine"} <= set(comparison.summary.planners)
    rows = [r for r in comparison.result.rows if r["planner"] in ("ppo", "mine")]
    by_planner = {p: [r["entropy"] for r in rows if r["planner"] == p] for p in ("ppo", "mine")}
    assert by_planner["ppo"] == by_planner["mine"]  # one policy, two planners, same flight


@pytest.mark.slow
def test_the_example_of_docs_sb3_runs_as_written(capsys):
    text = (Path(__file__).resolve().parents[1] / "docs" / "sb3.md").read_text()
    blocks = [b.split("```", 1)[0] for b in text.split("```python\n")[1:]]
    code = next(b for b in blocks if "final entropy" in b)  # the page's training example
    exec(compile(code, "docs/sb3.md", "exec"), {"__name__": "__main__"})
    assert "final entropy" in capsys.readouterr().out
