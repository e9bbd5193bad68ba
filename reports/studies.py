"""Studies that regenerate the paper's results, each one call (or one ``ipp-study`` command).

``robustness``: the paper's Table I. Every planner on the test missions of each team size and
communication range; learned planners are applied as trained (a COMA policy trained with 4
UAVs at 25 m flies 2 and 8 UAVs at 0, 25 m and infinite range without retraining). Writes one
``ipp-compare`` folder per setting plus ``robustness.md/.csv`` and ``robustness.png/.pdf``.

``credit`` and ``ablation`` train COMA runs alike (each resuming its folder), then compare them.
``sweep`` (:mod:`reports.sweep`) trains a grid of COMA runs the same way and scores them on
validation missions.

Every study runs on the ``local`` backend (processes on this machine) or on ``ray``
(:mod:`ipp_toolkit.runs.ray_backend`): one Ray for the whole study (:func:`backend_session`), every
mission flown as a Ray task as by ``ipp-compare --backend ray``, every training run one Ray
task (one CPU) that resumes its folder when retried or run again.
"""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ipp_toolkit.config.files import config_to_dict
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.config.settings import build_env_config, comm_label
from ipp_toolkit.runs.ray_backend import check_backend

from .compare import compare
from .plots import _colour, _new_figure, save_figure
from .tables import Summary, atomic_write_text

if TYPE_CHECKING:
    from ipp_toolkit.runs.ray_backend import RayCluster

__all__ = ["Setting", "RobustnessStudy", "robustness_study", "CreditStudy",
           "credit_assignment_study", "ablation_study", "seed_table", "ABLATIONS",
           "backend_session", "TrainTask", "train_run", "train_runs",
           "training_mission"]


@contextlib.contextmanager
def backend_session(backend: str, address: str | None,
                    workers: int) -> Iterator[RayCluster | None]:
    """The study's one Ray (None for ``backend="local"``): a local Ray with ``workers`` CPUs
    (``address=None``) or the cluster at ``address``, started or joined once for the whole
    study and shut down (disconnected) at its end; the evaluations inside reuse it.

    Raises:
        as :func:`ipp_toolkit.runs.ray_backend.check_backend`; ConnectionError: no Ray cluster
        answers at ``address``.
    """
    check_backend(backend, address)
    if backend == "local":
        yield None
        return
    from ipp_toolkit.runs.ray_backend import session

    with session(address, workers) as cluster:
        yield cluster


class Setting(NamedTuple):
    """One team setting of the robustness study."""

    agents: int
    comm: float
    failures: int = 0  # UAVs that fail at a random step (``team.random_failures``)

    @property
    def folder(self) -> str:
        """The setting's ``ipp-compare`` folder inside the study folder."""
        name = f"a{self.agents}-d{comm_label(self.comm)}"
        return name + (f"-f{self.failures}" if self.failures else "")


@dataclass
class RobustnessStudy:
    """Final-step results of every planner in every team setting.

    Attributes:
        settings: the :class:`Setting` (agents, comm, failures) triples in table order.
        planners: planner labels.
        summaries: the per-setting :class:`~reports.tables.Summary`.
        table: the Markdown table (best final entropy and F1 per setting in bold).
    """

    settings: list[Setting]
    planners: list[str]
    summaries: dict[Setting, Summary]
    table: str


