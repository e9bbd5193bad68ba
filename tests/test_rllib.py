"""``ipp-train rllib`` and the ``rllib`` planner: argument checks without Ray, the planner on a
policy file made here, and (slow, needs ``ray[rllib]``) one tiny training run flown by
``ipp-compare``."""

from __future__ import annotations

import importlib.util
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from baselines.rllib.planner import RLlibPlanner
from baselines.rllib.policy import (
    MaskedConvPolicy,
    RLlibArchitecture,
    RLlibPolicyFile,
    save_rllib_policy,
)
from baselines.rllib.training import RLlibTrainConfig
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import CheckpointError
from ipp_toolkit.runs.evaluation import evaluate
from ipp_toolkit.sim.features import actor_plane_names
from reports.cli import compare_main, train_main

REPO = Path(__file__).resolve().parents[1]


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


@pytest.mark.parametrize(("argv", "named"), [
    (["--algo", "DQN"], "'DQN'"),
    (["--iterations", "0"], "iterations must be an integer >= 1, got 0"),
    (["--num-env-runners", "-1"], "num_env_runners must be an integer >= 0, got -1"),
    (["--lr", "nan"], "lr must be a number > 0, got nan"),
    (["--address", "not-an-address"], "'not-an-address'"),
])
def test_bad_arguments_exit_2_naming_the_value(tmp_path: Path, capsys: pytest.CaptureFixture,
                                               argv: list[str], named: str) -> None:
    out = tmp_path / "run"
    assert train_main(["rllib", *argv, "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "ipp-train rllib: error:" in err and named in err
    assert not out.exists()


def test_unreachable_address_fails_fast_naming_it(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture) -> None:
    address = f"127.0.0.1:{_free_port()}"
    assert train_main(["rllib", "--address", address, "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert f"no Ray cluster answers at {address!r}" in err and "ray start --head" in err
    assert not (tmp_path / "run").exists()


def test_missing_rllib_names_the_install_command(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray.rllib", None)  # import ray.rllib -> ImportError
    assert train_main(["rllib", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    assert 'pip install -c constraints-rllib.txt -e ".[rllib]"' in err


def test_config_round_trips_and_refuses_unknown_keys() -> None:
    config = RLlibTrainConfig(algo="appo", comm_range=float("inf"))
    assert config.algo == "APPO"
    assert RLlibTrainConfig.from_dict(config.to_dict()) == config
    with pytest.raises(ValueError, match="unknown RLlib config keys"):
        RLlibTrainConfig.from_dict({**config.to_dict(), "bogus": 1})


def test_default_imports_leave_ray_alone() -> None:
    code = ("import sys, baselines.rllib.planner, baselines.rllib.training, "
            "baselines.rllib.env_config, reports.cli; "
            "loaded = [m for m in sys.modules if m == 'ray' or m.startswith('ray.')]; "
            "assert not loaded, loaded")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=REPO)


@pytest.mark.rllib
@pytest.mark.parametrize("algo", ["PPO", "APPO", "IMPALA"])
def test_an_iteration_is_one_train_batch_for_every_algorithm(algo: str) -> None:
    # APPO and IMPALA default to iterations of at least 10 s (min_time_s_per_iteration):
    # --iterations would count time, not --train-batch team steps as it does for PPO.
    pytest.importorskip("ray.rllib.algorithms.appo")
    from baselines.rllib.run import algorithm_config

    config = RLlibTrainConfig(algo=algo, train_batch=96, num_env_runners=2)
    rl_config = algorithm_config(config, EnvConfig(), base_seed=0)
    assert not rl_config.min_time_s_per_iteration
    assert rl_config.min_sample_timesteps_per_iteration == 96
    assert rl_config.count_steps_by == "env_steps"  # team steps, as --train-batch counts
    assert rl_config.num_env_runners == 2


def _policy_dir(tmp_path: Path, config: EnvConfig) -> Path:
    torch.manual_seed(0)
    grid = int(config.world.grid_points)
    arch = RLlibArchitecture(channels=len(actor_plane_names(config.features)), grid=grid,
                             width=4, features_dim=8, hidden=8)
    save_rllib_policy(tmp_path / "run" / "policy.pt", MaskedConvPolicy(arch),
                      RLlibPolicyFile(algo="PPO", architecture=arch, env_config=config,
                                      agent_steps=0, iteration=0))
    return tmp_path / "run"


def test_planner_flies_a_policy_file_and_never_picks_masked_actions(tmp_path: Path) -> None:
    config = EnvConfig()
    run = _policy_dir(tmp_path, config)
    planner = RLlibPlanner(run)
    assert planner.obs_shape[1:] == (11, 11)
    result = evaluate(config, [f"rllib={run}"], missions=2, seed=0, progress=False)
    assert result.rows and {row["planner"] for row in result.rows} == {"rllib"}
    # Every logit but one masked: the argmax is the one valid action.
    planes = torch.zeros(6, *planner.obs_shape)
    masks = torch.eye(6, dtype=torch.int8)
    chosen = planner.policy(planes, masks).argmax(dim=1).numpy()
    np.testing.assert_array_equal(chosen, np.arange(6))


def test_planner_refuses_missing_and_foreign_files(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="does not exist"):
        RLlibPlanner(tmp_path / "nothing")
    with pytest.raises(CheckpointError, match="needs a run folder"):
        RLlibPlanner(None)
    foreign = tmp_path / "foreign.pt"
    torch.save({"format": "ipp-toolkit/ppo"}, foreign)
    with pytest.raises(CheckpointError, match="ipp-toolkit/rllib"):
        RLlibPlanner(foreign)


@pytest.mark.slow
@pytest.mark.rllib
@pytest.mark.skipif(importlib.util.find_spec("ray") is None
                    or importlib.util.find_spec("ray.rllib") is None,
                    reason="needs ray[rllib] (pip install -c constraints-rllib.txt -e .[rllib])")
def test_one_iteration_on_a_local_ray_flies_through_ipp_compare(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    pytest.importorskip("ray.rllib.algorithms.ppo")
    run = tmp_path / "rllib"
    # One remote env runner: the sampling path a cluster uses (0 samples in the driver).
    common = ["--train-batch", "60", "--width", "4", "--features-dim", "8", "--hidden", "8",
              "--seed", "3", "--num-env-runners", "1", "--no-progress"]
    assert train_main(["rllib", "--algo", "PPO", "--iterations", "1", "--out", str(run),
                       *common]) == 0
    assert (run / "policy.pt").is_file() and (run / "checkpoint" / "ipp_state.json").is_file()
    assert "setting:" in capsys.readouterr().err
    # --resume carries on from the checkpoint; another config is refused.
    assert train_main(["rllib", "--algo", "PPO", "--iterations", "2", "--out", str(run),
                       "--resume", *common]) == 0
    assert RLlibPlanner(run).meta.iteration == 2
    assert train_main(["rllib", "--algo", "PPO", "--iterations", "3", "--out", str(run),
                       "--resume", "--lr", "0.1", *common]) == 2
    assert "only iterations may change" in capsys.readouterr().err
    out = tmp_path / "compare"
    assert compare_main(["--planners", f"rllib={run}", "--trials", "2", "--out", str(out),
                         "--no-progress"]) == 0
    assert (out / "results.csv").is_file()


@pytest.mark.slow
@pytest.mark.rllib
@pytest.mark.skipif(importlib.util.find_spec("ray") is None
                    or importlib.util.find_spec("ray.rllib") is None,
                    reason="needs ray[rllib] (pip install -c constraints-rllib.txt -e .[rllib])")
def test_appo_iterations_count_train_batches_on_a_remote_runner(tmp_path: Path) -> None:
    pytest.importorskip("ray.rllib.algorithms.appo")
    run = tmp_path / "appo"
    assert train_main(["rllib", "--algo", "APPO", "--iterations", "2", "--train-batch", "60",
                       "--agents", "2", "--width", "4", "--features-dim", "8", "--hidden", "8",
                       "--seed", "1", "--num-env-runners", "1", "--out", str(run),
                       "--no-progress"]) == 0
    meta = RLlibPlanner(run).meta
    assert meta.algo == "APPO" and meta.iteration == 2
    # Each iteration sampled at least one --train-batch of team steps (2 UAVs each): the
    # TensorBoard steps are the agent-steps after each iteration.
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    events = EventAccumulator(str(run / "tb" / "appo_1"))
    events.Reload()
    steps = [0] + [e.step for e in events.Scalars("time/agent_steps_per_s")]
    assert len(steps) == 3 and steps[-1] == meta.agent_steps
    assert all(b - a >= 60 * 2 for a, b in zip(steps[:-1], steps[1:], strict=True))
