"""Mixed-precision learning (``COMAConfig.precision``): bfloat16 forward passes in the
warm start and the updates, float32 weights, losses and deployed policies."""

from __future__ import annotations

import copy

import pytest
import torch
from helpers import tiny_coma, tiny_env

import coma.cli
import coma.learner
import coma.networks
from coma.cli import build_parser, configs_from_args
from coma.config import COMAConfig, from_dict
from coma.learner import make_optimisers, to_channels_last, train, update
from coma.networks import ConvNet, bfloat16_hardware, learning_forward, mixed_precision
from coma.persistence import build_networks, load_policy
from coma.planner import COMAPlanner
from coma.rollout import collect_rollout
from ipp_toolkit.io import CheckpointError
from ipp_toolkit.runs.evaluation import run_mission
from ipp_toolkit.sim.mission import MissionGeometry
from reports.cli import train_main


def test_the_precision_is_checked_by_name_and_old_configs_read_float32():
    with pytest.raises(ValueError, match=r"precision = 'float16'.*float32.*bfloat16"):
        COMAConfig(precision="float16")
    old = COMAConfig().to_dict()
    del old["precision"]  # a config saved before the field existed
    assert from_dict(old).precision == "float32"
    assert from_dict(COMAConfig(precision="bfloat16").to_dict()).precision == "bfloat16"


def test_the_flag_and_set_choose_the_precision(tmp_path, capsys):
    parser = build_parser()
    for argv in (["--precision", "bfloat16"], ["--set", "precision=bfloat16"]):
        coma_config, _ = configs_from_args(parser.parse_args(["--out", "x", *argv]))
        assert coma_config.precision == "bfloat16"
    assert configs_from_args(parser.parse_args(["--out", "x"]))[0].precision == "float32"
    with pytest.raises(SystemExit) as exit_info:
        parser.parse_args(["--out", "x", "--precision", "half"])
    assert exit_info.value.code == 2 and "'half'" in capsys.readouterr().err

    # Through --set: ipp-train coma exits 2 with one line naming the field and the value.
    assert train_main(["coma", "--out", str(tmp_path / "run"), "--set", "precision=half"]) == 2
    err = capsys.readouterr().err
    assert "precision = 'half'" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "run").exists()


def test_bfloat16_runs_the_convolutions_in_bfloat16_and_the_head_in_float32():
    torch.manual_seed(0)
    network = ConvNet(3, 11, 6, width=8, hidden=16)
    planes = torch.rand(5, 3, 11, 11)
    dtypes = {}
    for name in ("encoder", "head"):
        getattr(network, name).register_forward_hook(
            lambda module, inputs, output, name=name: dtypes.__setitem__(name, output.dtype))
    with mixed_precision("bfloat16", planes.device):
        network(planes)
    assert dtypes == {"encoder": torch.bfloat16, "head": torch.float32}
    out = learning_forward(network, planes, "bfloat16")
    exact = learning_forward(network, planes, "float32")
    assert out.dtype == exact.dtype == torch.float32
    assert torch.equal(exact, network(planes))  # float32: the plain forward pass, bit for bit
    assert not torch.equal(out, exact)
    assert torch.allclose(out, exact, atol=0.05, rtol=0.05)  # bfloat16 keeps ~3 digits


def _one_update(precision: str) -> tuple[dict[str, float], dict[str, torch.Tensor],
                                         dict[str, torch.Tensor]]:
    env = tiny_env()
    config = tiny_coma(precision=precision, minibatch_size=10, epochs=2)
    torch.manual_seed(0)
    networks = build_networks(config, env)
    to_channels_last(networks)
    rollout = collect_rollout(networks, env, MissionGeometry(env), 0, 0, 3, 0.3)
    before = {k: v.clone() for k, v in networks.critic.state_dict().items()}
    losses = update(networks, copy.deepcopy(networks.critic), make_optimisers(networks),
                    rollout, 0.3, torch.Generator().manual_seed(3))
    return losses, before, networks.critic.state_dict()


