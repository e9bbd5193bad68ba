"""Hyper-parameter sweeps of COMA (``ipp-study sweep``): a grid of training runs, scored on
validation missions only.

``--sweep lr_actor=1e-4,3e-4 --sweep clip_ratio=0.1,0.2 --seeds 0,1,2`` trains the cartesian
product of the swept values (4 grid points here) once per training seed (12 runs), each with
the ``cpu`` preset (:func:`coma.config.preset`) plus the fixed ``--set`` fields, as in
:func:`reports.studies.credit_assignment_study`: in a process pool or as Ray tasks, each
resuming its folder ``runs/<point>/s<seed>/``. Every run's ``best.pt`` and ``ig`` (the
reference) then fly the same ``validation`` missions (never ``test`` ones: a sweep selects
settings) in one comparison (``validation/``); ``sweep.md`` lists each grid point's mean and
standard deviation over seeds of the final entropy and of the paired gap to IG, with the
per-seed values, and ``sweep.csv`` one row per run.

The scoring missions are those of run seed ``seed`` (default :data:`SCORING_SEED`) in the
``validation`` namespace; a training run selects its ``best.pt`` on the validation missions of
its own training seed, so ``seed`` must not be one of the training seeds (refused).

Everything is checked before anything is written or trained: field names and values against
:class:`~coma.config.COMAConfig` (values read by :func:`coma.cli.coerce_value`, the parser of
``ipp-train coma --set``), duplicates, the seeds, the mission, and run folders already there
(a folder holding a run with other settings is refused, naming the difference). Run again,
a sweep trains nothing already finished (a run that diverged counts as finished) and scores
from the stored missions.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import itertools
import json
import math
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ipp_toolkit.config.files import config_to_dict
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.config.settings import build_env_config, describe_config, safe_name
from ipp_toolkit.io import write_json
from ipp_toolkit.runs.ray_backend import check_backend

from .compare import Comparison, compare
from .studies import (
    TrainTask,
    backend_session,
    train_run,
    train_runs,
    training_mission,
)
from .tables import Summary, atomic_write_text

__all__ = ["SCORING_SEED", "GridPoint", "SweepRun", "SweepStudy", "parse_assignments",
           "parse_sweep", "sweep_grid", "sweep_study", "sweep_table"]

SCORING_SEED = 10_000
"""Default run seed of the validation missions a sweep scores on: no training seed of a
sweep may equal it, so no run is scored on the missions it selected its ``best.pt`` on."""

DIVERGED = "diverged.json"
"""Written into a run folder whose training diverged (``coma.learner.TrainingDiverged``): the
run counts as finished, its last ``best.pt`` (if any) is scored and flagged."""


# --------------------------------------------------------------------------------------------
# Parsing and checking the grid


def _field_name(name: str) -> str:
    """The canonical name of a COMAConfig field: a warm-start field as ``warm_start.NAME``
    (the older flat names mapped by :func:`coma.config.nested_fields`, their one owner)."""
    from coma.config import nested_fields

    nested = nested_fields({name: ""})
    if set(nested) == {"warm_start"}:
        return "warm_start." + next(iter(nested["warm_start"]))
    return name


def _coerce(name: str, text: str) -> Any:
    """A value as ``ipp-train coma --set`` reads it (:func:`coma.cli.coerce_value`); a field
    holding a tuple (``team_sizes``, ``comm_ranges``, ``validation_terrains``) takes its items
    joined by ``+`` (``2+4+8``; empty: ``()``), since commas separate a sweep's values."""
    from coma.cli import coerce_value
    from coma.config import COMAConfig

    defaults = {f.name: f.default for f in dataclasses.fields(COMAConfig)}
    if isinstance(defaults.get(name), tuple):
        return [coerce_value(item.strip()) for item in text.split("+") if item.strip()]
    return coerce_value(text)


def _split(flag: str, item: str) -> tuple[str, str]:
    """``FIELD=VALUE`` -> (canonical field, value text); ValueError naming ``flag``."""
    name, sep, value = item.partition("=")
    if not sep or not name.strip():
        raise ValueError(f"{flag} expects FIELD=VALUE, got {item!r}")
    return _field_name(name.strip()), value.strip()


