"""The smaller edges: ipp-compare's help names the checkpoint planners, --set reaches PPO,
ARS logs the task metrics, a refused --resume names the differing fields, and the shipped
PPO policies export to SB3 zips."""

from __future__ import annotations

import json

import numpy as np
import torch

from baselines.sb3.export import export_sb3_zip
from baselines.sb3.loading import load_sb3_policy
from baselines.sb3.ppo import resolve_policy
from reports.cli import compare_main, train_main

TINY = ["--agents", "2", "--resolution", "1", "--n-envs", "1", "--width", "8",
        "--features-dim", "16", "--hidden", "16", "--no-progress"]


def test_compare_help_names_every_checkpoint_planner_spec(capsys):
    try:
        compare_main(["--help"])
    except SystemExit:
        pass
    text = " ".join(capsys.readouterr().out.split())
    for spec in ("sb3=PATH", "ppo=PATH", "rllib=RUN", "torchrl=PATH", "coma=PATH",
                 "SB3 model.zip"):
        assert spec in text, spec


def test_set_reaches_ppo_and_a_refused_resume_names_only_the_differing_fields(tmp_path,
                                                                              capsys):
    out = str(tmp_path / "ppo")
    args = ["sb3", "--algo", "PPO", "--timesteps", "64", "--batch-size", "32", *TINY,
            "--out", out]
    assert train_main([*args, "--set", "n_steps=32", "--set", "gamma=0.9"]) == 0
    record = json.loads((tmp_path / "ppo" / "policy.json").read_text())
    assert record["ppo_config"]["n_steps"] == 32 and record["ppo_config"]["gamma"] == 0.9
    capsys.readouterr()
    assert train_main([*args, "--set", "n_steps=16", "--set", "gamma=0.9", "--resume"]) == 2
    err = capsys.readouterr().err
    assert "n_steps = 32 in the run, 16 now" in err and "gamma" not in err
    assert "PPOTrainConfig(" not in err  # no whole config
    assert train_main([*args, "--set", "n_steps=32", "--set", "gamma=0.9", "--comm", "10",
                       "--resume"]) == 2
    assert "comm_range = 25.0 in the run, 10.0 now" in capsys.readouterr().err
    for bad, message in ((["--set", "n_steps=3x"], "not a whole number"),
                         (["--set", "nsteps=3"], "not a PPO hyper-parameter"),
                         (["--n-steps", "8", "--set", "n_steps=8"], "given twice")):
        assert train_main([*args[:-2], "--out", str(tmp_path / "bad"), *bad]) == 2
        assert message in capsys.readouterr().err


def test_ars_logs_final_entropy_and_f1(tmp_path):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    out = tmp_path / "ars"
    assert train_main(["sb3", "--algo", "ARS", "--timesteps", "300", *TINY,
                       "--out", str(out)]) == 0
    events = EventAccumulator(str(next((out / "tb").iterdir())))
    events.Reload()
    tags = events.Tags()["scalars"]
    assert "rollout/final_entropy" in tags and "rollout/final_f1" in tags


def test_a_shipped_ppo_policy_exports_to_a_zip_maskable_ppo_loads(tmp_path):
    from sb3_contrib import MaskablePPO

    from baselines.sb3.planner import SB3Planner

    path = export_sb3_zip("shipped:split", tmp_path / "split")
    assert path == tmp_path / "split.zip"
    model = MaskablePPO.load(path, device="cpu")
    policy, meta = load_sb3_policy(resolve_policy("shipped:split"))
    planes = torch.as_tensor(np.random.default_rng(0).uniform(-1, 1, (3, *meta.obs_shape)),
                             dtype=torch.float32)
    with torch.no_grad():
        ours = policy.get_distribution(planes).distribution.logits
        theirs = model.policy.get_distribution(planes).distribution.logits
    torch.testing.assert_close(ours, theirs)
    assert model.num_timesteps == meta.num_timesteps
    assert SB3Planner(path).algo == "MaskablePPO"
