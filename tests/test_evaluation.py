"""Tests of the evaluation runner (``ipp_toolkit.runs.evaluation``)."""

from __future__ import annotations

import hashlib
import json
import math
import multiprocessing
import platform
import sys
import time
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest
from helpers import page_faults_of_reallocation, small_config

from ipp_toolkit.planning import Planner, available_planners, planner_modules, register_planner
from ipp_toolkit.planning.specs import PlannerSpec
from ipp_toolkit.runs.evaluation import (
    RESULT_COLUMNS,
    EvaluationError,
    EvaluationResult,
    evaluate,
    load_results,
    run_mission,
)
from ipp_toolkit.runs.process_pool import WorkerPool
from ipp_toolkit.runs.run_folder import RunFolderError, allow_foreign_files
from ipp_toolkit.sim.mission import reset_mission
from ipp_toolkit.world.seeding import planner_seed

BUDGET = 4


def tiny_config(**team):
    return small_config(n_agents=2).replace(team={"budget": BUDGET, **team})


# Module-level planners: a spawned worker process unpickles them by reference (it imports
# this module), so they also run with workers > 1.
@register_planner("test-eval-first")
class FirstValid(Planner):
    """Deterministic: every UAV takes its first valid action. Counts its resets."""

    needs_observations = False
    resets: ClassVar[list[int]] = []
    interrupt_at: ClassVar[int | None] = None  # raise KeyboardInterrupt at this reset count

    def reset(self, config, seed):
        if FirstValid.interrupt_at is not None and len(FirstValid.resets) == \
                FirstValid.interrupt_at:
            raise KeyboardInterrupt
        FirstValid.resets.append(seed)

    def act(self, views):
        return np.array([int(np.flatnonzero(v.mask)[0]) for v in views])


@register_planner("test-eval-seeded")
class Seeded(Planner):
    """Random valid actions from the reset seed (checks the planner seed's determinism)."""

    def __init__(self, greedy: bool = False):
        self.greedy = greedy
        self.rng = np.random.default_rng(0)

    def reset(self, config, seed):
        self.rng = np.random.default_rng(seed)

    def act(self, views):
        assert views[0].observation.shape[0] > 0  # needs_observations defaults to True
        return np.array([int(self.rng.choice(np.flatnonzero(v.mask))) for v in views])


@register_planner("test-eval-fails")
class Fails(FirstValid):
    """Fails at one mission (recognised by its planner seed), also inside a worker process."""

    def __init__(self, fail_mission: int = 0):
        self.fail_seed = planner_seed(0, fail_mission)

    def reset(self, config, seed):
        if seed == self.fail_seed:
            raise RuntimeError("planner failure")


@pytest.fixture(autouse=True)
def _reset_counters():
    FirstValid.resets = []
    FirstValid.interrupt_at = None
    yield
    FirstValid.interrupt_at = None


def stripped(rows):
    """Rows without the (timing-dependent) plan_ms column, NaN-safe comparable as JSON."""
    return json.dumps([{k: v for k, v in row.items() if k != "plan_ms"} for row in rows])


