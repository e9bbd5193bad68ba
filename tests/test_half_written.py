"""Input that only fails when the first mission flies leaves no half-written folder, and
temporary files of a run killed mid-write are removed by the next run into the folder."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from reports.cli import compare_main

QUICK = ["--no-progress", "--trials", "1", "--agents", "2", "--budget", "2"]


def _raster_config(tmp_path, text: str) -> list[str]:
    config = tmp_path / "config.yaml"
    config.write_text(text)
    return ["--config", str(config), "--planners", "random"]


@pytest.mark.parametrize("case, message", [
    ("missing-raster", "No such file"),
    ("tiny-raster-quantile", "no interesting cell"),
    ("grid-too-coarse", "too coarse"),
    ("long-label", "characters long"),
    ("undecodable-label", "not valid UTF-8"),
])
def test_input_failing_on_the_first_mission_writes_nothing(tmp_path, capsys, case, message):
    if case == "missing-raster":
        flags = _raster_config(tmp_path, "terrain: {kind: raster, raster: "
                               f"{tmp_path / 'gone.npy'}, threshold: 1.0}}\n")
    elif case == "tiny-raster-quantile":
        np.save(tmp_path / "one.npy", np.ones((1, 1)))
        flags = ["--terrain", str(tmp_path / "one.npy"), "--threshold-quantile", "0.5",
                 "--planners", "random", "--resolution", "1"]
    elif case == "grid-too-coarse":
        flags = ["--area-size", "10", "--grid-spacing", "5", "--resolution", "5",
                 "--planners", "random"]
    elif case == "long-label":
        flags = ["--planners", "x" * 300 + ":random", "--resolution", "1"]
    else:
        flags = ["--planners", "bad\udcff:random", "--resolution", "1"]
    out = tmp_path / "out"
    assert compare_main([*QUICK, *flags, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and message in err.splitlines()[-1], err
    assert not out.exists()


def test_temporary_files_of_a_killed_run_are_removed_by_the_next(tmp_path, capsys,
                                                                 placeholder_figures):
    out = tmp_path / "out"
    argv = [*QUICK, "--planners", "random", "--resolution", "1", "--out", str(out)]
    assert compare_main(argv) == 0
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()  # a PID that no longer runs: the writer of the files below was killed
    stale = [out / f".curves.png.ipptk-{dead.pid}-0a1b2c3d.tmp",
             out / "trajectories" / f".random_mission0.png.ipptk-{dead.pid}-12345678.tmp",
             out / "shards" / "random" / f".mission_00000.json.ipptk-{dead.pid}-deadbeef.tmp"]
    # Not the toolkit's (another program's, or a running writer's): never touched.
    kept = [out / ".curves.png.4242.0a1b2c3d.tmp", out / "shards" / ".editor.swp.tmp",
            out / f".curves.png.ipptk-{os.getpid()}-0a1b2c3d.tmp"]
    for path in stale + kept:
        path.write_bytes(b"half")
    assert compare_main(argv) == 0
    capsys.readouterr()
    assert not any(path.exists() for path in stale)
    assert all(path.read_bytes() == b"half" for path in kept)
    assert (out / "curves.png").is_file()
