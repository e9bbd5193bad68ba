"""Evaluation runner: N test missions per planner, per-step metric curves, resumable.

:func:`evaluate` flies missions ``0 .. missions - 1`` of run ``seed`` in a namespace (``test`` by
default: terrains disjoint from ``train`` and ``validation``) with every planner. Mission k is
the same for every planner and any number of workers: its terrain, starts and sensor noise
come from ``reset_mission(config, seed, k, namespace)`` and the planner is reset with a seed
derived from ``(namespace, seed, k)`` only.

With ``out_dir`` every finished mission is stored at once as a shard, written atomically, so an
interrupted run resumes where it stopped, and a folder grows when other planners are flown
into it (the layout and reading stored missions back: :mod:`ipp_toolkit.runs.result_store`).

Results are tidy rows, one per (planner, mission, step) with the columns
:data:`RESULT_COLUMNS`; :meth:`EvaluationResult.curves` turns them into (missions, B + 1)
arrays. :func:`load_results` reads a folder back (both live in
:mod:`ipp_toolkit.runs.evaluation_result`, importable from here).

This module owns one planner's mission (:func:`run_mission`: its views, its timed ``act``,
its rows), the task runner that flies one (planner label, mission) with cached planners, and
:func:`evaluate`. Its neighbours own the rest: the mission loop (:mod:`ipp_toolkit.sim.driver`,
shared with COMA's rollouts), planner specs and their syntax
(:mod:`ipp_toolkit.planning.specs`), the planner seed
(:func:`ipp_toolkit.world.seeding.planner_seed`),
the worker processes (:mod:`ipp_toolkit.runs.process_pool`), the backend check and the optional
Ray backend (:mod:`ipp_toolkit.runs.ray_backend`, which imports Ray only when asked) and the
folder layout (:mod:`ipp_toolkit.runs.result_store`).
"""

from __future__ import annotations

import contextlib
import gc
import math
import os
import time
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._native import kernels
from ..config.limits import check_mission, check_result_rows
from ..config.schema import EnvConfig, check_int
from ..config.settings import safe_name
from ..io import write_json
from ..planning import (
    Planner,
    PlannerFactory,
    check_planner_name,
    make_planner,
    planner_views,
)
from ..planning.specs import PlannerSpec, as_specs
from ..sim.driver import fly_missions, start_missions
from ..sim.mission import MissionGeometry, MissionState
from ..world.seeding import check_namespace, planner_seed
from .evaluation_result import METRICS, EvaluationResult, load_results
from .process_pool import (
    WorkerPool,
    limit_blas_threads,
    limit_torch_threads,
    run_parallel,
    transferable_factory,
)
from .progress import progress_bar
from .ray_backend import check_backend
from .result_store import (
    RESULT_COLUMNS,
    EvaluationError,
    check_folder,
    check_label,
    folder_identity,
    read_stored_missions,
    stored_planners,
    trajectory_path,
    write_results_csv,
    write_shard,
    write_trajectory,
)
from .run_folder import EVALUATION_COMMAND, claim

__all__ = [
    "RESULT_COLUMNS",
    "METRICS",
    "EvaluationError",
    "EvaluationResult",
    "run_mission",
    "evaluate",
    "load_results",
]


# --------------------------------------------------------------------------------------------
# One mission


def _terrain_name(config: EnvConfig) -> str:
    terrain = config.terrain
    if terrain.kind == "raster" and terrain.raster is not None:
        return Path(terrain.raster).name
    return terrain.kind