def snapshot(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


PLANNERS = ["test-eval-first", "test-eval-seeded"]


def test_rows_curves_and_common_missions():
    result = evaluate(tiny_config(), PLANNERS, missions=2, seed=3, progress=False,
                      record_missions=(0, 1, 7))
    assert isinstance(result, EvaluationResult) and result.out_dir is None
    assert result.labels == PLANNERS and result.missions == [0, 1] and result.seed == 3
    assert len(result.rows) == 2 * 2 * (BUDGET + 1)
    for row in result.rows:
        assert tuple(row) == RESULT_COLUMNS
        assert (row["agents"], row["comm"], row["terrain"], row["seed"]) == (2, 25.0, "split", 3)
        if row["step"] == 0:
            assert math.isnan(row["reward"]) and math.isnan(row["plan_ms"])
        else:
            assert math.isfinite(row["reward"]) and row["plan_ms"] >= 0.0
    # Ordered by planner, mission, step.
    keys = [(PLANNERS.index(r["planner"]), r["mission"], r["step"]) for r in result.rows]
    assert keys == sorted(keys)
    # Same mission, same start: identical metrics at s = 0 for every planner.
    start = {(r["planner"], r["mission"]): (r["entropy"], r["f1"], r["rmse"])
             for r in result.rows if r["step"] == 0}
    for mission in (0, 1):
        assert start[(PLANNERS[0], mission)] == start[(PLANNERS[1], mission)]
    # Same terrain for every planner; another terrain for another mission.
    assert set(result.trajectories) == {(p, k) for p in PLANNERS for k in (0, 1)}
    truth = {key: t["ground_truth"] for key, t in result.trajectories.items()}
    for mission in (0, 1):
        np.testing.assert_array_equal(truth[(PLANNERS[0], mission)], truth[(PLANNERS[1], mission)])
    assert not np.array_equal(truth[(PLANNERS[0], 0)], truth[(PLANNERS[0], 1)])
    curves = result.curves("entropy")
    assert list(curves) == PLANNERS and curves[PLANNERS[0]].shape == (2, BUDGET + 1)
    assert np.isnan(result.curves("reward")[PLANNERS[1]][:, 0]).all()
    with pytest.raises(ValueError, match="unknown metric 'psnr'"):
        result.curves("psnr")


def test_run_mission_resets_with_the_derived_seed_and_records():
    config = tiny_config()
    planner = FirstValid()
    out = run_mission(config, planner, seed=5, mission=2, record_trajectory=True)
    assert FirstValid.resets == [planner_seed(5, 2, "test")]
    assert planner_seed(5, 2, "test") != planner_seed(5, 3, "test") != planner_seed(5, 2, "train")
    rows, trajectory = out["rows"], out["trajectory"]
    assert [r["step"] for r in rows] == list(range(BUDGET + 1))
    assert rows[0]["planner"] == "planner" and rows[0]["mission"] == 2
    assert trajectory["positions"].shape == (BUDGET + 1, 2, 3)
    assert trajectory["footprints"].shape == (BUDGET + 1, 2, 4)
    assert trajectory["ground_truth"].shape == (100, 100)
    assert trajectory["final_prob"].dtype == np.float16
    # The held-out namespace differs from the training terrains.
    state = reset_mission(config, 5, 2, "train")
    assert not np.array_equal(state.ground_truth, trajectory["ground_truth"])
    assert run_mission(config, planner, 5, 2, label="x")["trajectory"] is None


def test_workers_do_not_change_results(tmp_path):
    planners = list(PLANNERS)
    if "random" in available_planners():
        planners.append("random")  # an entry-point planner, imported inside the workers
    config = tiny_config()
    serial = evaluate(config, planners, missions=3, seed=1, workers=1, progress=False)
    parallel = evaluate(config, planners, missions=3, seed=1, workers=2, progress=False,
                        out_dir=tmp_path / "par")
    assert stripped(serial.rows) == stripped(parallel.rows)
    assert parallel.labels == serial.labels
    for key, trajectory in serial.trajectories.items():
        for name, value in trajectory.items():
            np.testing.assert_array_equal(np.asarray(value),
                                          np.asarray(parallel.trajectories[key][name]))
    assert stripped(load_results(tmp_path / "par").rows) == stripped(serial.rows)


def children_gone(timeout: float = 20.0) -> bool:
    """Whether this process's child processes have all exited (waiting up to ``timeout``)."""
    deadline = time.monotonic() + timeout
    while multiprocessing.active_children():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)
    return True


def test_a_pool_started_ahead_flies_the_same_missions_and_is_shut_down():
    assert planner_modules(["random", "no-such-planner"]) == ["baselines.heuristics.random_planner"]
    config = tiny_config()
    serial = evaluate(config, ["random"], missions=3, seed=1, workers=1, progress=False)
    pool = WorkerPool(2, planner_modules(["random"]))
    try:
        ahead = evaluate(config, ["random"], missions=3, seed=1, workers=2, progress=False,
                         pool=pool)
    finally:
        pool.close()
    assert stripped(ahead.rows) == stripped(serial.rows)
    assert children_gone()


