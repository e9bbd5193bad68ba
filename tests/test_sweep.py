"""``ipp-study sweep`` (reports/sweep.py): the grid's checks, the table, and tiny sweeps.

The argument checks run before anything is written or trained; the end-to-end sweeps use the
smallest COMA training of the study tests (tests/test_studies.py) and are marked slow.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from ipp_toolkit.config.files import config_to_dict
from reports.cli import study_main
from reports.studies import training_mission
from reports.sweep import (
    DIVERGED,
    GridPoint,
    SweepRun,
    _finished,
    parse_assignments,
    parse_sweep,
    sweep_grid,
    sweep_study,
    sweep_table,
)

#: The smallest COMA training of the study tests, as --set items and as fields.
TINY_SET = ["--set", "width=8", "--set", "hidden=16", "--set", "missions_per_update=2",
            "--set", "minibatch_size=60", "--set", "eval_missions=1", "--set", "warm_start="]
TINY = {"width": 8, "hidden": 16, "missions_per_update": 2, "minibatch_size": 60,
        "eval_missions": 1, "warm_start": ""}
TINY_RUN = ["--missions", "2", "--train-resolution", "1", "--resolution", "1", "--trials", "2",
            "--no-progress", *TINY_SET]


def never_train(task):
    raise AssertionError(f"run {task[0]!r} was trained")


# --------------------------------------------------------------------------------------------
# Argument checks: exit 2, one line naming the bad field or value, nothing written


@pytest.mark.parametrize(("argv", "message"), [
    (["--sweep", "lr_actr=1e-4,3e-4"], "--sweep lr_actr=1e-4: invalid COMA config: unknown "
                                       "key(s) ['lr_actr']"),
    (["--sweep", "lr_actor=1e-4,fast"], "--sweep lr_actor=fast: invalid COMA config: lr_actor "
                                        "= 'fast': must be a positive finite number"),
    (["--sweep", "clip_ratio=0.1,-1"], "clip_ratio = -1"),
    (["--sweep", "lr_actor=1e-4", "--sweep", "lr_actor=3e-4"], "--sweep gives lr_actor twice"),
    (["--sweep", "warm_start_missions=10", "--sweep", "warm_start.missions=20"],
     "--sweep gives warm_start.missions twice"),  # the older flat name is the same field
    (["--sweep", "lr_actor=1e-4,0.0001"], "the values '1e-4' and '0.0001' give the same run"),
    (["--sweep", "lr_actor=1e-4", "--set", "lr_actor=3e-4"], "lr_actor is both swept"),
    (["--sweep", "lr_actor=1e-4", "--set", "width=8", "--set", "width=16"],
     "--set gives width twice"),
    (["--sweep", "lr_actor=1e-4", "--seeds", "0,1", "--seeds", "2"],
     "--seeds is given 2 times (0,1 and 2)"),
    (["--sweep", "lr_actor=1e-4", "--seeds", "0,0"], "distinct non-negative integers, got [0, 0]"),
    (["--sweep", "seed=0,1"], "given with --seeds"),
    (["--sweep", "lr_actor=1e-4", "--set", "seed=3"], "given with --seeds"),
    (["--sweep", "lr_actor=1e-4", "--seeds", "0,1", "--seed", "1"],
     "the validation missions of seed 1 are those the seed-1 runs select their best.pt on"),
    (["--sweep", "missions=2,4", "--missions", "3"], "missions is given by --missions and by"),
    (["--sweep", "lr_actor"], "--sweep expects FIELD=VALUE, got 'lr_actor'"),
    (["--sweep", "lr_actor="], "no values"),
    (["--sweep", "team_sizes=2+x"], "'x' is not an integer >= 1"),
    (["--sweep", "warm_start.planner=nosuch"], "grid point warm_start.planner=nosuch: unknown "
                                               "planner 'nosuch'"),
    (["--sweep", "lr_actor=1e-4", "--agents", "2,4"], "--agents takes one value"),
    ([], "needs at least one --sweep"),
    (["--sweep", "lr_actor=1e-4", "--address", "127.0.0.1:6379"], "--address needs --backend"),
])
def test_bad_sweep_arguments_are_refused_before_anything_is_written(tmp_path, capsys, argv,
                                                                    message):
    out = tmp_path / "out"
    assert study_main(["sweep", "--out", str(out), "--no-progress", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("ipp-study: error: ")
    assert message in err
    assert not out.exists()


def test_sweep_is_only_for_the_sweep_study(tmp_path, capsys):
    assert study_main(["credit", "--sweep", "lr_actor=1e-4", "--out", str(tmp_path / "x")]) == 2
    assert "--sweep is for ipp-study sweep, not credit" in capsys.readouterr().err
    assert study_main(["credit", "--seeds", "0", "--seeds", "1", "--out",
                       str(tmp_path / "x")]) == 2
    assert "--seeds is given 2 times" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_the_grid_is_the_product_of_the_swept_values_read_as_ipp_train_reads_them():
    sweep = parse_sweep(["lr_actor=1e-4,3e-4", "warm_start_missions=10,20",
                         "comm_ranges=0+inf,25"])
    assert list(sweep) == ["lr_actor", "warm_start.missions", "comm_ranges"]
    assert sweep["lr_actor"] == [("1e-4", 1e-4), ("3e-4", 3e-4)]
    assert sweep["comm_ranges"] == [("0+inf", [0, math.inf]), ("25", [25])]
    grid = sweep_grid(sweep, parse_assignments(["width=8", "normalise_advantage=false"]),
                      [0, 1], 100)
    assert len(grid) == 8
    point, config = grid[1]  # the last field varies fastest
    assert point.label == "lr_actor=0.0001,warm_start.missions=10,comm_ranges=25"
    assert point.folder == "lr_actor-0.0001_warm_start.missions-10_comm_ranges-25"
    assert (config.lr_actor, config.warm_start.missions, config.comm_ranges) == (1e-4, 10, (25,))
    assert (config.width, config.normalise_advantage, config.missions) == (8, False, 100)
    assert grid[0][0].label.endswith("comm_ranges=0+inf")
    assert len({p.folder for p, _ in grid}) == 8
    with pytest.raises(ValueError, match="--set: invalid COMA config: width = 0"):
        sweep_grid(sweep, {"width": 0}, [0], 100)


def test_the_table_gives_mean_and_spread_over_seeds_and_bolds_the_best_point(tmp_path):
    a, b, c = (GridPoint((("lr_actor", v),)) for v in (1e-4, 3e-4, 1e-3))
    runs = [SweepRun(a, 0, tmp_path, entropy=0.40, gap=0.02),
            SweepRun(a, 1, tmp_path, entropy=0.50, gap=0.04),
            SweepRun(b, 0, tmp_path, entropy=0.30, gap=-0.08),
            SweepRun(b, 1, tmp_path, entropy=0.36, gap=-0.02, diverged=True),
            SweepRun(c, 0, tmp_path), SweepRun(c, 1, tmp_path, diverged=True)]
    table = sweep_table(runs, [a, b, c])
    lines = table.splitlines()
    assert lines[0] == ("| lr_actor | seeds | final entropy | gap to IG | "
                        "per seed: entropy (gap) |")
    spread = np.std([0.40, 0.50], ddof=1)
    assert lines[2] == (f"| 0.0001 | 2 | 0.450 ± {spread:.3f} | +0.030 ± "
                        f"{np.std([0.02, 0.04], ddof=1):.3f} | s0 0.400 (+0.020); "
                        "s1 0.500 (+0.040) |")
    assert lines[3].startswith(f"| 0.0003 | 2 | **0.330 ± {np.std([0.3, 0.36], ddof=1):.3f}** "
                               "| **-0.050 ± ")
    assert lines[3].endswith("s0 0.300 (-0.080); s1 0.360 (-0.020)† |")
    assert lines[4] == "| 0.001 | 0 | - | - | s0 no policy; s1 no policy† |"
    assert table.count("**") == 4


def _fake_run(folder: Path, config, updates: int) -> None:
    """A run folder as training leaves it, without weights: config.json, progress.csv and an
    empty last.pt."""
    folder.mkdir(parents=True)
    env = config_to_dict(training_mission(1.0))
    (folder / "config.json").write_text(json.dumps({"coma": config.to_dict(), "env": env}))
    rows = "update,missions\n" + "".join(f"{k},{2 * k}\n" for k in range(1, updates + 1))
    (folder / "progress.csv").write_text(rows)
    (folder / "last.pt").write_bytes(b"")


def test_finished_and_diverged_runs_are_not_trained_and_other_runs_are_refused(
        tmp_path, monkeypatch):
    import reports.sweep
    from coma.config import preset
    from coma.learner import TrainingDiverged

    trained = []

    def diverges(task):
        trained.append(task[0])
        raise TrainingDiverged("loss is nan")

    monkeypatch.setattr(reports.sweep, "train_run", diverges)
    kwargs = dict(seeds=[2], overrides=TINY, missions=4, train_resolution=1.0, trials=1,
                  eval_resolution=1.0, out=tmp_path, progress=False)
    finished = preset("cpu", **TINY, missions=4, lr_actor=1e-4, seed=2)
    _fake_run(tmp_path / "runs" / "lr_actor-0.0001" / "s2", finished, updates=2)
    # lr_actor = 1e-4 is finished (2 updates of 2 missions, no best.pt: nothing to score);
    # lr_actor = 1 diverges: noted in its folder, the sweep goes on.
    study = sweep_study(["lr_actor=1e-4,1"], **kwargs)
    assert trained == ["lr_actor=1@s2"]
    diverged = tmp_path / "runs" / "lr_actor-1" / "s2"
    assert json.loads((diverged / DIVERGED).read_text()) == {"error": "loss is nan"}
    assert _finished(diverged, finished.replace(lr_actor=1))  # a rerun does not train it
    assert [(r.label, r.diverged, math.isnan(r.entropy)) for r in study.runs] == [
        ("lr_actor=0.0001@s2", False, True), ("lr_actor=1@s2", True, True)]
    assert "| 0.0001 | 0 | - | - | s2 no policy |" in study.table
    assert "| 1 | 0 | - | - | s2 no policy† |" in study.table and study.best is None
    with open(tmp_path / "sweep.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [(r["point"], r["seed"], r["run"], r["diverged"]) for r in rows] == [
        ("lr_actor=0.0001", "2", "runs/lr_actor-0.0001/s2", "false"),
        ("lr_actor=1", "2", "runs/lr_actor-1/s2", "true")]
    assert float(rows[0]["ig_final_entropy"]) == pytest.approx(study.ig_entropy)
    assert (tmp_path / "validation" / "shards" / "ig").is_dir()
    # More missions than the folder's run, or other settings: refused by name, untrained.
    with pytest.raises(ValueError, match=r"lr_actor-0.0001/s2' holds a run with missions = 4, "
                                         r"this sweep asks for 6"):
        sweep_study(["lr_actor=1e-4"], run=never_train, **{**kwargs, "missions": 6})
    with pytest.raises(ValueError, match="holds a run with width = 8, this sweep asks for 16"):
        sweep_study(["lr_actor=1e-4"], run=never_train,
                    **{**kwargs, "overrides": {**TINY, "width": 16}})
    with pytest.raises(ValueError, match="another mission config"):
        sweep_study(["lr_actor=1e-4"], run=never_train, **{**kwargs, "agents": 2})


# --------------------------------------------------------------------------------------------
# End to end


@pytest.fixture(scope="module")
def local_sweep(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep")
    code = study_main(["sweep", "--sweep", "lr_actor=1e-4,3e-4", "--seeds", "0",
                       "--out", str(out), *TINY_RUN])
    assert code == 0
    return out


@pytest.mark.slow
def test_a_tiny_sweep_trains_scores_on_validation_missions_and_resumes(local_sweep, capsys):
    out = local_sweep
    from coma.persistence import load_policy

    for value in ("0.0001", "0.0003"):
        networks, _ = load_policy(out / "runs" / f"lr_actor-{value}" / "s0" / "best.pt")
        assert networks.coma_config.lr_actor == float(value)
        assert networks.coma_config.width == 8 and networks.coma_config.seed == 0
    stored = json.loads((out / "validation" / "config.json").read_text())
    assert stored["namespace"] == "validation" and stored["seed"] == 10_000
    table = (out / "sweep.md").read_text()
    assert "2 validation missions (run seed 10000; never test missions)" in table
    rows = [line for line in table.splitlines() if line.startswith("| 0.000")]
    assert len(rows) == 2 and sum(row.count("**") for row in rows) == 4
    with open(out / "sweep.csv", newline="") as handle:
        runs = list(csv.DictReader(handle))
    assert [(r["lr_actor"], r["seed"], r["missions"]) for r in runs] == [
        ("0.0001", "0", "2"), ("0.0003", "0", "2")]
    for run in runs:  # the gap is the run's final entropy minus IG's on the same missions
        assert float(run["gap_to_ig"]) == pytest.approx(
            float(run["final_entropy"]) - float(run["ig_final_entropy"]), abs=1e-5)
    # Run again: nothing is trained, the same table comes from the stored missions.
    weights = {p: p.stat().st_mtime_ns for p in (out / "runs").rglob("*.pt")}
    capsys.readouterr()
    assert study_main(["sweep", "--sweep", "lr_actor=1e-4,3e-4", "--seeds", "0",
                       "--out", str(out), *TINY_RUN]) == 0
    assert {p: p.stat().st_mtime_ns for p in weights} == weights
    assert (out / "sweep.md").read_text() == table
    # Another fixed setting over the same folders is refused before anything is trained.
    assert study_main(["sweep", "--sweep", "lr_actor=1e-4,3e-4", "--seeds", "0", "--out",
                       str(out), *TINY_RUN, "--set", "epochs=2"]) == 2
    assert "holds a run with epochs = 4, this sweep asks for 2" in capsys.readouterr().err


@pytest.mark.slow
def test_a_sweep_on_ray_trains_as_ray_tasks_and_gives_the_local_table(local_sweep, tmp_path,
                                                                      monkeypatch):
    pytest.importorskip("ray")

    def no_training_here(*args, **kwargs):
        raise AssertionError("a run was trained in the calling process, not on Ray")

    monkeypatch.setattr("coma.learner.train", no_training_here)  # Ray workers keep theirs
    out = tmp_path / "ray"
    assert study_main(["sweep", "--sweep", "lr_actor=1e-4,3e-4", "--seeds", "0", "--out",
                       str(out), "--backend", "ray", "--workers", "2", *TINY_RUN]) == 0
    assert (out / "sweep.md").read_text() == (local_sweep / "sweep.md").read_text()
    for value in ("0.0001", "0.0003"):  # the same seed trains the same weights on Ray
        run = Path("runs") / f"lr_actor-{value}" / "s0" / "best.pt"
        assert (out / run).read_bytes() == (local_sweep / run).read_bytes()