def run_mission(config: EnvConfig, planner: Planner, seed: int, mission: int,
                namespace: str = "test", geometry: MissionGeometry | None = None,
                record_trajectory: bool = False, label: str | None = None,
                observer: Callable[[MissionState], None] | None = None) -> dict[str, Any]:
    """Fly mission ``mission`` of run ``seed`` with ``planner``.

    The planner is reset with :func:`planner_seed` ``(seed, mission, namespace)``; then, per
    step, it gets the agents' views and its ``act`` is timed (``plan_ms``).

    Args:
        config: the mission configuration (budget B, N agents).
        planner: the planner; ``planner.needs_observations`` and ``needs_local_maps`` decide
            whether the views carry the actor planes and the local maps' per-cell arrays.
        seed: run seed (>= 0).
        mission: mission index (>= 0).
        namespace: random-stream namespace (``test`` for held-out terrains).
        geometry: a prebuilt :class:`MissionGeometry` of ``config`` (built when omitted).
        record_trajectory: also return the path, the ground truth and the final global map.
        label: value of the ``planner`` column; defaults to ``planner.name``.
        observer: called with the mission state after the reset and after every step (e.g.
            to render frames); it must not modify the state.

    Returns:
        ``{"rows": [...], "trajectory": None | {...}}``. ``rows`` holds B + 1 dicts with the
        keys :data:`RESULT_COLUMNS`, one per step s = 0..B (``reward`` and ``plan_ms`` are NaN
        at s = 0). ``trajectory`` holds ``positions`` (B + 1, N, 3) float64 metres,
        ``footprints`` (B + 1, N, 4) int64 rectangles, ``ground_truth`` (H, W) bool,
        ``final_prob`` (H, W) float16 of the global map, ``area_size`` and ``resolution``
        (floats, metres).
    """
    state, = start_missions(config, seed, mission, 1, namespace, geometry)
    planner.reset(config, seed=planner_seed(seed, mission, namespace))
    base = {
        "planner": label if label is not None else str(getattr(planner, "name", "planner")),
        "agents": int(config.team.n_agents),
        "comm": float(config.team.comm_range),
        "terrain": _terrain_name(config),
        "seed": int(seed),
        "mission": int(mission),
    }
    times = [math.nan]
    positions: list[np.ndarray] = []
    footprints: list[np.ndarray] = []

    def act(states: Sequence[MissionState]) -> list[Sequence[int]]:
        views = planner_views(states[0], planner)
        start = time.perf_counter()
        actions = planner.act(views)
        times.append((time.perf_counter() - start) * 1000.0)
        return [actions]

    def watch(states: Sequence[MissionState]) -> None:
        if observer is not None:
            observer(states[0])
        if record_trajectory:
            positions.append(states[0].positions_m().astype(np.float64))
            footprints.append(states[0].footprints.astype(np.int64))

    flight = fly_missions([state], act, watch)
    rewards = [math.nan, *flight.rewards[0].tolist()]
    rows = []
    for step, metrics in enumerate(state.history):
        rows.append({**base, "step": step, "entropy": float(metrics.entropy),
                     "f1": float(metrics.f1), "rmse": float(metrics.rmse),
                     "reward": rewards[step], "plan_ms": times[step]})
    trajectory = None
    if record_trajectory:
        trajectory = {
            "ground_truth": np.asarray(state.ground_truth, dtype=bool).copy(),
            "final_prob": state.maps.prob[state.global_index].astype(np.float16),
            "positions": np.stack(positions),
            "footprints": np.stack(footprints),
            "area_size": float(config.world.area_size),
            "resolution": float(config.world.resolution),
        }
    return {"rows": rows, "trajectory": trajectory}


# --------------------------------------------------------------------------------------------
# Running many missions (in this process, or in worker processes: ipp_toolkit.runs.process_pool)


@dataclass
class _Entry:
    spec: PlannerSpec
    factory: PlannerFactory | None = None  # sent to workers; None: look the name up there


class _Runner:
    """Flies (label, mission) tasks of one evaluation; caches the geometry and the planners."""

    def __init__(self, config: EnvConfig, seed: int, namespace: str,
                 entries: Mapping[str, _Entry], record: frozenset[int],
                 single_thread: bool = False):
        self.config = config
        self.seed = seed
        self.namespace = namespace
        self.entries = dict(entries)
        self.record = record
        self.single_thread = single_thread
        self._geometry: MissionGeometry | None = None
        self._planners: dict[str, Planner] = {}

    @property
    def geometry(self) -> MissionGeometry:
        if self._geometry is None:
            self._geometry = MissionGeometry(self.config)
        return self._geometry

    def planner(self, label: str) -> Planner:
        planner = self._planners.get(label)
        if planner is None:
            entry = self.entries[label]
            spec = entry.spec
            try:
                if entry.factory is not None:
                    planner = entry.factory(**spec.options)
                    if not isinstance(planner, Planner):
                        raise TypeError(f"planner factory {spec.name!r} returned "
                                        f"{type(planner).__name__}, not a Planner")
                else:
                    planner = make_planner(spec.name, **spec.options)
            except Exception as err:
                err.add_note(f"while building planner {label!r} ({spec.name} with options "
                             f"{spec.options})")
                raise
            if self.single_thread:
                limit_torch_threads()
            self._planners[label] = planner
        return planner

    def run(self, label: str, mission: int) -> tuple[str, int, dict[str, Any]]:
        fresh = label not in self._planners
        planner = self.planner(label)
        try:
            result = run_mission(self.config, planner, self.seed, mission, self.namespace,
                                 self.geometry, record_trajectory=mission in self.record,
                                 label=label)
        except Exception as err:
            err.add_note(f"while flying mission {mission} (seed {self.seed}, namespace "
                         f"{self.namespace!r}) with planner {label!r}")
            raise
        if self.single_thread:
            limit_torch_threads()
            if fresh:
                # A worker's first mission with a planner has imported what it needs (torch,
                # SB3) and loaded the compiled kernels; those objects live as long as the
                # worker, so they leave the collector's generations: its full passes, and
                # the one when the worker exits (about 1 s with torch loaded), skip them.
                gc.freeze()
        return label, mission, result


