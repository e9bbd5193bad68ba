"""Tests of the Ray backend (``evaluate(..., backend="ray")``, ``ipp-compare --backend ray``,
``ipp-study ... --backend ray``).

The tests that need a running Ray are marked slow and share one local Ray (2 CPUs) per module
(but the first, which checks that a study starts one Ray of its own);
every test that needs Ray installed is skipped without it (``pip install -c constraints.txt
-e ".[ray]"``). Missing Ray is simulated by making it unimportable, so that test always runs.
"""

from __future__ import annotations

import csv
import hashlib
import importlib.util
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planning import Planner, register_planner
from ipp_toolkit.planning.specs import PlannerSpec
from ipp_toolkit.runs import ray_backend
from ipp_toolkit.runs.evaluation import evaluate, load_results
from ipp_toolkit.runs.ray_backend import RayCluster, RayUnavailableError, probe, start_local
from ipp_toolkit.world.seeding import planner_seed
from reports.cli import compare_main, study_main
from reports.studies import credit_assignment_study, robustness_study, train_run, train_runs


def _ray_importable() -> bool:
    try:
        return importlib.util.find_spec("ray") is not None
    except (ImportError, ValueError):  # ValueError: sys.modules["ray"] is None
        return False


HAS_RAY = _ray_importable()
needs_ray = pytest.mark.skipif(not HAS_RAY, reason='Ray is not installed (the optional extra: '
                                                   'pip install -c constraints.txt -e ".[ray]")')

PLANNERS = "ig,random"
MISSIONS = 3


def tiny_config() -> EnvConfig:
    return EnvConfig().replace(world={"resolution": 1.0}, team={"n_agents": 2, "budget": 3})


def stripped(rows):
    """Rows without the timing column ``plan_ms``, comparable as JSON (NaN-safe)."""
    return json.dumps([{k: v for k, v in row.items() if k != "plan_ms"} for row in rows])


def csv_rows(path: Path) -> list[dict[str, str]]:
    """The rows of a ``results.csv`` without the timing column ``plan_ms``."""
    with open(path, newline="") as handle:
        return [{k: v for k, v in row.items() if k != "plan_ms"}
                for row in csv.DictReader(handle)]


#: The smallest COMA training of the study tests (tests/test_studies.py).
TINY_COMA = {"width": 8, "hidden": 16, "missions_per_update": 2, "minibatch_size": 60,
             "eval_missions": 1, "warm_start": ""}
TINY_STUDY = ["--planners", "random,coverage", "--agents", "2", "--comm", "0,inf", "--trials",
              "2", "--resolution", "1", "--no-progress"]


