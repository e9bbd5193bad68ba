"""The Ray backend of the evaluation runner: missions flown as Ray tasks, on one machine or many.

:func:`ipp_toolkit.runs.evaluation.evaluate` with ``backend="ray"`` runs its (planner label,
mission) tasks here instead of in :mod:`ipp_toolkit.runs.process_pool`, with the same contract:
every result is handed to ``finish`` in the calling process as it arrives (so the result
folder is written there, one atomic shard per mission, exactly as with the local backend);
on a failed mission no more tasks start, the running ones are awaited and stored, and the
first error is raised; on KeyboardInterrupt the running tasks are cancelled and nothing more
is stored.

* :func:`connect` starts a local Ray (``address=None``: ``num_cpus`` = the workers, no
  dashboard, worker logs not forwarded; shut down at the end) or connects to a running cluster
  (``address="HOST:PORT"`` as printed by ``ray start --head``, ``"ray://HOST:PORT"`` or
  ``"auto"``; only disconnected at the end). An address checked not to answer raises
  :class:`ConnectionError` within seconds instead of letting ``ray.init`` retry for minutes.
* :func:`session` holds one connection for several evaluations (a study's settings, its
  training runs): the evaluations inside reuse it instead of starting their own Ray.
* :func:`run_calls` runs any importable function as Ray tasks with declared CPUs, retried
  when a worker dies (a study's training runs, which resume their folders).
* :func:`run_ray` runs one task per (label, mission), ``num_cpus=1`` each, at most as many at
  once as the cluster has CPUs. A task whose worker process or node dies is retried by Ray
  (:data:`MAX_RETRIES`), so a killed worker loses nothing; a planner's own exception is not
  retried. Each worker process keeps the task runner (and so its built planners) across the
  tasks of one evaluation, runs one thread, and limits BLAS and torch to one thread, as the
  process pool's workers do.
* :func:`check_backend` owns the rule for a backend (:data:`BACKENDS`) and an address, for
  every caller (``evaluate``, ``compare``, the studies, COMA's workers);
  :func:`add_backend_flags` and :func:`check_backend_flags` are its command-line spelling.

Ray is optional (``pip install -c constraints.txt -e ".[ray]"``): this module imports it only
inside :func:`require_ray`, so importing it costs nothing without Ray.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import socket
import sys
import time
import uuid
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import Any

from ..extras import install_command, require_extra
from .process_pool import (
    TaskResult,
    TaskRunner,
    limit_blas_threads,
    limit_torch_threads,
    prepare_worker_process,
    single_thread_variables,
    temporary_environment,
)

__all__ = ["add_backend_flags", "BACKENDS", "check_backend", "check_backend_flags",
           "CONNECT_TIMEOUT_S", "INSTALL_COMMAND", "MAX_RETRIES", "RayCluster",
           "RayUnavailableError", "connect", "probe", "require_ray", "run_calls", "run_ray",
           "session", "start_local"]

INSTALL_COMMAND = install_command("ray")
"""How to install the optional Ray extra (from the repository root)."""

BACKENDS = ("local", "ray")
"""Where work runs (missions of ``evaluate``, a study's runs, COMA's rollout workers): this
machine's processes, or Ray tasks and actors. :func:`check_backend` owns the rule."""

MAX_RETRIES = 3
"""How often Ray reruns a task whose worker process or node died (not a planner's error)."""

CONNECT_TIMEOUT_S = 5.0
"""How long :func:`connect` waits for an address to answer before giving up."""

_CPUS_REREAD_S = 1.0
"""Seconds between two reads of the cluster's CPU count while tasks are submitted."""

_HTTP2_PREFACE = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n"


class RayUnavailableError(ImportError):
    """``backend="ray"`` was asked and Ray cannot be imported; the message says how to install."""