# --------------------------------------------------------------------------------------------
# The runner


def evaluate(config: EnvConfig, planners: str | Sequence[str | PlannerSpec], missions: int = 50,
             seed: int = 0, workers: int = 1, out_dir: str | os.PathLike[str] | None = None,
             progress: bool = True, namespace: str = "test",
             record_missions: Sequence[int] = (0,),
             on_recorded: Callable[[str, int, dict[str, Any], list[dict[str, Any]]], None]
             | None = None, backend: str = "local",
             address: str | None = None, pool: WorkerPool | None = None) -> EvaluationResult:
    """Fly missions ``0 .. missions - 1`` of run ``seed`` with every planner.

    Every input is checked before any work or file: planner names (an unknown one raises
    listing the registered planners), labels, counts, and ``out_dir`` (a folder holding
    another configuration raises :class:`EvaluationError` and stays untouched). With
    ``workers == 1`` (local backend) the planners are also built before anything is
    written; with the ray backend, Ray is started or reached before anything is written.

    Args:
        config: the mission configuration.
        planners: names (``"ig"``, ``"coma=ckpt.pt"``, see :meth:`PlannerSpec.parse`), specs,
            or one comma-separated string.
        missions: number of missions per planner (>= 1).
        seed: run seed (>= 0).
        workers: processes (>= 1); > 1 runs one task per (planner, mission) in a "spawn"
            process pool, each worker single-threaded. Results do not depend on it. With
            ``backend="ray"`` and no ``address``: the CPUs of the local Ray it starts.
        out_dir: results folder (see the module docstring); missions already stored there
            are not flown again. None keeps everything in memory.
        progress: show a tqdm progress bar counting missions.
        namespace: random-stream namespace; ``test`` terrains are disjoint from ``train`` and
            ``validation``.
        record_missions: mission indices whose trajectories are kept (and written as npz);
            indices >= ``missions`` are ignored.
        on_recorded: called in this process as ``on_recorded(label, mission, trajectory,
            rows)`` as soon as a recorded mission has been flown (not for one read back from
            ``out_dir``), e.g. to draw it while the other missions fly.
        backend: ``"local"`` (this process, or the process pool) or ``"ray"``: one Ray task
            per (planner, mission), see :mod:`ipp_toolkit.runs.ray_backend`; results are stored
            in this process either way, and do not depend on the backend.
        address: with ``backend="ray"``, the cluster to use (``HOST:PORT`` as printed by
            ``ray start --head``, ``ray://HOST:PORT`` or ``auto``; its CPUs decide how many
            missions fly at once); None starts a local Ray with ``workers`` CPUs for this
            call (a process already connected to Ray uses that connection).
        pool: worker processes started ahead (:class:`~ipp_toolkit.runs.process_pool.WorkerPool`)
            for ``workers > 1`` on the local backend; the evaluation shuts it down when its
            missions are done. The caller closes it where it goes unused (``finally``).

    Returns:
        the :class:`EvaluationResult`; its rows are ordered by planner, mission, step.

    Raises:
        ValueError: a bad input (the message names the value).
        EvaluationError: ``out_dir`` holds results of another configuration or another
            planner under one of the labels.
        ipp_toolkit.runs.ray_backend.RayUnavailableError: ``backend="ray"`` without Ray installed
            (an ImportError; the message gives the install command).
        ConnectionError: no Ray cluster answers at ``address`` (within seconds).
    """
    inputs = _check_inputs(config, planners, missions, seed, workers, namespace, backend,
                           address, record_missions)
    folder = Path(out_dir) if out_dir is not None else None
    with contextlib.ExitStack() as stack:
        if folder is not None:
            # Held until the results are written: a second run into the folder is refused.
            # The given path: an empty one is refused, not taken as the current folder.
            stack.enter_context(claim(out_dir, EVALUATION_COMMAND, "out_dir"))
        return _evaluate_claimed(config, inputs, folder, progress, namespace, on_recorded,
                                 backend, address, pool)


@dataclass(frozen=True)
class _Inputs:
    """:func:`evaluate`'s inputs once checked."""

    specs: list[PlannerSpec]
    labels: list[str]
    missions: int
    seed: int
    workers: int
    record: frozenset[int]