def test_a_bfloat16_update_keeps_float32_weights_and_moves_them_as_float32_does():
    losses, start, exact = _one_update("float32")
    mixed_losses, mixed_start, mixed = _one_update("bfloat16")
    assert all(torch.equal(start[k], mixed_start[k]) for k in start)  # the same start
    assert set(mixed_losses) == set(losses)
    for key, value in mixed_losses.items():
        assert value == pytest.approx(losses[key], rel=0.1, abs=1e-3), key
    steps = torch.cat([(exact[k] - start[k]).flatten() for k in start])
    mixed_steps = torch.cat([(mixed[k] - start[k]).flatten() for k in start])
    assert all(v.dtype == torch.float32 and torch.isfinite(v).all() for v in mixed.values())
    assert not torch.equal(steps, mixed_steps)  # the passes did run in bfloat16
    cosine = torch.nn.functional.cosine_similarity(steps, mixed_steps, dim=0)
    assert cosine > 0.9, float(cosine)


def test_a_bfloat16_run_is_reproducible_and_its_policy_flies_in_float32(tmp_path):
    config = tiny_coma(precision="bfloat16", warm_start={"planner": "coverage", "missions": 2,
                                                         "missions_per_batch": 2, "epochs": 1,
                                                         "minibatch_size": 20})
    results = [train(config, tiny_env(), tmp_path / name, progress=False, tensorboard=False)
               for name in ("a", "b")]
    (first, _), (second, _) = (load_policy(r.best_policy) for r in results)
    assert first.coma_config.precision == "bfloat16"
    for key, value in first.actor.state_dict().items():
        assert value.dtype == torch.float32 and torch.equal(value, second.actor.state_dict()[key])
    outcome = run_mission(tiny_env(), COMAPlanner(results[0].best_policy), seed=0, mission=0)
    assert len(outcome["rows"]) == tiny_env().team.budget + 1


@pytest.mark.parametrize("native", [True, False])
def test_ipp_train_coma_takes_the_precision_flag(tmp_path, monkeypatch, capsys, native):
    # Where the CPU has no bfloat16 instructions, the run says it is likely slower, and runs.
    monkeypatch.setattr(coma.networks, "bfloat16_hardware", lambda device: native)
    out = tmp_path / "run"
    assert train_main(["coma", "--out", str(out), "--missions", "2", "--agents", "2",
                       "--resolution", "1.0", "--precision", "bfloat16",
                       "--set", "width=8", "--set", "hidden=16",
                       "--set", "missions_per_update=2", "--set", "eval_missions=1",
                       "--set", "minibatch_size=60", "--warm-start", "none"]) == 0
    networks, _ = load_policy(out / "last.pt")
    assert networks.coma_config.precision == "bfloat16"
    err = capsys.readouterr().err
    assert ("this CPU has no bfloat16 instructions" in err) is not native
    assert "COMA (coma, bfloat16)" in err  # the progress line names the precision
    assert "setting: 2 UAVs" in err  # the setting in force, as every command prints it


@pytest.mark.parametrize(("capabilities", "answer"), [
    ({"avx512_bf16": True, "amx_bf16": False}, True),   # e.g. AMD Zen 4 and 5
    ({"avx512_bf16": False, "amx_bf16": True}, True),   # e.g. Intel Sapphire Rapids
    ({"avx512_bf16": False, "amx_bf16": False}, False),  # e.g. Intel Cascade Lake
    ({"asimd": True}, None),                             # flags torch lists for another CPU
])
def test_the_bfloat16_hardware_check_reads_the_cpu_flags(monkeypatch, capabilities, answer):
    monkeypatch.setattr(torch.cpu, "get_capabilities", lambda: capabilities)
    assert bfloat16_hardware(torch.device("cpu")) is answer


def test_a_run_resumes_only_in_its_precision_and_the_refusal_names_it(tmp_path, monkeypatch,
                                                                     capsys):
    config = tiny_coma(missions=4, precision="bfloat16")
    train(config, tiny_env(), tmp_path, progress=False, tensorboard=False, max_updates=1)

    def fly_reference(*args, **kwargs):
        raise AssertionError("IG's reference missions flew before the refusal")

    # Refused before anything flies or starts: no start line, no reference missions.
    monkeypatch.setattr(coma.learner, "reference_scores", fly_reference)
    with pytest.raises(CheckpointError,
                       match=r"precision = 'bfloat16' in the run, 'float32' now"):
        train(config.replace(precision="float32", selection="worst_vs_ig"), tiny_env(),
              tmp_path, resume=True, progress=False, tensorboard=False, announce="START")
    assert "START" not in capsys.readouterr().err
    monkeypatch.undo()
    resumed = train(config, tiny_env(), tmp_path, resume=True, progress=False,
                    tensorboard=False)
    assert resumed.updates == 2