def add_backend_flags(parser: Any, backend_help: str, address_help: str) -> None:
    """The command line's ``--backend local|ray`` and ``--address HOST:PORT`` (one spelling
    for ``ipp-compare``, ``ipp-study`` and ``ipp-train coma``; check them with
    :func:`check_backend_flags`).

    Args:
        parser: an ``argparse.ArgumentParser``.
        backend_help: what runs where, e.g. "where the missions fly: processes on this
            machine, or Ray tasks" (the install note is appended).
        address_help: appended to the address's help after "as printed by `ray start
            --head`", e.g. " (results are written here)".
    """
    parser.add_argument("--backend", choices=BACKENDS, default="local",
                        help=f"{backend_help} (needs the ray extra: {INSTALL_COMMAND}; see "
                             "docs/ray.md)")
    parser.add_argument("--address", default=None, metavar="HOST:PORT",
                        help="with --backend ray: the Ray cluster's head, as printed by `ray "
                             f"start --head`{address_help}; default: start a local Ray with "
                             "--workers CPUs")


def check_backend(backend: str, address: str | None, flags: bool = False) -> None:
    """The one check of a backend and a Ray address, before any work: ``backend`` is one of
    :data:`BACKENDS`, an ``address`` is a non-empty string and needs ``backend="ray"``, and
    ``backend="ray"`` needs Ray installed (even where nothing would run, so a missing Ray is
    reported at once). ``evaluate``, the studies, ``ipp-compare`` and COMA's workers call it.

    Args:
        backend: ``"local"`` or ``"ray"``.
        address: the Ray cluster's ``HOST:PORT``, or None (a local Ray with ``backend="ray"``).
        flags: word the messages as the command line's flags (``--address needs --backend
            ray``) instead of the Python arguments (``address is only used with
            backend='ray'``); see :func:`check_backend_flags`.

    Raises:
        ValueError: an unknown backend, an empty address, or an address without Ray (each
            naming the value).
        RayUnavailableError: ``backend="ray"`` without Ray (the message gives the install
            command).
    """
    backend_name, address_name = ("--backend", "--address") if flags else ("backend", "address")
    if backend not in BACKENDS:
        raise ValueError(f"{backend_name} must be one of {', '.join(BACKENDS)}, got {backend!r}")
    if address is not None and (not isinstance(address, str) or not address.strip()):
        raise ValueError(f"{address_name} must be a non-empty string (a Ray cluster's "
                         f"HOST:PORT), got {address!r}")
    if address is not None and backend != "ray":
        raise ValueError("--address needs --backend ray" if flags else
                         f"address is only used with backend='ray', got backend={backend!r}")
    if backend == "ray":
        require_ray()


def check_backend_flags(backend: str, address: str | None) -> None:
    """Refuse the flags of :func:`add_backend_flags` that cannot run, before any work: the
    command-line wording of :func:`check_backend` (the caller prints the message and exits
    with code 2).

    Raises:
        ValueError: ``--address`` without ``--backend ray``, or an empty ``--address``.
        RayUnavailableError: ``--backend ray`` without Ray (the message gives the install
            command).
    """
    check_backend(backend, address, flags=True)


def require_ray() -> Any:
    """Import and return the ``ray`` module, or raise :class:`RayUnavailableError` naming the
    install command (:func:`~ipp_toolkit.extras.require_extra`)."""
    return require_extra("ray", "the ray backend", INSTALL_COMMAND, package="Ray",
                         error=RayUnavailableError)


# --------------------------------------------------------------------------------------------
# Starting or joining a Ray cluster


def _host_port(address: str) -> tuple[str, int] | None:
    """``(host, port)`` of ``HOST:PORT``, ``[V6]:PORT`` or ``ray://HOST:PORT``; None for a
    name Ray resolves itself (``auto``, ``local``)."""
    text = address.strip()
    if "://" in text:
        scheme, text = text.split("://", 1)
        if scheme != "ray":
            raise ValueError(f"unsupported Ray address {address!r}: give HOST:PORT (as printed "
                             "by `ray start --head`), ray://HOST:PORT or auto")
    if text in ("auto", "local"):
        return None
    host, sep, port = text.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"malformed Ray address {address!r}: give HOST:PORT (as printed by "
                         "`ray start --head`, e.g. 127.0.0.1:6379), ray://HOST:PORT or auto")
    return host, int(port)


