"""The process pool of the evaluation runner: tasks flown in spawned, single-threaded workers.

This module owns how :func:`ipp_toolkit.runs.evaluation.evaluate` runs with ``workers > 1``: a
"spawn" process pool (:class:`WorkerPool`) whose workers run one intra-op thread
(:func:`single_thread_environment`, :func:`limit_torch_threads`) and keep the task runner
that comes with their tasks (pickled once, unpickled once per worker); which planner
factories can travel to a worker (:func:`transferable_factory`); and :func:`run_parallel`,
which stores results as they arrive and, on a failed task, keeps the finished ones and raises
the first error. The runner itself (what one task does) belongs to the evaluation module; any
object with ``single_thread`` and ``run(label, mission)`` serves.

A pool can be started ahead of its tasks (``ipp-compare`` starts it first): its workers
spawn and import the planners' modules (torch, SB3) at once, and one of them can build and
check the planners (:meth:`WorkerPool.call`) before the tasks come, so the main process never
imports those modules. The workers of a pool also share the compiling of the simulator's
kernels when Numba's cache does not hold them yet (the first run of a checkout): each takes
kernels from a shared counter and, if it compiled any, waits for the others to finish
(:func:`_compile_kernels_together`).
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import importlib
import multiprocessing
import os
import pickle
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, Protocol

from .._native import kernels
from ..planning import (
    PlannerFactory,
    entry_point_planners,
    planner_factory,
    planners_in_process,
)
from ..planning.specs import PlannerSpec

__all__ = ["TaskRunner", "WorkerPool", "children_ignore_sigint", "stop_workers", "guard_worker",
           "limit_blas_threads", "limit_torch_threads", "retain_freed_memory",
           "prepare_worker_process", "single_thread_environment", "single_thread_process",
           "single_thread_variables",
           "temporary_environment", "transferable_factory", "run_parallel"]

_THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")

TaskResult = tuple[str, int, dict[str, Any]]
"""What a task gives back: (planner label, mission index, the mission's result)."""


class TaskRunner(Protocol):
    """Flies one (label, mission) task; picklable, sent to every worker once."""

    single_thread: bool

    def run(self, label: str, mission: int) -> TaskResult: ...


def limit_blas_threads() -> Any:
    """One thread for NumPy's BLAS in this process (a context manager restores the old count).

    The toolkit's matrix products are small and many (footprint sums, smoothing): on a
    2-core machine OpenBLAS's threads made them ten times slower than one thread (measured
    in experiments/performance/README.md), and processes, not threads, are its parallelism.
    The CLI, the
    trainers and the evaluation workers call this; :func:`ipp_toolkit.runs.evaluation.evaluate`
    uses it as a context manager in the calling process.
    """
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


#: glibc's ``mallopt`` parameters (malloc.h).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3


def retain_freed_memory() -> bool:
    """Let this process reuse the memory it frees instead of handing it back (glibc only).

    A mission allocates its maps afresh (about 40 MB at r_M = 0.1 m: five belief arrays, the
    gain cache) and frees them when it ends. glibc gives blocks that large back to the kernel
    at once, so every mission's arrays were new pages for the kernel to map and zero again:
    about 13 ms of system time per mission on the 2-core VM (380,000 page faults in 93
    missions, 58,000 with this). Served from the heap instead, and the heap never trimmed, a
    worker reuses the same memory mission after mission and keeps its peak size until it
    exits. The trainers call it too: it spares their first updates the page faults of their
    activations and planes (tens of MB each), though their steady rate moved by only about
    3 %, within the machine's drift (experiments/performance/README.md). Memory only: no
    number changes.

    Returns:
        whether the allocator took the settings (False off glibc, e.g. macOS or musl).
    """
    import ctypes
    import platform

    if platform.libc_ver()[0] != "glibc":
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    # The largest threshold glibc accepts on 64-bit systems; a mission's arrays are smaller.
    return bool(mallopt(_M_MMAP_THRESHOLD, 32 * 1024 * 1024)
                and mallopt(_M_TRIM_THRESHOLD, 1 << 30))


def limit_torch_threads() -> None:
    """One intra-op thread for torch, if a planner imported it (it is never imported here)."""
    torch = sys.modules.get("torch")
    if torch is not None:
        with contextlib.suppress(Exception):
            if torch.get_num_threads() != 1:
                torch.set_num_threads(1)



_WORKER: TaskRunner | None = None
_WORKER_RUNNER: bytes | None = None  # the pickled runner _WORKER was made from
_PARENT_POLL_S = 1.0


def _exit_with_parent(parent: int) -> None:
    """Leave as soon as the process that started this worker is gone (killed, crashed)."""
    while True:
        time.sleep(_PARENT_POLL_S)
        if os.getppid() != parent:
            os._exit(1)


def guard_worker(parent: int) -> None:
    """In a pool worker: ignore Ctrl-C (the main process handles it) and exit with ``parent``.

    Call it first thing in a pool's initializer, with the main process's PID passed in its
    ``initargs``. It exits at once when that process is already gone.
    """
    if os.getppid() != parent:
        os._exit(1)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    threading.Thread(target=_exit_with_parent, args=(parent,), daemon=True).start()


#: How long a worker that compiled kernels waits for the others to finish theirs: long enough
#: for a slow machine's whole share, short enough that a sibling that never starts (it failed
#: to import something) costs only this once.
_COMPILE_WAIT_S = 60.0


def _compile_kernels_together(claimed: Any, finished: Any, workers: int,
                              wait_s: float = _COMPILE_WAIT_S, announced: Any = None) -> int:
    """Take a share of the mission kernels to compile; if any had to be compiled, wait for
    the other workers to finish their share.

    Every worker would otherwise compile all of them on its first mission, at the same time
    as the others (7 s on the development VM, the first time a checkout runs); shared, each
    compiles about 1 / n of them and loads the rest from Numba's cache. Once cached, each
    worker loads its share and goes on without waiting (a wait for the slowest worker's
    start cost about 0.2 s a run). ``claimed`` and ``finished`` are shared integers: the
    next kernel to take, and how many workers are done taking. Returns how many kernels this
    worker compiled. A kernel that fails to compile here fails the mission that calls it,
    with its own error. The first worker to meet a kernel that is not in Numba's cache says
    so on stderr (:data:`~ipp_toolkit._native.kernels.COMPILE_NOTE`), once for the pool:
    ``announced`` is a shared flag (None: this worker says it if it compiles).
    """
    def claim() -> int:
        with claimed.get_lock():
            claimed.value += 1
            return claimed.value - 1

    def announce() -> None:
        if announced is not None:
            with announced.get_lock():
                if announced.value:
                    return
                announced.value = 1
        kernels.print_compile_note()

    compiled = 0
    with contextlib.suppress(Exception):  # see above: the mission reports it
        compiled = kernels.compile_mission_kernels(claim, announce)
    with finished.get_lock():
        finished.value += 1
    deadline = time.monotonic() + wait_s
    while compiled and finished.value < workers and time.monotonic() < deadline:
        time.sleep(0.01)
    return compiled


def _init_worker(parent: int, modules: tuple[str, ...],
                 kernel_share: tuple[Any, Any, int, Any] | None) -> None:
    """Process-pool initializer: one thread per worker, take a share of the kernels
    (``kernel_share``: :func:`_compile_kernels_together`'s counters, the number of workers
    and the shared flag of its note; None: each on first use), then import ``modules`` ahead.
    The kernels first: a first run says that it compiles within seconds of its start, not
    after the planners' imports (torch, SB3).

    Ctrl-C reaches every process of the terminal's group; only the main process handles it
    (it stops the pool), so a worker ignores it instead of printing its own traceback. A
    worker whose main process (``parent``) was killed outright exits on its own (a watcher
    thread). ``parent`` comes from the main process, not from ``os.getppid()`` here: a worker
    still starting when the main process died has already been handed to another parent,
    and would wait for tasks forever (every worker holds the task queue's write end).
    """
    guard_worker(parent)
    prepare_worker_process()
    if kernel_share is not None:
        claimed, finished, workers, announced = kernel_share
        _compile_kernels_together(claimed, finished, workers, announced=announced)
    for module in modules:
        # Ahead of the tasks only: a module that fails to import fails the task that needs
        # it, with the planner's own error.
        with contextlib.suppress(Exception):
            importlib.import_module(module)


def _worker_ready() -> None:
    """The task each worker is started with (the pool spawns a process per pending task)."""


def _worker_task(runner: bytes, label: str, mission: int) -> TaskResult:
    """Fly one task with the pickled ``runner``, unpickled once per worker and kept."""
    global _WORKER, _WORKER_RUNNER
    if runner != _WORKER_RUNNER:
        _WORKER = pickle.loads(runner)
        _WORKER.single_thread = True
        _WORKER_RUNNER = runner
    assert _WORKER is not None
    return _WORKER.run(label, mission)


class WorkerPool:
    """Spawned, single-threaded worker processes, started now for tasks to come.

    The workers start at once (one pending no-op task each) and import ``modules`` (e.g.
    :func:`ipp_toolkit.planning.planner_modules`), so a caller can start the pool, do its own
    start-up, then hand the pool to :func:`run_parallel` (through ``evaluate(pool=...)``),
    which shuts it down.
    :meth:`close` stops the workers of a pool that was not used (call it in a ``finally``).
    With more than one worker, each takes a share of the simulator's kernels to compile or
    load as it starts (:func:`_compile_kernels_together`): ``kernels_claimed`` counts the
    kernels taken (plus one claim past the end per worker), ``kernels_finished`` the
    workers done taking.
    """

    def __init__(self, n_workers: int, modules: Sequence[str] = ()) -> None:
        if n_workers < 1:
            raise ValueError(f"n_workers must be >= 1, got {n_workers}")
        self.n_workers = n_workers
        context = multiprocessing.get_context("spawn")
        # One process per worker, each starting with a share of the kernels to compile.
        self.kernels_claimed = context.Value("i", 0)
        self.kernels_finished = context.Value("i", 0)
        self.kernels_announced = context.Value("i", 0)  # the compile note, said once
        kernel_share = ((self.kernels_claimed, self.kernels_finished, n_workers,
                         self.kernels_announced) if n_workers > 1 else None)
        self.executor = concurrent.futures.ProcessPoolExecutor(
            max_workers=n_workers, mp_context=context,
            initializer=_init_worker, initargs=(os.getpid(), tuple(modules), kernel_share))
        # Workers inherit one thread each and an ignored Ctrl-C (a worker still importing
        # when it comes would otherwise print a traceback).
        with single_thread_environment(), children_ignore_sigint():
            for _ in range(n_workers):
                self.executor.submit(_worker_ready)

    def call(self, function: Callable[..., Any], *args: Any) -> Any:
        """``function(*args)`` in one of the workers (once it has started); its result, or its
        exception raised here. ``function`` and ``args`` travel pickled (a function by
        reference: it must be importable by the worker)."""
        return self.executor.submit(function, *args).result()

    def close(self) -> None:
        """Stop the workers now (nothing if :func:`run_parallel` already shut the pool)."""
        stop_workers(self.executor)


@contextlib.contextmanager
def temporary_environment(variables: Mapping[str, str]) -> Iterator[None]:
    """Set environment ``variables`` for the block (child processes started in it inherit
    them), then restore the old values."""
    saved = {name: os.environ.get(name) for name in variables}
    try:
        os.environ.update(variables)
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def single_thread_variables() -> dict[str, str]:
    """The thread-count variables of a single-threaded worker (OpenMP, MKL, OpenBLAS)."""
    return dict.fromkeys(_THREAD_VARIABLES, "1")


def single_thread_process() -> None:
    """Make this worker process single-threaded for good: the thread-count variables (for
    libraries it imports later), BLAS (threadpoolctl) and torch, if imported. Every kind of
    worker (pool processes, Ray tasks and actors, COMA's rollout workers) starts with it
    (through :func:`prepare_worker_process`)."""
    os.environ.update(single_thread_variables())
    limit_blas_threads()
    limit_torch_threads()


def prepare_worker_process() -> None:
    """Set up a process that works for another one: single-threaded for good
    (:func:`single_thread_process`) and keeping the memory it frees for its next task
    (:func:`retain_freed_memory`). Every kind of worker starts with it: evaluation pool
    processes and Ray mission tasks, COMA's rollout processes and Ray actors."""
    single_thread_process()
    retain_freed_memory()


def single_thread_environment() -> contextlib.AbstractContextManager[None]:
    """Set the thread-count variables while worker processes start (they inherit them)."""
    return temporary_environment(single_thread_variables())


def transferable_factory(spec: PlannerSpec) -> PlannerFactory | None:
    """The factory of ``spec`` to send to worker processes (pickled by reference).

    None when a worker finds the planner by itself (an entry point this process has not
    loaded, or one whose factory cannot travel); an entry point is not loaded here for this.

    Raises:
        ValueError: the factory lives where a spawned worker cannot import it (a local
            scope, or ``__main__`` of an interactive session or notebook).
    """
    entry_points = entry_point_planners()
    if spec.name in entry_points and spec.name not in planners_in_process():
        return None
    factory = planner_factory(spec.name)
    main = sys.modules.get("__main__")
    importable = not (getattr(factory, "__module__", None) == "__main__"
                      and getattr(main, "__file__", None) is None)
    if importable:
        try:
            pickle.dumps(factory)
        except Exception:
            importable = False
    if importable:
        return factory
    if spec.name in entry_points:
        return None
    raise ValueError(f"planner {spec.name!r} is registered by "
                     f"{getattr(factory, '__qualname__', factory)!r}, which worker processes "
                     "cannot import (a local or interactive definition): define it in an "
                     "importable module, or use workers=1")


# --------------------------------------------------------------------------------------------
# Results


def run_parallel(runner: TaskRunner, tasks: Sequence[tuple[str, int]], n_workers: int,
                 finish: Callable[[str, int, dict[str, Any]], None], bar: Any,
                 pool: WorkerPool | None = None) -> None:
    """Fly ``tasks`` in a spawn process pool; ``finish`` stores each result as it arrives.

    ``pool``: workers started ahead (else ``n_workers`` are started now); it is shut down
    when the tasks are done. On a failed mission the pending tasks are cancelled, the
    running ones are awaited and stored, and the first error is raised. On
    KeyboardInterrupt nothing more is stored.
    """
    futures: list[concurrent.futures.Future] = []
    stored: set[concurrent.futures.Future] = set()
    error: BaseException | None = None
    executor = (pool if pool is not None else WorkerPool(n_workers)).executor
    try:
        blob = pickle.dumps(runner)  # sent with every task (a few kB), unpickled once
        futures = [executor.submit(_worker_task, blob, label, mission)
                   for label, mission in tasks]
        for future in concurrent.futures.as_completed(futures):
            if future.exception() is not None:
                error = future.exception()
                break
            finish(*future.result())
            stored.add(future)
            bar.update(1)
    except BaseException:
        stop_workers(executor)
        raise
    executor.shutdown(wait=True, cancel_futures=True)
    if error is not None:
        if isinstance(error, concurrent.futures.process.BrokenProcessPool):
            error.add_note("a worker process of the evaluation died: it could not start (e.g. "
                           "it failed to import a planner) or was killed (e.g. out of memory)")
        for future in futures:
            if (future not in stored and future.done() and not future.cancelled()
                    and future.exception() is None):
                finish(*future.result())
                bar.update(1)
        raise error


@contextlib.contextmanager
def children_ignore_sigint() -> Iterator[None]:
    """Ignore SIGINT while child processes start, so they begin with it ignored.

    An ignored signal stays ignored across exec, and Python keeps it so at start-up. The main
    process ignores Ctrl-C only for the few milliseconds of the submissions.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def stop_workers(executor: concurrent.futures.ProcessPoolExecutor) -> None:
    """Shut the pool down now: cancel its pending tasks and terminate its workers (an
    interrupt: their running missions are dropped).

    ``shutdown(cancel_futures=True)`` only cancels tasks not yet started; the running ones
    would hold the terminal until they end. The executor exposes no public way to stop them,
    so its process table and manager thread are read defensively, and before ``shutdown``,
    which drops both.
    """
    processes = list((getattr(executor, "_processes", None) or {}).values())
    manager = getattr(executor, "_executor_manager_thread", None)
    executor.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        with contextlib.suppress(Exception):
            process.terminate()
    # Let the pool's manager thread see its workers gone and close its pipes now: left to the
    # interpreter's exit, concurrent.futures' exit hook could wake it while it closes them
    # and print a traceback ("Bad file descriptor") after the one-line interrupt message.
    if manager is not None:
        with contextlib.suppress(Exception):
            manager.join(timeout=10)