def parse_assignments(items: Sequence[str], flag: str = "--set") -> dict[str, Any]:
    """``--set FIELD=VALUE`` items -> ``{field: value}`` (values as :func:`_coerce` reads them).

    Not checked against COMAConfig here (the caller's preset does that, naming the field).

    Raises:
        ValueError: an item without ``=``, or a field given twice.
    """
    values: dict[str, Any] = {}
    for item in items:
        name, text = _split(flag, item)
        if name in values:
            raise ValueError(f"{flag} gives {name} twice")
        values[name] = _coerce(name, text)
    return values


def parse_sweep(items: Sequence[str]) -> dict[str, list[tuple[str, Any]]]:
    """``--sweep FIELD=V1,V2,...`` items -> ``{field: [(text, value), ...]}`` in given order.

    Raises:
        ValueError: an item without ``=`` or without values, or a field given twice.
    """
    grid: dict[str, list[tuple[str, Any]]] = {}
    for item in items:
        name, text = _split("--sweep", item)
        if name in grid:
            raise ValueError(f"--sweep gives {name} twice; list all its values in one "
                             f"--sweep {name}=V1,V2,...")
        texts = [t.strip() for t in text.split(",")]
        if not text.strip():
            raise ValueError(f"--sweep {item!r}: no values (--sweep {name}=V1,V2,...)")
        grid[name] = [(t, _coerce(name, t)) for t in texts]
    return grid


def _text(value: Any) -> str:
    """A value as a grid point shows it (floats by repr: ``3e-4`` is ``0.0003``)."""
    if isinstance(value, bool):
        return str(value).lower()
    if value == "":
        return '""'  # e.g. warm_start.planner = "": no warm start
    if isinstance(value, list | tuple):
        return "+".join(_text(v) for v in value)
    if isinstance(value, float) and math.isinf(value):
        return "inf"
    return str(value)


@dataclass(frozen=True)
class GridPoint:
    """One point of the grid: the swept fields and their values, in ``--sweep`` order.

    Attributes:
        values: ``((field, value), ...)``.
    """

    values: tuple[tuple[str, Any], ...]

    @property
    def label(self) -> str:
        """``field=value,field=value`` (names the point in tables and in the comparison)."""
        return ",".join(f"{name}={_text(value)}" for name, value in self.values)

    @property
    def folder(self) -> str:
        """The point's folder name under ``runs/`` (file-name-safe)."""
        return safe_name("_".join(f"{name}-{_text(value)}" for name, value in self.values))


def sweep_grid(sweep: Mapping[str, Sequence[tuple[str, Any]]], fixed: Mapping[str, Any],
               seeds: Sequence[int], missions: int) -> list[tuple[GridPoint, Any]]:
    """Every grid point with its COMAConfig for seed 0, each checked (nothing is written).

    Args:
        sweep: :func:`parse_sweep`'s grid.
        fixed: the fields of every run (``--set``).
        seeds: the training seeds (distinct non-negative integers).
        missions: training missions per run (unless swept).

    Returns:
        ``[(point, COMAConfig), ...]`` in grid order (the last field varies fastest).

    Raises:
        ValueError: naming the field and value: an unknown field or a bad value (as
            COMAConfig words it), ``seed`` swept or set (use ``seeds``), a field both swept
            and set, values of one field that give the same config, bad seeds, or grid
            points whose folder names coincide.
    """
    from coma.config import preset

    if not sweep:
        raise ValueError("a sweep needs at least one --sweep FIELD=V1,V2,...")
    if isinstance(missions, bool) or not isinstance(missions, int) or missions < 1:
        raise ValueError(f"missions must be an integer >= 1, got {missions!r}")
    if not seeds or len(set(seeds)) != len(seeds) or any(
            isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds):
        raise ValueError(f"seeds must be distinct non-negative integers, got {list(seeds)}")
    if "seed" in sweep or "seed" in fixed:
        raise ValueError("the training seeds are given with --seeds (seeds=...), not as the "
                         "field seed")
    both = sorted(set(sweep) & set(fixed))
    if both:
        raise ValueError(f"{both[0]} is both swept (--sweep) and set (--set); give it once")
    base = {"missions": missions, **fixed}
    try:
        preset("cpu", **base)
    except ValueError as err:
        raise ValueError(f"--set: {err}") from None
    for name, values in sweep.items():
        seen: dict[str, str] = {}
        for text, value in values:
            try:
                config = preset("cpu", **{**base, name: value})
            except ValueError as err:
                raise ValueError(f"--sweep {name}={text}: {err}") from None
            key = json.dumps(config.to_dict(), sort_keys=True)
            if key in seen:
                raise ValueError(f"--sweep {name}: the values {seen[key]!r} and {text!r} give "
                                 "the same run; give each value once")
            seen[key] = text
    grid = []
    folders: dict[str, str] = {}
    for combination in itertools.product(*[[(name, value) for _, value in values]
                                           for name, values in sweep.items()]):
        point = GridPoint(tuple(combination))
        config = preset("cpu", **{**base, **dict(combination)})
        if point.folder in folders:
            raise ValueError(f"grid points {folders[point.folder]!r} and {point.label!r} map "
                             f"to the same folder name {point.folder!r}; change a value")
        folders[point.folder] = point.label
        grid.append((point, config))
    return grid