def probe(address: str, timeout: float = CONNECT_TIMEOUT_S) -> None:
    """Check that a gRPC server (a Ray head's GCS) answers at ``address``, within ``timeout``.

    ``ray.init`` retries an address that does not answer for minutes; this fails fast.

    Raises:
        ConnectionError: nothing listens there, or what listens does not speak gRPC.
        ValueError: a malformed address.
    """
    target = _host_port(address)
    if target is None:
        return
    hint = ("start a cluster with `ray start --head` and pass the address it prints, or leave "
            "the address out to start a local Ray")
    try:
        with socket.create_connection(target, timeout=timeout) as sock:
            # A gRPC (HTTP/2) server answers the client preface with a SETTINGS frame.
            sock.settimeout(timeout)
            sock.sendall(_HTTP2_PREFACE + bytes([0, 0, 0, 4, 0, 0, 0, 0, 0]))
            header = b""
            deadline = time.monotonic() + timeout
            while len(header) < 9 and time.monotonic() < deadline:
                chunk = sock.recv(9 - len(header))
                if not chunk:
                    break
                header += chunk
    except OSError as err:
        reason = (f"no answer within {timeout:g} s" if isinstance(err, TimeoutError)
                  else err.strerror or str(err))
        raise ConnectionError(f"no Ray cluster answers at {address!r} ({reason}); "
                              f"{hint}") from None
    if len(header) < 9 or header[3] != 4:  # frame type 4: SETTINGS
        raise ConnectionError(f"the server at {address!r} is not a Ray head (it does not "
                              f"speak gRPC); {hint}")


class RayCluster:
    """A Ray connection of one evaluation; :meth:`close` shuts down what :func:`connect` began.

    Attributes:
        ray: the ``ray`` module.
        owned: this evaluation started (or connected) Ray and shuts it down (or disconnects)
            at :meth:`close`; False when the process was already connected.
        address: the address given, None for a local Ray.
    """

    def __init__(self, ray: Any, owned: bool, address: str | None):
        self.ray = ray
        self.owned = owned
        self.address = address

    def cpus(self) -> int:
        """CPUs of the cluster now (nodes may join or leave during a run); at least 1."""
        try:
            return max(1, int(self.ray.cluster_resources().get("CPU", 1)))
        except Exception:  # the head is briefly unreachable: keep going with one slot
            return 1

    def close(self) -> None:
        if self.owned and self.ray.is_initialized():
            self.ray.shutdown()
        self.owned = False


def connect(address: str | None, num_cpus: int) -> RayCluster:
    """Start a local Ray with ``num_cpus`` CPUs (``address=None``) or join the cluster at
    ``address``; a process already connected to Ray keeps its connection.

    Raises:
        RayUnavailableError: Ray is not installed.
        ConnectionError: nothing (or no gRPC server) answers at ``address`` within
            :data:`CONNECT_TIMEOUT_S` seconds.
        ValueError: a malformed address, or ``address`` given while this process is
            connected to another cluster.
    """
    ray = require_ray()
    if address is not None:
        probe(address)
    if ray.is_initialized():
        current = _current_address(ray)
        if address is not None and not _same_cluster(address, current):
            raise ValueError(f"this process is already connected to the Ray cluster at "
                             f"{current!r}, not {address!r}: call ray.shutdown() first, or "
                             "leave the address out to use the current one")
        return RayCluster(ray, owned=False, address=address)
    if address is None:
        start_local(num_cpus)
        return RayCluster(ray, owned=True, address=address)
    refused = (ConnectionError, RuntimeError, getattr(ray.exceptions, "AuthenticationError",
                                                      ConnectionError))
    try:
        ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING)
    except refused as err:
        reason = (str(err).strip().splitlines() or [type(err).__name__])[0]
        hint = ""
        if os.environ.get("RAY_AUTH_MODE") is None:
            hint = ("; a cluster started with token authentication (Ray's default when a token "
                    "exists) needs RAY_AUTH_MODE=token and its token (~/.ray/auth_token or "
                    "RAY_AUTH_TOKEN) in this shell too")
        raise ConnectionError(f"cannot join the Ray cluster at {address!r}: {reason}{hint} "
                              "(see docs/ray.md)") from None
    return RayCluster(ray, owned=True, address=address)