def snapshot(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


# Module-level planners: Ray workers on this machine import this module by reference.
@register_planner("test-ray-first")
class FirstValid(Planner):
    """Deterministic: every UAV takes its first valid action."""

    needs_observations = False

    def reset(self, config, seed):
        pass

    def act(self, views):
        return np.array([int(np.flatnonzero(v.mask)[0]) for v in views])


@register_planner("test-ray-dies")
class DiesOnce(FirstValid):
    """Kills its own worker process (SIGKILL) at one mission, the first time it is flown.

    ``marker`` is a file created just before the kill: the retried task finds it and flies.
    """

    def __init__(self, marker: str = "", die_mission: int = 1):
        self.marker = Path(marker)
        self.die_seed = planner_seed(0, die_mission)

    def reset(self, config, seed):
        if seed == self.die_seed and not self.marker.exists():
            self.marker.write_text(str(os.getpid()))
            os.kill(os.getpid(), signal.SIGKILL)


@register_planner("test-ray-fails")
class Fails(FirstValid):
    """Raises at one mission (recognised by its planner seed)."""

    def __init__(self, fail_mission: int = 2):
        self.fail_seed = planner_seed(0, fail_mission)

    def reset(self, config, seed):
        if seed == self.fail_seed:
            raise RuntimeError("planner failure")


# --------------------------------------------------------------------------------------------
# Without a running Ray


def test_missing_ray_is_one_line_with_the_install_command(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now raises ImportError
    out = tmp_path / "out"
    code = compare_main(["--backend", "ray", "--planners", "random", "--trials", "1",
                         "--resolution", "1", "--no-progress", "--out", str(out)])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("ipp-compare: error: ")
    assert 'pip install -c constraints.txt -e ".[ray]"' in err
    assert not out.exists()
    with pytest.raises(RayUnavailableError, match="pip install"):
        evaluate(tiny_config(), "random", missions=1, progress=False, backend="ray",
                 out_dir=out)
    assert not out.exists()


def test_optional_imports_share_one_message_form(monkeypatch):
    """require_ray, require_rllib and make_torchrl_env import through require_extra: one line
    naming what needs the package, why it failed and the install command."""
    from baselines.rllib.training import RLlibUnavailableError, require_rllib
    from ipp_toolkit.extras import install_command, require_extra
    from ipp_toolkit.torchrl_env import make_torchrl_env

    assert require_extra("json", "a test", "no install") is json
    for module in ("ray", "ray.rllib", "torchrl.envs"):
        monkeypatch.setitem(sys.modules, module, None)  # importing it raises ImportError
    cases = [(ray_backend.require_ray, RayUnavailableError, "the ray backend needs Ray, ",
              'pip install -c constraints.txt -e ".[ray]"'),
             (require_rllib, RLlibUnavailableError, "ipp-train rllib needs ray[rllib], ",
              'pip install -c constraints-rllib.txt -e ".[rllib]"'),
             (make_torchrl_env, ImportError, "make_torchrl_env needs torchrl, ",
              install_command("torchrl"))]
    for call, error, start, install in cases:
        with pytest.raises(error) as raised:
            call()
        message = str(raised.value)
        assert message.startswith(start) and "which cannot be imported here (" in message
        assert message.endswith(f"install the optional extra with: {install}")
        assert "\n" not in message
    assert issubclass(RLlibUnavailableError, ValueError)  # ipp-train rllib exits 2 on it


@pytest.mark.parametrize(("argv", "message"), [
    (["--address", "127.0.0.1:6379"], "--address needs --backend ray"),
    (["--backend", "dask"], "invalid choice: 'dask'"),
    (["--backend", "ray", "--address", " "], "--address must be a non-empty string"),
])
def test_backend_flags_are_checked(tmp_path, capsys, argv, message):
    out = tmp_path / "out"
    assert compare_main([*argv, "--planners", "random", "--trials", "1", "--out",
                         str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"backend": "dask"}, "backend must be one of local, ray, got 'dask'"),
    ({"address": "127.0.0.1:6379"}, "address is only used with backend='ray'"),
    ({"backend": "ray", "address": ""}, "address must be a non-empty string"),
])
def test_evaluate_checks_backend_arguments(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        evaluate(tiny_config(), "random", missions=1, progress=False,
                 out_dir=tmp_path / "out", **kwargs)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("backend", "address", "message", "flag_message"), [
    ("dask", None, "backend must be one of local, ray, got 'dask'",
     "--backend must be one of local, ray, got 'dask'"),
    ("local", "127.0.0.1:6379", "address is only used with backend='ray', got backend='local'",
     "--address needs --backend ray"),
    ("ray", " ", "address must be a non-empty string (a Ray cluster's HOST:PORT), got ' '",
     "--address must be a non-empty string (a Ray cluster's HOST:PORT), got ' '"),
])
def test_one_backend_check_serves_every_caller(tmp_path, backend, address, message,
                                               flag_message):
    from coma.parallel import check_workers
    from reports.compare import compare

    out = tmp_path / "out"
    callers = {
        "check_backend": lambda: ray_backend.check_backend(backend, address),
        "evaluate": lambda: evaluate(tiny_config(), "random", missions=1, progress=False,
                                     out_dir=out, backend=backend, address=address),
        "compare": lambda: compare(agents=2, planners="random", trials=1, resolution=1.0,
                                   progress=False, out=out, backend=backend,
                                   address=address),
        "robustness_study": lambda: robustness_study(
            "random", agents=(2,), comms=(0.0,), trials=1, out=out, progress=False,
            backend=backend, address=address),
        "coma check_workers": lambda: check_workers(1, backend, address),
    }
    for name, call in callers.items():
        with pytest.raises(ValueError) as caught:
            call()
        assert str(caught.value) == message, name
    with pytest.raises(ValueError) as caught:
        ray_backend.check_backend_flags(backend, address)
    assert str(caught.value) == flag_message
    assert not out.exists()


