"""Tests of the ``ipp-compare`` console script (``reports.cli.compare_main``)."""

from __future__ import annotations

import hashlib
import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from ipp_toolkit.config.settings import named_terrain_kinds
from ipp_toolkit.planning import available_planners
from reports import compare_planners
from reports.cli import compare_main

FLAGS = ("--agents", "--comm", "--planners", "--trials", "--seed", "--terrain", "--threshold",
         "--workers", "--out", "--config", "--resolution", "--budget", "--area-size",
         "--no-progress")
TINY = ["--agents", "2", "--trials", "2", "--resolution", "0.5", "--budget", "3",
        "--planners", "random,coverage", "--workers", "1", "--no-progress"]


def _have(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


needs_evaluation = pytest.mark.skipif(not _have("ipp_toolkit.runs.evaluation"),
                                      reason="ipp_toolkit.runs.evaluation is not written yet")
needs_baselines = pytest.mark.skipif(
    not (_have("baselines.heuristics.random_planner") and _have("baselines.heuristics.coverage")),
    reason="the baseline planners random and coverage are not written yet")


def snapshot(folder: Path) -> dict[str, str]:
    """Content hash of every file under ``folder``."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_help_lists_every_flag_with_its_default(capsys):
    assert compare_main(["--help"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("usage: ipp-compare")
    for flag in FLAGS:
        assert flag in text, flag
    for default in ("file's, else 4", "file's, else 25", "(default: default)", "(default: 50)",
                    "(default: 0)", "file's, else split",
                    "(default: results/compare-aN-dD for the paper's configuration"):
        assert default in " ".join(text.split()), default
    # No meaningless defaults: an unset option or a switch says nothing.
    assert "(default: None)" not in text and "(default: False)" not in text


def _fails(capsys, argv: list[str], message: str) -> str:
    assert compare_main(argv) == 2
    err = capsys.readouterr().err
    assert "ipp-compare: error: " in err and message in err, err
    return err


@pytest.mark.parametrize(("argv", "message"), [
    (["--agents", "0"], "argument --agents: must be an integer >= 1, got '0'"),
    (["--agents", "two"], "argument --agents: must be an integer >= 1, got 'two'"),
    (["--trials", "0"], "argument --trials: must be an integer >= 1, got '0'"),
    (["--comm", "-3"], "--comm must be >= 0"),
    (["--workers", "0"], "argument --workers"),
    (["--resolution", "0"], "argument --resolution: must be a positive number"),
    (["--bogus"], "unrecognized arguments: --bogus"),
])
def test_bad_flags_exit_2(capsys, tmp_path, argv, message):
    out = tmp_path / "out"
    _fails(capsys, argv + ["--out", str(out)], message)
    assert not out.exists()


def test_bad_terrain_exits_2_and_writes_nothing(capsys, tmp_path):
    out = tmp_path / "out"
    _fails(capsys, ["--terrain", str(tmp_path / "missing.tif"), "--threshold", "0.5",
                    "--out", str(out)], "cannot read terrain file")
    _fails(capsys, ["--terrain", "splt", "--out", str(out)],
           f"terrain is one of {', '.join(named_terrain_kinds())} or a raster FILE")
    raster = tmp_path / "field.npy"
    np.save(raster, np.zeros((10, 10)))
    _fails(capsys, ["--terrain", str(raster), "--out", str(out)], "needs a threshold")
    garbage = tmp_path / "garbage.tif"
    garbage.write_bytes(b"not a tiff")
    _fails(capsys, ["--terrain", str(garbage), "--threshold", "1", "--out", str(out)],
           "cannot read raster file")
    unreadable = tmp_path / "folder.tif"
    unreadable.mkdir()
    _fails(capsys, ["--terrain", str(unreadable), "--threshold", "1", "--out", str(out)],
           "not a file")
    _fails(capsys, ["--config", str(tmp_path / "nope.yaml"), "--out", str(out)],
           "cannot read config file")
    assert not out.exists()


def test_default_planners_skip_the_unbuildable(monkeypatch, capsys):
    module = sys.modules["reports.compare"]

    def fake_make(name, **options):
        if name == "coma":
            raise FileNotFoundError("no checkpoint at runs/coma/latest.pt")
        if name == "ppo":
            raise ValueError("ppo needs a checkpoint")
        return object()

    monkeypatch.setattr(module, "available_planners", lambda: ["coma", "ig", "ppo", "random"])
    monkeypatch.setattr(module, "make_planner", fake_make)
    assert module.default_planners() == ["ig", "random"]
    err = capsys.readouterr().err
    assert "skipping planner 'coma'" in err and "no checkpoint" in err
    assert "skipping planner 'ppo'" in err


@needs_evaluation
def test_unknown_planner_exits_2_and_lists_registered(capsys, tmp_path):
    out = tmp_path / "out"
    err = _fails(capsys, ["--planners", "random,astar", "--out", str(out)],
                 "unknown planner 'astar'; registered planners: ")
    for name in available_planners():
        assert name in err
    assert not out.exists()


@needs_evaluation
def test_an_unknown_planner_is_refused_before_workers_start_listing_this_process_planners(
        capsys, tmp_path, monkeypatch):
    import ipp_toolkit.planning as planners_module
    from ipp_toolkit.runs import process_pool

    def no_pool(*args, **kwargs):
        raise AssertionError("a worker pool was started for a run that is refused")

    # Registered by decorator in this process only: a spawned worker would not list it.
    monkeypatch.setitem(planners_module._REGISTRY, "only-in-this-process", object)
    monkeypatch.setattr(process_pool.WorkerPool, "__init__", no_pool)
    out = tmp_path / "out"
    err = _fails(capsys, ["--planners", "random,astar", "--workers", "2", "--out", str(out)],
                 "unknown planner 'astar'; registered planners: ")
    assert "only-in-this-process" in err
    assert not out.exists()


@needs_evaluation
@needs_baselines
def test_end_to_end_writes_everything_and_refuses_another_config(capsys, tmp_path,
                                                                 monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert compare_main(TINY) == 0
    printed = capsys.readouterr().out
    # The default --out: another resolution and budget than the paper's are in its name.
    out, = (tmp_path / "results").iterdir()
    assert out.name.startswith("compare-a2-d25-r0.5-b3-")
    for name in ("summary.md", "summary.csv", "summary.tex", "curves.png", "curves.pdf",
                 "results.csv", "config.json", "trajectories/random_mission0.png",
                 "trajectories/random_mission0.pdf", "trajectories/coverage_mission0.png",
                 "trajectories/coverage_mission0.pdf"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    table = (out / "summary.md").read_text(encoding="utf-8")
    assert table in printed
    assert "| random |" in table and "| coverage |" in table
    assert "2 missions" in table and "2 UAVs" in table and "D = 25 m" in table
    assert "Entropy 33 % (s=1)" in table and "F1 100 % (s=3)" in table
    assert "Planning time per step:" in printed and " ms" in printed

    before = snapshot(out)
    argv = [*TINY, "--out", str(out)]
    budget = argv.index("--budget") + 1
    argv[budget] = "4"
    _fails(capsys, argv, "")  # another configuration into the same folder
    assert snapshot(out) == before

    # The same configuration again resumes from the stored results.
    assert compare_main([*TINY, "--out", str(out)]) == 0
    assert (out / "summary.md").read_text(encoding="utf-8") == table


def test_compare_is_exported():
    import reports

    assert reports.compare_planners is compare_planners and callable(compare_planners)
    assert {"compare_planners", "summarise", "plot_curves",
            "plot_trajectories"} <= set(reports.__all__)


def test_reports_compare_is_the_module_and_the_earlier_spelling_still_runs(monkeypatch):
    import types

    import reports

    module = importlib.import_module("reports.compare")
    assert isinstance(module, types.ModuleType) and reports.compare is module
    assert module.compare is compare_planners  # from reports.compare import compare
    # from reports import compare; compare(...): the module forwards the call, with a warning.
    monkeypatch.setattr(reports, "compare_planners", lambda *args, **kwargs: (args, kwargs))
    with pytest.warns(FutureWarning, match="use reports.compare_planners"):
        assert reports.compare(trials=2) == ((), {"trials": 2})


@needs_evaluation
@needs_baselines
def test_raster_terrain_file_end_to_end(capsys, tmp_path, placeholder_figures):
    raster = tmp_path / "field.npy"
    values = np.zeros((20, 20))
    values[:, :8] = 1.0
    np.save(raster, values)
    out = tmp_path / "raster"
    argv = ["--agents", "3", "--trials", "1", "--resolution", "0.5", "--budget", "2",
            "--planners", "random", "--workers", "1", "--no-progress", "--terrain", str(raster),
            "--threshold", "0.5", "--out", str(out)]
    assert compare_main(argv) == 0
    assert "terrain field.npy" in capsys.readouterr().out  # evaluate names it by file
    assert (out / "trajectories" / "random_mission0.png").is_file()


@needs_evaluation
def test_compare_records_checkpoints_and_the_paired_column(tmp_path, capsys,
                                                           placeholder_figures):
    from coma.persistence import DEFAULT_SHIPPED, resolve_policy

    out = tmp_path / "out"
    argv = ["--agents", "4", "--trials", "2", "--resolution", "1.0", "--budget", "2",
            "--planners", "ig,random,coma", "--workers", "1", "--no-progress", "--out", str(out)]
    assert compare_main(argv) == 0
    stored = json.loads((out / "config.json").read_text())
    shipped = resolve_policy(f"shipped:{DEFAULT_SHIPPED}")
    digest = hashlib.sha256(shipped.read_bytes()).hexdigest()
    assert stored["checkpoints"]["coma"] == {"checkpoint": shipped.name, "sha256": digest}
    assert "ig" not in stored["checkpoints"]
    summary = (out / "summary.md").read_text()
    assert "Δ vs ig" in summary and f"sha256:{digest[:16]}" in summary
    header = (out / "summary.csv").read_text().splitlines()[0]
    assert "entropy_final_minus_ig_se" in header and "win_rate_vs_ig" in header
    # Weights that changed under a stored label are refused before anything is written.
    stored["checkpoints"]["coma"]["sha256"] = "0" * 64
    (out / "config.json").write_text(json.dumps(stored))
    before = snapshot(out)
    assert compare_main(argv) == 2
    assert "changed since its missions were stored" in capsys.readouterr().err
    assert snapshot(out) == before


def test_the_papers_real_world_protocol_runs_with_the_shipped_policies(tmp_path, capsys,
                                                                       placeholder_figures):
    # The paper's field: 40 m x 40 m, waypoints every 4 m (11 x 11, the policies' grid),
    # altitudes 5/10/15 m, a temperature raster thresholded at 25 deg C. Coarser cells and a
    # short budget keep it quick; the command is the documented one otherwise.
    y, x = np.mgrid[0:80, 0:80] / 80.0
    raster = tmp_path / "temperature.npy"
    np.save(raster, (20.0 + 8.0 * np.sin(3 * x + 1) * np.cos(2 * y)).astype(np.float32))
    out = tmp_path / "field"
    argv = ["--area-size", "40", "--resolution", "0.8", "--grid-spacing", "4",
            "--terrain", str(raster), "--threshold", "25", "--planners", "ig,coma,ppo",
            "--trials", "1", "--budget", "2", "--workers", "1", "--no-progress",
            "--out", str(out)]
    assert compare_main(argv) == 0
    assert "waypoints every 4 m" in capsys.readouterr().err
    stored = json.loads((out / "config.json").read_text())
    assert stored["config"]["world"]["grid_spacing"] == 4.0
    trajectory = np.load(out / "trajectories" / "coma_mission0.npz")
    # Fixed starts snap to the nearest waypoints: (10, 10) m -> (12, 12) m, 40 m stays.
    assert trajectory["positions"][0, :, :2].tolist() == [[12, 12], [40, 12], [40, 40],
                                                          [12, 40]]


def test_a_policy_for_another_grid_is_refused_before_anything_is_written(tmp_path, capsys):
    out = tmp_path / "small"
    argv = ["--planners", "ig,coma", "--area-size", "40", "--trials", "1", "--no-progress",
            "--out", str(out)]
    assert compare_main(argv) == 2
    err = capsys.readouterr().err
    assert "'coma'" in err and "11-waypoint grid, requested 9" in err
    assert not out.exists()


def test_the_console_scripts_leave_matplotlib_to_the_figures():
    # ipp-compare's evaluation workers are spawned and import the console script's module:
    # they never draw, so importing it must not import matplotlib (about 0.6 s each).
    import subprocess
    import sys

    code = ("import sys, reports.cli; print('matplotlib' in sys.modules); "
            "from reports import plot_curves; print('matplotlib' in sys.modules, "
            "plot_curves.__module__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=300).stdout.split()
    assert out == ["False", "True", "reports.plots"]