def test_a_pool_of_no_workers_is_refused_naming_the_count():
    with pytest.raises(ValueError, match="n_workers must be >= 1, got 0"):
        WorkerPool(0)
    assert children_gone()


@pytest.fixture
def started_pools(monkeypatch) -> list[WorkerPool]:
    """Every WorkerPool that reports.compare starts from now on, in order."""
    import reports.compare  # noqa: F401 - the module, loaded

    started: list[WorkerPool] = []

    class Recorded(WorkerPool):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            started.append(self)

    # The module, not the function the package exports under the same name.
    monkeypatch.setattr(sys.modules["reports.compare"], "WorkerPool", Recorded)
    return started


def test_compare_stops_the_workers_it_started_when_a_planner_is_refused(tmp_path,
                                                                        started_pools):
    from reports.compare import compare

    started = started_pools
    out = tmp_path / "out"
    with pytest.raises(ValueError, match="cannot be built"):
        compare(planners=f"random,coma={tmp_path / 'missing.pt'}", trials=2, workers=2,
                out=out, progress=False, config=tiny_config())
    assert [pool.n_workers for pool in started] == [2]  # started before the planners' checks
    assert not out.exists()
    assert children_gone()


def test_compare_starts_no_workers_when_every_mission_is_stored(tmp_path, started_pools,
                                                               placeholder_figures):
    from reports.compare import compare

    started = started_pools
    out = tmp_path / "out"
    run = dict(planners="random,coverage", workers=2, out=out, progress=False,
               config=tiny_config())
    first = compare(trials=2, **run)
    assert len(started) == 1
    again = compare(trials=2, **run)  # nothing left to fly: reported from the shards
    assert len(started) == 1
    assert stripped(again.result.rows) == stripped(first.result.rows)
    (out / "shards" / "coverage" / "mission_00001.json").unlink()
    compare(trials=2, **run)  # one mission to fly again: workers
    assert len(started) == 2
    assert stripped(load_results(out).rows) == stripped(first.result.rows)
    assert children_gone()


_WORKER_CHECK_SCRIPT = """
import sys
from pathlib import Path
from ipp_toolkit.planning import check_planner_name
from reports.compare import compare

out = Path(sys.argv[1])
check_planner_name("coma")  # an entry point: known, and not loaded for that
for name, message in (("no-such-planner", "registered planners"), ("coma_mixed", "removed")):
    try:
        check_planner_name(name)
    except ValueError as err:
        assert message in str(err), err
    else:
        raise AssertionError(name)
setting = dict(agents=2, comm=25.0, resolution=0.5, budget=3, trials=1, progress=False)
try:
    compare(planners="random,coma=" + str(out / "missing.pt"), workers=2, out=out / "refused",
            **setting)
except ValueError as err:
    assert "planner 'coma' cannot be built" in str(err), err
else:
    raise AssertionError("a missing checkpoint was accepted")
assert not (out / "refused").exists()
parallel = compare(planners="random,coma", workers=2, out=out / "parallel", **setting)
assert "coma.planner" not in sys.modules and "torch" not in sys.modules
serial = compare(planners="random,coma", workers=1, **setting)
strip = lambda rows: repr([{k: v for k, v in r.items() if k != "plan_ms"} for r in rows])
assert strip(parallel.result.rows) == strip(serial.result.rows)  # repr: nan == nan
print("checked")
"""