def test_the_toolkit_does_not_import_ray():
    code = ("import sys, ipp_toolkit.runs.evaluation, ipp_toolkit.runs.ray_backend, reports.cli, "
            "reports.compare, reports.studies, reports.generalisation; "
            "print('ray' in sys.modules)")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True)
    assert result.stdout.strip() == "False"


@pytest.mark.parametrize("address", ["nohost", "127.0.0.1:", "127.0.0.1:99999",
                                     "http://127.0.0.1:6379"])
def test_malformed_addresses(address):
    with pytest.raises(ValueError, match="address"):
        probe(address)


def test_an_address_without_a_ray_head_fails_fast():
    # Nothing listens on port 1: refused at once.
    start = time.monotonic()
    with pytest.raises(ConnectionError, match="no Ray cluster answers at '127.0.0.1:1'"):
        probe("127.0.0.1:1")
    assert time.monotonic() - start < 5
    # A server that accepts but does not speak gRPC (not a Ray head): refused within seconds.
    server = socket.create_server(("127.0.0.1", 0))
    port = server.getsockname()[1]
    accepted: list[socket.socket] = []

    def accept() -> None:
        connection, _ = server.accept()
        accepted.append(connection)
        connection.sendall(b"HTTP/1.1 400 Bad Request\r\n\r\n")

    thread = threading.Thread(target=accept, daemon=True)
    thread.start()
    try:
        with pytest.raises(ConnectionError, match="not a Ray head"):
            probe(f"127.0.0.1:{port}", timeout=2.0)
    finally:
        thread.join(5)
        for connection in accepted:
            connection.close()
        server.close()


@needs_ray
def test_unreachable_address_is_a_clear_error_within_seconds(tmp_path, capsys):
    out = tmp_path / "out"
    start = time.monotonic()
    code = compare_main(["--backend", "ray", "--address", "127.0.0.1:1", "--planners",
                         "random", "--trials", "1", "--resolution", "1", "--no-progress",
                         "--out", str(out)])
    assert time.monotonic() - start < 20
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("ipp-compare: error: no Ray cluster answers at '127.0.0.1:1'")
    assert "ray start --head" in err[-1]
    assert not out.exists()


# --------------------------------------------------------------------------------------------
# ipp-study: the errors, without a running Ray


@pytest.mark.parametrize("study", ["robustness", "credit", "ablation", "generalisation"])
def test_ipp_study_without_ray_is_one_line_with_the_install_command(tmp_path, monkeypatch,
                                                                    capsys, study):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now raises ImportError
    out = tmp_path / "out"
    assert study_main([study, "--backend", "ray", "--out", str(out), *TINY_STUDY]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("ipp-study: error: ")
    assert 'pip install -c constraints.txt -e ".[ray]"' in err
    assert not out.exists()
    with pytest.raises(RayUnavailableError, match="pip install"):
        robustness_study("random", agents=(2,), comms=(0.0,), trials=1, out=out,
                         progress=False, backend="ray")
    with pytest.raises(RayUnavailableError, match="pip install"):
        credit_assignment_study(["coma"], missions=2, overrides=TINY_COMA, out=out,
                                progress=False, backend="ray")
    assert not out.exists()


@pytest.mark.parametrize(("argv", "message"), [
    (["--address", "127.0.0.1:6379"], "--address needs --backend ray"),
    (["--backend", "local", "--address", "127.0.0.1:6379"], "--address needs --backend ray"),
    (["--backend", "dask"], "invalid choice: 'dask'"),
])
def test_ipp_study_backend_flags_are_checked(tmp_path, capsys, argv, message):
    out = tmp_path / "out"
    assert study_main(["robustness", *argv, "--out", str(out), *TINY_STUDY]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"backend": "dask"}, "backend must be one of local, ray, got 'dask'"),
    ({"address": "127.0.0.1:6379"}, "address is only used with backend='ray'"),
])
def test_studies_check_backend_arguments(tmp_path, kwargs, message):
    from reports.generalisation import Cell, generalisation_study
    from reports.studies import ablation_study

    out = tmp_path / "out"
    with pytest.raises(ValueError, match=message):
        robustness_study("random", agents=(2,), comms=(0.0,), trials=1, out=out,
                         progress=False, **kwargs)
    with pytest.raises(ValueError, match=message):
        credit_assignment_study(["coma"], missions=2, out=out, progress=False, **kwargs)
    with pytest.raises(ValueError, match=message):
        ablation_study(["masking"], missions=2, out=out, progress=False, **kwargs)
    with pytest.raises(ValueError, match=message):
        generalisation_study("ig,random", [Cell("split", 2, 0.0)], trials=1, out=out,
                             progress=False, **kwargs)
    assert not out.exists()


