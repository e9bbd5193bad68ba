"""Tests of the Ray backend (``evaluate(..., backend="ray")``, ``ipp-compare --backend ray``).

The tests that need a running Ray are marked slow and share one local Ray (2 CPUs) per module;
every test that needs Ray installed is skipped without it (``pip install -c constraints.txt
-e ".[ray]"``). Missing Ray is simulated by making it unimportable, so that test always runs.
"""

from __future__ import annotations

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

from ipp_toolkit.config import EnvConfig
from ipp_toolkit.evaluation import evaluate, load_results
from ipp_toolkit.planner_specs import PlannerSpec
from ipp_toolkit.planners import Planner, register_planner
from ipp_toolkit.ray_backend import RayUnavailableError, probe, start_local
from ipp_toolkit.seeding import planner_seed
from reports.cli import compare_main


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


@pytest.mark.parametrize(("argv", "message"), [
    (["--address", "127.0.0.1:6379"], "--address needs --backend ray"),
    (["--backend", "dask"], "invalid choice: 'dask'"),
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


def test_the_toolkit_does_not_import_ray():
    code = ("import sys, ipp_toolkit.evaluation, ipp_toolkit.ray_backend, reports.cli, "
            "reports.compare; print('ray' in sys.modules)")
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
