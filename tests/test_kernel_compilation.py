"""Compiling the mission kernels ahead, and sharing that work between a pool's workers."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

import pytest

from ipp_toolkit._native import kernels
from ipp_toolkit.runs.process_pool import WorkerPool

needs_numba = pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not importable")

# Flies one mission of every default planner of ipp-compare in a fresh interpreter (no other
# test's calls in its kernels), then prints the argument types each public kernel of the
# three compiled modules was called with, and those mission_kernels() declares. In memory:
# the files and figures of an output folder call no kernel (and drawing them took two thirds
# of the time).
_FLOWN_TYPES = """
import json
from ipp_toolkit._native import kernels
from reports.compare import compare

compare(trials=1, workers=1, progress=False)
flown, declared = {}, {}
for module in (kernels._compiled(), kernels._compiled_step(), kernels._compiled_noise()):
    for name, value in vars(module).items():
        if not name.startswith("_") and getattr(value, "signatures", None):
            flown[name] = sorted(str(types) for types in value.signatures)
for kernel, types in kernels.mission_kernels():
    declared.setdefault(kernel.__name__, []).append(str(types))
print(json.dumps({"flown": flown, "declared": {k: sorted(v) for k, v in declared.items()}}))
"""


@pytest.mark.slow  # every default planner flies in a fresh interpreter
@needs_numba
def test_mission_kernels_declares_exactly_the_kernels_and_types_missions_fly():
    environment = {k: v for k, v in os.environ.items() if k != "IPP_TOOLKIT_NO_NUMBA"}
    done = subprocess.run([sys.executable, "-c", _FLOWN_TYPES], capture_output=True,
                          text=True, env=environment, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    found = json.loads(done.stdout.strip().splitlines()[-1])
    assert found["flown"] == found["declared"]
    assert "fuse_evidence" in found["flown"]


def test_a_pools_workers_compile_the_kernels_between_them():
    pool = WorkerPool(2)
    try:
        pool.call(os.getpid)  # one worker has started
        deadline = time.monotonic() + 120
        while pool.kernels_finished.value < 2 and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        pool.close()
    assert pool.kernels_finished.value == 2
    # Every kernel taken once, and one claim past the end by each worker; without Numba none.
    expected = len(kernels.mission_kernels()) + 2 if kernels.AVAILABLE else 0
    assert pool.kernels_claimed.value == expected


@pytest.mark.slow  # compiles every kernel into an empty cache; the sharing is tested above
@needs_numba
def test_a_worker_that_compiled_waits_for_the_others_then_goes_on_alone():
    # A fresh interpreter with an empty cache folder compiles (its share is every kernel, as
    # the sibling never comes) and waits for it (0.5 s here); with the cache full it loads
    # them and does not wait.
    script = (
        "import multiprocessing, sys, time\n"
        "from ipp_toolkit.runs.process_pool import _compile_kernels_together\n"
        "values = [multiprocessing.Value('i', 0) for _ in range(2)]\n"
        "start = time.monotonic()\n"
        "compiled = _compile_kernels_together(*values, 2, wait_s=0.5)\n"
        "print(compiled, values[0].value, values[1].value, time.monotonic() - start)\n")
    runs, notes = [], []
    with tempfile.TemporaryDirectory() as cache:
        environment = {**os.environ, "NUMBA_CACHE_DIR": cache}
        for _ in range(2):
            done = subprocess.run([sys.executable, "-c", script], capture_output=True,
                                  text=True, env=environment, timeout=300, check=False)
            assert done.returncode == 0, done.stderr[-2000:]
            runs.append(done.stdout.split())
            notes.append(kernels.COMPILE_NOTE in done.stderr)
    assert notes == [True, False]  # said when it compiles, not when it loads
    total = len(kernels.mission_kernels())
    (compiled, claimed, finished, waited), (cached, claimed_again, _, _) = runs
    assert int(compiled) == total and int(cached) == 0
    assert float(waited) >= 0.5  # the whole wait: the sibling never finished
    assert int(claimed) == int(claimed_again) == total + 1 and int(finished) == 1


def test_one_worker_compiles_on_first_use_as_before():
    pool = WorkerPool(1)
    try:
        pool.call(os.getpid)
    finally:
        pool.close()
    assert pool.kernels_claimed.value == 0


class _FakeKernel:
    """A stand-in for a Numba dispatcher: counts its compiles, each a cache miss."""

    def __init__(self, name: str) -> None:
        self.__name__ = name
        self.compiled = 0
        self.stats = type("Stats", (), {"cache_misses": {}})()

    def compile(self, types: tuple) -> None:
        self.compiled += 1
        self.stats.cache_misses[types] = 1


@pytest.fixture
def fake_kernels(monkeypatch):
    """Three fake mission kernels; ``uncached`` names those Numba's cache does not hold."""
    found = [(_FakeKernel(name), (name,)) for name in ("a", "b", "c")]
    uncached: set[str] = set()
    monkeypatch.setattr(kernels, "AVAILABLE", True)
    monkeypatch.setattr(kernels, "mission_kernels", lambda: found)
    monkeypatch.setattr(kernels, "cached", lambda kernel, types: kernel.__name__ not in uncached)
    return found, uncached


def test_a_compile_is_announced_once_and_a_load_not_at_all(fake_kernels, capsys):
    found, uncached = fake_kernels
    said = []
    kernels.compile_mission_kernels(announce=lambda: said.append(1))
    assert said == [] and all(kernel.compiled == 1 for kernel, _ in found)  # all loads
    uncached.update({"b", "c"})
    kernels.compile_mission_kernels(announce=lambda: said.append(1))
    assert said == [1]  # once, before the first kernel that compiles
    kernels.compile_mission_kernels(announce=kernels.print_compile_note)
    assert capsys.readouterr().err == kernels.COMPILE_NOTE + "\n"


def test_a_pools_workers_say_once_between_them_that_they_compile(fake_kernels, capsys):
    import multiprocessing

    from ipp_toolkit.runs.process_pool import _compile_kernels_together

    _, uncached = fake_kernels
    uncached.update({"a", "b", "c"})
    claimed, finished, announced = (multiprocessing.Value("i", 0) for _ in range(3))
    for _ in range(2):  # two workers, one after the other here; each takes what is left
        claimed.value = 0
        _compile_kernels_together(claimed, finished, 2, wait_s=0.0, announced=announced)
    assert capsys.readouterr().err.count(kernels.COMPILE_NOTE) == 1


@needs_numba
def test_cached_tells_a_compile_from_a_load(tmp_path):
    # A one-line kernel in its own module and an empty cache folder: not cached, compiled
    # (cached in this process), then in a fresh interpreter loaded from the disk cache.
    (tmp_path / "tiny_kernel.py").write_text(
        "from numba import njit\n\n\n@njit(cache=True)\ndef add(a, b):\n    return a + b\n")
    script = ("import sys\n"
              f"sys.path.insert(0, {str(tmp_path)!r})\n"
              "from numba import types\n"
              "import tiny_kernel\n"
              "from ipp_toolkit._native.kernels import cached\n"
              "argument_types = (types.int64, types.int64)\n"
              "before = cached(tiny_kernel.add, argument_types)\n"
              "tiny_kernel.add.compile(argument_types)\n"
              "print(before, cached(tiny_kernel.add, argument_types))\n")
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    runs = []
    for _ in range(2):
        done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                              env=environment, timeout=120, check=False)
        assert done.returncode == 0, done.stderr[-2000:]
        runs.append(done.stdout.split())
    assert runs == [["False", "True"], ["True", "True"]]