@contextlib.contextmanager
def session(address: str | None, num_cpus: int) -> Iterator[RayCluster]:
    """One Ray for a block of several evaluations (a study): :func:`connect` on entry,
    :meth:`RayCluster.close` on exit (also on an error or Ctrl-C).

    Every ``evaluate(..., backend="ray")`` and :func:`run_calls` inside the block uses this
    connection (:func:`connect` keeps a process's existing connection), so a local Ray is
    started once, not once per evaluation. A process already connected keeps its connection
    after the block.

    Raises:
        as :func:`connect`.
    """
    cluster = connect(address, num_cpus)
    try:
        yield cluster
    finally:
        cluster.close()


def start_local(num_cpus: int) -> None:
    """Start the local Ray of :func:`connect` (``address=None``) in this process.

    ``address="local"``: a new instance even when ``RAY_ADDRESS`` names a cluster; no GPUs,
    no dashboard, worker logs not forwarded, Ray's start-up notes not shown. Its processes
    start with this process's ``sys.path`` as ``PYTHONPATH`` and one thread per library (as
    the process pool's spawned workers do), so a planner defined in a module the caller can
    import (e.g. beside its script) is found as with the local backend.
    """
    ray = require_ray()
    paths = [os.path.abspath(p or os.curdir) for p in sys.path]
    paths = [p for p in dict.fromkeys(paths) if os.path.isdir(p)]
    variables = {**single_thread_variables(), "PYTHONPATH": os.pathsep.join(paths)}
    with temporary_environment(variables):  # inherited by the raylet, so by its workers
        ray.init(address="local", num_cpus=int(num_cpus), num_gpus=0, include_dashboard=False,
                 log_to_driver=False, logging_level=logging.ERROR)


def _current_address(ray: Any) -> str | None:
    try:
        return str(ray.get_runtime_context().gcs_address)
    except Exception:
        return None


def _same_cluster(address: str, current: str | None) -> bool:
    """Whether ``address`` may name the cluster at ``current`` (Ray replaces a loopback host
    by the node's address, so the ports are compared)."""
    target = _host_port(address)
    if target is None or current is None:
        return True
    return current.rpartition(":")[2] == str(target[1])


# --------------------------------------------------------------------------------------------
# Tasks

_RUNNERS: dict[str, TaskRunner] = {}
"""In a Ray worker process: the runner of the evaluation being flown (one at a time)."""


def _prepared(runner: TaskRunner) -> TaskRunner:
    """``runner`` single-threaded, in a worker process set up as every worker is."""
    prepare_worker_process()
    runner.single_thread = True
    return runner


def _fly(token: str, boxed_runner: list[Any], cwd: str, label: str,
         mission: int) -> TaskResult:
    """One Ray task: fly (label, mission) with the worker's cached runner of evaluation
    ``token`` (fetched from the object store on the worker's first task of it).

    The worker first moves to ``cwd``, the calling process's directory, where it exists on
    the worker's node (always on the calling machine; elsewhere with a shared file system),
    so relative paths (checkpoints, terrain files) mean what they mean to the caller.
    """
    runner = _RUNNERS.get(token)
    if runner is None:
        import ray

        if os.path.isdir(cwd):
            os.chdir(cwd)
        runner = _prepared(ray.get(boxed_runner[0]))
        _RUNNERS.clear()  # a worker reused by a later evaluation drops the earlier runner
        _RUNNERS[token] = runner
    return runner.run(label, mission)


