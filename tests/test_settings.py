"""The one config builder: explicit value > config file > tool defaults > the paper's."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from coma.cli import build_parser, configs_from_args
from ipp_toolkit.config.files import load_config
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.config.settings import (
    build_env_config,
    comm_label,
    format_comm,
    parse_comm,
    safe_name,
)
from reports.cli import compare_main, simulate_main


def _yaml(tmp_path: Path, text: str, name: str = "mission.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_file_wins_over_defaults_and_flags_win_over_file(tmp_path):
    path = _yaml(tmp_path, "team: {n_agents: 8, comm_range: 0}\nterrain: {kind: blobs}\n")
    from_file = build_env_config(path)
    assert (from_file.team.n_agents, from_file.team.comm_range) == (8, 0.0)
    assert from_file.terrain.kind == "blobs"
    flagged = build_env_config(path, agents=2, comm=math.inf, terrain="split")
    assert (flagged.team.n_agents, flagged.team.comm_range) == (2, math.inf)
    assert flagged.terrain.kind == "split"
    assert build_env_config() == EnvConfig()


def test_tool_defaults_lose_to_the_file_only_where_it_writes_the_key(tmp_path):
    defaults = {"world": {"resolution": 0.5}, "features": {"own_position": True}}
    path = _yaml(tmp_path, "world: {resolution: 1.0}\n")
    config = build_env_config(path, defaults=defaults)
    assert config.world.resolution == 1.0  # the file writes it
    assert config.features.own_position  # the file is silent: the tool's default
    assert build_env_config(path, defaults=defaults, resolution=2.5).world.resolution == 2.5


def test_team_without_fixed_starts_gets_random_starts(tmp_path):
    assert build_env_config(agents=3).team.start == "random"
    assert build_env_config(_yaml(tmp_path, "team: {n_agents: 3}\n")).team.start == "random"
    # Fixed starts snap to the nearest waypoints (40 m -> 20 m in a 20 m area) ...
    assert build_env_config(agents=4, area_size=20.0, resolution=0.5).team.start == "fixed"
    # ... unless two would share one: then the default start is random.
    assert build_env_config(agents=4, area_size=10.0, resolution=0.5,
                            grid_spacing=10.0).team.start == "random"
    assert build_env_config(agents=12).features.agent_id_scale == 12
    explicit = _yaml(tmp_path, "team: {n_agents: 3, start: fixed}\n", "fixed.yaml")
    with pytest.raises(ValueError, match=r"team\.start.*fixed\.yaml"):
        build_env_config(explicit)


@pytest.mark.parametrize("text, message", [
    ("team: {n_agents: 4}\nteam: {comm_range: 0}\n", "duplicate key 'team'"),
    ("team: {n_agents: 4, n_agents: 8}\n", "duplicate key 'n_agents'"),
    ("team: {n_agent: 4}\n", "unknown key(s) ['n_agent']"),
    ("teams: {n_agents: 4}\n", "unknown section(s) ['teams']"),
    ("team: 4\n", "section 'team' must be a mapping"),
    ("team: {n_agents: -1}\n", "team.n_agents = -1"),
    ("- 1\n- 2\n", "must hold a mapping"),
])
def test_bad_config_files_name_the_bad_thing_and_the_file(tmp_path, text, message):
    path = _yaml(tmp_path, text, "bad.yaml")
    with pytest.raises(ValueError) as info:
        build_env_config(path)
    assert message in str(info.value) and "bad.yaml" in str(info.value)
    with pytest.raises(ValueError, match="bad.yaml"):
        load_config(path)


def test_threshold_with_a_synthetic_terrain_is_refused(tmp_path):
    with pytest.raises(ValueError, match="threshold 0.5 is in a raster's units.*'blobs'"):
        build_env_config(terrain="blobs", threshold=0.5)
    with pytest.raises(ValueError, match="threshold"):
        build_env_config(threshold=0.5)


def test_replace_with_a_bad_section_value_is_a_value_error():
    with pytest.raises(ValueError, match="section 'team' must be a TeamConfig"):
        EnvConfig().replace(team=5)


def test_text_forms():
    assert parse_comm("inf") == math.inf and parse_comm("25") == 25.0
    with pytest.raises(ValueError, match="--comm.*'-3'"):
        parse_comm("-3")
    with pytest.raises(ValueError, match="'x'"):
        parse_comm("x")
    assert (comm_label(math.inf), comm_label(25.0), format_comm(0.0)) == ("inf", "25", "0 m")
    assert safe_name("mine:coma=runs/x.pt") == "mine_coma_runs_x.pt"


def test_ipp_compare_honours_the_config_file(tmp_path, capsys, monkeypatch,
                                             placeholder_figures):
    monkeypatch.chdir(tmp_path)
    path = _yaml(tmp_path, "team: {n_agents: 2, comm_range: 0, budget: 2}\n"
                           "world: {resolution: 1.0}\nterrain: {kind: blobs}\n")
    assert compare_main(["--config", str(path), "--planners", "random", "--trials", "1",
                         "--workers", "1", "--no-progress"]) == 0
    captured = capsys.readouterr()
    assert "2 UAVs" in captured.err and "D = 0 m" in captured.err and "blobs" in captured.err
    folder, = (tmp_path / "results").iterdir()  # named from the file's setting
    assert folder.name.startswith("compare-a2-d0-blobs-r1-b2-")
    stored = json.loads((folder / "config.json").read_text())
    env = stored["config"]
    assert env["team"]["n_agents"] == 2 and env["team"]["comm_range"] == 0
    assert env["terrain"]["kind"] == "blobs" and env["world"]["resolution"] == 1.0


def test_ipp_compare_refuses_a_threshold_with_a_synthetic_terrain(tmp_path, capsys):
    out = tmp_path / "out"
    assert compare_main(["--terrain", "blobs", "--threshold", "3", "--out", str(out),
                         "--planners", "random"]) == 2
    assert "threshold 3.0" in capsys.readouterr().err
    assert not out.exists()


def test_ipp_train_coma_honours_the_config_file(tmp_path):
    path = _yaml(tmp_path, "world: {resolution: 1.0}\nteam: {n_agents: 2}\n")
    _, env = configs_from_args(build_parser().parse_args(["--out", "x", "--config", str(path)]))
    assert env.world.resolution == 1.0 and env.team.n_agents == 2
    assert env.features.own_position  # the trainer's default, not written by the file
    _, env = configs_from_args(build_parser().parse_args(
        ["--out", "x", "--config", str(path), "--agents", "8", "--resolution", "0.5"]))
    assert env.world.resolution == 0.5 and env.team.n_agents == 8
    _, env = configs_from_args(build_parser().parse_args(["--out", "x"]))
    assert env.world.resolution == 0.5 and env.team.n_agents == 4


def test_ipp_simulate_refuses_an_unwritable_out_before_flying(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("")
    assert simulate_main(["--out", str(blocker / "sub"), "--resolution", "1.0"]) == 2
    err = capsys.readouterr()
    assert "--out" in err.err and "sub" in err.err and "step" not in err.out


def test_ipp_simulate_writes_the_metrics_of_every_step(tmp_path, capsys):
    assert simulate_main(["--out", str(tmp_path), "--resolution", "1.0", "--agents", "2"]) == 0
    lines = (tmp_path / "metrics.csv").read_text().splitlines()
    assert lines[0] == "step,reward,entropy,f1,rmse" and len(lines) == 1 + 16
    entropy = [float(line.split(",")[2]) for line in lines[1:]]
    assert 0 < entropy[-1] < entropy[0] <= 1
    assert (tmp_path / "final.png").exists() and " 15 " in capsys.readouterr().out


def test_threshold_quantile_keyword(tmp_path):
    assert build_env_config(terrain="fractal",
                            threshold_quantile=0.8).terrain.threshold_quantile == (0.8, 0.8)
    raster = tmp_path / "r.npy"
    np.save(raster, np.arange(16.0).reshape(4, 4))
    from_file = build_env_config(terrain=str(raster), threshold_quantile=0.5)
    assert from_file.terrain.kind == "raster" and from_file.terrain.threshold is None
    with pytest.raises(ValueError, match="not both"):
        build_env_config(terrain=str(raster), threshold=3.0, threshold_quantile=0.5)


def test_ipp_compare_validation_namespace(tmp_path, capsys, monkeypatch,
                                          placeholder_figures):
    monkeypatch.chdir(tmp_path)
    argv = ["--agents", "2", "--resolution", "1.0", "--budget", "2", "--trials", "1",
            "--planners", "random", "--workers", "1", "--no-progress"]
    assert compare_main(argv + ["--namespace", "validation"]) == 0
    folder, = (tmp_path / "results").iterdir()
    assert folder.name.startswith("validate-a2-d25-r1-b2-")
    stored = json.loads((folder / "config.json").read_text())
    assert stored["namespace"] == "validation"
    assert compare_main(argv + ["--namespace", "validation", "--out", str(folder),
                                "--seed", "0"]) == 0
    assert compare_main(argv + ["--namespace", "test", "--out", str(folder)]) == 2
    assert "namespace" in capsys.readouterr().err


def test_describe_config_names_a_raster_threshold_or_its_quantile(tmp_path):
    from ipp_toolkit.config.settings import describe_config

    raster = tmp_path / "field.npy"
    np.save(raster, np.arange(16.0).reshape(4, 4))
    by_value = describe_config(build_env_config(terrain=str(raster), threshold=3.0))
    by_quantile = describe_config(build_env_config(terrain=str(raster), threshold_quantile=0.5))
    assert "raster field.npy >= 3" in by_value
    assert "raster field.npy >= quantile 0.5" in by_quantile


def test_ipp_compare_runs_a_raster_thresholded_at_a_quantile(tmp_path, capsys,
                                                            placeholder_figures):
    raster = tmp_path / "field.npy"
    np.save(raster, np.arange(400.0).reshape(20, 20))
    assert compare_main(["--terrain", str(raster), "--threshold-quantile", "0.6", "--agents",
                         "2", "--resolution", "1.0", "--budget", "2", "--trials", "1",
                         "--planners", "random", "--workers", "1", "--no-progress",
                         "--out", str(tmp_path / "out")]) == 0
    assert "quantile 0.6" in capsys.readouterr().err


def test_feature_flags_are_typed_by_the_feature_config():
    from ipp_toolkit.config.settings import parse_feature_flags

    parsed = parse_feature_flags(["gain=true", "own_position=off", "gain_smoothing=5",
                                  "agent_id_scale=8"])
    assert parsed == {"gain": True, "own_position": False, "gain_smoothing": 5.0,
                      "agent_id_scale": 8}
    config = build_env_config(features=parsed)
    assert config.features.gain and config.features.gain_smoothing == 5.0
    for bad, named in (("gain=maybe", "gain"), ("gain_smoothing=wide", "gain_smoothing"),
                       ("colour=true", "colour"), ("gain", "gain")):
        with pytest.raises(ValueError, match=named):
            parse_feature_flags([bad])


def test_paper_preset_trains_on_the_papers_inputs():
    _, env = configs_from_args(build_parser().parse_args(["--out", "x", "--preset", "paper"]))
    assert not env.features.own_position and not env.features.gain
    _, env = configs_from_args(build_parser().parse_args(
        ["--out", "x", "--preset", "paper", "--feature", "own_position=true"]))
    assert env.features.own_position  # an explicit flag still wins
