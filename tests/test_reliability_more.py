"""More hostile inputs refused before anything is written: unknown study families, a raster
file replaced between runs into one folder, a hand-edited result shard, an inconsistent
COMA update counter on resume, terrain lattices too fine or too coarse, thin rasters."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.runs.evaluation import evaluate
from reports.cli import compare_main, study_main


@pytest.mark.parametrize("flag", ["--families", "--team-families"])
def test_an_unknown_study_family_is_refused_before_anything_flies(tmp_path, capsys, flag):
    out = tmp_path / "study"
    argv = ["generalisation", "--planners", "ig,random", "--trials", "1", "--agents", "2",
            "--comm", "0", "--families", "split", "--team-families", "split",
            "--out", str(out), "--no-progress"]
    argv[argv.index(flag) + 1] = "split,nope"
    assert study_main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert f"{flag}: unknown terrain kind 'nope'" in err and "blobs" in err
    assert not out.exists()


def test_a_raster_file_replaced_between_two_runs_into_one_folder_is_refused(tmp_path,
                                                                            capsys):
    raster, out = tmp_path / "field.npy", tmp_path / "out"
    argv = ["--terrain", str(raster), "--threshold", "0.5", "--planners", "random",
            "--trials", "1", "--agents", "2", "--budget", "2", "--resolution", "2",
            "--out", str(out), "--no-progress"]
    field = np.zeros((8, 8))
    field[:, 4:] = 1.0
    np.save(raster, field)
    assert compare_main(argv) == 0
    assert compare_main(argv) == 0  # the same content: its missions are reused
    np.save(raster, field[::-1].T)  # another content under the same name
    capsys.readouterr()
    assert compare_main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and str(raster) in err and "another content" in err


def test_a_hand_edited_shard_is_warned_about_and_flown_again(tmp_path):
    config = EnvConfig().replace(world={"resolution": 1.0}, team={"n_agents": 2, "budget": 2})
    out = tmp_path / "out"
    first = evaluate(config, ["random"], missions=2, seed=3, progress=False, out_dir=out)
    shard = out / "shards" / "random" / "mission_00001.json"
    data = json.loads(shard.read_text())
    flown = data["rows"][2]["entropy"]
    data["rows"][2]["entropy"] = flown / 2  # finite, plausible, and not what was flown
    shard.write_text(json.dumps(data))
    with pytest.warns(UserWarning, match="checksum does not match its content"):
        result = evaluate(config, ["random"], missions=2, seed=3, progress=False, out_dir=out)
    assert [r["entropy"] for r in result.rows] == [r["entropy"] for r in first.rows]
    assert json.loads(shard.read_text())["rows"][2]["entropy"] == flown


@pytest.mark.parametrize("counters, shown", [
    ({"update": 10**9, "missions": 2 * 10**9}, "update = 1000000000"),
    ({"update": -1, "missions": -2}, "update = -1"),
    ({"update": 1.5, "missions": 3}, "update = 1.5"),
    ({"update": 1, "missions": 3}, "missions = 3"),
    ({"update": 3, "missions": 6}, "update = 3 and missions = 6"),
])
def test_a_resumed_coma_checkpoint_with_inconsistent_counters_is_refused(tmp_path, counters,
                                                                        shown):
    import torch
    from helpers import tiny_coma, tiny_env

    from coma.learner import train
    from ipp_toolkit.io import CheckpointError

    out = tmp_path / "run"
    train(tiny_coma(), tiny_env(), out, progress=False, tensorboard=False, max_updates=1)
    data = torch.load(out / "last.pt", weights_only=True)
    data["progress"].update(counters)
    torch.save(data, out / "last.pt")
    with pytest.raises(CheckpointError, match=re.escape(shown)):
        train(tiny_coma(), tiny_env(), out, resume=True, progress=False, tensorboard=False)


@pytest.mark.parametrize("kind", ["blobs", "mixture"])
@pytest.mark.parametrize("scale", [1e-6, 0.002, 1e6, 1e300])
def test_a_blob_scale_whose_lattice_is_too_fine_or_too_coarse_is_refused(kind, scale):
    with pytest.raises(ValueError, match=re.escape(f"terrain.blob_scale = {scale!r}")) as err:
        EnvConfig().replace(terrain={"kind": kind, "blob_scale": scale})
    assert "choose one in [0.0124, 806] m for this 50 m area" in str(err.value)


def test_the_allowed_blob_scales_are_accepted_and_named_by_the_cli(tmp_path, capsys):
    from ipp_toolkit.config.terrain_checks import blob_scale_range

    for area in (10.0, 50.0, 1000.0):
        low, high = blob_scale_range(area)
        for scale in (low, high):
            EnvConfig().replace(world={"area_size": area}, team={"start": "random"},
                                terrain={"kind": "blobs", "blob_scale": scale})
    EnvConfig().replace(terrain={"kind": "split", "blob_scale": 1e-6})  # blobs not drawn
    config = tmp_path / "config.yaml"
    config.write_text("terrain: {kind: blobs, blob_scale: 1.0e-6}\n")
    out = tmp_path / "out"
    assert compare_main(["--config", str(config), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "terrain.blob_scale = 1e-06" in err
    assert not out.exists()


def _refused_thin_raster(tmp_path, capsys, shape, extra=()):
    raster, out = tmp_path / "thin.npy", tmp_path / "out"
    thin = np.zeros(shape, dtype=bool)
    thin.flat[: thin.size // 2] = True
    np.save(raster, thin)
    argv = ["--terrain", str(raster), "--threshold", "0.5", "--planners", "random",
            "--trials", "1", "--out", str(out), "--no-progress", *extra]
    assert compare_main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and str(raster) in err
    assert "IPP_MAX_RESAMPLE_WEIGHTS" in err and " x ".join(map(str, shape)) in err
    assert not out.exists()


def test_a_thin_raster_is_bounded_by_its_resampling(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("IPP_MAX_RESAMPLE_WEIGHTS", "10000")
    _refused_thin_raster(tmp_path, capsys, (1, 5000), ["--resolution", "2"])


@pytest.mark.parametrize("shape", [(1, 10_000_000), (3_000_000, 1)])
def test_a_raster_of_one_row_or_column_is_refused_before_its_resampling(tmp_path, capsys,
                                                                        shape):
    _refused_thin_raster(tmp_path, capsys, shape)