_REMOTE: dict[int, Any] = {}


def _remote_fly(ray: Any) -> Any:
    remote = _REMOTE.get(id(ray))
    if remote is None:
        remote = _REMOTE[id(ray)] = ray.remote(num_cpus=1, max_retries=MAX_RETRIES)(_fly)
    return remote


def run_ray(cluster: RayCluster, runner: TaskRunner, tasks: Sequence[tuple[str, int]],
            finish: Callable[[str, int, dict[str, Any]], None], bar: Any) -> None:
    """Fly ``tasks`` as Ray tasks on ``cluster``; ``finish`` stores each result as it arrives.

    Two tasks per CPU of the cluster are in flight, one running and one queued behind it
    (the CPU count is re-read during the run, so nodes that join mid-run are used). On a
    failed mission no more tasks are started, the submitted ones are awaited and stored, and
    the first error is raised (the planner's own exception, its remote traceback chained). On
    KeyboardInterrupt the submitted tasks are cancelled (their workers stopped) and nothing
    more is stored.
    """
    ray = cluster.ray
    fly = _remote_fly(ray)
    token = uuid.uuid4().hex
    runner_ref = ray.put(runner)
    cwd = os.getcwd()

    def submit(task: tuple[str, int]) -> Any:
        return fly.remote(token, [runner_ref], cwd, *task)

    def store(task: tuple[str, int], result: TaskResult) -> None:
        finish(*result)
        bar.update(1)

    def notes(task: tuple[str, int]) -> tuple[str, str]:
        label, mission = task
        return (f"mission {mission} of planner {label!r} was lost: its Ray worker or node died "
                f"{MAX_RETRIES + 1} times (e.g. out of memory, or the node left the cluster); "
                "run the same command again to fly what is missing",
                f"a Ray worker could not fly mission {mission} of planner {label!r}: every "
                "node needs the toolkit and the planner's module importable, at the versions "
                "of this machine (see docs/ray.md)")

    _run_queue(cluster, tasks, submit, store, notes, num_cpus=1, depth=2)


def _call(cwd: str, function: Callable[..., Any], args: tuple[Any, ...]) -> Any:
    """One Ray task of :func:`run_calls`: ``function(*args)`` in ``cwd`` (where it exists on
    the worker's node), single-threaded."""
    if os.path.isdir(cwd):
        os.chdir(cwd)
    os.environ.update(single_thread_variables())
    with limit_blas_threads():
        limit_torch_threads()
        return function(*args)


_REMOTE_CALL: dict[int, Any] = {}


def _remote_call(ray: Any) -> Any:
    remote = _REMOTE_CALL.get(id(ray))
    if remote is None:
        remote = _REMOTE_CALL[id(ray)] = ray.remote(max_retries=MAX_RETRIES)(_call)
    return remote