def _check_training(config: Any, env: EnvConfig) -> None:
    """What ``ipp-train coma`` checks before it writes: the training and validation settings,
    the warm start's planner and the starting policy (ValueError naming the value)."""
    from coma.config import mission_settings
    from coma.validation import validation_settings

    validation_settings(config, mission_settings(config, env))
    if config.warm_start.enabled:
        from ipp_toolkit.planning import planner_factory

        planner_factory(config.warm_start.planner)
    if config.init_policy and not Path(config.init_policy).is_file():
        raise ValueError(f"init_policy {config.init_policy!r}: no such policy file")


# --------------------------------------------------------------------------------------------
# Run folders: finished, resumable, or holding another run


def _finished(folder: Path, config: Any) -> bool:
    """Whether the run in ``folder`` needs no more training: it diverged, or its
    ``progress.csv`` reached the last update and ``last.pt`` is there."""
    if (folder / DIVERGED).is_file():
        return True
    if not (folder / "last.pt").is_file() or not (folder / "progress.csv").is_file():
        return False
    with open(folder / "progress.csv", newline="") as handle:
        updates = [row.get("update", "") for row in csv.DictReader(handle)]
    total = math.ceil(config.missions / config.missions_per_update)
    return bool(updates) and updates[-1].isdigit() and int(updates[-1]) >= total


def _check_folder(folder: Path, config: Any, env: EnvConfig) -> None:
    """Refuse a run folder that holds a run with other settings (before anything is trained).

    Raises:
        ValueError: naming the folder and the first differing field.
    """
    from coma.config import from_dict

    path = folder / "config.json"
    if not path.is_file():
        return
    try:
        stored = json.loads(path.read_text(encoding="utf-8"))
        stored_coma = from_dict(stored["coma"]).to_dict()
        stored_env = stored["env"]
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError,
            ValueError) as err:
        raise ValueError(f"{str(path)!r} is unreadable ({err}); move the run folder away "
                         "or use another --out") from None
    wanted = config.to_dict()
    for name in sorted(wanted):
        if stored_coma.get(name) != wanted[name]:
            raise ValueError(
                f"{str(folder)!r} holds a run with {name} = {stored_coma.get(name)!r}, this "
                f"sweep asks for {wanted[name]!r}; use another --out (or the same settings)")
    if stored_env != json.loads(json.dumps(config_to_dict(env))):
        raise ValueError(f"{str(folder)!r} holds a run on another mission config (--agents, "
                         "--comm, --train-resolution); use another --out")


def _train_or_note_divergence(task: TrainTask) -> str:
    """Worker: :func:`reports.studies.train_run`; a run whose loss diverged is finished, with
    :data:`DIVERGED` written into its folder (the sweep goes on with the other runs)."""
    from coma.learner import TrainingDiverged

    try:
        return train_run(task)
    except TrainingDiverged as err:
        write_json(Path(task[3]) / DIVERGED, {"error": str(err)})
        return str(Path(task[3]) / "best.pt")


# --------------------------------------------------------------------------------------------
# Scores and the table


