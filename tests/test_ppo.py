"""PPO with parameter sharing: training, checkpoints, the planner and the command line."""

from __future__ import annotations

import json
import math
import platform
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import page_faults_of_reallocation, small_config
from sb3_contrib import MaskablePPO
from stable_baselines3.common.vec_env import VecMonitor

import baselines.sb3.ppo as ppo
from baselines.sb3.planner import PPOPlanner
from baselines.sb3.ppo import (
    PPOTrainConfig,
    load_policy,
    masked_greedy_actions,
    save_policy,
)
from baselines.sb3.ppo_training import main, train_ppo, training_env_config
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import CheckpointError, save_torch
from ipp_toolkit.planning import agent_views
from ipp_toolkit.runs.evaluation import run_mission
from ipp_toolkit.sim.features import gain_plane_channels, option_gain_cells
from ipp_toolkit.sim.mission import reset_mission
from ipp_toolkit.vec import make_sb3_vec_env

torch.set_num_threads(1)

TINY = dict(n_envs=1, n_steps=64, batch_size=128, n_epochs=1, checkpoint_every=128)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A MaskablePPO run of 512 agent-transitions at 0.5 m (about 1 s)."""
    out = tmp_path_factory.mktemp("ppo")
    config = PPOTrainConfig(total_timesteps=512, **TINY)
    path = train_ppo(config, EnvConfig(), out, progress=False)
    return config, out, path


def test_training_writes_policy_config_and_checkpoint(trained):
    config, out, path = trained
    assert path == out / "policy.pt"
    assert path.stat().st_size < 2_000_000
    meta = json.loads((out / "policy.json").read_text())
    assert meta["format"] == "ipp-toolkit/ppo"
    assert meta["obs_shape"] == [7, 11, 11]
    assert meta["num_timesteps"] == 512
    assert meta["ppo_config"] == config.to_dict()
    assert meta["env_config"]["world"]["resolution"] == 0.5
    assert (out / "checkpoint.pt").is_file() and (out / "checkpoint.json").is_file()
    assert any((out / "tb").rglob("events.out.tfevents.*"))


def test_planner_flies_valid_missions(trained):
    _, out, path = trained
    planner = PPOPlanner(str(path))
    assert planner.name == "ppo"
    env_config = training_env_config(PPOTrainConfig(), EnvConfig())
    result = run_mission(env_config, planner, seed=0, mission=0)  # raises on a masked action
    assert len(result["rows"]) == env_config.team.budget + 1
    # The same policy flies other team sizes (the planes do not depend on N).
    run_mission(small_config(n_agents=2), planner, seed=0, mission=1)


def test_save_load_round_trip_gives_identical_actions(tmp_path):
    config = PPOTrainConfig(**TINY)
    env_config = training_env_config(config, EnvConfig())
    vec = make_sb3_vec_env(env_config, n_envs=1, seed=0)
    try:
        model = MaskablePPO("MlpPolicy", VecMonitor(vec), n_steps=64, batch_size=128,
                            policy_kwargs=ppo.policy_kwargs(config, env_config), seed=1)
        model.learn(256)
        batches, mask_batches = [vec.reset()], [vec.action_masks()]
        rng = np.random.default_rng(0)
        for _ in range(5):  # more varied inputs: a few random valid steps
            now = mask_batches[-1]
            batches.append(vec.step((rng.random(now.shape) * now).argmax(1))[0])
            mask_batches.append(vec.action_masks())
        obs, masks = np.concatenate(batches), np.concatenate(mask_batches)
    finally:
        vec.close()
    expected, _ = model.predict(obs, deterministic=True, action_masks=masks)
    path = save_policy(tmp_path / "p.pt", model, config, env_config)
    policy, meta = load_policy(path)
    assert meta["obs_shape"] == (7, 11, 11) and meta["ppo_config"] == config
    np.testing.assert_array_equal(masked_greedy_actions(policy, obs, masks), expected)
    # The planner (one batched forward over the team) agrees too.
    state = reset_mission(env_config, seed=0, mission=0, namespace="test")
    views = agent_views(state)
    planner = PPOPlanner(path)
    planner.reset(env_config, seed=0)
    team_obs = np.stack([v.observation for v in views])
    team_masks = np.stack([v.mask for v in views]).astype(bool)
    np.testing.assert_array_equal(planner.act(views),
                                  model.predict(team_obs, deterministic=True,
                                                action_masks=team_masks)[0])


def test_unmasked_ppo_trains_without_invalid_actions(tmp_path):
    config = PPOTrainConfig(total_timesteps=256, masked=False, **TINY)
    path = train_ppo(config, EnvConfig(), tmp_path, progress=False)
    policy, meta = load_policy(path)
    assert meta["algo"] == "ppo"
    run_mission(training_env_config(config, EnvConfig()), PPOPlanner(path), seed=0, mission=0)


def test_resume_continues_from_the_checkpoint(tmp_path):
    config = PPOTrainConfig(total_timesteps=256, **TINY)
    train_ppo(config, EnvConfig(), tmp_path, progress=False)
    with pytest.raises(ValueError, match="already holds a PPO run"):
        train_ppo(config, EnvConfig(), tmp_path, progress=False)
    longer = PPOTrainConfig(total_timesteps=512, **TINY)
    train_ppo(longer, EnvConfig(), tmp_path, progress=False, resume=True)
    assert json.loads((tmp_path / "policy.json").read_text())["num_timesteps"] == 512
    other = PPOTrainConfig(total_timesteps=768, **{**TINY, "n_epochs": 2})
    with pytest.raises(ValueError, match="cannot resume"):
        train_ppo(other, EnvConfig(), tmp_path, progress=False, resume=True)


def test_planner_refuses_corrupt_and_foreign_files(tmp_path, trained):
    corrupt = tmp_path / "corrupt.pt"
    corrupt.write_bytes(trained[2].read_bytes()[:1000])
    with pytest.raises(CheckpointError, match="corrupt"):
        PPOPlanner(corrupt)
    foreign = tmp_path / "coma.pt"
    save_torch(foreign, {"actor": {}}, "ipp-toolkit/coma")
    with pytest.raises(CheckpointError, match="ipp-toolkit/coma"):
        PPOPlanner(foreign)
    with pytest.raises(CheckpointError, match="does not exist"):
        PPOPlanner(tmp_path / "missing.pt")
    payload = torch.load(trained[2], weights_only=True)
    payload["policy"] = {k: v[..., :1] for k, v in payload["policy"].items()}
    bad = tmp_path / "bad_weights.pt"
    torch.save(payload, bad)
    with pytest.raises(CheckpointError, match="do not fit"):
        PPOPlanner(bad)


def test_planner_refuses_a_model_of_another_observation_shape(tmp_path):
    config = PPOTrainConfig(**TINY)
    six_planes = training_env_config(config, EnvConfig().replace(features={"budget": False}))
    vec = make_sb3_vec_env(six_planes, n_envs=1, seed=0)
    try:
        model = MaskablePPO("MlpPolicy", VecMonitor(vec), n_steps=64, batch_size=128,
                            policy_kwargs=ppo.policy_kwargs(config, six_planes))
    finally:
        vec.close()
    path = save_policy(tmp_path / "six.pt", model, config, six_planes)
    planner = PPOPlanner(path)
    # Views built with the mission's own 7 planes do not fit the 6-plane model: refused.
    with pytest.raises(CheckpointError, match=r"\(6, 11, 11\).*\(7, 11, 11\)"):
        planner.act(agent_views(reset_mission(small_config(), seed=0, mission=0)))
    # Through the evaluation runner the policy observes with its own planes and flies.
    result = run_mission(small_config(), planner, seed=0, mission=0)
    assert len(result["rows"]) == small_config().team.budget + 1
    assert any("features" in note for note in planner.transfer_notes)
    with pytest.raises(CheckpointError, match="grid"):
        planner.reset(small_config(world={"area_size": 40.0}), seed=0)


def test_missing_default_checkpoint_says_how_to_train(tmp_path, monkeypatch):
    monkeypatch.setattr(ppo, "DEFAULT_CHECKPOINT", tmp_path / "none.pt")
    with pytest.raises(CheckpointError, match="ipp-train ppo"):
        PPOPlanner()


def test_config_validation_and_round_trip():
    with pytest.raises(ValueError, match="n_envs must be an integer >= 1, got 0"):
        PPOTrainConfig(n_envs=0)
    with pytest.raises(ValueError, match="batch_size 4096 is larger than a rollout"):
        PPOTrainConfig(batch_size=4096, n_steps=64, n_envs=1)
    with pytest.raises(ValueError, match="gamma must lie in"):
        PPOTrainConfig(gamma=1.5)
    config = PPOTrainConfig(comm_range=math.inf, masked=False)
    assert PPOTrainConfig.from_dict(json.loads(json.dumps(config.to_dict()))) == config
    with pytest.raises(ValueError, match="unknown key"):
        PPOTrainConfig.from_dict({"lr": 1e-3, "bogus": 1})


def test_command_line(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["--timesteps", "128", "--n-envs", "1", "--n-steps", "32", "--batch-size", "64",
                 "--agents", "2", "--comm", "inf", "--no-masked", "--out", str(out),
                 "--no-progress"]) == 0
    meta = json.loads((out / "policy.json").read_text())
    assert meta["env_config"]["team"]["n_agents"] == 2
    assert meta["env_config"]["team"]["comm_range"] == "inf" and meta["algo"] == "ppo"
    assert main(["--timesteps", "0", "--out", str(tmp_path / "x")]) == 2
    assert "total_timesteps must be an integer >= 1, got 0" in capsys.readouterr().err
    assert main(["--config", str(tmp_path / "missing.yaml"), "--out", str(tmp_path / "y")]) == 2
    assert "missing.yaml" in capsys.readouterr().err
    for bad in (["--agents", "0", "--out", str(tmp_path / "z")], ["--timesteps", "many"]):
        with pytest.raises(SystemExit) as exit_info:  # argparse's own exit
            main(bad)
        assert exit_info.value.code == 2
    assert not (tmp_path / "z").exists()


@pytest.mark.parametrize("name", sorted(ppo.SHIPPED_POLICIES))
def test_every_shipped_policy_loads_by_name_and_flies(name):
    planner = PPOPlanner(f"shipped:{name}")
    assert planner.checkpoint == ppo.CHECKPOINTS / ppo.SHIPPED_POLICIES[name]
    assert planner.checkpoint.stat().st_size < 3_000_000  # committed weights stay small
    assert planner.checkpoint.with_suffix(".json").is_file()  # with its record
    run_mission(small_config(), planner, seed=0, mission=0)


def test_the_discounting_planner_reads_its_logits_from_the_latent_of_one_forward_pass():
    from baselines.sb3.planner import _gain_prior_latent
    from ipp_toolkit.planning import policy_inputs

    planner = PPOPlanner()  # the default policy has a gain prior and discounts
    assert planner._discounts
    state = reset_mission(small_config(), seed=1)
    planner.reset(state.config, seed=1)
    observations, _ = policy_inputs(agent_views(state, features=planner.observation_features))
    latent, gains = _gain_prior_latent(planner.policy, observations)
    with torch.no_grad():
        logits = planner.policy.action_net(latent)
    assert torch.equal(logits, ppo.actor_logits(planner.policy, observations))
    assert gains.shape == (4, 6)


def test_default_ppo_is_the_default_shipped_policy_and_names_resolve_for_sb3_too():
    from baselines.sb3.planner import SB3Planner

    assert PPOPlanner().checkpoint == ppo.resolve_policy(f"shipped:{ppo.DEFAULT_SHIPPED}")
    assert SB3Planner("shipped:split").checkpoint == ppo.CHECKPOINTS / "ppo_4agents_d25.pt"
    assert ppo.resolve_policy("runs/x/policy.pt") == Path("runs/x/policy.pt")
    with pytest.raises(ValueError, match="unknown shipped policy 'nope'; shipped policies: "
                                         "shipped:split"):
        PPOPlanner("shipped:nope")


@pytest.mark.parametrize("preset,name", [("shipped", "split"), ("split", "split"),
                                         ("learned-mixture", "learned-mixture")])
def test_ppo_preset_gives_the_shipped_runs_flags(preset, name):
    from baselines.sb3.ppo_training import _parser, run_config_from_args

    path = ppo.CHECKPOINTS / ppo.SHIPPED_POLICIES[name]
    record = json.loads(path.with_suffix(".json").read_text())
    args = _parser(preset).parse_args(["--preset", preset])
    env_config, run_fields = run_config_from_args(args, PPOTrainConfig())
    made = {**run_fields, "n_steps": args.n_steps, "batch_size": args.batch_size, "lr": args.lr,
            "ent_coef": args.ent_coef, "masked": args.masked, "gain_prior": args.gain_prior}
    stored = record["ppo_config"]
    assert {k: v for k, v in made.items() if k != "total_timesteps"} == \
        {k: stored.get(k, 0.0) for k in made if k != "total_timesteps"}
    assert made["total_timesteps"] == record["num_timesteps"]  # what the policy trained
    # The recipe's mission settings are the policy's (terrain, feature planes, world).
    trained = ppo.load_policy(path)[1]["env_config"]
    assert env_config == trained
    assert _parser(preset).parse_args(["--timesteps", "10"]).timesteps == 10


def test_ppo_parallelism_flag_is_workers_with_the_old_name_kept():
    from baselines.sb3.ppo_training import _parser

    assert _parser().parse_args(["--workers", "2"]).num_cpus == 2
    assert _parser().parse_args(["--num-cpus", "3"]).num_cpus == 3


# --------------------------------------------------------------------------------------------
# Gain prior


def _gain_world(config: PPOTrainConfig) -> EnvConfig:
    return training_env_config(config, EnvConfig().replace(
        features={"gain": True, "gain_smoothing": 5.0}))


def _random_batches(vec, steps: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Observations and masks of ``steps`` random valid joint steps (varied inputs)."""
    batches, mask_batches = [vec.reset()], [vec.action_masks()]
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        now = mask_batches[-1]
        batches.append(vec.step((rng.random(now.shape) * now).argmax(1))[0])
        mask_batches.append(vec.action_masks())
    return np.concatenate(batches), np.concatenate(mask_batches)