def _check_inputs(config: EnvConfig, planners: str | Sequence[str | PlannerSpec],
                  missions: int, seed: int, workers: int, namespace: str, backend: str,
                  address: str | None, record_missions: Sequence[int]) -> _Inputs:
    """Every input of :func:`evaluate` checked (ValueError naming the value), before any
    folder is touched."""
    if not isinstance(config, EnvConfig):
        raise ValueError(f"config must be an EnvConfig, got {type(config).__name__}")
    missions = check_int("missions", missions, 1)
    workers = check_int("workers", workers, 1)
    seed = check_int("seed", seed, 0)
    check_namespace(namespace)
    check_backend(backend, address)  # a missing Ray is reported even when nothing is left to fly
    if isinstance(record_missions, int | np.integer):
        record_missions = (int(record_missions),)
    record = frozenset(check_int("record_missions", k, 0) for k in record_missions)
    record = frozenset(k for k in record if k < missions)
    specs = as_specs(planners)
    for spec in specs:
        check_planner_name(spec.name)  # an unknown name: refused, listing the registered ones
    labels = [spec.effective_label for spec in specs]
    _check_labels(labels)
    # Sizes that cannot fit are refused before any folder is touched.
    check_result_rows(config.team.budget, missions, len(specs))
    check_mission(config, at_once=min(workers, missions * len(specs)))
    return _Inputs(specs, labels, missions, seed, workers, record)


def _check_labels(labels: list[str]) -> None:
    """Refuse a label given twice, two labels of one file name, or a label no file can have."""
    stems: dict[str, str] = {}
    for label in labels:
        if label in stems.values():
            raise ValueError(f"planner label {label!r} is given twice; give one a label")
        other = stems.get(safe_name(label))
        if other is not None:
            raise ValueError(f"planner labels {other!r} and {label!r} map to the same file "
                             f"name {safe_name(label)!r}; rename one")
        stems[safe_name(label)] = label
        check_label(label)


def _evaluate_claimed(config: EnvConfig, inputs: _Inputs, folder: Path | None, progress: bool,
                      namespace: str,
                      on_recorded: Callable[[str, int, dict[str, Any], list[dict[str, Any]]],
                                            None] | None, backend: str,
                      address: str | None, pool: WorkerPool | None) -> EvaluationResult:
    """:func:`evaluate` once its inputs are checked and ``folder`` (if any) is claimed:
    read what the folder holds, fly the rest, write results.csv."""
    labels, missions = inputs.labels, inputs.missions
    identity = folder_identity(config, inputs.seed, namespace)
    # The folder's config.json matches identity (else refused); shards are checked against it.
    has_identity = check_folder(folder, identity, inputs.specs) if folder is not None else False
    store = _Store(folder, identity, has_identity, inputs.specs, on_recorded)
    if folder is not None and has_identity:
        store.done, store.trajectories = read_stored_missions(
            folder, labels, missions, inputs.record, config.team.budget, identity)
    tasks = [(label, mission) for mission in range(missions) for label in labels
             if (label, mission) not in store.done]
    # Counted per planner for the result: a rerun says what it reused and what it flew.
    reused = dict(Counter(label for label, _ in store.done))
    flown = dict(Counter(label for label, _ in tasks))
    n_workers = min(inputs.workers, len(tasks))
    local = backend == "local" and n_workers <= 1
    if local and tasks:
        # Compiled (or loaded) ahead, as a pool's workers do, saying so where Numba's cache
        # does not hold them: a first run is otherwise silent for up to a minute. A kernel
        # that fails to compile fails the mission that calls it, with its own error.
        with contextlib.suppress(Exception):
            kernels.compile_mission_kernels(announce=kernels.print_compile_note)
    runner = _prepare_runner(config, inputs, namespace, tasks, local)
    cluster = None
    if backend == "ray" and tasks:
        from .ray_backend import connect

        cluster = connect(address, n_workers)  # starts or reaches Ray before anything is written
    try:
        with progress_bar(len(labels) * missions, "evaluate", "missions",
                          initial=len(labels) * missions - len(tasks),
                          disable=not progress) as bar:
            _fly(runner, tasks, local, cluster, n_workers, pool, store.finish, bar)
    finally:
        if cluster is not None:
            cluster.close()
    store.prepare()
    result = _results(config, inputs, store, folder, namespace)
    result.reused, result.flown = reused, flown
    return result


