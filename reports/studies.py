"""Studies that regenerate the paper's results, each one call (or one ``ipp-study`` command).

``robustness``: the paper's Table I. Every planner on the test missions of each team size and
communication range; learned planners are applied as trained (a COMA policy trained with 4
UAVs at 25 m flies 2 and 8 UAVs at 0, 25 m and infinite range without retraining). Writes one
``ipp-compare`` folder per setting plus ``robustness.md/.csv`` and ``robustness.png/.pdf``.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .compare import compare
from .plots import _colour, _new_figure, save_figure
from .tables import Summary, atomic_write_text

__all__ = ["RobustnessStudy", "robustness_study"]


@dataclass
class RobustnessStudy:
    """Final-step results of every planner in every (agents, comm) setting.

    Attributes:
        settings: (agents, comm) pairs in table order.
        planners: planner labels.
        summaries: the per-setting :class:`~reports.tables.Summary`.
        table: the Markdown table (best final entropy and F1 per setting in bold).
    """

    settings: list[tuple[int, float]]
    planners: list[str]
    summaries: dict[tuple[int, float], Summary]
    table: str


def _comm_text(comm: float) -> str:
    return "inf" if math.isinf(comm) else f"{comm:g}"


def _table(settings: list[tuple[int, float]], planners: list[str],
           summaries: dict[tuple[int, float], Summary]) -> tuple[str, str]:
    """Markdown and CSV of the final entropy and F1 per setting and planner."""
    header = ["agents", "D [m]"] + [f"{p} {m}" for p in planners for m in ("entropy", "F1")]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    csv_lines = ["agents,comm,planner,entropy_mean,entropy_std,f1_mean,f1_std,missions"]
    for setting in settings:
        summary = summaries[setting]
        step = summary.budget
        stats = {p: (summary.stat(p, "entropy", step), summary.stat(p, "f1", step))
                 for p in planners}
        best_h = min(s[0].mean for s in stats.values())
        best_f = max(s[1].mean for s in stats.values())
        cells = [str(setting[0]), _comm_text(setting[1])]
        for planner in planners:
            h, f = stats[planner]
            text_h = f"{h.mean:.3f} ± {h.std:.3f}"
            text_f = f"{f.mean:.3f} ± {f.std:.3f}"
            cells.append(f"**{text_h}**" if h.mean == best_h else text_h)
            cells.append(f"**{text_f}**" if f.mean == best_f else text_f)
            csv_lines.append(f"{setting[0]},{_comm_text(setting[1])},{planner},{h.mean:.6g},"
                             f"{h.std:.6g},{f.mean:.6g},{f.std:.6g},{h.n}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n", "\n".join(csv_lines) + "\n"


def _figure(settings: list[tuple[int, float]], planners: list[str],
            summaries: dict[tuple[int, float], Summary], stem: Path) -> list[Path]:
    figure = _new_figure(max(6.0, 1.0 * len(settings)), 3.6)
    axes = figure.subplots(1, 2)
    x = np.arange(len(settings))
    width = 0.8 / max(len(planners), 1)
    for metric, ax in zip(("entropy", "f1"), axes, strict=True):
        for k, planner in enumerate(planners):
            stats = [summaries[s].stat(planner, metric, summaries[s].budget) for s in settings]
            ax.bar(x + (k - (len(planners) - 1) / 2) * width, [s.mean for s in stats], width,
                   yerr=[s.std for s in stats], label=planner, color=_colour(k), capsize=2)
        ax.set_xticks(x, [f"N={a}\nD={_comm_text(c)}" for a, c in settings], fontsize=7)
        ax.set(ylabel=f"final {'entropy' if metric == 'entropy' else 'F1'}", ylim=(0, 1))
    axes[0].legend(fontsize=7)
    return save_figure(figure, stem)


def robustness_study(planners: str | Sequence[str] = "coma,ig,coverage",
                     agents: Sequence[int] = (2, 4, 8),
                     comms: Sequence[float] = (0.0, 25.0, math.inf), trials: int = 50,
                     seed: int = 0, out: str | os.PathLike[str] = "results/robustness",
                     workers: int = 1, resolution: float | None = None,
                     progress: bool = True,
                     note: Callable[[str], None] | None = None) -> RobustnessStudy:
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
    """
    out = Path(out)
    settings = [(int(a), float(c)) for a in agents for c in comms]
    summaries: dict[tuple[int, float], Summary] = {}
    labels: list[str] = []
    for n_agents, comm in settings:
        folder = out / f"a{n_agents}-d{_comm_text(comm)}"
        comparison = compare(agents=n_agents, comm=comm, planners=planners, trials=trials,
                             seed=seed, workers=workers, out=folder, resolution=resolution,
                             progress=progress, note=note)
        summaries[(n_agents, comm)] = comparison.summary
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