def _table(settings: list[Setting], planners: list[str],
           summaries: dict[Setting, Summary]) -> tuple[str, str]:
    """Markdown and CSV of the final entropy and F1 per setting and planner."""
    header = (["agents", "D [m]", "failures"]
              + [f"{p} {m}" for p in planners for m in ("entropy", "F1")])
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    csv_lines = ["agents,comm,failures,planner,entropy_mean,entropy_std,f1_mean,f1_std,"
                 "missions"]
    for setting in settings:
        summary = summaries[setting]
        step = summary.budget
        stats = {p: (summary.stat(p, "entropy", step), summary.stat(p, "f1", step))
                 for p in planners}
        best_h = min(s[0].mean for s in stats.values())
        best_f = max(s[1].mean for s in stats.values())
        cells = [str(setting.agents), comm_label(setting.comm), str(setting.failures)]
        for planner in planners:
            h, f = stats[planner]
            text_h = f"{h.mean:.3f} ± {h.std:.3f}"
            text_f = f"{f.mean:.3f} ± {f.std:.3f}"
            cells.append(f"**{text_h}**" if h.mean == best_h else text_h)
            cells.append(f"**{text_f}**" if f.mean == best_f else text_f)
            csv_lines.append(f"{setting.agents},{comm_label(setting.comm)},{setting.failures},"
                             f"{planner},{h.mean:.6g},{h.std:.6g},{f.mean:.6g},{f.std:.6g},"
                             f"{h.n}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n", "\n".join(csv_lines) + "\n"


def _figure(settings: list[Setting], planners: list[str],
            summaries: dict[Setting, Summary], stem: Path) -> list[Path]:
    figure = _new_figure(max(6.0, 1.0 * len(settings)), 3.6)
    axes = figure.subplots(1, 2)
    x = np.arange(len(settings))
    width = 0.8 / max(len(planners), 1)
    for metric, ax in zip(("entropy", "f1"), axes, strict=True):
        for k, planner in enumerate(planners):
            stats = [summaries[s].stat(planner, metric, summaries[s].budget) for s in settings]
            ax.bar(x + (k - (len(planners) - 1) / 2) * width, [s.mean for s in stats], width,
                   yerr=[s.std for s in stats], label=planner, color=_colour(k), capsize=2)
        ax.set_xticks(x, [f"N={a}\nD={comm_label(c)}" + (f"\n{f} fail" if f else "")
                          for a, c, f in settings], fontsize=7)
        ax.set(ylabel=f"final {'entropy' if metric == 'entropy' else 'F1'}", ylim=(0, 1))
    axes[0].legend(fontsize=7)
    return save_figure(figure, stem)


def robustness_study(planners: str | Sequence[str] = "coma,ig,coverage",
                     agents: Sequence[int] = (2, 4, 8),
                     comms: Sequence[float] = (0.0, 25.0, math.inf), trials: int = 50,
                     seed: int = 0, out: str | os.PathLike[str] = "results/robustness",
                     workers: int = 1, resolution: float | None = None,
                     progress: bool = True,
                     note: Callable[[str], None] | None = None,
                     failures: Sequence[int] = (0,), backend: str = "local",
                     address: str | None = None) -> RobustnessStudy:
    """Run the robustness study (paper Table I) and write its table and figure into ``out``.

    Args:
        planners: comma-separated names or specs (``coma=PATH`` for your own policy).
        agents: team sizes.
        comms: communication ranges in metres (``math.inf`` allowed).
        trials: test missions per setting.
        seed: run seed of the missions.
        out: the study folder; one ``ipp-compare`` folder per setting inside (resumable).
        workers: evaluation processes.
        resolution: map resolution override (default: the protocol's 0.1 m).
        progress: show progress bars.
        note: receives notes (skipped planners); default stderr.
        failures: numbers of UAVs that fail at a random step of each mission
            (``team.random_failures``; beyond the paper); every team setting is flown with
            each. A count that leaves no UAV of a team is refused.
        backend: ``"local"`` or ``"ray"``: every mission a Ray task, on one Ray for the
            whole study (the same results; see :func:`reports.compare.compare`).
        address: with ``backend="ray"``, the cluster's head (``HOST:PORT``); None starts a
            local Ray with ``workers`` CPUs.
    """
    check_backend(backend, address)
    out = Path(out)
    settings = [Setting(int(a), float(c), int(f)) for a in agents for c in comms
                for f in failures]
    for setting in settings:  # every setting is checked before any mission is flown
        build_env_config(None, agents=setting.agents, comm=setting.comm).replace(
            team={"random_failures": setting.failures})
    if backend == "ray":
        from .compare import resolve_planners

        resolve_planners(planners, note)  # a bad planner fails before Ray starts
    summaries: dict[Setting, Summary] = {}
    labels: list[str] = []
    with backend_session(backend, address, workers):
        for setting in settings:
            config = build_env_config(None, agents=setting.agents, comm=setting.comm,
                                      resolution=resolution)
            if setting.failures:
                config = config.replace(team={"random_failures": setting.failures})
            comparison = compare(planners=planners, trials=trials, seed=seed, workers=workers,
                                 out=out / setting.folder, config=config, progress=progress,
                                 note=note, backend=backend, address=address)
            summaries[setting] = comparison.summary
            labels = list(comparison.summary.planners)
    markdown, csv_text = _table(settings, labels, summaries)
    caption = (f"Final entropy and F1 (mean ± std over {trials} test missions, seed {seed}) "
               "after the whole budget; learned policies are applied as trained.\n\n")
    atomic_write_text(out / "robustness.md", caption + markdown)
    atomic_write_text(out / "robustness.csv", csv_text)
    _figure(settings, labels, summaries, out / "robustness")
    return RobustnessStudy(settings, labels, summaries, caption + markdown)


# --------------------------------------------------------------------------------------------
# Credit assignment: COMA against its variants


@dataclass
class CreditStudy:
    """Outcome of :func:`credit_assignment_study`.

    Attributes:
        policies: variant -> path of its ``best.pt``.
        table: the Markdown table of the test comparison (one row per variant).
        out: the study folder (``runs/<variant>/`` training runs, ``compare/`` the test).
    """

    policies: dict[str, Path]
    table: str
    out: Path


def train_run(task: tuple[str, dict, dict, str, bool]) -> str:
    """Worker: train one COMA run into its folder (resuming it if it exists); its best.pt."""
    import torch

    from coma.config import preset
    from coma.learner import train
    from ipp_toolkit.config.files import config_from_dict

    _label, coma_values, env_values, folder, progress = task
    torch.set_num_threads(1)
    config = preset("cpu", **coma_values)
    env = config_from_dict(env_values)
    run = Path(folder)
    train(config, env, run, resume=(run / "last.pt").exists(), progress=progress,
          tensorboard=False)
    return str(run / "best.pt")


TrainTask = tuple[str, dict, dict, str, bool]
"""One training run: (label, COMAConfig fields, EnvConfig dict, run folder, progress)."""


def train_runs(tasks: list[TrainTask], workers: int, cluster: RayCluster | None = None,
                progress: bool = False,
                run: Callable[[TrainTask], Any] = train_run) -> dict[str, Path]:
    """Train every task; label -> its best.pt.

    Without ``cluster``: in ``workers`` spawned processes when > 1, else here. With one:
    each run is a Ray task declaring one CPU (COMA trains on the CPU), retried when its
    worker dies; every try resumes the run's folder (``last.pt``), so a study stopped on a
    cluster continues where its runs stopped. The folders are written by the workers, in
    this process's directory: on a cluster it must be on a file system every node shares
    (checked: a run whose ``last.pt`` this process cannot see raises FileNotFoundError).
    ``progress`` shows a bar of finished runs (Ray only). ``run`` trains one task (tests
    replace it).
    """
    import concurrent.futures
    import multiprocessing
    import os

    from ipp_toolkit.runs.process_pool import guard_worker

    if cluster is not None:
        return _train_on_ray(tasks, cluster, progress, run)
    if workers > 1 and len(tasks) > 1:
        context = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(
                min(workers, len(tasks)), mp_context=context, initializer=guard_worker,
                initargs=(os.getpid(),)) as pool:
            paths = list(pool.map(run, tasks))
    else:
        paths = [run(task) for task in tasks]
    return {task[0]: Path(path) for task, path in zip(tasks, paths, strict=True)}


def _train_on_ray(tasks: list[TrainTask], cluster: RayCluster, progress: bool,
                  run: Callable[[TrainTask], Any]) -> dict[str, Path]:
    """The Ray case of :func:`train_runs`."""
    from ipp_toolkit.runs.progress import progress_bar
    from ipp_toolkit.runs.ray_backend import run_calls

    quiet = [(label, values, env, folder, False)  # worker output is not forwarded
             for label, values, env, folder, _ in tasks]
    with progress_bar(len(tasks), "train", "runs", disable=not progress) as bar:
        run_calls(cluster, run, [(task,) for task in quiet],
                  describe=lambda k: f"training run {tasks[k][0]!r} ({tasks[k][3]})",
                  num_cpus=1, done=lambda k, result: bar.update(1))
    for _label, _values, _env, folder, _ in tasks:
        # A sweep's run that diverged before its first checkpoint leaves only the marker
        # ``diverged.json`` (reports.sweep.DIVERGED) in its folder.
        if not any((Path(folder) / name).is_file() for name in ("last.pt", "diverged.json")):
            raise FileNotFoundError(
                f"the training run in {folder!r} ended on a Ray worker, but its last.pt is not "
                f"here ({os.getcwd()!r}): on a cluster, run the study in a folder every node "
                "shares (see docs/ray.md)")
    # The paths as this process names them, so a study begun on the local backend resumes.
    return {task[0]: Path(task[3]) / "best.pt" for task in tasks}


def _training_seeds(seeds: Sequence[int] | None, overrides: dict | None) -> list[int]:
    """The training seeds of a study: ``seeds``, or the one in ``overrides`` (default 0)."""
    if seeds is None:
        return [int((overrides or {}).get("seed", 0))]
    seeds = list(seeds)
    if "seed" in (overrides or {}):
        raise ValueError(f"give the training seed either in seeds ({seeds}) or in overrides "
                         f"(seed = {overrides['seed']!r}), not both")
    if not seeds or len(set(seeds)) != len(seeds) or any(
            isinstance(s, bool) or not isinstance(s, int) or s < 0 for s in seeds):
        raise ValueError(f"seeds must be distinct non-negative integers, got {seeds}")
    return seeds


def _seeded_tasks(runs: list[tuple[str, dict, dict, Path]], seeds: list[int],
                  progress: bool) -> list[tuple[str, dict, dict, str, bool]]:
    """One training task per run and seed: with one seed the run's own label and folder,
    with several ``LABEL@sK`` in ``FOLDER-sK``."""
    tasks = []
    several = len(seeds) > 1
    for label, values, env, folder in runs:
        for seed in seeds:
            tasks.append((f"{label}@s{seed}" if several else label, {**values, "seed": seed},
                          env, str(folder) + (f"-s{seed}" if several else ""), progress))
    return tasks


def seed_table(summary: Summary, runs: Sequence[str], seeds: Sequence[int]) -> str:
    """Markdown table of each run over its training seeds (policies labelled ``RUN@sK``).

    Each cell is the mean over seeds of the per-seed mean over test missions, +- the standard
    deviation over seeds (ddof = 1), for the entropy at 33/67/100 % of the budget and the final
    F1. Best mean per column in bold.
    """
    steps = list(summary.steps)
    columns = [("entropy", step) for step in steps] + [("f1", summary.budget)]
    values: dict[tuple[str, str, int], tuple[float, float]] = {}
    for run in runs:
        for metric, step in columns:
            means = np.array([summary.stat(f"{run}@s{seed}", metric, step).mean
                              for seed in seeds])
            spread = float(means.std(ddof=1)) if len(means) > 1 else 0.0
            values[(run, metric, step)] = (float(means.mean()), spread)
    header = ["Run", "seeds"] + [f"{'Entropy' if m == 'entropy' else 'F1'} "
                                 f"{summary.fraction(step)}" for m, step in columns]
    lines = ["| " + " | ".join(header) + " |", "|:---|" + "---:|" * (len(header) - 1)]
    for run in runs:
        cells = [run, str(len(seeds))]
        for metric, step in columns:
            column = [values[(r, metric, step)][0] for r in runs]
            best = min(column) if metric == "entropy" else max(column)
            mean, spread = values[(run, metric, step)]
            text = f"{mean:.3f} ± {spread:.3f}"
            cells.append(f"**{text}**" if round(mean, 3) == round(best, 3) else text)
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _compare_runs(policies: dict[str, Path], out: Path, name: str, caption: str, trials: int,
                  seed: int, workers: int, eval_resolution: float | None,
                  progress: bool, runs: Sequence[str] = (),
                  seeds: Sequence[int] = (), backend: str = "local",
                  address: str | None = None) -> CreditStudy:
    """Fly the trained policies on the test missions; write ``out/name`` and ``out/compare``.

    With several training ``seeds``, the text starts with :func:`seed_table` over ``runs``.
    """
    from ipp_toolkit.planning.specs import PlannerSpec

    specs = [PlannerSpec("coma", {"checkpoint": str(path)}, label=label)
             for label, path in policies.items()]
    comparison = compare(agents=4, comm=25.0, planners=specs, trials=trials, seed=seed,
                         workers=workers, out=out / "compare", resolution=eval_resolution,
                         progress=progress, backend=backend, address=address)
    text = caption + "\n\n"
    if len(seeds) > 1:
        text += ("Over training seeds (mean ± std over seeds of each seed's mean over the test "
                 "missions):\n\n" + seed_table(comparison.summary, runs, seeds)
                 + "\n\nEvery trained policy:\n\n")
    text += comparison.table + "\n"
    atomic_write_text(out / name, text)
    return CreditStudy(policies, text, out)


def training_mission(train_resolution: float, paper_inputs: bool = False) -> EnvConfig:
    """The default training mission of ``ipp-train coma`` at ``train_resolution``: with the
    ``own_position`` plane, or the paper's inputs alone (``paper_inputs``, as the ``paper``
    and ``scratch`` presets train)."""
    return EnvConfig().replace(world={"resolution": train_resolution},
                               features={"own_position": not paper_inputs})


def credit_assignment_study(variants: Sequence[str] | None = None, missions: int = 5_000,
                            overrides: dict | None = None, train_resolution: float = 0.5,
                            trials: int = 50, seed: int = 0,
                            out: str | os.PathLike[str] = "results/credit",
                            workers: int = 1, eval_resolution: float | None = None,
                            progress: bool = True,
                            seeds: Sequence[int] | None = None, backend: str = "local",
                            address: str | None = None, preset: str = "cpu") -> CreditStudy:
    """Train COMA and its credit-assignment variants alike, then compare them on test missions.

    Every variant gets the preset ``preset`` with ``overrides`` and ``missions`` training
    missions on the default mission (4 UAVs, D = 25 m; the ``own_position`` plane, except
    for the presets trained on the paper's inputs, ``paper`` and ``scratch``) at map
    resolution ``train_resolution``; the greedy policies (``best.pt``, chosen on validation
    missions) then fly the same ``trials`` test missions. Runs resume if interrupted.
    ``preset="scratch"`` trains every variant from random networks.

    Args:
        variants: subset of ``coma.config.VARIANTS`` (default: all four).
        missions: training missions per variant.
        overrides: COMAConfig fields for every variant (e.g. ``{"seed": 1}``).
        train_resolution: r_M of the training missions.
        trials: test missions.
        seed: run seed of the test missions.
        out: the study folder.
        workers: variants trained in parallel processes (and evaluation workers).
        eval_resolution: r_M of the test missions (default: the protocol's 0.1 m).
        progress: show progress bars.
        seeds: training seeds; with several, every variant is trained once per seed (policies
            ``VARIANT@sK``) and the table starts with the mean and spread over seeds (default:
            one seed, ``overrides["seed"]`` or 0).
        backend: ``"local"`` or ``"ray"``: on one Ray for the whole study, every training
            run is a Ray task (one CPU; retried and resumed from its folder when its worker
            dies) and every test mission too; the run folders must then be on a file system
            the Ray nodes share.
        address: with ``backend="ray"``, the cluster's head (``HOST:PORT``); None starts a
            local Ray with ``workers`` CPUs.
    """
    from coma.cli import PAPER_INPUT_PRESETS
    from coma.config import PRESETS, VARIANTS

    if preset not in PRESETS:
        raise ValueError(f"unknown COMA preset {preset!r}; choose from {sorted(PRESETS)}")
    variants = list(VARIANTS if variants is None else variants)
    unknown = sorted(set(variants) - set(VARIANTS))
    if unknown:
        raise ValueError(f"unknown variant(s) {unknown}; choose from {list(VARIANTS)}")
    training_seeds = _training_seeds(seeds, overrides)
    check_backend(backend, address)
    out = Path(out)
    env = config_to_dict(training_mission(train_resolution, preset in PAPER_INPUT_PRESETS))
    values = {**PRESETS[preset], **(overrides or {}), "missions": int(missions)}
    tasks = _seeded_tasks([(v, {**values, "variant": v}, env, out / "runs" / v)
                           for v in variants], training_seeds, progress and workers == 1)
    caption = (f"Credit-assignment study: each variant trained for {missions} missions "
               f"({preset} preset, overrides {overrides or {}}), "
               f"{_seeds_text(training_seeds)}; "
               f"test: {trials} missions.")
    with backend_session(backend, address, workers) as cluster:
        policies = train_runs(tasks, workers, cluster, progress)
        return _compare_runs(policies, out, "credit.md", caption, trials, seed, workers,
                             eval_resolution, progress, variants, training_seeds, backend,
                             address)


def _seeds_text(seeds: Sequence[int]) -> str:
    return (f"training seed {seeds[0]}" if len(seeds) == 1
            else f"training seeds {', '.join(map(str, seeds))}")


# --------------------------------------------------------------------------------------------
# Feature ablation


#: Ablations besides switching a feature plane: training without action masks, and the
#: position plane (a) on the absolute grid instead of centred on the agent.
ABLATIONS = ("masking", "centred")


def ablation_study(ablations: Sequence[str], missions: int = 3_000,
                   overrides: dict | None = None, train_resolution: float = 0.5,
                   trials: int = 50, seed: int = 0,
                   out: str | os.PathLike[str] = "results/ablation", workers: int = 1,
                   eval_resolution: float | None = None, progress: bool = True,
                   seeds: Sequence[int] | None = None, backend: str = "local",
                   address: str | None = None) -> CreditStudy:
    """Train COMA on the default mission and on variants of it with one setting toggled.

    Each name in ``ablations`` is a ``FeatureConfig`` switch (toggled: a plane that is on is
    removed, ``own_position`` is removed since it is on in the training mission), or
    ``masking`` (train without action masks: masked choices hold the UAV; the deployed policy
    is still masked), or ``centred`` (the absolute position plane). The run ``full`` is the
    unchanged mission. Every run gets the same ``cpu``-preset training (``missions``, plus
    ``overrides``); the greedy policies then fly the same ``trials`` test missions.

    ``seeds``, ``backend`` and ``address`` work as in :func:`credit_assignment_study`.

    Returns:
        a :class:`CreditStudy` whose ``policies`` are keyed ``full`` and ``-<name>`` for a
        setting removed or ``+<name>`` for a plane the training mission lacks (with ``@sK``
        appended per seed when there are several).
    """
    from dataclasses import fields

    from ipp_toolkit.config.schema import FeatureConfig

    switches = {f.name for f in fields(FeatureConfig) if f.type in (bool, "bool")}
    unknown = sorted(set(ablations) - switches - set(ABLATIONS))
    if unknown:
        raise ValueError(f"unknown ablation(s) {unknown}; choose from "
                         f"{sorted(switches | set(ABLATIONS))}")
    training_seeds = _training_seeds(seeds, overrides)
    check_backend(backend, address)
    out = Path(out)
    base = training_mission(train_resolution)
    values = {**(overrides or {}), "missions": int(missions)}
    runs = [("full", values, config_to_dict(base), out / "runs" / "full")]
    for name in ablations:
        sign = "-"
        if name == "masking":
            env = base.replace(team={"invalid_action": "hold"})
        else:
            added = not getattr(base.features, name)
            env = base.replace(features={name: added})
            sign = "+" if added else "-"
        runs.append((f"{sign}{name}", values, config_to_dict(env), out / "runs" / name))
    tasks = _seeded_tasks(runs, training_seeds, progress and workers == 1)
    caption = (f"Feature ablation: COMA trained for {missions} missions per run (cpu preset, "
               f"overrides {overrides or {}}), {_seeds_text(training_seeds)}; '-x' = x "
               f"removed, '+x' = x added; test: {trials} missions.")
    with backend_session(backend, address, workers) as cluster:
        policies = train_runs(tasks, workers, cluster, progress)
        return _compare_runs(policies, out, "ablation.md", caption, trials, seed, workers,
                             eval_resolution, progress, [run[0] for run in runs],
                             training_seeds, backend, address)