def test_option_gain_cells_read_each_option_at_its_waypoint():
    # Grid 5 (centre 2), gain planes at channels 7, 8, 9 (level, up, down); north is +y (a
    # row further down the window), east is +x.
    channel, row, col = option_gain_cells([7, 8, 9], 5)
    assert channel.tolist() == [8, 7, 7, 7, 7, 9]  # up, north, east, south, west, down
    assert row.tolist() == [2, 3, 2, 1, 2, 2]
    assert col.tolist() == [2, 2, 3, 2, 1, 2]
    with pytest.raises(ValueError, match="three planes"):
        option_gain_cells([7, 8], 5)


def test_untrained_gain_prior_policy_flies_the_argmax_of_the_gain_planes():
    config = PPOTrainConfig(gain_prior=20.0, **TINY)
    env_config = _gain_world(config)
    vec = make_sb3_vec_env(env_config, n_envs=1, seed=3)
    try:
        obs, masks = _random_batches(vec, 6, seed=1)
    finally:
        vec.close()
    policy = ppo._build_policy(config, env_config, obs.shape[1:])
    channel, row, col = option_gain_cells(
        gain_plane_channels(env_config.features), obs.shape[-1])
    gains = obs[:, channel, row, col]  # (B, 6)
    expected = np.where(masks.astype(bool), gains, -np.inf).argmax(1)
    assert len(set(expected.tolist())) > 1  # the check sees several different choices
    np.testing.assert_array_equal(masked_greedy_actions(policy, obs, masks), expected)
    # The prior's weight sets how sharply the untrained policy samples.
    with torch.no_grad():
        dist = policy.get_distribution(torch.as_tensor(obs[:1]))
    logits = dist.distribution.logits[0]
    relative = torch.as_tensor(gains[0] / (gains[0].max() + 1e-8))
    torch.testing.assert_close(logits - logits.max(),
                               (20.0 * relative) - (20.0 * relative).max(), atol=1e-4, rtol=0)