@dataclass(frozen=True)
class SweepRun:
    """One training run of a sweep and its validation scores.

    Attributes:
        point: the grid point.
        seed: the training seed.
        folder: the run folder.
        entropy: mean final entropy over the validation missions (NaN: no policy to score).
        f1: mean final F1.
        gap: paired difference of the final entropy to IG's on the same missions (mean).
        gap_se: its standard error (NaN for one mission).
        win_rate: share of missions with a lower final entropy than IG.
        missions: validation missions scored.
        diverged: the training diverged (the scores are its last ``best.pt``'s).
    """

    point: GridPoint
    seed: int
    folder: Path
    entropy: float = math.nan
    f1: float = math.nan
    gap: float = math.nan
    gap_se: float = math.nan
    win_rate: float = math.nan
    missions: int = 0
    diverged: bool = False

    @property
    def label(self) -> str:
        """The run's planner label in the comparison: ``POINT@sSEED``."""
        return f"{self.point.label}@s{self.seed}"


@dataclass
class SweepStudy:
    """Outcome of :func:`sweep_study`.

    Attributes:
        points: the grid points in grid order.
        seeds: the training seeds.
        runs: every run (point-major, then seed), scored.
        ig_entropy: IG's mean final entropy on the same validation missions.
        table: the text of ``sweep.md``.
        out: the sweep folder.
    """

    points: list[GridPoint]
    seeds: list[int]
    runs: list[SweepRun]
    ig_entropy: float
    table: str
    out: Path

    @property
    def best(self) -> GridPoint | None:
        """The grid point with the lowest mean final entropy over seeds (None: no run has a
        policy to score)."""
        point = min(self.points, key=lambda p: _over_seeds(self.runs, p, "entropy")[0])
        return point if math.isfinite(_over_seeds(self.runs, point, "entropy")[0]) else None


def _over_seeds(runs: Sequence[SweepRun], point: GridPoint, name: str) -> tuple[float, float]:
    """Mean and sample std (ddof 1; 0 for one seed) over the scored seeds of ``point``."""
    values = np.array([getattr(r, name) for r in runs if r.point == point])
    values = values[np.isfinite(values)]
    if not len(values):
        return math.inf, math.nan
    return float(values.mean()), float(values.std(ddof=1)) if len(values) > 1 else 0.0


def sweep_table(runs: Sequence[SweepRun], points: Sequence[GridPoint]) -> str:
    """Markdown table: one row per grid point (one column per swept field), the mean ± std
    over seeds of the final entropy and of the gap to IG, then each seed's values; the best
    point (lowest mean final entropy at the printed precision) in bold. ``†``: diverged."""
    fields = [name for name, _ in points[0].values]
    header = [*fields, "seeds", "final entropy", "gap to IG", "per seed: entropy (gap)"]
    lines = ["| " + " | ".join(header) + " |",
             "|" + ":---|" * len(fields) + "---:|" * 3 + ":---|"]
    means = {p: _over_seeds(runs, p, "entropy")[0] for p in points}
    best = min(round(m, 3) for m in means.values())
    for point in points:
        own = [r for r in runs if r.point == point]
        scored = [r for r in own if math.isfinite(r.entropy)]
        entropy, entropy_sd = _over_seeds(runs, point, "entropy")
        gap, gap_sd = _over_seeds(runs, point, "gap")
        cells = [_text(value) for _, value in point.values] + [str(len(scored))]
        if scored:
            numbers = [f"{entropy:.3f} ± {entropy_sd:.3f}", f"{gap:+.3f} ± {gap_sd:.3f}"]
            if round(entropy, 3) == best:
                numbers = [f"**{text}**" for text in numbers]
        else:
            numbers = ["-", "-"]
        per_seed = "; ".join(
            f"s{r.seed} " + (f"{r.entropy:.3f} ({r.gap:+.3f})" if math.isfinite(r.entropy)
                             else "no policy") + ("†" if r.diverged else "") for r in own)
        lines.append("| " + " | ".join(cells + numbers + [per_seed]) + " |")
    return "\n".join(lines)