# Slow: three interpreters and two pools import torch. Faster tests hold its parts: the
# results of workers (above), a refusal from a worker (tests/test_bad_inputs.py).
@pytest.mark.slow
def test_compare_with_workers_checks_the_planners_in_a_worker(tmp_path):
    """The workers import torch and SB3 anyway; with them the main process of ``compare``
    neither builds a planner nor loads a planner's module, and refuses a bad one all the
    same, before anything is written. A fresh interpreter: this one has loaded them."""
    import subprocess

    done = subprocess.run([sys.executable, "-c", _WORKER_CHECK_SCRIPT, str(tmp_path)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip().endswith("checked")


def test_interrupted_run_resumes_without_redoing_missions(tmp_path):
    config = tiny_config()
    reference = evaluate(config, PLANNERS, missions=3, progress=False,
                         out_dir=tmp_path / "full")
    out = tmp_path / "out"
    FirstValid.resets = []
    FirstValid.interrupt_at = 2  # missions 0 and 1 finish, Ctrl-C at mission 2
    with pytest.raises(KeyboardInterrupt):
        evaluate(config, PLANNERS, missions=3, progress=False, out_dir=out)
    names = {p.name for p in (out / "shards" / PLANNERS[0]).glob("mission_*.json")}
    assert names == {"mission_00000.json", "mission_00001.json"}
    assert not (out / "results.csv").exists()
    assert not list(out.rglob("*.tmp"))
    before = {p: p.stat().st_mtime_ns for p in (out / "shards").rglob("mission_*.json")}

    FirstValid.interrupt_at = None
    FirstValid.resets = []
    resumed = evaluate(config, PLANNERS, missions=3, progress=False, out_dir=out)
    assert FirstValid.resets == [planner_seed(0, 2)]  # only mission 2 was flown
    assert all(p.stat().st_mtime_ns == t for p, t in before.items())
    assert stripped(resumed.rows) == stripped(reference.rows)
    assert stripped(load_results(out).rows) == stripped(reference.rows)
    assert set(resumed.trajectories) == {(p, 0) for p in PLANNERS}

    # More missions extend the stored ones; fewer planners give a smaller results.csv.
    FirstValid.resets = []
    extended = evaluate(config, PLANNERS[:1], missions=4, progress=False, out_dir=out)
    assert FirstValid.resets == [planner_seed(0, 3)]
    assert {r["planner"] for r in extended.rows} == {PLANNERS[0]}
    assert load_results(out).missions == [0, 1, 2, 3]


def test_failing_worker_keeps_finished_missions(tmp_path):
    out = tmp_path / "out"
    spec = PlannerSpec("test-eval-fails", {"fail_mission": 2})
    with pytest.raises(RuntimeError, match="planner failure") as caught:
        evaluate(tiny_config(), [spec], missions=4, workers=2, progress=False, out_dir=out)
    assert any("mission 2" in note for note in caught.value.__notes__)
    names = {p.name for p in (out / "shards" / "test-eval-fails").glob("mission_*.json")}
    assert {"mission_00000.json", "mission_00001.json"} <= names
    assert "mission_00002.json" not in names and not (out / "results.csv").exists()


def test_local_planner_with_workers_is_refused_before_writing(tmp_path):
    @register_planner("test-eval-local")
    class Local(FirstValid):
        pass

    out = tmp_path / "out"
    with pytest.raises(ValueError, match="'test-eval-local' .* cannot import .* workers=1"):
        evaluate(tiny_config(), ["test-eval-local"], missions=2, workers=2, progress=False,
                 out_dir=out)
    assert not out.exists()
    assert len(evaluate(tiny_config(), ["test-eval-local"], missions=2, progress=False).rows) \
        == 2 * (BUDGET + 1)


def test_deleted_and_corrupt_shards_are_redone(tmp_path):
    config = tiny_config()
    out = tmp_path / "out"
    first = evaluate(config, PLANNERS, missions=3, progress=False, out_dir=out)
    shards = out / "shards" / PLANNERS[0]
    (shards / "mission_00001.json").unlink()
    (shards / "mission_00002.json").write_text('{"format": 1, "rows": [', encoding="utf-8")
    kept = shards / "mission_00000.json"
    kept_time = kept.stat().st_mtime_ns
    FirstValid.resets = []
    with pytest.warns(UserWarning, match=r"mission_00002\.json' is corrupt"):
        again = evaluate(config, PLANNERS, missions=3, progress=False, out_dir=out)
    assert FirstValid.resets == [planner_seed(0, 1), planner_seed(0, 2)]
    assert kept.stat().st_mtime_ns == kept_time
    assert stripped(again.rows) == stripped(first.rows)
    json.loads((shards / "mission_00002.json").read_text(encoding="utf-8"))
    # A recorded mission whose npz is gone is flown again to record it.
    (out / "trajectories" / f"{PLANNERS[0]}_mission0.npz").unlink()
    FirstValid.resets = []
    evaluate(config, PLANNERS, missions=3, progress=False, out_dir=out)
    assert FirstValid.resets == [planner_seed(0, 0)]
    assert (out / "trajectories" / f"{PLANNERS[0]}_mission0.npz").is_file()


def test_another_configuration_is_refused_and_nothing_written(tmp_path):
    out = tmp_path / "out"
    evaluate(tiny_config(), PLANNERS[:1], missions=2, progress=False, out_dir=out)
    before = snapshot(out)
    with pytest.raises(EvaluationError, match=r"out.*another configuration.*config\.team\.budget"):
        evaluate(tiny_config(budget=BUDGET + 1), PLANNERS[:1], missions=2, progress=False,
                 out_dir=out)
    with pytest.raises(EvaluationError, match=r"differing: seed\)"):
        evaluate(tiny_config(), PLANNERS, missions=2, seed=9, progress=False, out_dir=out)
    with pytest.raises(EvaluationError, match="namespace"):
        evaluate(tiny_config(), PLANNERS, missions=2, progress=False, out_dir=out,
                 namespace="validation")
    # The same label for another planner (or other options) would mix results.
    spec = PlannerSpec("test-eval-seeded", label=PLANNERS[0])
    with pytest.raises(EvaluationError, match="another label"):
        evaluate(tiny_config(), [spec], missions=2, progress=False, out_dir=out)
    assert issubclass(EvaluationError, ValueError)
    assert snapshot(out) == before
    stray = tmp_path / "stray"
    (stray / "shards").mkdir(parents=True)
    with pytest.raises(RunFolderError, match="holds files no run of the toolkit wrote"):
        evaluate(tiny_config(), PLANNERS, missions=1, progress=False, out_dir=stray)
    with allow_foreign_files(), pytest.raises(EvaluationError, match="no config.json"):
        evaluate(tiny_config(), PLANNERS, missions=1, progress=False, out_dir=stray)


def test_a_folder_from_before_a_new_config_field_is_reused(tmp_path):
    """A field added later (with a default that keeps the old behaviour) is not a change."""
    out = tmp_path / "out"
    evaluate(tiny_config(), PLANNERS[:1], missions=2, progress=False, out_dir=out)
    identity = json.loads((out / "config.json").read_text(encoding="utf-8"))
    del identity["config"]["features"]["gain"]  # as written before the field existed
    (out / "config.json").write_text(json.dumps(identity), encoding="utf-8")
    FirstValid.resets = []
    evaluate(tiny_config(), PLANNERS[:1], missions=2, progress=False, out_dir=out)
    assert FirstValid.resets == []  # nothing flown again
    identity["config"]["features"]["gain"] = True  # a real difference is still refused
    (out / "config.json").write_text(json.dumps(identity), encoding="utf-8")
    with pytest.raises(EvaluationError, match=r"config\.features\.gain"):
        evaluate(tiny_config(), PLANNERS[:1], missions=2, progress=False, out_dir=out)


def test_load_results_round_trip_and_refusals(tmp_path):
    out = tmp_path / "out"
    config = tiny_config(comm_range=math.inf)
    result = evaluate(config, [PlannerSpec("test-eval-seeded", label="seeded (a)"),
                               "test-eval-first"], missions=2, seed=4, progress=False,
                      out_dir=out)
    lines = (out / "results.csv").read_text(encoding="utf-8").splitlines()
    assert lines[0] == ",".join(RESULT_COLUMNS)
    assert lines[1].startswith("seeded (a),2,inf,split,4,0,0,") and lines[1].endswith(",,")
    loaded = load_results(out)
    assert loaded.config == config and loaded.seed == 4 and loaded.namespace == "test"
    assert loaded.labels == ["seeded (a)", "test-eval-first"]
    assert stripped(loaded.rows) == stripped(result.rows)
    assert [r["plan_ms"] for r in loaded.rows][1:3] == [r["plan_ms"] for r in result.rows][1:3]
    assert set(loaded.trajectories) == set(result.trajectories) == {("seeded (a)", 0),
                                                                    ("test-eval-first", 0)}
    for key, trajectory in result.trajectories.items():
        for name, value in trajectory.items():
            np.testing.assert_array_equal(np.asarray(value), loaded.trajectories[key][name])
    for metric in ("entropy", "reward"):
        for label, curve in result.curves(metric).items():
            np.testing.assert_array_equal(curve, loaded.curves(metric)[label])

    with pytest.raises(EvaluationError, match="config.json' is missing"):
        load_results(tmp_path / "nothing")
    (out / "results.csv").write_text("planner,step\nx,1\n", encoding="utf-8")
    with pytest.raises(EvaluationError, match="results.csv' is malformed"):
        load_results(out)
    (out / "results.csv").write_text(",".join(RESULT_COLUMNS) + "\nx,two" + ",1" * 10 + "\n",
                                     encoding="utf-8")
    with pytest.raises(EvaluationError, match="results.csv' is malformed: line 2"):
        load_results(out)


def test_trajectory_npz_of_mission_0(tmp_path):
    out = tmp_path / "out"
    evaluate(tiny_config(), PLANNERS[:1], missions=2, progress=False, out_dir=out)
    files = sorted(p.name for p in (out / "trajectories").iterdir())
    assert files == [f"{PLANNERS[0]}_mission0.npz"]
    with np.load(out / "trajectories" / files[0]) as data:
        assert data["ground_truth"].dtype == bool and data["ground_truth"].shape == (100, 100)
        assert data["final_prob"].dtype == np.float16 and data["final_prob"].shape == (100, 100)
        assert data["positions"].shape == (BUDGET + 1, 2, 3)
        assert data["footprints"].shape == (BUDGET + 1, 2, 4)
        assert data["footprints"].dtype.kind == "i"
        assert float(data["area_size"]) == 50.0 and float(data["resolution"]) == 0.5
        # Metres: the fixed starts of two UAVs at 15 m.
        np.testing.assert_allclose(data["positions"][0], [[10, 10, 15], [40, 40, 15]])
    config = json.loads((out / "config.json").read_text(encoding="utf-8"))
    assert config["seed"] == 0 and config["namespace"] == "test" and "version" in config


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"missions": 0}, "missions must be an integer >= 1, got 0"),
    ({"workers": 0}, "workers must be an integer >= 1, got 0"),
    ({"seed": -1}, "seed must be an integer >= 0, got -1"),
    ({"record_missions": (-2,)}, "record_missions must be an integer >= 0, got -2"),
    ({"planners": ["test-eval-first", "astar"]},
     "unknown planner 'astar'; registered planners: .*test-eval-first"),
    ({"planners": ["test-eval-first", "test-eval-first"]},
     "planner label 'test-eval-first' is given twice"),
    ({"planners": [PlannerSpec("test-eval-first", label="a b"),
                   PlannerSpec("test-eval-seeded", label="a_b")]}, "same file name 'a_b'"),
    ({"planners": []}, "no planner given"),
    ({"planners": [PlannerSpec("test-eval-seeded", {"bogus": 1})]}, "bogus"),
])
def test_bad_inputs_raise_before_writing(tmp_path, kwargs, message):
    out = tmp_path / "out"
    arguments = {"planners": PLANNERS, "missions": 1, "progress": False, "out_dir": out,
                 **kwargs}
    with pytest.raises((ValueError, TypeError), match=message):
        evaluate(tiny_config(), **arguments)
    assert not out.exists()