@needs_ray
@pytest.mark.parametrize("study", ["robustness", "credit"])
def test_ipp_study_at_an_unreachable_address_fails_within_seconds(tmp_path, capsys, study):
    out = tmp_path / "out"
    start = time.monotonic()
    code = study_main([study, "--backend", "ray", "--address", "127.0.0.1:1", "--missions",
                       "2", "--out", str(out), *TINY_STUDY])
    assert time.monotonic() - start < 20
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("ipp-study: error: no Ray cluster answers at '127.0.0.1:1'")
    assert not out.exists()


# --------------------------------------------------------------------------------------------
# ipp-study on a Ray of its own (before the module's Ray below is started)


@pytest.mark.slow
def test_a_robustness_study_on_ray_gives_the_local_results_on_one_ray(tmp_path, monkeypatch):
    if not HAS_RAY:
        pytest.skip('Ray is not installed (pip install -c constraints.txt -e ".[ray]")')
    import ray

    was_running = ray.is_initialized()  # True only if this process already ran the tests below
    connections: list[bool] = []  # per connect(): whether it started (owned) a Ray
    real_connect = ray_backend.connect

    def counting_connect(address, num_cpus):
        cluster = real_connect(address, num_cpus)
        connections.append(cluster.owned)
        return cluster

    monkeypatch.setattr(ray_backend, "connect", counting_connect)
    local, on_ray = tmp_path / "local", tmp_path / "ray"
    assert study_main(["robustness", "--out", str(local), *TINY_STUDY]) == 0
    assert connections == []
    assert study_main(["robustness", "--workers", "2", "--backend", "ray", "--out",
                       str(on_ray), *TINY_STUDY]) == 0
    # One Ray for the study: started (or joined) once; every setting's evaluation reused it.
    assert connections == [not was_running, False, False]
    assert ray.is_initialized() == was_running  # the study's own Ray is shut down at its end
    for setting in ("a2-d0", "a2-dinf"):
        rows = csv_rows(local / setting / "results.csv")
        assert len(rows) == 2 * 2 * 16  # planners x missions x (budget + 1) steps
        assert csv_rows(on_ray / setting / "results.csv") == rows
    assert (on_ray / "robustness.csv").read_text() == (local / "robustness.csv").read_text()


# --------------------------------------------------------------------------------------------
# With a running Ray (one local Ray for the module)


@pytest.fixture(scope="module")
def ray_cluster():
    if not HAS_RAY:
        pytest.skip('Ray is not installed (pip install -c constraints.txt -e ".[ray]")')
    import ray

    start_local(2)  # the local Ray that evaluate starts; its workers import this module
    try:
        yield ray
    finally:
        ray.shutdown()


@pytest.fixture(scope="module")
def local_reference(tmp_path_factory):
    folder = tmp_path_factory.mktemp("local")
    return evaluate(tiny_config(), PLANNERS, missions=MISSIONS, seed=1, progress=False,
                    out_dir=folder)


