"""A training run on a raster file records the file's sha256 in its folder, and ``--resume``
refuses to go on once the file was replaced, naming the file and both digests (the missions
would no longer be those the run trained on). The raster is a tiny one made here."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest

from reports.cli import train_main


def _write_raster(path, turned: bool = False) -> str:
    """An 8 x 8 field, half of it interesting (turned: the other content under the same name);
    returns its sha256."""
    field = np.zeros((8, 8))
    field[:, 4:] = 1.0
    np.save(path, field[::-1].T if turned else field)
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def raster_run(tmp_path):
    """(raster file, its sha256, YAML config of a raster terrain, run folder)."""
    raster = tmp_path / "field.npy"
    digest = _write_raster(raster)
    config = tmp_path / "raster.yaml"
    config.write_text(f"terrain: {{kind: raster, raster: '{raster}', threshold: 0.5}}\n")
    return raster, digest, config, tmp_path / "run"


def _refused_after_the_file_changed(argv, raster, before, capsys) -> None:
    after = _write_raster(raster, turned=True)
    assert after != before
    capsys.readouterr()
    assert train_main([*argv, "--resume"]) == 2
    err = capsys.readouterr().err
    line = err.strip().splitlines()[-1]
    assert "Traceback" not in err and ": error: " in line
    assert f"raster file {str(raster)!r}" in line and before in line and after in line


def test_a_coma_run_records_its_raster_and_resumes_only_on_the_same_content(raster_run,
                                                                           capsys):
    raster, digest, config, out = raster_run
    argv = ["coma", "--config", str(config), "--out", str(out), "--missions", "2",
            "--agents", "2", "--resolution", "1.0", "--no-progress", "--set", "width=8",
            "--set", "hidden=16", "--set", "missions_per_update=2", "--set", "eval_missions=1",
            "--set", "minibatch_size=60", "--warm-start", "none"]
    assert train_main(argv) == 0
    assert json.loads((out / "config.json").read_text())["raster_sha256"] == digest
    _refused_after_the_file_changed(argv, raster, digest, capsys)


@pytest.mark.parametrize("trainer", [
    ["ppo", "--n-steps", "16", "--batch-size", "32", "--set", "n_epochs=1"],
    ["sb3", "--algo", "A2C"],
], ids=["ppo", "sb3"])
def test_an_sb3_run_records_its_raster_and_resumes_only_on_the_same_content(raster_run,
                                                                           capsys, trainer):
    raster, digest, config, out = raster_run
    argv = [*trainer, "--config", str(config), "--out", str(out), "--timesteps", "64",
            "--n-envs", "1", "--checkpoint-every", "64", "--agents", "2", "--resolution", "1",
            "--no-progress"]
    assert train_main(argv) == 0
    for record in ("checkpoint.json", "policy.json"):
        assert json.loads((out / record).read_text())["raster_sha256"] == digest
    assert train_main([*argv, "--resume"]) == 0  # the same content: it goes on
    _refused_after_the_file_changed(argv, raster, digest, capsys)


def test_a_prior_run_records_its_raster_and_resumes_only_on_the_same_content(raster_run,
                                                                            capsys):
    raster, digest, config, out = raster_run
    argv = ["prior", "--config", str(config), "--out", str(out), "--rounds", "1",
            "--missions", "1", "--validation-missions", "1", "--epochs", "1", "--width", "2",
            "--resolution", "1", "--team-sizes", "2", "--comm-ranges", "25", "--no-progress"]
    assert train_main(argv) == 0
    assert json.loads((out / "config.json").read_text())["raster_sha256"] == digest
    assert train_main([*argv, "--resume"]) == 0  # the same content: it goes on
    _refused_after_the_file_changed(argv, raster, digest, capsys)