def _csv(runs: Sequence[SweepRun], ig_entropy: float, out: Path) -> str:
    """One row per run; ``run`` is its folder inside the sweep folder."""
    fields = [name for name, _ in runs[0].point.values]
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["point", *fields, "seed", "run", "final_entropy", "final_f1",
                     "gap_to_ig", "gap_se", "win_rate", "ig_final_entropy", "missions",
                     "diverged"])
    for r in runs:
        writer.writerow([r.point.label, *[_text(v) for _, v in r.point.values], r.seed,
                         r.folder.relative_to(out).as_posix(),
                         *[f"{x:.6g}" for x in (r.entropy, r.f1, r.gap, r.gap_se, r.win_rate,
                                                ig_entropy)],
                         r.missions, str(r.diverged).lower()])
    return buffer.getvalue()


# --------------------------------------------------------------------------------------------
# The study


def sweep_study(sweep: Mapping[str, Sequence[tuple[str, Any]]] | Sequence[str],
                seeds: Sequence[int] = (0,), overrides: Mapping[str, Any] | None = None,
                missions: int = 5_000, train_resolution: float = 0.5,
                agents: int | None = None, comm: float | None = None, trials: int = 50,
                seed: int = SCORING_SEED, out: str | os.PathLike[str] = "results/sweep",
                workers: int = 1, eval_resolution: float | None = None,
                progress: bool = True, backend: str = "local", address: str | None = None,
                run: Callable[[TrainTask], Any] = _train_or_note_divergence) -> SweepStudy:
    """Train the grid of COMA runs and score each on validation missions; write the table.

    Args:
        sweep: ``--sweep`` items (``["lr_actor=1e-4,3e-4"]``) or :func:`parse_sweep`'s grid.
        seeds: training seeds; every grid point is trained once per seed.
        overrides: COMAConfig fields of every run (``--set``; dotted warm-start names allowed).
        missions: training missions per run (the field ``missions`` may be swept instead).
        train_resolution: r_M of the training missions (the default mission of
            ``ipp-train coma``: 4 UAVs, D = 25 m, the ``own_position`` plane).
        agents, comm: team size and range of the training and the validation missions
            (None: 4 and 25 m); not swept.
        trials: validation missions each run (and IG) flies.
        seed: run seed of those missions (must not be a training seed).
        out: the sweep folder: ``runs/<point>/s<seed>/``, ``validation/`` (the comparison,
            resumable), ``sweep.md``, ``sweep.csv``.
        workers: runs trained at once and evaluation processes (``backend="ray"`` without
            ``address``: the CPUs of the local Ray).
        eval_resolution: r_M of the validation missions (default: the protocol's 0.1 m).
        progress: show progress bars.
        backend, address: as in :func:`reports.studies.credit_assignment_study`: every run a
            Ray task (one CPU, retried and resumed), every validation mission too; the run
            folders must then be on a file system the nodes share.
        run: trains one task (tests replace it).

    Raises:
        ValueError: bad input (see :func:`sweep_grid`; a scoring seed among the training
            seeds, a run folder holding another run), checked before anything is written.
    """
    grid_values = parse_sweep(sweep) if _is_items(sweep) else dict(sweep)  # type: ignore[arg-type]
    seeds = list(seeds)
    grid = sweep_grid(grid_values, dict(overrides or {}), seeds, missions)
    _check_scoring(seed, seeds, trials)
    check_backend(backend, address)
    env = build_env_config(training_mission(train_resolution), agents=agents, comm=comm)
    validation = build_env_config(None, agents=env.team.n_agents, comm=env.team.comm_range,
                                  resolution=eval_resolution)
    out = Path(out)
    runs, tasks = _plan_runs(grid, seeds, env, out, progress and workers == 1)
    points = [point for point, _ in grid]
    with backend_session(backend, address, workers) as cluster:
        if tasks:
            train_runs(tasks, workers, cluster, progress, run)
        runs = [dataclasses.replace(r, diverged=(r.folder / DIVERGED).is_file()) for r in runs]
        comparison = _validate_runs(runs, trials, seed, workers, out, validation, progress,
                                    backend, address)
    scored = _scored(runs, comparison.summary)
    ig = comparison.summary.stat("ig", "entropy", comparison.summary.budget)
    fixed = ", ".join(f"{k} = {_text(v)}" for k, v in (overrides or {}).items()) or "none"
    seed_text = ", ".join(map(str, seeds))
    caption = (
        f"COMA sweep: {len(points)} grid points x training seeds {seed_text}, cpu preset, "
        f"{missions} training missions per run unless swept, fixed fields: {fixed}; trained "
        f"on {describe_config(env)}. Scored on {trials} validation missions (run seed "
        f"{seed}; never test missions) on {describe_config(validation)}. Final entropy: mean "
        f"± std over seeds of each run's mean over the missions; gap to IG: the paired "
        f"difference of the final entropy to IG's on the same missions (negative: better "
        f"than IG), likewise over seeds. IG: {ig.mean:.3f} ± {ig.std:.3f} (over missions). "
        f"Best grid point in bold." + (" †: training diverged, its last best.pt is scored."
                                      if any(r.diverged for r in scored) else ""))
    table = caption + "\n\n" + sweep_table(scored, points) + "\n"
    atomic_write_text(out / "sweep.md", table)
    atomic_write_text(out / "sweep.csv", _csv(scored, ig.mean, out))
    return SweepStudy(points, seeds, scored, ig.mean, table, out)