def run_calls(cluster: RayCluster, function: Callable[..., Any],
              calls: Sequence[tuple[Any, ...]], describe: Callable[[int], str],
              num_cpus: int = 1, done: Callable[[int, Any], None] | None = None) -> list[Any]:
    """Run ``function(*args)`` for every ``args`` of ``calls`` as Ray tasks on ``cluster``.

    The general form of :func:`run_ray` (e.g. the training runs of a study): each call is one
    task declaring ``num_cpus`` CPUs, retried by Ray (:data:`MAX_RETRIES`) when its worker
    process or node dies, so ``function`` must be safe to run again (a training run resumes
    its folder). It runs in the calling process's directory where that exists on the
    worker's node, single-threaded (BLAS, OpenMP, torch). At most as many calls as the
    cluster has CPUs for are in flight; on a failed call no more start, the running ones are
    awaited and the first error is raised (the function's own exception, its remote traceback
    chained); on KeyboardInterrupt the running calls are cancelled.

    ``function`` must be importable by the workers (a module-level function of an installed
    module: Ray sends it by reference). ``describe(k)`` names call ``k`` in error notes
    (e.g. ``"training run 'coma'"``); ``done(k, result)`` is called in this process as each
    call ends.

    Returns:
        the results, in the order of ``calls``.
    """
    ray = cluster.ray
    remote = _remote_call(ray).options(num_cpus=num_cpus)
    cwd = os.getcwd()
    results: dict[int, Any] = {}

    def submit(k: int) -> Any:
        return remote.remote(cwd, function, tuple(calls[k]))

    def store(k: int, result: Any) -> None:
        results[k] = result
        if done is not None:
            done(k, result)

    def notes(k: int) -> tuple[str, str]:
        what = describe(k)
        return (f"{what} was lost: its Ray worker or node died {MAX_RETRIES + 1} times (e.g. "
                "out of memory, or the node left the cluster); run the same command again to "
                "continue it",
                f"a Ray worker could not run {what}: every node needs the toolkit importable, "
                "at the versions of this machine (see docs/ray.md)")

    _run_queue(cluster, range(len(calls)), submit, store, notes, num_cpus=num_cpus)
    return [results[k] for k in range(len(calls))]


def _run_queue(cluster: RayCluster, items: Iterable[Any], submit: Callable[[Any], Any],
               store: Callable[[Any, Any], None], notes: Callable[[Any], tuple[str, str]],
               num_cpus: int, depth: int = 1) -> None:
    """The loop of :func:`run_ray` and :func:`run_calls`: keep ``depth`` items per free slot
    of the cluster (``num_cpus`` CPUs per item) submitted, ``store`` each result as it
    arrives; the first error stops new submissions and is raised once the submitted items
    ended (``notes(item)``: the notes of a lost item and of one a worker could not run);
    KeyboardInterrupt cancels the submitted items.

    ``depth`` 2 keeps a short task queued behind each running one, so a worker starts its
    next mission without waiting for the round trip of the last result to this process
    (about 30 ms a task on a local Ray, as long as a small mission). The cluster's CPU count
    is re-read at most once a second (nodes may join or leave), not after every result.
    """
    ray = cluster.ray
    queue = deque(items)
    running: dict[Any, Any] = {}
    error: BaseException | None = None
    capacity, read_at = 1, -math.inf
    try:
        while queue or running:
            if queue and error is None:
                if time.monotonic() - read_at > _CPUS_REREAD_S:
                    capacity = cluster.cpus() // max(1, num_cpus) * depth
                    read_at = time.monotonic()
                slots = capacity - len(running)
                while queue and (slots > 0 or not running):
                    item = queue.popleft()
                    running[submit(item)] = item
                    slots -= 1
            ready, _ = ray.wait(list(running), num_returns=1)
            for ref in ready:
                item = running.pop(ref)
                try:
                    result = ray.get(ref)
                except Exception as err:  # the task's own error, or a worker lost too often
                    if error is None:
                        error = _unwrap(ray, err, *notes(item))
                        queue.clear()
                    continue
                store(item, result)
    except BaseException:
        for ref in running:
            with contextlib.suppress(Exception):  # already finished, or its worker gone
                ray.cancel(ref, force=True)
        raise
    if error is not None:
        raise error


def _unwrap(ray: Any, err: Exception, lost_note: str, import_note: str) -> BaseException:
    """The task's own exception of a failed task (its remote traceback chained), or the Ray
    error with a note saying what was lost (``lost_note``) or could not run
    (``import_note``)."""
    exceptions = ray.exceptions
    cause = getattr(err, "cause", None)
    if isinstance(err, exceptions.RayTaskError) and isinstance(cause, Exception):
        cause.__cause__ = err
        return cause
    lost = tuple(getattr(exceptions, name) for name in (
        "WorkerCrashedError", "NodeDiedError", "OutOfMemoryError", "ObjectLostError",
        "TaskUnschedulableError") if hasattr(exceptions, name))
    err.add_note(lost_note if isinstance(err, lost) else import_note)
    return err