@pytest.mark.slow
def test_ray_gives_the_rows_of_the_local_backend(ray_cluster, local_reference, tmp_path):
    drawn = []
    result = evaluate(tiny_config(), PLANNERS, missions=MISSIONS, seed=1, progress=False,
                      out_dir=tmp_path / "ray", backend="ray",
                      on_recorded=lambda label, mission, *_: drawn.append((label, mission)))
    assert ray_cluster.is_initialized()  # the module's Ray is used, and left running
    assert stripped(result.rows) == stripped(local_reference.rows)
    assert result.labels == local_reference.labels
    assert sorted(drawn) == [("ig", 0), ("random", 0)]
    for key, trajectory in local_reference.trajectories.items():
        for name, value in trajectory.items():
            np.testing.assert_array_equal(np.asarray(value),
                                          np.asarray(result.trajectories[key][name]))
    assert stripped(load_results(tmp_path / "ray").rows) == stripped(local_reference.rows)
    local_csv = (local_reference.out_dir / "results.csv").read_text().splitlines()
    ray_csv = (tmp_path / "ray" / "results.csv").read_text().splitlines()
    assert local_csv[0] == ray_csv[0] and len(local_csv) == len(ray_csv)


@pytest.mark.slow
def test_ray_completes_a_folder_begun_by_the_local_backend(ray_cluster, local_reference,
                                                          tmp_path):
    out = tmp_path / "out"
    evaluate(tiny_config(), PLANNERS, missions=1, seed=1, progress=False, out_dir=out)
    before = {p: p.stat().st_mtime_ns for p in (out / "shards").rglob("mission_*.json")}
    assert len(before) == 2
    resumed = evaluate(tiny_config(), PLANNERS, missions=MISSIONS, seed=1, progress=False,
                       out_dir=out, backend="ray")
    assert all(p.stat().st_mtime_ns == t for p, t in before.items())  # not flown again
    assert stripped(resumed.rows) == stripped(local_reference.rows)
    stored = load_results(out)
    keys = [(r["planner"], r["mission"], r["step"]) for r in stored.rows]
    assert len(keys) == len(set(keys)) == len(local_reference.rows)  # no duplicates
    assert stripped(stored.rows) == stripped(local_reference.rows)
    # Everything stored: the ray backend neither flies nor starts anything.
    snap = snapshot(out / "shards")
    evaluate(tiny_config(), PLANNERS, missions=MISSIONS, seed=1, progress=False, out_dir=out,
             backend="ray")
    assert snapshot(out / "shards") == snap


@pytest.mark.slow
def test_a_killed_worker_loses_no_mission(ray_cluster, tmp_path):
    marker = tmp_path / "killed"
    spec = PlannerSpec("test-ray-dies", {"marker": str(marker), "die_mission": 1})
    result = evaluate(tiny_config(), [spec], missions=MISSIONS, progress=False,
                      out_dir=tmp_path / "out", backend="ray")
    assert marker.exists()  # a worker was killed mid-run ...
    assert int(marker.read_text()) != os.getpid()
    assert load_results(tmp_path / "out").missions == list(range(MISSIONS))  # ... and retried
    reference = evaluate(tiny_config(), [spec], missions=MISSIONS, progress=False)
    assert stripped(result.rows) == stripped(reference.rows)


@pytest.mark.slow
def test_a_failing_mission_raises_its_error_and_keeps_the_others(ray_cluster, tmp_path):
    out = tmp_path / "out"
    spec = PlannerSpec("test-ray-fails", {"fail_mission": 2})
    with pytest.raises(RuntimeError, match="planner failure") as caught:
        evaluate(tiny_config(), [spec], missions=4, progress=False, out_dir=out,
                 backend="ray")
    assert any("mission 2" in note for note in getattr(caught.value, "__notes__", []))
    names = {p.name for p in (out / "shards" / "test-ray-fails").glob("mission_*.json")}
    assert {"mission_00000.json", "mission_00001.json"} <= names
    assert "mission_00002.json" not in names and not (out / "results.csv").exists()


# --------------------------------------------------------------------------------------------
# Studies' training runs as Ray tasks (on the module's Ray)


def train_or_die_once(task):
    """A training task whose worker dies (SIGKILL) after its first update the first time.

    Run by Ray workers (imported from this module): the retried task resumes the folder.
    """
    from coma.config import preset
    from coma.learner import train
    from ipp_toolkit.config.files import config_from_dict

    label, values, env, folder, _ = task
    marker = Path(folder).with_name(Path(folder).name + ".killed")
    if label == "killed" and not marker.exists():
        train(preset("cpu", **values), config_from_dict(env), folder, progress=False,
              tensorboard=False, max_updates=1)
        marker.write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)
    return train_run(task)


