"""Sizes a file or flag can ask for: each is estimated before anything runs and refused above
its documented limit (exit 2, the estimate and the variable that lifts it in one line,
nothing written); the limits can be lifted."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from baselines.sb3.ppo import resolve_policy as resolve_ppo_policy
from coma.persistence import resolve_policy
from ipp_toolkit.config.limits import LimitError, check_mission, limit_value
from ipp_toolkit.config.schema import EnvConfig
from reports.cli import compare_main, train_main

QUICK = ["--planners", "random", "--no-progress"]


def refused(run, tmp_path, capsys, needle: str) -> str:
    out = tmp_path / "out"
    assert run(out) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()[-1]) < 600
    assert needle in err.splitlines()[-1]
    assert not out.exists()
    return err


@pytest.mark.parametrize("flags, needle", [
    (["--resolution", "1e-5"], "IPP_MAX_MISSION_GB"),
    (["--area-size", "100000"], "IPP_MAX_MISSION_GB"),
    (["--grid-spacing", "0.001"], "IPP_MAX_MISSION_GB"),
    (["--budget", "1000000000"], "IPP_MAX_RESULT_ROWS"),
    (["--trials", "1000000000000"], "IPP_MAX_RESULT_ROWS"),
])
def test_compare_refuses_sizes_that_cannot_fit(tmp_path, capsys, flags, needle):
    err = refused(lambda out: compare_main([*QUICK, *flags, "--out", str(out)]), tmp_path,
                  capsys, needle)
    assert "needs" in err and "over the limit of" in err


@pytest.mark.parametrize("argv, needle", [
    (["coma", "--width", "100000"], "width = 100000 is over the limit"),
    (["coma", "--width", "9000"], "IPP_MAX_PARAMETERS"),
    (["ppo", "--width", "100000"], "width = 100000 is over the limit"),
    (["ppo", "--width", "4000", "--features-dim", "60000"], "IPP_MAX_PARAMETERS"),
])
def test_training_refuses_networks_that_cannot_fit(tmp_path, capsys, argv, needle):
    refused(lambda out: train_main([*argv, "--out", str(out)]), tmp_path, capsys, needle)


@pytest.mark.parametrize("planner, section, field, value, needle", [
    ("coma", "coma_config", "width", 10 ** 6, "width = 1000000 is over the limit"),
    ("coma", "coma_config", "width", 20_000, "IPP_MAX_PARAMETERS"),
    ("ppo", "ppo_config", "width", 10 ** 6, "width = 1000000 is over the limit"),
    ("ppo", "ppo_config", "width", 20_000, "IPP_MAX_PARAMETERS"),
])
def test_checkpoint_sizes_are_bounded_before_building(tmp_path, capsys, planner, section,
                                                      field, value, needle):
    shipped = resolve_policy("shipped:paper-actor") if planner == "coma" else \
        resolve_ppo_policy("shipped:split")
    data = torch.load(shipped, weights_only=True)
    data[section][field] = value
    path = tmp_path / "huge.pt"
    torch.save(data, path)
    # --workers 1: the check runs here, not in a worker that would import torch first
    # (tests/test_bad_inputs.py refuses a checkpoint from a worker).
    err = refused(lambda out: compare_main([*QUICK, "--planners", f"{planner}={path}",
                                            "--workers", "1", "--out", str(out)]),
                  tmp_path, capsys, needle)
    assert str(path) in err


def test_a_raster_over_the_limit_is_refused_before_it_is_read(tmp_path, capsys, monkeypatch):
    raster = tmp_path / "big.npy"
    np.save(raster, np.zeros((40, 50), dtype=np.float32))
    monkeypatch.setenv("IPP_MAX_RASTER_CELLS", "1000")
    err = refused(lambda out: compare_main([*QUICK, "--terrain", str(raster), "--threshold",
                                            "0.5", "--out", str(out)]), tmp_path, capsys,
                  "IPP_MAX_RASTER_CELLS")
    assert "40 x 50" in err and "2,000 cells" in err


def test_a_yaml_alias_bomb_is_refused_in_one_short_line(tmp_path, capsys):
    bomb = tmp_path / "bomb.yaml"
    lines = ['a: &a ["x","x","x","x","x","x","x","x","x"]']
    for prev, name in zip("abcdefgh", "bcdefghi", strict=True):
        lines.append(f"{name}: &{name} [{','.join([f'*{prev}'] * 9)}]")
    lines.append("world: {prior: *i}")
    bomb.write_text("\n".join(lines))
    err = refused(lambda out: compare_main([*QUICK, "--config", str(bomb), "--out", str(out)]),
                  tmp_path, capsys, "anchors and aliases")
    assert len(err) < 2000


def test_limits_are_lifted_by_their_variable_and_a_bad_value_is_named(monkeypatch):
    big = EnvConfig().replace(world={"resolution": 0.01})  # 5000 x 5000 cells, about 4 GiB
    check_mission(big)
    with pytest.raises(LimitError, match="IPP_MAX_MISSION_GB"):
        check_mission(big, at_once=4)
    monkeypatch.setenv("IPP_MAX_MISSION_GB", "inf")
    check_mission(big, at_once=4)
    monkeypatch.setenv("IPP_MAX_MISSION_GB", "lots")
    with pytest.raises(ValueError, match="IPP_MAX_MISSION_GB='lots'"):
        limit_value("mission_memory")