def _check_scoring(seed: int, seeds: list[int], trials: int) -> None:
    """Refuse a scoring seed that is no non-negative integer or is a training seed, and bad
    ``trials`` (ValueError)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if seed in seeds:
        raise ValueError(f"the validation missions of seed {seed} are those the seed-{seed} "
                         "runs select their best.pt on; score on another --seed (default "
                         f"{SCORING_SEED})")
    if isinstance(trials, bool) or not isinstance(trials, int) or trials < 1:
        raise ValueError(f"trials must be an integer >= 1, got {trials!r}")


def _plan_runs(grid: list[tuple[GridPoint, Any]], seeds: list[int], env: EnvConfig, out: Path,
               bars: bool) -> tuple[list[SweepRun], list[TrainTask]]:
    """Every run of the grid (point x seed) and the training tasks of those not finished,
    each checked against the training mission and its folder (ValueError)."""
    runs: list[SweepRun] = []
    tasks: list[TrainTask] = []
    env_values = config_to_dict(env)
    for point, config in grid:
        try:
            _check_training(config, env)
        except ValueError as err:
            raise ValueError(f"grid point {point.label}: {err}") from None
        for training_seed in seeds:
            folder = out / "runs" / point.folder / f"s{training_seed}"
            seeded = config.replace(seed=training_seed)
            _check_folder(folder, seeded, env)
            runs.append(SweepRun(point, training_seed, folder))
            if not _finished(folder, seeded):
                # The checked config itself, every field (the worker applies it to "cpu").
                tasks.append((runs[-1].label, seeded.to_dict(), env_values, str(folder),
                              bars))
    return runs, tasks


def _validate_runs(runs: list[SweepRun], trials: int, seed: int, workers: int, out: Path,
                   validation: EnvConfig, progress: bool, backend: str,
                   address: str | None) -> Comparison:
    """IG and every run with a ``best.pt``, flown on the same validation missions."""
    from ipp_toolkit.planning.specs import PlannerSpec

    flown = [r for r in runs if (r.folder / "best.pt").is_file()]
    specs = [PlannerSpec("ig", label="ig")] + [
        PlannerSpec("coma", {"checkpoint": str(r.folder / "best.pt")}, label=r.label)
        for r in flown]
    return compare(planners=specs, trials=trials, seed=seed, workers=workers,
                   out=out / "validation", config=validation, progress=progress,
                   namespace="validation", backend=backend, address=address)


def _scored(runs: list[SweepRun], summary: Summary) -> list[SweepRun]:
    """The runs with their validation scores (a run without a policy as it is)."""
    budget = summary.budget
    scored = []
    for r in runs:
        paired = summary.paired.get(r.label)
        if paired is None:
            scored.append(r)
            continue
        scored.append(dataclasses.replace(
            r, entropy=summary.stat(r.label, "entropy", budget).mean,
            f1=summary.stat(r.label, "f1", budget).mean, gap=paired.mean, gap_se=paired.se,
            win_rate=paired.win_rate, missions=paired.n))
    return scored


def _is_items(sweep: Any) -> bool:
    return not isinstance(sweep, Mapping) and all(isinstance(item, str) for item in sweep)