def test_planner_spec_parse_and_options():
    assert PlannerSpec.parse("ig") == PlannerSpec("ig", {}, "ig")
    spec = PlannerSpec.parse(" coma=runs/x/ckpt.pt ")
    assert (spec.name, spec.options, spec.effective_label) == (
        "coma", {"checkpoint": "runs/x/ckpt.pt"}, "coma")
    assert PlannerSpec("ig").effective_label == "ig"
    assert PlannerSpec("coma", {"checkpoint": Path("a/b.pt")}).options == {"checkpoint": "a/b.pt"}
    assert hash(spec) == hash(PlannerSpec.parse("coma=runs/x/ckpt.pt"))
    labelled = PlannerSpec.parse("coma-mixed:coma=C:/runs/m.pt")
    assert (labelled.name, labelled.options, labelled.effective_label) == (
        "coma", {"checkpoint": "C:/runs/m.pt"}, "coma-mixed")
    assert PlannerSpec.parse("mine:ig").effective_label == "mine"
    for bad in ("", "=x", "coma=", ":coma", "x:", "x:=a"):
        with pytest.raises(ValueError, match=r"NAME or \[LABEL:\]NAME=CHECKPOINT"):
            PlannerSpec.parse(bad)
    with pytest.raises(ValueError, match="JSON-serialisable"):
        PlannerSpec("ig", {"f": object()})


