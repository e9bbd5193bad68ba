"""Bad input that used to end in a traceback gets a clear error naming the value: YAML keys
that are not names, YAML nested too deep, a failed UAV in ipp-simulate, a damaged run
record on resume, wrong argument types in the Python API, and a corrupt trajectory on a
rerun (warned about and flown again)."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from ipp_toolkit.config.files import read_config_file
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.env import IPPEnv
from reports import compare_planners as compare
from reports.cli import compare_main, simulate_main, train_main


@pytest.mark.parametrize("text, message", [
    ("1: 2\n", "key 1 is not a name (a string) but of type int"),
    ("world: {1: 2, resolution: 1.0}\n", "key 1 in section 'world' is not a name"),
    ("3: {}\nworld: {}\n", "key 3 is not a name"),
    ("? [a, b]\n: 1\n", "a key must be a plain value, not a sequence (line 1"),
    ("world: {? {a: 1}\n : 1}\n", "a key must be a plain value, not a mapping"),
    ("[" * 100_000 + "]" * 100_000, "nested more than 64 levels deep"),
])
def test_yaml_keys_that_are_not_names_and_deep_nesting_are_refused(tmp_path, capsys, text,
                                                                   message):
    path = tmp_path / "config.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=re.escape(message)):
        read_config_file(path)
    assert compare_main(["--config", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and message in err and str(path) in err


def test_simulate_flies_on_when_uav_0_and_others_fail(tmp_path, capsys):
    config = tmp_path / "config.yaml"
    config.write_text("world: {resolution: 1.0}\n"
                      "team: {budget: 4, failures: [[0, 1], [1, 2], [2, 2]]}\n")
    assert simulate_main(["--config", str(config), "--out", str(tmp_path / "out")]) == 0
    lines = (tmp_path / "out" / "metrics.csv").read_text().splitlines()
    assert len(lines) == 1 + 5 and "Traceback" not in capsys.readouterr().err


@pytest.mark.parametrize("stored", ["[1, 2]", "\"text\"", "{\"kind\": 3", "null"])
def test_a_prior_run_with_a_damaged_record_is_refused_on_resume(tmp_path, capsys, stored):
    out = tmp_path / "out"
    out.mkdir()
    (out / "run.json").write_text(json.dumps({"format": 1, "command": "ipp-train prior"}))
    (out / "config.json").write_text(stored)
    (out / "last.pt").write_bytes(b"x")
    assert train_main(["prior", "--resume", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "config.json" in err


@pytest.fixture(scope="module")
def env():
    return IPPEnv(EnvConfig().replace(world={"resolution": 1.0}))


@pytest.mark.parametrize("options", ["mission", ["mission"], 3])
def test_reset_refuses_options_that_are_not_a_dict(env, options):
    with pytest.raises(TypeError, match=r"options must be a dict such as \{'mission': 3\}"):
        env.reset(seed=0, options=options)


@pytest.mark.parametrize("actions", [None, [0, 1, 2, 3], 5])
def test_step_refuses_actions_that_are_not_a_dict(env, actions):
    env.reset(seed=0)
    with pytest.raises(TypeError, match="actions must be a dict of agent name -> action"):
        env.step(actions)


@pytest.mark.parametrize("changes, error, message", [
    ({"trials": math.inf}, ValueError, "trials must be an integer >= 1, got inf"),
    ({"trials": None}, ValueError, "trials must be an integer >= 1, got None"),
    ({"trials": "3"}, ValueError, "trials must be an integer >= 1, got '3'"),
    ({"workers": math.nan}, ValueError, "workers must be an integer >= 1, got nan"),
    ({"config": 123}, TypeError, "config must be an EnvConfig, a YAML file path or None"),
    ({"terrain": np.zeros((3, 3))}, TypeError, "terrain must be a terrain kind or a raster"),
])
def test_compare_names_an_argument_of_the_wrong_type(changes, error, message):
    with pytest.raises(error, match=message):
        compare(**{"planners": "random", "trials": 1, "resolution": 1.0, "progress": False,
                   **changes})


def test_a_corrupt_trajectory_is_warned_about_and_flown_again(tmp_path, capsys,
                                                               placeholder_figures):
    out = tmp_path / "out"
    argv = ["--planners", "random", "--resolution", "1", "--budget", "2", "--agents", "2",
            "--trials", "1", "--no-progress", "--out", str(out)]
    assert compare_main(argv) == 0
    npz = out / "trajectories" / "random_mission0.npz"
    for damage in (npz.read_bytes()[:40], b"not a zip at all", b""):
        npz.write_bytes(damage)
        with pytest.warns(UserWarning, match="is unreadable"):
            assert compare_main(argv) == 0
        assert "Traceback" not in capsys.readouterr().err
        assert np.load(npz)["positions"].shape[0] >= 1  # written again
