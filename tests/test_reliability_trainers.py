"""Every trainer of ``ipp-train`` reports a refused limit as bad input: one line naming the
value, exit code 2, no traceback and no folder left, whatever asks for too much (a flag, a
config file, an environment variable) and whether or not the optional Ray is installed. The
trainers share one way of reporting errors and interrupts (``run_reporting``)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from ipp_toolkit.runs.progress import run_reporting
from reports.cli import train_main

FILES = {
    "res.yaml": "world: {resolution: 1.0e-300}\n",
    "area.yaml": "world: {area_size: 1.0e+200}\n",
    "raster.yaml": "world: {resolution: 1.0}\n"
                   "terrain: {kind: raster, raster: field.npy, threshold: 0.5}\n",
}


@pytest.fixture
def inputs(tmp_path, monkeypatch):
    """The config files of the cases in ``tmp_path`` (the working folder), beside an 8 x 8
    raster."""
    monkeypatch.chdir(tmp_path)
    field = np.zeros((8, 8))
    field[:, 4:] = 1.0
    np.save(tmp_path / "field.npy", field)
    for name, text in FILES.items():
        (tmp_path / name).write_text(text)
    return tmp_path


CASES = [
    ({}, ["ppo", "--config", "res.yaml"], "at r_M = 1e-300 m"),
    # the missions' estimate comes first: it names the area, not the network it would widen
    ({}, ["ppo", "--config", "area.yaml"], "(area 1e+200 m at r_M"),
    ({"IPP_MAX_ROLLOUT_GB": "0.0001"}, ["ppo"], "a rollout of n_steps 64 x n_envs 4"),
    ({}, ["sb3", "--algo", "A2C", "--set", "n_steps=100000000"], "n_steps 100000000"),
    ({}, ["sb3", "--algo", "DQN", "--config", "res.yaml"], "at r_M = 1e-300 m"),
    ({"IPP_MAX_ROLLOUT_GB": "0.0001"}, ["coma"], "an update of 50 missions"),
    ({}, ["coma", "--config", "res.yaml"], "at r_M = 1e-300 m"),
    # the prior refused these only once its folder was written, or never (r_M = 1e-300 m
    # built the smoother's tables for ever)
    ({}, ["prior", "--resolution", "1e-300"], "at r_M = 1e-300 m"),
    ({"IPP_MAX_MISSION_GB": "0.000001"}, ["prior"], "over the limit of 1e-06 GiB"),
    ({"IPP_MAX_RASTER_CELLS": "10"}, ["prior", "--config", "raster.yaml"], "(8 x 8) needs 64"),
    # rllib checks its sizes before it needs Ray
    ({}, ["rllib", "--config", "res.yaml"], "at r_M = 1e-300 m"),
    ({}, ["rllib", "--train-batch", "100000000000"], "a train batch of 100000000000 team"),
    ({}, ["rllib", "--envs-per-runner", "100000"], "100000 at once, needs"),
]


@pytest.mark.parametrize("env, argv, needle", CASES,
                         ids=[" ".join(argv) + "".join(env) for env, argv, _ in CASES])
def test_a_refused_limit_is_one_line_and_exit_code_2_from_every_trainer(inputs, capsys,
                                                                       monkeypatch, env, argv,
                                                                       needle):
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    out = inputs / "out"
    assert train_main([*argv, "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    line = err.strip().splitlines()[-1]
    assert "Traceback" not in err
    assert line.startswith(f"ipp-train {argv[0]}") and ": error: " in line
    assert needle in line and "over the limit of" in line and "IPP_MAX_" in line
    assert not out.exists()


def test_the_command_refuses_an_endless_prior_without_a_traceback(tmp_path):
    # In a process of its own, with a time limit: before the fix it never ended.
    out = tmp_path / "out"
    done = subprocess.run(
        [sys.executable, "-c", "import sys; from reports.cli import train_main; "
         "sys.exit(train_main(sys.argv[1:]))", "prior", "--resolution", "1e-300",
         "--out", str(out), "--no-progress"],
        capture_output=True, text=True, timeout=300)
    assert done.returncode == 2
    assert "Traceback" not in done.stderr
    assert "r_M = 1e-300 m" in done.stderr.strip().splitlines()[-1]
    assert not out.exists()


def test_run_reporting_reports_bad_input_interrupts_and_lets_other_errors_through(capsys):
    from ipp_toolkit.config.limits import LimitError

    def fails(error: BaseException):
        def work() -> int:
            raise error
        return work

    assert run_reporting("tool", fails(LimitError("n = 7 is over the limit")), "again") == 2
    assert capsys.readouterr().err == "tool: error: n = 7 is over the limit\n"
    assert run_reporting("tool", fails(ConnectionError("no Ray")), "again",
                         errors=(ConnectionError,)) == 2
    assert "tool: error: no Ray" in capsys.readouterr().err
    asked = []

    def how() -> str:
        asked.append(1)
        return "continue with --resume --out d"

    assert run_reporting("tool", fails(KeyboardInterrupt()), how) == 130
    assert capsys.readouterr().err == "\ntool: interrupted; continue with --resume --out d\n"
    assert asked == [1]
    assert run_reporting("tool", lambda: 0, how) == 0 and asked == [1]  # asked only then
    with pytest.raises(RuntimeError):  # a failure, not bad input: not turned into exit 2
        run_reporting("tool", fails(RuntimeError("bug")), "again")
