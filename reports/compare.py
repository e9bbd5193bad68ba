"""Compare planners on one configuration in three lines (the Python face of ``ipp-compare``).

Example (a notebook)::

    from reports import compare_planners
    comparison = compare_planners(agents=4, comm=25.0, planners="ig,coverage,random", trials=20)
    comparison            # renders the Markdown table; comparison.plot("figs") draws

:func:`compare_planners` (also here under its earlier name, ``compare``) builds the
:class:`~ipp_toolkit.config.schema.EnvConfig` (the one builder,
:func:`ipp_toolkit.config.settings.build_env_config`: keyword > config file > defaults),
checks and builds every planner (:func:`resolve_planners`) before anything is written, runs
:func:`ipp_toolkit.runs.evaluation.evaluate` and summarises the rows; with ``out`` it also writes
the tables and figures next to the raw results. The summary pairs every planner with each
reference planner on the same missions (by default ``ig`` and ``ig_spatial``, where flown).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import numbers
import os
import sys
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ipp_toolkit.config.limits import check_mission, check_result_rows
from ipp_toolkit.config.schema import EnvConfig, check_int
from ipp_toolkit.config.settings import build_env_config, format_comm, safe_name
from ipp_toolkit.io import write_json
from ipp_toolkit.planning import (
    FEATURES_NOTE,
    Planner,
    available_planners,
    check_planner_name,
    make_planner,
    planner_factory,
    planner_modules,
    planners_in_process,
)
from ipp_toolkit.runs.process_pool import WorkerPool
from ipp_toolkit.runs.progress import report_interrupt
from ipp_toolkit.runs.ray_backend import check_backend
from ipp_toolkit.runs.result_store import shard_path, trajectory_path
from ipp_toolkit.runs.run_folder import EVALUATION_COMMAND, claim

from .tables import Summary, flown_references, summarise, to_markdown, write_tables

if TYPE_CHECKING:
    from ipp_toolkit.planning.specs import PlannerSpec
    from ipp_toolkit.runs.evaluation import EvaluationResult

__all__ = [
    "Comparison",
    "compare",
    "compare_planners",
    "build_config",
    "resolve_planners",
    "default_planners",
    "DEFAULT_PLANNERS",
    "safe_name",
]

build_config = build_env_config
"""The one config builder (:func:`ipp_toolkit.config.settings.build_env_config`) under its old
name."""


def draw_trajectory(out_dir: Path, config: EnvConfig, label: str, mission: int,
                    trajectory: Mapping[str, Any],
                    final: tuple[float, float] | None) -> list[Path]:
    """Draw one recorded mission to ``out_dir/trajectories/<label>_mission<k>.png/.pdf``.

    ``final`` is the mission's final (entropy, F1), shown in the title when given. A figure
    drawn before from the same mission and title is kept (``reuse`` of
    :func:`~reports.plots.plot_trajectories`): a finished run reported again, or a folder
    grown by one planner, redraws only what changed.

    Returns:
        the figure's paths (PNG, PDF), drawn now or before.
    """
    from .plots import plot_trajectories  # matplotlib only where figures are drawn

    title = (f"{label}, mission {mission}: {config.team.n_agents} UAVs, "
             f"D = {format_comm(config.team.comm_range)}")
    if final is not None:
        title += f"; final entropy {final[0]:.3f}, F1 {final[1]:.3f}"
    stem = out_dir / "trajectories" / f"{safe_name(label)}_mission{mission}"
    return plot_trajectories(trajectory, stem, title, reuse=True)


@dataclass
class Comparison:
    """The outcome of :func:`compare_planners`.

    Attributes:
        result: the raw ``EvaluationResult`` (tidy rows, curves, recorded trajectories).
        summary: the :class:`~reports.tables.Summary` of the rows.
    """

    result: EvaluationResult
    summary: Summary

    @property
    def table(self) -> str:
        """The Markdown table (caption line, then the table)."""
        return to_markdown(self.summary)

    @property
    def plan_ms(self) -> dict[str, float]:
        """Mean planning time per step in milliseconds, per planner."""
        return dict(self.summary.plan_ms)

    def _repr_markdown_(self) -> str:
        return self.table

    def plot(self, out_dir: str | os.PathLike[str],
             drawn: Collection[tuple[str, int]] = ()) -> list[Path]:
        """Draw ``curves.png/.pdf`` and one trajectory figure per recorded mission.

        Trajectory figures go to ``out_dir/trajectories/<label>_mission<k>.png/.pdf``; those
        of ``drawn`` (label, mission) pairs are already there (:func:`compare_planners` draws them
        while the other missions fly), and so are figures drawn before from the same data:
        neither is drawn again.

        Returns:
            every figure's paths.
        """
        from .plots import plot_curves

        out = Path(out_dir)
        paths = plot_curves(self.result.rows, out, reuse=True)
        final = self._final_metrics()
        config = self.result.config
        for (label, mission), trajectory in sorted(self.result.trajectories.items(),
                                                   key=lambda item: (str(item[0][0]),
                                                                     int(item[0][1]))):
            if (str(label), int(mission)) in drawn:
                continue
            paths += draw_trajectory(out, config, str(label), int(mission), trajectory,
                                     final.get((str(label), int(mission))))
        return paths

    def write(self, out_dir: str | os.PathLike[str],
              drawn: Collection[tuple[str, int]] = ()) -> list[Path]:
        """Write ``summary.md/.csv/.tex`` and every figure of :meth:`plot` into ``out_dir``."""
        return list(write_tables(self.summary, out_dir).values()) + self.plot(out_dir, drawn)

    def _final_metrics(self) -> dict[tuple[str, int], tuple[float, float]]:
        budget = self.summary.budget
        return {(str(r["planner"]), int(r["mission"])): (float(r["entropy"]), float(r["f1"]))
                for r in self.result.rows if int(r["step"]) == budget}


DEFAULT_PLANNERS = ("ig", "ig_spatial", "ig_learned", "coverage", "random", "coma", "ppo")
"""What ``ipp-compare`` flies without ``--planners``."""


def interrupted(tool: str, out_dir: Path, interrupt: BaseException | None = None) -> int:
    """Ctrl-C (or SIGTERM): one line saying how to continue (exit code 130, or 143 for SIGTERM,
    as a shell reports the signals; :func:`~ipp_toolkit.runs.progress.report_interrupt`).

    Every mission is stored atomically as it ends, so the same command flies only the rest.
    """
    return report_interrupt(tool, f"the missions already flown are kept in {str(out_dir)!r}: "
                            "run the same command again to continue", interrupt)


def default_planners(note: Callable[[str], None] | None = None,
                     names: Sequence[str] = DEFAULT_PLANNERS) -> list[str]:
    """The planners of ``names`` that can be built with their default options.

    A planner whose construction fails with ``FileNotFoundError`` or ``ValueError`` (a learned
    planner without a checkpoint), or whose entry point cannot be imported, is skipped and
    ``note`` is called with the reason (default: printed to stderr).
    """
    if note is None:
        def note(text: str) -> None:
            print(text, file=sys.stderr)
    available = available_planners()
    kept = []
    for name in names:
        if name not in available:
            note(f"note: skipping planner {name!r} (not registered)")
            continue
        try:
            make_planner(name)
        except (FileNotFoundError, ValueError) as err:
            note(f"note: skipping planner {name!r} (not available with default options: {err})")
            continue
        except ImportError as err:
            note(f"note: skipping planner {name!r} (its module cannot be imported: {err})")
            continue
        kept.append(name)
    return kept


def _current_planners() -> list[str]:
    """Every registered planner (``--planners all``)."""
    return list(available_planners())


def resolve_planners(planners: str | Sequence[str | PlannerSpec] | None,
                     note: Callable[[str], None] | None = None) -> list[PlannerSpec]:
    """Parse, check and test-build the planners of a comparison.

    Args:
        planners: None or ``"default"`` (:data:`DEFAULT_PLANNERS`), ``"all"`` (every
            registered planner but deprecated aliases), a comma-separated string
            (``"ig,coverage,coma=runs/x/ckpt.pt"``) or a sequence of names / specs.
        note: receives the notes about skipped planners.

    Returns:
        one ``PlannerSpec`` per planner, in the given order.

    Raises:
        ValueError: an unknown planner (the message lists the registered ones), a removed
            one (the message says what to use instead), a planner that cannot be built with
            its options (e.g. a missing checkpoint), a duplicate label or an empty list.
    """
    return [spec for spec, _ in _built_planners(planners, note)]


def _planner_keyword(planners: str | Sequence[str | PlannerSpec] | None) -> str | None:
    """``"default"`` or ``"all"`` where ``planners`` names a set of planners, else None."""
    if planners is None:
        return "default"
    if isinstance(planners, str) and planners.strip() in ("all", "default"):
        return planners.strip()
    return None


def _listed_items(planners: str | Sequence[str | PlannerSpec]) -> list[str | PlannerSpec]:
    """The items of a comma-separated list (empty ones dropped) or of a sequence, stripped."""
    if isinstance(planners, str):
        return [item.strip() for item in planners.split(",") if item.strip()]
    return [item.strip() if isinstance(item, str) else item for item in planners]


def _built_planners(planners: str | Sequence[str | PlannerSpec] | None,
                    note: Callable[[str], None] | None) -> list[tuple[PlannerSpec, Planner]]:
    from ipp_toolkit.planning.specs import PlannerSpec

    keyword = _planner_keyword(planners)
    if keyword is not None:
        items: list[str | PlannerSpec] = list(default_planners(
            note, _current_planners() if keyword == "all" else DEFAULT_PLANNERS))
        if not items:
            raise ValueError("no planner is available: registered planners: "
                             f"{', '.join(available_planners()) or 'none'}")
    else:
        items = _listed_items(planners)
    if not items:
        raise ValueError("no planner given")
    built: list[tuple[PlannerSpec, Planner]] = []
    labels: set[str] = set()
    for item in items:
        spec = item if isinstance(item, PlannerSpec) else PlannerSpec.parse(item)
        planner_factory(spec.name)  # an unknown or removed name: ValueError naming it
        label = spec.label or spec.name
        if label in labels:
            raise ValueError(f"planner {label!r} is given twice")
        labels.add(label)
        try:
            planner = make_planner(spec.name, **dict(spec.options))
        except (OSError, ValueError, TypeError, ImportError) as err:
            raise ValueError(f"planner {label!r} cannot be built: {err}") from err
        built.append((spec, planner))
    return built


def _print_note(text: str) -> None:
    print(text, file=sys.stderr)


def _checked_planners(planners: str | Sequence[str | PlannerSpec] | None, env_config: EnvConfig,
                      note: Callable[[str], None] | None = None,
                      ) -> tuple[list[PlannerSpec], dict[str, dict[str, str]], list[str]]:
    """Build the planners of a comparison and check that each can fly ``env_config``.

    Returns:
        the planners' specs, their checkpoint records (:func:`planner_checkpoints`) and, when
        ``note`` is None, the notes about skipped default planners (else ``note`` gets them).

    Raises:
        ValueError: see :func:`resolve_planners`; also a policy made for another grid or
            team, refused here, before anything is written, not when its first mission flies.
    """
    notes: list[str] = []
    say = note or notes.append
    built = _built_planners(planners, say)
    for spec, planner in built:
        try:
            planner.reset(env_config, seed=0)
        except ValueError as err:
            raise ValueError(f"planner {spec.effective_label!r} cannot fly this "
                             f"configuration: {err}") from err
        # A learned policy flown off its training setting says so (a transfer, not an error);
        # the mission's own feature switches are not one: a policy observes with its own.
        transfer = [text for text in getattr(planner, "transfer_notes", None) or []
                    if not text.startswith(FEATURES_NOTE)]
        if transfer:
            say(f"note: planner {spec.effective_label!r} flies off its training setting: "
                + "; ".join(transfer))
    return [spec for spec, _ in built], planner_checkpoints(built), notes


def planner_checkpoints(built: Sequence[tuple[PlannerSpec, Planner]]) -> dict[str, dict[str, str]]:
    """``{label: {"checkpoint": file name, "sha256": hex}}`` of every planner with weights
    (a ``checkpoint`` attribute naming a file)."""
    found = {}
    for spec, planner in built:
        path = getattr(planner, "checkpoint", None)
        if path is not None and Path(path).is_file():
            digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
            found[str(spec.effective_label)] = {"checkpoint": Path(path).name, "sha256": digest}
    return found


def _record_checkpoints(out: Path, checkpoints: dict[str, dict[str, str]], write: bool) -> None:
    """Refuse a label whose weights changed since its missions were stored in ``out``; with
    ``write``, add the checkpoints to ``out/config.json`` (once the evaluation wrote it)."""
    path = out / "config.json"
    if not path.is_file():
        return
    try:
        stored = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return  # the evaluation reports an unreadable identity itself
    known = stored.get("checkpoints", {}) if isinstance(stored, dict) else {}
    for label, record in checkpoints.items():
        old = known.get(label)
        if old and old.get("sha256") != record["sha256"] \
                and (out / "shards" / safe_name(label)).is_dir():
            raise ValueError(f"the weights of planner {label!r} ({record['checkpoint']}) "
                             f"changed since its missions were stored in {str(out)!r} "
                             f"(sha256 {old.get('sha256', '?')[:12]} -> "
                             f"{record['sha256'][:12]}); use another folder or label")
    if write:
        stored["checkpoints"] = {**known, **checkpoints}
        write_json(path, stored)


def compare_planners(agents: int | None = None, comm: float | None = None,
                     planners: str | Sequence[str | PlannerSpec] | None = None, trials: int = 50,
                     seed: int = 0, terrain: str | os.PathLike[str] | None = None,
                     threshold: float | None = None, workers: int = 1,
                     out: str | os.PathLike[str] | None = None,
                     config: EnvConfig | str | os.PathLike[str] | None = None,
                     resolution: float | None = None, budget: int | None = None,
                     progress: bool = True, area_size: float | None = None,
                     grid_spacing: float | None = None,
                     note: Callable[[str], None] | None = None, animate: bool = False,
                     reference: str | Sequence[str] | None = None, namespace: str = "test",
                     backend: str = "local", address: str | None = None) -> Comparison:
    """Evaluate planners on the test missions of one configuration and summarise them.

    Args:
        config: the configuration, with ``agents``, ``comm``, ``terrain``, ``threshold``,
            ``resolution``, ``budget``, ``area_size`` and ``grid_spacing`` over it, see
            :func:`ipp_toolkit.config.settings.build_env_config` (None: the config's value, else the
            paper's: 4 UAVs, D = 25 m, ``split``).
        planners: see :func:`resolve_planners`; None: every available registered planner.
        trials: number of test missions (>= 1).
        seed: run seed of the missions.
        workers: parallel evaluation processes (>= 1); with ``backend="ray"`` and no
            ``address``, the CPUs of the local Ray started for the run.
        out: folder for the raw results (``config.json``, ``results.csv``, ``shards/``,
            ``trajectories/*.npz``), the tables and the figures; None keeps everything in
            memory.
        progress: show a progress bar.
        note: receives notes about skipped default planners (default: stderr).
        animate: with ``out``, also write ``animations/<planner>.gif`` of mission 0.
        reference: the planners of the summary's paired columns, one column each (final
            entropy minus theirs on the same missions, with its standard error and win
            rate): a label, comma-separated labels or a sequence; each must be flown. None:
            ``ig`` and ``ig_spatial``, each that is not flown left out.
        namespace: ``test`` (the held-out missions) or ``validation`` (the missions to select
            policies and settings on; never select on test missions).
        backend: ``"local"`` (processes on this machine) or ``"ray"`` (one Ray task per
            mission; the same results), see :func:`ipp_toolkit.runs.evaluation.evaluate`.
        address: with ``backend="ray"``, the Ray cluster (``HOST:PORT`` of its head); None
            starts a local Ray for the run. A process already connected to Ray (a study's
            :func:`reports.studies.backend_session`, or ``ray.init`` by the caller) uses
            that connection and keeps it.

    Returns:
        the :class:`Comparison`; its ``table`` is the Markdown table.

    Raises:
        ValueError: bad input, checked before anything is written;
            ``ipp_toolkit.runs.evaluation.EvaluationError`` (a ValueError) when ``out`` holds
            results of another configuration.
        ipp_toolkit.runs.ray_backend.RayUnavailableError: ``backend="ray"`` without Ray.
        ConnectionError: no Ray cluster answers at ``address``.
    """
    seed = check_int("seed", seed, 0)  # 1.5 is refused, not truncated
    _check_run_inputs(trials, workers, namespace, backend, address)
    env_config = build_env_config(config, agents=agents, comm=comm, terrain=terrain,
                                  threshold=threshold, resolution=resolution, budget=budget,
                                  area_size=area_size, grid_spacing=grid_spacing)
    # Before any worker starts or planner loads (the evaluation checks the same, later).
    check_result_rows(env_config.team.budget, int(trials), max(1, len(_requested_specs(planners))))
    check_mission(env_config, at_once=min(int(workers), int(trials)))
    with contextlib.ExitStack() as stack:
        if out is not None:
            # Held until the tables and figures are written: a second run into the folder
            # (another seed, say) is refused instead of mixing its missions in.
            stack.enter_context(claim(out, EVALUATION_COMMAND))
        pool, names = _start_workers(stack, planners, out, trials, workers, backend)
        specs, checkpoints = _build_planners(pool, names, planners, env_config, note, reference)
        if out is not None:
            _record_checkpoints(Path(out), checkpoints, write=False)  # before anything is written
        drawer = _TrajectoryDrawer(out, env_config)
        result = _fly_missions(env_config, specs, trials, seed, workers, out, progress,
                               namespace, backend, address, pool, drawer)
        if out is not None:
            _record_checkpoints(Path(out), checkpoints, write=True)
            (note or _print_note)(result.reuse_note())  # a rerun that flies nothing says so
        comparison = Comparison(result, _summary(result, reference, checkpoints))
        if out is not None:
            _write_outputs(comparison, Path(out), drawer.drawn, animate, specs, int(seed))
        return comparison


# The function's earlier name, kept for ``from reports.compare import compare`` (the package's
# ``reports.compare`` is this module, so the package exports the function as compare_planners).
compare = compare_planners


def _check_run_inputs(trials: int, workers: int, namespace: str, backend: str,
                      address: str | None) -> None:
    """Refuse bad counts, namespace or backend (ValueError) before the planners are built."""
    for name, value in (("trials", trials), ("workers", workers)):
        # Checked by type first: int(inf) and int(None) would raise their own errors.
        if isinstance(value, bool) or not isinstance(value, numbers.Real) \
                or not math.isfinite(value) or int(value) != value or value < 1:
            raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    if namespace not in ("test", "validation"):
        raise ValueError(f"namespace must be 'test' or 'validation', got {namespace!r}")
    check_backend(backend, address)


def _start_workers(stack: contextlib.ExitStack, planners: str | Sequence[str | PlannerSpec]
                   | None, out: str | os.PathLike[str] | None, trials: int, workers: int,
                   backend: str) -> tuple[WorkerPool | None, list[str]]:
    """The worker processes of a local run with ``workers > 1`` (closed by ``stack``), or
    None; and the names of the planners asked for, each checked to be registered."""
    pool = None
    requested = _requested_specs(planners)
    names = [spec.name for spec in requested]
    for name in names:
        # Here, before any worker starts: an unknown name's message lists the planners
        # registered in this process too, which a spawned worker does not know.
        check_planner_name(name)
    if backend == "local" and workers > 1 and not _all_stored(out, requested, trials):
        # The workers start and import the planners' modules at once; one of them builds
        # and checks the planners, then the evaluation hands them their tasks. A run
        # whose every mission is stored already has nothing to fly: no workers.
        pool = WorkerPool(min(int(workers), int(trials) * max(len(names), 1)),
                          planner_modules(names))
        stack.callback(pool.close)  # stops them if the run ends before the evaluation
    return pool, names


def _build_planners(pool: WorkerPool | None, names: list[str],
                    planners: str | Sequence[str | PlannerSpec] | None, env_config: EnvConfig,
                    note: Callable[[str], None] | None,
                    reference: str | Sequence[str] | None
                    ) -> tuple[list[PlannerSpec], dict[str, dict[str, str]]]:
    """Build and check every planner (in a worker where there are workers), and the
    references named among them; their specs and the checkpoints they load."""
    if pool is not None and not set(names) & set(planners_in_process()):
        # A worker builds and checks the planners (the workers import torch and SB3
        # anyway): this process never imports them, which on two cores is worth about
        # a second of the start-up. Not for a planner registered in this process only.
        specs, checkpoints, notes = pool.call(_checked_planners, planners, env_config)
        for text in notes:
            (note or _print_note)(text)
    else:
        specs, checkpoints, _ = _checked_planners(planners, env_config, note or _print_note)
    labels = [spec.effective_label for spec in specs]
    flown_references(reference, labels)  # a named reference that is not flown is refused
    return specs, checkpoints


class _TrajectoryDrawer:
    """Draws each recorded mission into ``out`` as soon as it has flown, while the workers
    fly the other missions, not after all of them; ``drawn`` names what it drew."""

    def __init__(self, out: str | os.PathLike[str] | None, env_config: EnvConfig) -> None:
        self.out, self.env_config = out, env_config
        self.drawn: set[tuple[str, int]] = set()

    def __call__(self, label: str, mission: int, trajectory: dict[str, Any],
                 rows: list[dict[str, Any]]) -> None:
        if self.out is not None:
            draw_trajectory(Path(self.out), self.env_config, label, mission, trajectory,
                            (float(rows[-1]["entropy"]), float(rows[-1]["f1"])))
            self.drawn.add((label, mission))


def _fly_missions(env_config: EnvConfig, specs: list[PlannerSpec], trials: int, seed: int,
                  workers: int, out: str | os.PathLike[str] | None, progress: bool,
                  namespace: str, backend: str, address: str | None, pool: WorkerPool | None,
                  drawer: _TrajectoryDrawer) -> EvaluationResult:
    """Evaluate the planners; with workers or Ray, ``drawer`` draws mission 0 as it lands."""
    from ipp_toolkit.runs.evaluation import evaluate

    return evaluate(env_config, specs, missions=int(trials), seed=int(seed),
                    workers=int(workers), out_dir=out, progress=progress, namespace=namespace,
                    record_missions=(0,),
                    on_recorded=drawer if workers > 1 or backend == "ray" else None,
                    backend=backend, address=address, pool=pool)


def _summary(result: EvaluationResult, reference: str | Sequence[str] | None,
             checkpoints: dict[str, dict[str, str]]) -> Summary:
    """The summary of the rows: paired with each reference (default ig and ig_spatial, where
    flown), naming the weights."""
    return summarise(result.rows, reference=reference, checkpoints={
        label: f"{record['checkpoint']} sha256:{record['sha256'][:16]}"
        for label, record in checkpoints.items()})


def _write_outputs(comparison: Comparison, out: Path, drawn: set[tuple[str, int]],
                   animate: bool, specs: list[PlannerSpec], seed: int) -> None:
    """The tables and figures (the trajectories not ``drawn`` yet) and, with ``animate``,
    ``animations/<planner>.gif``: mission 0 of every planner, flown again."""
    comparison.write(out, drawn)
    if not animate:
        return
    from .animation import animate_mission

    env_config = comparison.result.config
    for spec in specs:
        planner = make_planner(spec.name, **spec.options)
        label = spec.effective_label
        animate_mission(env_config, planner,
                        out / "animations" / f"{safe_name(str(label))}.gif",
                        seed=seed, mission=0)


def _requested_specs(planners: str | Sequence[str | PlannerSpec] | None) -> list[PlannerSpec]:
    """The planners ``planners`` asks for, as far as they parse, unbuilt (to warm the workers
    and to see what is stored already; a keyword's planners as if all were available)."""
    from ipp_toolkit.planning.specs import PlannerSpec

    keyword = _planner_keyword(planners)
    if keyword is not None:
        names = list(DEFAULT_PLANNERS) if keyword == "default" else available_planners()
        return [PlannerSpec(name) for name in names]
    specs = []
    for item in _listed_items(planners):
        try:
            specs.append(item if isinstance(item, PlannerSpec) else PlannerSpec.parse(item))
        except ValueError:
            continue  # refused with its message when the planners are built
    return specs


def _all_stored(out: str | os.PathLike[str] | None, requested: Sequence[PlannerSpec],
                trials: int) -> bool:
    """Whether ``out`` holds every mission of every ``requested`` planner
    (:func:`_requested_specs`) already, and mission 0's trajectory: then there is nothing to
    fly and no worker to start. Only a guess from the files' names, for speed: the
    evaluation checks the folder and the shards (a corrupt one is flown again), with or
    without workers, to the same results."""
    if out is None:
        return False
    folder = Path(out)
    labels = [spec.effective_label for spec in requested]
    return bool(labels) and all(
        trajectory_path(folder, label, 0).exists()
        and all(shard_path(folder, label, mission).exists() for mission in range(int(trials)))
        for label in labels)