def _train_variant(task: tuple[str, dict, dict, str, bool]) -> str:
    """Worker: train one variant into its run folder (resuming it if it exists)."""
    import torch

    from coma.config import preset
    from coma.learner import train
    from ipp_toolkit.config import config_from_dict

    variant, overrides, env_values, folder, progress = task
    torch.set_num_threads(1)
    config = preset("cpu", **{**overrides, "variant": variant})
    env = config_from_dict(env_values)
    run = Path(folder)
    train(config, env, run, resume=(run / "last.pt").exists(), progress=progress,
          tensorboard=False)
    return str(run / "best.pt")


def credit_assignment_study(variants: Sequence[str] | None = None, missions: int = 5_000,
                            overrides: dict | None = None, train_resolution: float = 0.5,
                            trials: int = 50, seed: int = 0,
                            out: str | os.PathLike[str] = "results/credit",
                            workers: int = 1, eval_resolution: float | None = None,
                            progress: bool = True) -> CreditStudy:
    """Train COMA and its credit-assignment variants alike, then compare them on test missions.

    Every variant gets the ``cpu`` preset with ``overrides`` and ``missions`` training
    missions on the default mission (4 UAVs, D = 25 m, the ``own_position`` plane) at map
    resolution ``train_resolution``; the greedy policies (``best.pt``, chosen on validation
    missions) then fly the same ``trials`` test missions. Runs resume if interrupted.

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
    """
    import concurrent.futures
    import multiprocessing

    from coma.config import VARIANTS
    from ipp_toolkit.config import EnvConfig, config_to_dict
    from ipp_toolkit.evaluation import PlannerSpec

    variants = list(VARIANTS if variants is None else variants)
    unknown = sorted(set(variants) - set(VARIANTS))
    if unknown:
        raise ValueError(f"unknown variant(s) {unknown}; choose from {list(VARIANTS)}")
    out = Path(out)
    env = EnvConfig().replace(world={"resolution": train_resolution},
                              features={"own_position": True})
    values = {**(overrides or {}), "missions": int(missions)}
    tasks = [(v, values, config_to_dict(env), str(out / "runs" / v), progress and workers == 1)
             for v in variants]
    if workers > 1:
        context = multiprocessing.get_context("spawn")
        with concurrent.futures.ProcessPoolExecutor(min(workers, len(tasks)),
                                                    mp_context=context) as pool:
            paths = list(pool.map(_train_variant, tasks))
    else:
        paths = [_train_variant(task) for task in tasks]
    policies = {v: Path(p) for v, p in zip(variants, paths, strict=True)}
    specs = [PlannerSpec("coma", {"checkpoint": str(path)}, label=variant)
             for variant, path in policies.items()]
    comparison = compare(agents=4, comm=25.0, planners=specs, trials=trials, seed=seed,
                         workers=workers, out=out / "compare", resolution=eval_resolution,
                         progress=progress)
    caption = (f"Credit-assignment study: each variant trained for {missions} missions "
               f"(cpu preset, overrides {overrides or {}}), one training seed; test: "
               f"{trials} missions.\n\n")
    atomic_write_text(out / "credit.md", caption + comparison.table + "\n")
    return CreditStudy(policies, caption + comparison.table, out)