@pytest.mark.slow
def test_a_credit_study_trains_its_runs_as_ray_tasks(ray_cluster, tmp_path, monkeypatch):
    def no_training_here(*args, **kwargs):
        raise AssertionError("a run was trained in the calling process, not on Ray")

    monkeypatch.setattr("coma.learner.train", no_training_here)  # Ray workers keep theirs
    study = credit_assignment_study(["coma", "decentralised"], missions=2,
                                    overrides=TINY_COMA, train_resolution=1.0, trials=1,
                                    eval_resolution=1.0, out=tmp_path, progress=False,
                                    workers=2, backend="ray")
    assert ray_cluster.is_initialized()  # the module's Ray is used, and left running
    assert study.policies == {v: tmp_path / "runs" / v / "best.pt"
                              for v in ("coma", "decentralised")}
    for variant in ("coma", "decentralised"):
        assert (tmp_path / "runs" / variant / "last.pt").is_file()
        assert study.policies[variant].is_file()
    table = (tmp_path / "credit.md").read_text()
    assert "| coma |" in table and "| decentralised |" in table
    assert len(csv_rows(tmp_path / "compare" / "results.csv")) == 2 * 1 * 16
    # Run again: every run is complete, so each Ray task only resumes and returns.
    stamps = {p: p.stat().st_mtime_ns for p in (tmp_path / "runs").rglob("*.pt")}
    again = credit_assignment_study(["coma", "decentralised"], missions=2,
                                    overrides=TINY_COMA, train_resolution=1.0, trials=1,
                                    eval_resolution=1.0, out=tmp_path, progress=False,
                                    workers=2, backend="ray")
    assert again.table == study.table
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps


@pytest.mark.slow
def test_a_killed_training_worker_is_retried_and_resumes_its_run(ray_cluster, tmp_path):
    import torch

    from coma.persistence import load_policy
    from ipp_toolkit.config.files import config_to_dict
    from reports.studies import training_mission

    env = config_to_dict(training_mission(1.0))
    values = {**TINY_COMA, "missions": 4, "checkpoint_every": 1}  # two updates
    tasks = [(label, values, env, str(tmp_path / label), False)
             for label in ("killed", "straight")]
    policies = train_runs(tasks, 2, RayCluster(ray_cluster, owned=False, address=None),
                           run=train_or_die_once)
    marker = tmp_path / "killed.killed"
    assert marker.exists() and int(marker.read_text()) != os.getpid()  # a worker died ...
    assert policies == {label: tmp_path / label / "best.pt" for label in ("killed", "straight")}
    with open(tmp_path / "killed" / "progress.csv", newline="") as handle:
        assert [int(row["update"]) for row in csv.DictReader(handle)] == [1, 2]  # ... resumed
    killed, _ = load_policy(tmp_path / "killed" / "last.pt")
    straight, _ = load_policy(tmp_path / "straight" / "last.pt")
    for key, value in straight.actor.state_dict().items():  # the same run as without the kill
        assert torch.equal(value, killed.actor.state_dict()[key]), key


@pytest.mark.slow
def test_a_training_error_on_ray_is_the_runs_own_error(ray_cluster, tmp_path):
    from ipp_toolkit.config.files import config_to_dict
    from ipp_toolkit.io import CheckpointError
    from reports.studies import training_mission

    env = config_to_dict(training_mission(1.0))
    task = ("coma", {**TINY_COMA, "missions": 2}, env, str(tmp_path / "run"), False)
    train_runs([task], 1, RayCluster(ray_cluster, owned=False, address=None))
    other = ("coma", {**TINY_COMA, "missions": 2, "lr_actor": 1.0}, env, str(tmp_path / "run"),
             False)
    with pytest.raises(CheckpointError, match="other COMA settings") as caught:
        train_runs([other], 1, RayCluster(ray_cluster, owned=False, address=None))
    assert "RayTaskError" in repr(caught.value.__cause__)  # the remote traceback is chained
