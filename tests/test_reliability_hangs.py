"""Input that would hang or run for hours is refused by name before anything runs: special
files (a FIFO, a device) as configs or checkpoints, a mission of too many steps, sizes whose
estimate itself overflows, and zip members that inflate past a limit."""

from __future__ import annotations

import os
import threading
import zipfile
from contextlib import contextmanager

import pytest

from baselines.sb3.zips import load_sb3_zip
from ipp_toolkit.config.files import load_config
from ipp_toolkit.config.limits import LimitError, check_mission, mission_bytes
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.env import IPPEnv
from ipp_toolkit.io import CheckpointError, load_torch
from reports.cli import compare_main, simulate_main, train_main

QUICK = ["--planners", "random", "--no-progress", "--trials", "1"]


@contextmanager
def fifo(path):
    """A FIFO at ``path``; a reader that blocks on it is released after 30 s (it then reads
    nothing), so a regression fails the test instead of hanging the suite."""
    os.mkfifo(path)
    done = threading.Event()

    def release() -> None:
        if not done.wait(30):
            fd = os.open(path, os.O_RDWR)  # never blocks on Linux; unblocks the reader
            os.close(fd)

    thread = threading.Thread(target=release, daemon=True)
    thread.start()
    try:
        yield path
    finally:
        done.set()
        thread.join()


def _last_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err
    return err.splitlines()[-1]


@pytest.mark.parametrize("run", [
    lambda config, out: compare_main([*QUICK, "--config", str(config), "--out", str(out)]),
    lambda config, out: simulate_main(["--config", str(config), "--out", str(out)]),
    lambda config, out: train_main(["ppo", "--config", str(config), "--out", str(out)]),
])
def test_a_fifo_as_config_is_refused_not_read(tmp_path, capsys, run):
    with fifo(tmp_path / "config.yaml") as config:
        assert run(config, tmp_path / "out") == 2
    line = _last_line(capsys)
    assert "is a FIFO (named pipe), not a regular file" in line and str(config) in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name", ["sb3", "ppo", "coma"])
def test_a_fifo_as_checkpoint_is_refused_not_read(tmp_path, capsys, name):
    with fifo(tmp_path / "policy.zip") as path:
        argv = [*QUICK, "--resolution", "1", "--planners", f"{name}={path}"]
        assert compare_main([*argv, "--out", str(tmp_path / "out")]) == 2
    line = _last_line(capsys)
    assert "is a FIFO (named pipe)" in line and str(path) in line


def test_a_device_as_checkpoint_or_config_is_refused(tmp_path):
    with pytest.raises(CheckpointError, match="'/dev/zero' is a device"):
        load_torch("/dev/zero", "ipp-toolkit/coma")
    with pytest.raises(CheckpointError, match="'/dev/zero' is a device"):
        load_sb3_zip("/dev/zero")
    with pytest.raises(ValueError, match="config file '/dev/null' is a device"):
        load_config("/dev/null")


def test_a_mission_of_too_many_steps_is_refused_with_its_estimate(tmp_path, capsys,
                                                                  monkeypatch):
    argv = [*QUICK, "--budget", "200000", "--resolution", "1"]
    assert compare_main([*argv, "--out", str(tmp_path / "out")]) == 2
    line = _last_line(capsys)
    assert "budget 200000 with 4 UAVs" in line and "800,000 UAV-steps" in line
    assert "IPP_MAX_MISSION_STEPS" in line and " h per mission" in line
    assert not (tmp_path / "out").exists()
    config = EnvConfig().replace(world={"resolution": 1.0}, team={"budget": 200_000})
    with pytest.raises(LimitError, match="IPP_MAX_MISSION_STEPS"):
        IPPEnv(config)
    monkeypatch.setenv("IPP_MAX_MISSION_STEPS", "inf")  # the explicit way to allow it
    check_mission(config)


@pytest.mark.parametrize("flag, value", [("--resolution", "1e-300"),
                                         ("--grid-spacing", "1e-300"),
                                         ("--area-size", "1e200")])
def test_absurd_sizes_are_refused_not_overflowed(tmp_path, capsys, flag, value):
    out = tmp_path / "out"
    assert compare_main([*QUICK, flag, value, "--out", str(out)]) == 2
    assert "IPP_MAX_MISSION_GB" in _last_line(capsys)
    assert simulate_main([flag, value, "--out", str(out)] if flag == "--resolution"
                         else ["--out", str(out), "--resolution", "1e-300"]) == 2
    assert "IPP_MAX_MISSION_GB" in _last_line(capsys)
    assert train_main(["ppo", "--resolution", "1e-300", "--out", str(out)]) == 2
    assert "IPP_MAX_MISSION_GB" in _last_line(capsys)
    assert not out.exists()
    key = {"--resolution": "resolution", "--grid-spacing": "grid_spacing",
           "--area-size": "area_size"}[flag]
    config_file = tmp_path / "config.yaml"
    yaml_value = value.replace("1e", "1.0e").replace("e2", "e+2")  # YAML 1.1's float form
    config_file.write_text(f"world: {{{key}: {yaml_value}}}\nteam: {{start: random}}\n")
    assert compare_main([*QUICK, "--config", str(config_file), "--out", str(out)]) == 2
    assert "IPP_MAX_MISSION_GB" in _last_line(capsys)
    config = load_config(config_file)
    assert mission_bytes(config) == float("inf")
    with pytest.raises(LimitError, match="IPP_MAX_MISSION_GB"):
        IPPEnv(config)


def test_a_zip_member_that_inflates_past_the_limit_is_refused(tmp_path, monkeypatch):
    path = tmp_path / "model.zip"
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("data", "{}" + " " * 100_000)  # inflates 100 kB from a few hundred B
        archive.writestr("policy.pth", b"")
    monkeypatch.setenv("IPP_MAX_ZIP_MEMBER_BYTES", "50000")
    with pytest.raises(CheckpointError, match="member 'data' of SB3 zip .* is over the limit"):
        load_sb3_zip(path)