def test_progress_bar_counts_missions(capsys):
    evaluate(tiny_config(), "test-eval-first,test-eval-seeded", missions=2, progress=True)
    err = capsys.readouterr().err
    assert "4/4" in err and "mission" in err


def _python(code: str, *args: str) -> str:
    """Run ``code`` in a fresh interpreter (what it changes in its process stays there)."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          check=True, timeout=300)
    return done.stdout.strip()


def test_a_worker_freezes_what_its_first_mission_with_a_planner_loaded():
    code = """
import gc, sys
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.runs.evaluation import _Entry, _Runner
from ipp_toolkit.planning.specs import PlannerSpec
config = EnvConfig().replace(world={"resolution": 0.5}, team={"budget": 3})
entries = {name: _Entry(PlannerSpec.parse(name)) for name in ("random", "coverage")}
runner = _Runner(config, 0, "test", entries, frozenset(), single_thread=sys.argv[1] == "worker")
counts = [gc.get_freeze_count()]
for label, mission in [("random", 0), ("random", 1), ("coverage", 1)]:
    runner.run(label, mission)
    counts.append(gc.get_freeze_count())
print(*counts)
"""
    start, first, again, other = (int(n) for n in _python(code, "worker").split())
    # Frozen once per planner, after its first mission, not after every one (a frozen object
    # freed since leaves the count).
    assert start == 0 and 0 < first and again <= first < other
    assert _python(code, "main").split() == ["0"] * 4  # not in the calling process


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc",
                    reason="retain_freed_memory sets glibc's allocator")
def test_a_worker_reuses_freed_memory_without_new_page_faults():
    code = """