def _prepare_runner(config: EnvConfig, inputs: _Inputs, namespace: str,
                    tasks: list[tuple[str, int]], local: bool) -> _Runner:
    """The runner of the ``tasks``. In this process (``local``) its planners are built now,
    so one that cannot be built fails before anything is written; for workers each planner
    travels as a factory they can rebuild."""
    spec_of = dict(zip(inputs.labels, inputs.specs, strict=True))
    entries = {label: _Entry(spec_of[label]) for label in inputs.labels}
    flown = dict.fromkeys(label for label, _ in tasks)
    if not local:
        for label in flown:
            entries[label].factory = transferable_factory(spec_of[label])
        return _Runner(config, inputs.seed, namespace, entries, inputs.record)
    runner = _Runner(config, inputs.seed, namespace, entries, inputs.record)
    for label in flown:
        runner.planner(label)
    return runner


def _fly(runner: _Runner, tasks: list[tuple[str, int]], local: bool, cluster: Any,
         n_workers: int, pool: WorkerPool | None,
         finish: Callable[[str, int, dict[str, Any]], None], bar: Any) -> None:
    """Fly the ``tasks`` in this process, as Ray tasks on ``cluster``, or in worker
    processes; ``finish`` stores each flown mission."""
    if not tasks:
        return
    if local:
        with limit_blas_threads():
            for label, mission in tasks:
                finish(*runner.run(label, mission))
                bar.update(1)
    elif cluster is not None:
        from .ray_backend import run_ray

        run_ray(cluster, runner, tasks, finish, bar)
    else:
        run_parallel(runner, tasks, n_workers, finish, bar, pool)


class _Store:
    """Where flown missions go: rows and trajectories in memory and, with a folder, its
    shards, trajectories and (once) its identity and planner specs."""

    def __init__(self, folder: Path | None, identity: dict[str, Any], has_identity: bool,
                 specs: list[PlannerSpec],
                 on_recorded: Callable[[str, int, dict[str, Any], list[dict[str, Any]]],
                                       None] | None) -> None:
        self.folder, self.identity, self.has_identity = folder, identity, has_identity
        self.specs = specs
        self.spec_of = {spec.effective_label: spec for spec in specs}
        self.on_recorded = on_recorded
        self.done: dict[tuple[str, int], list[dict[str, Any]]] = {}
        self.trajectories: dict[tuple[str, int], dict[str, Any]] = {}
        self.prepared = False

    def prepare(self) -> None:
        """Write the folder's identity and planner specs, once: when the first mission has
        flown (or nothing is left to fly), so input that fails on the first mission (a
        missing raster, a grid that does not fit, a planner that cannot act) leaves nothing
        behind."""
        if self.folder is None or self.prepared:
            return
        if not self.has_identity:
            write_json(self.folder / "config.json", self.identity)
        for spec in self.specs:
            path = self.folder / "shards" / safe_name(spec.effective_label) / "planner.json"
            if not path.exists():
                write_json(path, spec.to_dict())
        self.prepared = True

    def finish(self, label: str, mission: int, result: dict[str, Any]) -> None:
        """Keep one flown mission (and store it in the folder, if any)."""
        if self.folder is not None:
            self.prepare()
            if result["trajectory"] is not None:
                write_trajectory(trajectory_path(self.folder, label, mission),
                                 result["trajectory"])
            write_shard(self.folder, self.spec_of[label], mission, result, self.identity)
        self.done[(label, mission)] = result["rows"]
        if result["trajectory"] is not None:
            self.trajectories[(label, mission)] = result["trajectory"]
            if self.on_recorded is not None:
                self.on_recorded(label, mission, result["trajectory"], result["rows"])


def _results(config: EnvConfig, inputs: _Inputs, store: _Store, folder: Path | None,
             namespace: str) -> EvaluationResult:
    """The rows of every requested mission, with a folder also those of the planners stored
    in it before (written to results.csv)."""
    labels = inputs.labels
    rows = [row for label in labels for mission in range(inputs.missions)
            for row in store.done[(label, mission)]]
    if folder is not None:
        # A result folder is a growing set: planners flown into it before keep their rows.
        stored = stored_planners(folder, labels, inputs.missions, config.team.budget,
                                 store.identity)
        labels = labels + list(stored)
        rows += [row for label_rows in stored.values() for row in label_rows]
        write_results_csv(folder / "results.csv", rows)
    trajectories = store.trajectories
    return EvaluationResult(config=config, seed=inputs.seed, rows=rows, labels=labels,
                            trajectories={key: trajectories[key] for key in sorted(
                                trajectories, key=lambda k: (labels.index(k[0]), k[1]))
                                if key[1] in inputs.record},
                            out_dir=folder, namespace=namespace)
