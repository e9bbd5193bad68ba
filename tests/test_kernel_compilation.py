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
    runs = []
    with tempfile.TemporaryDirectory() as cache:
        environment = {**os.environ, "NUMBA_CACHE_DIR": cache}
        for _ in range(2):
            done = subprocess.run([sys.executable, "-c", script], capture_output=True,
                                  text=True, env=environment, timeout=300, check=False)
            assert done.returncode == 0, done.stderr[-2000:]
            runs.append(done.stdout.split())
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