import resource, sys
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.runs.evaluation import run_mission
from ipp_toolkit.planning import make_planner
from ipp_toolkit.runs.process_pool import retain_freed_memory
if sys.argv[1] == "retain":
    assert retain_freed_memory()
config = EnvConfig().replace(team={"budget": 3})  # r_M = 0.1 m: 500 x 500 maps
planner = make_planner("ig")  # reads the local maps: their per-cell arrays are built
run_mission(config, planner, 0, 0)
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for mission in range(1, 4):
    run_mission(config, planner, 0, mission)
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""
    plain, retained = int(_python(code, "plain")), int(_python(code, "retain"))
    # Each mission's maps were new pages (about 3,300 faults); kept, they are reused.
    assert plain > 3 * 1000 and retained < plain / 4


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc",
                    reason="retain_freed_memory sets glibc's allocator")
@pytest.mark.parametrize("setup", [
    # an evaluation pool process, as its initializer leaves it
    "import os\nfrom ipp_toolkit.runs.process_pool import _init_worker\n"
    "_init_worker(os.getppid(), (), None)",
    # a Ray worker, as its first mission task of an evaluation leaves it (Ray not needed)
    "import types\nfrom ipp_toolkit.runs.ray_backend import _prepared\n"
    "assert _prepared(types.SimpleNamespace()).single_thread",
], ids=["pool", "ray"])
def test_every_mission_worker_keeps_freed_memory_for_reuse(setup):
    plain, prepared = page_faults_of_reallocation(), page_faults_of_reallocation(setup)
    assert plain > 1000 and prepared < plain / 10, (plain, prepared)