def test_gain_prior_policy_trains_saves_and_flies_identically(tmp_path):
    config = PPOTrainConfig(total_timesteps=256, gain_prior=10.0, **TINY)
    env_config = _gain_world(config)
    path = train_ppo(config, env_config, tmp_path / "run", progress=False)
    policy, meta = load_policy(path)
    assert meta["ppo_config"].gain_prior == 10.0
    assert isinstance(policy, ppo.GainPriorMaskablePolicy)
    # Training moved the action layer away from the pure prior.
    weight = policy.action_net.weight.detach()
    assert weight[:, :-6].abs().max() > 0
    vec = make_sb3_vec_env(env_config, n_envs=1, seed=4)
    try:
        obs, masks = _random_batches(vec, 4, seed=2)
    finally:
        vec.close()
    with torch.no_grad():
        logits = policy.action_net(policy.mlp_extractor.forward_actor(
            policy.extract_features(torch.as_tensor(obs), policy.pi_features_extractor)))
    expected = logits.masked_fill(~torch.as_tensor(masks.astype(bool)), -math.inf).argmax(1)
    planner = PPOPlanner(path)
    planner.reset(env_config, seed=0)
    np.testing.assert_array_equal(masked_greedy_actions(planner.policy, obs, masks),
                                  expected.numpy())
    result = run_mission(env_config, planner, seed=0, mission=0)
    assert len(result["rows"]) == env_config.team.budget + 1


