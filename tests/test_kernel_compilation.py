"""Compiling the mission kernels ahead, and sharing that work between a pool's workers."""

from __future__ import annotations

import json
import multiprocessing
import os
import subprocess
import sys
import time

import pytest

from ipp_toolkit import kernels
from ipp_toolkit.process_pool import WorkerPool, _compile_kernels_together

needs_numba = pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not importable")

# Flies one mission of every default planner of ipp-compare in a fresh interpreter (no other
# test's calls in its kernels), then prints the argument types each public kernel of the
# three compiled modules was called with, and those mission_kernels() declares.
_FLOWN_TYPES = """
import json, sys, tempfile
from pathlib import Path
from ipp_toolkit import kernels
from reports.compare import compare

with tempfile.TemporaryDirectory() as folder:
    compare(trials=1, workers=1, out=Path(folder) / "out", progress=False)
flown, declared = {}, {}
for module in (kernels._compiled(), kernels._compiled_step(), kernels._compiled_noise()):
    for name, value in vars(module).items():
        if not name.startswith("_") and getattr(value, "signatures", None):
            flown[name] = sorted(str(types) for types in value.signatures)
for kernel, types in kernels.mission_kernels():
    declared.setdefault(kernel.__name__, []).append(str(types))
print(json.dumps({"flown": flown, "declared": {k: sorted(v) for k, v in declared.items()}}))
"""


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
        pool.call(os.getpid)  # its worker is past the barrier: both have taken their share
    finally:
        pool.close()
    # Every kernel taken once, and one claim past the end by each worker; without Numba none.
    expected = len(kernels.mission_kernels()) + 2 if kernels.AVAILABLE else 0
    assert pool.kernels_claimed.value == expected


def test_a_worker_whose_siblings_never_come_compiles_all_and_goes_on():
    context = multiprocessing.get_context("spawn")
    claimed, everyone = context.Value("i", 0), context.Barrier(2)
    started = time.monotonic()
    taken = _compile_kernels_together(claimed, everyone, wait_s=0.2)
    assert time.monotonic() - started < 60
    assert everyone.broken
    assert taken == (len(kernels.mission_kernels()) if kernels.AVAILABLE else 0)


def test_one_worker_compiles_on_first_use_as_before():
    pool = WorkerPool(1)
    try:
        pool.call(os.getpid)
    finally:
        pool.close()
    assert pool.kernels_claimed.value == 0
