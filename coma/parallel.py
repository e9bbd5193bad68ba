"""COMA's rollouts and validation missions on K workers: this process, local processes, Ray.

The learner (``coma.learner``) asks a :class:`Workers` for each update's rollout and for the
greedy flights of each validation; the update itself stays in the learner's process (on its
``device``). The missions of a call are split into at most K consecutive blocks
(:func:`split_missions`, at the boundaries of the groups of missions the actor scores
together), each block is flown by one worker with a CPU copy of the actor, and the blocks are
joined in mission order. Every mission samples from its own stream
(:func:`coma.rollout.sampling_generator`) and is scored beside the same missions wherever it
flies, so the joined rollout is the one a single process flies, bit for bit, whatever K and
the backend: a run's weights do not depend on them (``tests/test_coma_workers.py``; on
machines of one kind: two CPU models may round the same network differently).

* :class:`InProcess` (``workers=1``, the local backend): no worker process. The learner's own
  networks fly when they are on the CPU (exactly the path of a run without workers); a CPU
  copy of the actor when they are on a GPU.
* :class:`ProcessWorkers` (``workers=K > 1``, the local backend): a "spawn" process pool kept
  for the whole run, each worker with one torch, BLAS and OpenMP thread
  (``ipp_toolkit.runs.process_pool``) and its own copy of the networks and geometries. A worker
  that dies (killed, out of memory) breaks the pool: a new pool flies the call's blocks again,
  up to :data:`MAX_RETRIES` times.
* :class:`RayWorkers` (``backend="ray"``): K Ray actors of one CPU each, on a local Ray with K
  CPUs or on a cluster (``address``); each holds its networks and geometries, and gets the
  actor's weights with every call (one object in Ray's store per call). An actor whose process
  or node dies is restarted by Ray and its call run again (up to :data:`MAX_RETRIES` times).
  Every actor must find a free CPU: on a cluster with fewer free CPUs than K the run waits.

:func:`make_workers` builds the right one; a :class:`Workers` is a context manager that stops
its processes (or actors) at the end.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import multiprocessing
import os
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import torch

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.runs.process_pool import (
    children_ignore_sigint,
    guard_worker,
    prepare_worker_process,
    single_thread_environment,
    stop_workers,
)
from ipp_toolkit.runs.ray_backend import check_backend
from ipp_toolkit.sim.mission import MissionGeometry

from .config import COMAConfig
from .networks import ConvNet
from .persistence import COMANetworks, build_networks
from .rollout import Rollout, actor_batches, collect_rollout
from .validation import GreedyFlights, fly_greedy

__all__ = ["MAX_RETRIES", "RunSpec", "RolloutWorker", "Workers", "InProcess",
           "ProcessWorkers", "RayWorkers", "make_workers", "split_missions", "to_channels_last",
           "resolve_device", "check_workers", "cpu_actor_state"]

MAX_RETRIES = 3
"""How often a call is flown again after a worker died (the local pool; Ray's own retries of
an actor's call: ``ipp_toolkit.runs.ray_backend.MAX_RETRIES``)."""


def to_channels_last(networks: COMANetworks) -> None:
    """Train every convolution channels-last (:meth:`ConvNet.use_channels_last`); the
    workers' copies of the actor use the same layout, so they compute the same numbers."""
    for network in (networks.actor, networks.critic, networks.value):
        if network is not None:
            for module in network.modules():
                if isinstance(module, ConvNet):
                    module.use_channels_last()


def resolve_device(device: str | torch.device) -> torch.device:
    """The learner's device: ``cpu`` or ``cuda`` (``cuda:N``), checked to exist here.

    Raises:
        ValueError: another name, or ``cuda`` on a machine without a usable CUDA device
            (naming the value and why).
    """
    try:
        resolved = torch.device(device)
    except (RuntimeError, TypeError):
        raise ValueError(f"device {device!r}: choose cpu or cuda") from None
    if resolved.type == "cpu":
        return resolved
    if resolved.type != "cuda":
        raise ValueError(f"device {device!r}: choose cpu or cuda")
    if not torch.cuda.is_available():
        why = ("this torch is built without CUDA" if torch.version.cuda is None
               else "no CUDA device is visible")
        raise ValueError(f"device {str(device)!r}: {why} (torch {torch.__version__}); train "
                         "with --device cpu")
    if resolved.index is not None and resolved.index >= torch.cuda.device_count():
        raise ValueError(f"device {str(device)!r}: this machine has "
                         f"{torch.cuda.device_count()} CUDA device(s)")
    return resolved


def split_missions(first_mission: int, n_missions: int, parts: int) -> list[tuple[int, int]]:
    """``(first, count)`` of at most ``parts`` consecutive, non-empty blocks covering missions
    ``first_mission .. first_mission + n_missions - 1``, cut only between the groups the actor
    scores together (:func:`coma.rollout.actor_batches`), each cut at the group boundary
    nearest an even split."""
    edges = [first_mission + a for a, _ in actor_batches(first_mission, n_missions)[1:]]
    bounds = [first_mission]
    for k in range(1, parts):
        ideal = first_mission + n_missions * k / parts
        later = [edge for edge in edges if edge > bounds[-1]]
        if not later:
            break
        bounds.append(min(later, key=lambda edge: (abs(edge - ideal), edge)))
    bounds.append(first_mission + n_missions)
    return [(start, stop - start) for start, stop in zip(bounds[:-1], bounds[1:], strict=True)]


@dataclass(frozen=True)
class RunSpec:
    """What every worker needs to fly a run's missions (sent to each worker once).

    Attributes:
        coma_config: the run's hyper-parameters (the actor's architecture).
        env_config: the mission the networks are built for.
        settings: the training settings (``coma.config.mission_settings``).
        checks: the validation settings (``coma.validation.validation_settings``).
        seed: the run seed.
    """

    coma_config: COMAConfig
    env_config: EnvConfig
    settings: tuple[EnvConfig, ...]
    checks: tuple[EnvConfig, ...]
    seed: int


class RolloutWorker:
    """One worker's state: CPU networks in the learner's layout and the missions' geometries.

    Built once per worker; every call brings the actor's weights (a state dict of CPU
    tensors), so a worker restarted from scratch flies the same missions the same way.
    """

    def __init__(self, spec: RunSpec,
                 geometries: dict[tuple[str, int], MissionGeometry] | None = None):
        self.spec = spec
        self.networks: COMANetworks | None = None
        self._geometries = dict(geometries or {})

    def geometry(self, kind: str, k: int) -> MissionGeometry:
        """The geometry of training setting ``k`` (``kind="train"``) or validation setting
        ``k`` (``kind="check"``), built on first use."""
        key = (kind, k)
        if key not in self._geometries:
            configs = self.spec.settings if kind == "train" else self.spec.checks
            self._geometries[key] = MissionGeometry(configs[k])
        return self._geometries[key]

    def load(self, actor_state: dict[str, torch.Tensor]) -> COMANetworks:
        """This worker's networks with the actor's weights ``actor_state`` (built on first
        use; only the actor flies, the critics are never read)."""
        if self.networks is None:
            self.networks = build_networks(self.spec.coma_config, self.spec.env_config)
            to_channels_last(self.networks)
        self.networks.actor.load_state_dict(actor_state)
        return self.networks

    def rollout(self, networks: COMANetworks, setting: int, first_mission: int,
                n_missions: int, eps: float) -> Rollout:
        """Training missions ``first_mission ..`` of setting ``setting``, sampled by
        ``networks``' actor (:func:`coma.rollout.collect_rollout`)."""
        return collect_rollout(networks, self.spec.settings[setting],
                               self.geometry("train", setting), self.spec.seed, first_mission,
                               n_missions, eps)

    def greedy(self, networks: COMANetworks, check: int, first_mission: int,
               n_missions: int) -> GreedyFlights:
        """Validation missions ``first_mission ..`` of validation setting ``check``, flown
        greedily by ``networks``' actor (in eval mode for the flight)."""
        actor = networks.actor
        was_training = actor.training
        actor.eval()
        try:
            return fly_greedy(actor, self.spec.checks[check], self.geometry("check", check),
                              self.spec.seed, first_mission, n_missions)
        finally:
            actor.train(was_training)


def cpu_actor_state(networks: COMANetworks) -> dict[str, torch.Tensor]:
    """The actor's weights as CPU tensors (what the workers load)."""
    return {name: tensor.detach().cpu() for name, tensor in networks.actor.state_dict().items()}


def _on_cpu(networks: COMANetworks) -> bool:
    return all(p.device.type == "cpu" for p in networks.actor.parameters())


class Workers:
    """Flies a run's missions for the learner; a context manager that stops its workers.

    Attributes:
        count: the number of workers (blocks per call).
    """

    count: int = 1

    def rollout(self, networks: COMANetworks, setting: int, first_mission: int,
                n_missions: int, eps: float) -> Rollout:
        """The rollout of training missions ``first_mission ..`` of setting ``setting``."""
        blocks = split_missions(first_mission, n_missions, self.count)
        return Rollout.concatenate(self._map("rollout", networks, [
            (setting, first, count, eps) for first, count in blocks]))

    def greedy(self, networks: COMANetworks, check: int, n_missions: int) -> GreedyFlights:
        """The greedy flights of validation missions ``0 .. n_missions - 1`` of validation
        setting ``check`` (what :func:`coma.validation.validate` asks its ``fly`` for)."""
        blocks = split_missions(0, n_missions, self.count)
        return GreedyFlights.concatenate(self._map("greedy", networks, [
            (check, first, count) for first, count in blocks]))

    def _map(self, method: str, networks: COMANetworks,
             calls: Sequence[tuple[Any, ...]]) -> list[Any]:
        """``method(networks' actor, *args)`` on the workers, one call per worker at most;
        the results in the order of ``calls``."""
        raise NotImplementedError

    def close(self) -> None:
        """Stop the workers (nothing for :class:`InProcess`)."""

    def __enter__(self) -> Workers:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class InProcess(Workers):
    """The learner's process flies every mission (``workers=1``, the local backend)."""

    def __init__(self, spec: RunSpec,
                 geometries: dict[tuple[str, int], MissionGeometry] | None = None):
        self._worker = RolloutWorker(spec, geometries)

    def _map(self, method: str, networks: COMANetworks,
             calls: Sequence[tuple[Any, ...]]) -> list[Any]:
        # CPU networks fly themselves (no copy); GPU ones through the worker's CPU copy.
        flying = networks if _on_cpu(networks) else self._worker.load(cpu_actor_state(networks))
        return [getattr(self._worker, method)(flying, *args) for args in calls]


# --------------------------------------------------------------------------------------------
# Local processes

_WORKER: RolloutWorker | None = None
"""In a pool worker process: its state."""


def _init_process(spec: RunSpec, parent: int) -> None:
    """Pool initializer: exit with ``parent``, ignore Ctrl-C, one thread per library, freed
    memory kept for the next rollout."""
    global _WORKER
    guard_worker(parent)
    prepare_worker_process()
    _WORKER = RolloutWorker(spec)


def _process_call(method: str, actor_state: dict[str, torch.Tensor], *args: Any) -> Any:
    if _WORKER is None:  # pragma: no cover - only if the initializer did not run
        raise RuntimeError("COMA rollout worker used without its initializer")
    return getattr(_WORKER, method)(_WORKER.load(actor_state), *args)


class ProcessWorkers(Workers):
    """K spawned processes kept for the run (``workers=K > 1``, the local backend)."""

    def __init__(self, spec: RunSpec, count: int):
        self.count = count
        self._spec = spec
        self._executor: concurrent.futures.ProcessPoolExecutor | None = None
        self._start()

    def _start(self) -> None:
        self._executor = concurrent.futures.ProcessPoolExecutor(
            max_workers=self.count, mp_context=multiprocessing.get_context("spawn"),
            initializer=_init_process, initargs=(self._spec, os.getpid()))
        # Start every worker now: they import torch while the learner sets up.
        self._submit([(os.getpid,)] * self.count)

    def _submit(self, calls: Sequence[tuple[Any, ...]]) -> list[concurrent.futures.Future]:
        assert self._executor is not None
        # Workers start on a submission; they inherit one thread each and an ignored Ctrl-C.
        with single_thread_environment(), children_ignore_sigint():
            return [self._executor.submit(*call) for call in calls]

    def _map(self, method: str, networks: COMANetworks,
             calls: Sequence[tuple[Any, ...]]) -> list[Any]:
        state = cpu_actor_state(networks)
        for attempt in range(MAX_RETRIES + 1):
            try:
                futures = self._submit([(_process_call, method, state, *args)
                                        for args in calls])
                return [future.result() for future in futures]
            except concurrent.futures.process.BrokenProcessPool as error:
                self._stop()
                if attempt == MAX_RETRIES:
                    error.add_note(f"a COMA rollout worker process died {MAX_RETRIES + 1} times "
                                   "(killed, out of memory, or it could not start: a script "
                                   "that trains needs an `if __name__ == \"__main__\":` "
                                   "guard); resume the run with --resume")
                    raise
                self._start()  # a fresh pool flies the blocks again: the same missions
        raise AssertionError("unreachable")  # pragma: no cover

    def pids(self) -> list[int]:
        """The worker processes' ids (read from the executor's process table, which it does
        not expose publicly; for diagnostics and the tests that kill a worker)."""
        return sorted(getattr(self._executor, "_processes", None) or {})

    def _stop(self) -> None:
        executor, self._executor = self._executor, None
        if executor is None:
            return
        # An interrupt or a failed update must not wait for the running workers' blocks.
        stop_workers(executor)

    def close(self) -> None:
        self._stop()


# --------------------------------------------------------------------------------------------
# Ray actors


class RayRolloutWorker:
    """The body of a Ray actor: a :class:`RolloutWorker` in one single-threaded process."""

    def __init__(self, spec: RunSpec, cwd: str):
        if os.path.isdir(cwd):  # relative paths (terrain files) mean what they mean to the caller
            os.chdir(cwd)
        prepare_worker_process()
        self._worker = RolloutWorker(spec)

    def call(self, method: str, actor_state: dict[str, torch.Tensor], *args: Any) -> Any:
        return getattr(self._worker, method)(self._worker.load(actor_state), *args)

    def pid(self) -> int:
        """The actor's process id (for diagnostics and the tests that kill it)."""
        return os.getpid()


_RAY_CLASSES: dict[int, Any] = {}


class RayWorkers(Workers):
    """K Ray actors of one CPU each (``backend="ray"``)."""

    def __init__(self, spec: RunSpec, count: int, address: str | None = None):
        from ipp_toolkit.runs.ray_backend import MAX_RETRIES as RAY_RETRIES
        from ipp_toolkit.runs.ray_backend import connect

        self.count = count
        self._cluster = connect(address, count)
        ray = self._cluster.ray
        if self._cluster.cpus() < count:  # the actors would wait for CPUs forever
            cpus = self._cluster.cpus()
            self._cluster.close()
            raise ValueError(f"the Ray cluster has {cpus} CPU(s), fewer than the {count} "
                             "workers asked for (one CPU each): lower --workers")
        actor_class = _RAY_CLASSES.get(id(ray))
        if actor_class is None:
            actor_class = _RAY_CLASSES[id(ray)] = ray.remote(
                num_cpus=1, max_restarts=RAY_RETRIES, max_task_retries=RAY_RETRIES,
            )(RayRolloutWorker)
        self.actors = [actor_class.remote(spec, os.getcwd()) for _ in range(count)]

    def _map(self, method: str, networks: COMANetworks,
             calls: Sequence[tuple[Any, ...]]) -> list[Any]:
        ray = self._cluster.ray
        state = ray.put(cpu_actor_state(networks))  # one copy in the store for every actor
        refs = [actor.call.remote(method, state, *args)
                for actor, args in zip(self.actors, calls, strict=False)]
        try:
            return ray.get(refs)
        except Exception as error:
            raise _unwrap(ray, error) from None
        except BaseException:
            for ref in refs:
                with contextlib.suppress(Exception):
                    ray.cancel(ref, force=True)
            raise

    def pids(self) -> list[int]:
        """The actors' process ids."""
        return self._cluster.ray.get([actor.pid.remote() for actor in self.actors])

    def close(self) -> None:
        ray = self._cluster.ray
        for actor in self.actors:
            with contextlib.suppress(Exception):
                ray.kill(actor)
        self.actors = []
        self._cluster.close()


def _unwrap(ray: Any, error: Exception) -> BaseException:
    """A worker's own exception (its remote traceback chained), or Ray's error with a note
    saying that an actor was lost too often."""
    cause = getattr(error, "cause", None)
    if isinstance(error, ray.exceptions.RayTaskError) and isinstance(cause, Exception):
        cause.__cause__ = error
        return cause
    error.add_note("a COMA rollout actor died more often than Ray restarts it (killed, out "
                   "of memory, its node left the cluster), or could not start (every node "
                   "needs the toolkit importable, see docs/ray.md); resume the run with "
                   "--resume")
    return error


def make_workers(spec: RunSpec, workers: int = 1, backend: str = "local",
                 address: str | None = None,
                 geometries: dict[tuple[str, int], MissionGeometry] | None = None) -> Workers:
    """The workers of a run: :class:`InProcess` for one local worker, :class:`ProcessWorkers`
    for several, :class:`RayWorkers` for the Ray backend (``geometries``: ones the caller has
    built already, for the in-process worker).

    Raises:
        ValueError: ``workers`` below 1, an unknown backend, an address without Ray, or a
            Ray cluster with fewer CPUs than ``workers``.
        ipp_toolkit.runs.ray_backend.RayUnavailableError: Ray is not installed.
        ConnectionError: no Ray cluster answers at ``address``.
    """
    check_workers(workers, backend, address)
    if backend == "ray":
        return RayWorkers(spec, workers, address)
    if workers == 1:
        return InProcess(spec, geometries)
    return ProcessWorkers(spec, workers)


def check_workers(workers: int, backend: str, address: str | None) -> None:
    """Refuse bad worker settings by name, before anything is written.

    Raises:
        ValueError: ``workers`` below 1 or not an integer; a bad backend or address (as
            :func:`ipp_toolkit.runs.ray_backend.check_backend`).
        ipp_toolkit.runs.ray_backend.RayUnavailableError: ``backend="ray"`` without Ray.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers = {workers!r}: must be an integer >= 1")
    check_backend(backend, address)