def test_gain_prior_without_gain_planes_is_refused_before_any_work(tmp_path, capsys):
    config = PPOTrainConfig(gain_prior=5.0, **TINY)
    with pytest.raises(ValueError, match="gain_prior = 5.0.*features.gain"):
        ppo.policy_kwargs(config, training_env_config(config, EnvConfig()))
    out = tmp_path / "run"
    assert main(["--gain-prior", "5", "--out", str(out), "--no-progress"]) == 2
    assert "gain_prior = 5.0" in capsys.readouterr().err
    assert not out.exists()
    with pytest.raises(ValueError, match="gain_prior"):
        PPOTrainConfig(gain_prior=-1.0)


def test_a_loaded_policy_acts_without_an_optimiser_or_torch_dynamo():
    # Any torch optimiser imports torch._dynamo (about 3 s per process): a policy loaded to
    # act gets a NoOptimizer instead, which refuses to train.
    import subprocess
    import sys

    code = ("import sys; from ipp_toolkit.planning import make_planner; "
            "planner = make_planner('ppo'); "
            "print(type(planner.policy.optimizer).__name__, 'torch._dynamo' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=300)
    assert out.stdout.split() == ["NoOptimizer", "False"]
    optimiser = ppo.NoOptimizer([torch.zeros(1)], lr=1e-3)
    with pytest.raises(RuntimeError, match="not to train"):
        optimiser.step()
    with pytest.raises(RuntimeError, match="not to train"):
        optimiser.zero_grad()



@pytest.mark.slow  # a fresh process trains; test_evaluation tests the allocator setting fast
@pytest.mark.skipif(platform.libc_ver()[0] != "glibc",
                    reason="retain_freed_memory sets glibc's allocator")
def test_the_trainer_process_keeps_freed_memory_for_reuse(tmp_path):
    # After train_ppo(), allocating again what was just freed costs no new pages.
    setup = f"""
from baselines.sb3.ppo import PPOTrainConfig
from baselines.sb3.ppo_training import train_ppo
from ipp_toolkit.config.schema import EnvConfig
config = PPOTrainConfig(total_timesteps=128, **{TINY!r})
train_ppo(config, EnvConfig(), {str(tmp_path / "run")!r}, progress=False)
"""
    plain, trained = page_faults_of_reallocation(), page_faults_of_reallocation(setup)
    assert plain > 1000 and trained < plain / 10, (plain, trained)


def test_training_leaves_no_tensorboard_writer_running(tmp_path):
    """SB3 keeps its TensorBoard writer (a thread and an open file) alive after learn: a
    process that trains several runs must not collect them."""
    import threading

    before = set(threading.enumerate())
    config = PPOTrainConfig(total_timesteps=256, **TINY)
    train_ppo(config, EnvConfig(), tmp_path, progress=False)
    left = [thread.name for thread in threading.enumerate() if thread not in before]
    assert not left, left
    assert any((tmp_path / "tb").rglob("events.out.tfevents.*"))  # the log was written
