"""``ipp-study generalisation``: do learned planners beat IG off their training distribution?

Every planner flies the same test missions in a grid of cells:

* each terrain family at the paper's setting (4 UAVs, D = 25 m): ``split`` (the training
  distribution of the paper's policies), ``blobs``, ``fractal`` and, one cell per real *test*
  raster file, ``real`` (random crops, rotations/flips, threshold quantiles and starts: each
  mission is a different map, so the standard error is one over maps);
* the nine team settings (2/4/8 UAVs x D 0/25 m/inf) on ``split`` and ``blobs``.

A cell is an ``ipp-compare`` folder (resumable); the study writes ``generalisation.md``,
``.csv``, ``.tex`` and ``generalisation.png/.pdf``: mean final entropy per planner and the
paired difference of every other planner to each reference planner (by default IG, the
paper's baseline, and ``ig_spatial``, the best heuristic, where flown): mean ± standard error
over missions and the share of missions ahead. A difference is **bold** where the planner is
ahead by two standard errors (mean < 0 and mean <= -2 SE; identical missions are level). The
figure plots the differences to the first reference only.

With ``backend="ray"`` every cell's missions fly as Ray tasks, on one Ray for the whole study
(:func:`reports.studies.backend_session`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ipp_toolkit.config.schema import EnvConfig, terrain_kinds
from ipp_toolkit.config.settings import comm_label, format_comm
from ipp_toolkit.planning.specs import PlannerSpec, as_specs
from ipp_toolkit.runs.ray_backend import check_backend
from ipp_toolkit.world.families import real_raster_names

from .compare import DEFAULT_PLANNERS, compare
from .plots import _colour, _new_figure, save_figure
from .studies import backend_session
from .tables import DEFAULT_REFERENCES, Paired, Summary, atomic_write_text, flown_references

__all__ = ["Cell", "GeneralisationStudy", "check_families", "generalisation_study",
           "study_cells"]

NINE_SETTINGS = tuple((a, c) for a in (2, 4, 8) for c in (0.0, 25.0, math.inf))


@dataclass(frozen=True)
class Cell:
    """One cell of the study: a terrain (a family, or one real raster) and a team setting."""

    terrain: str
    agents: int
    comm: float
    real_source: str = ""

    @property
    def label(self) -> str:
        return f"real:{self.real_source}" if self.real_source else self.terrain

    @property
    def folder(self) -> str:
        return f"{self.label.replace(':', '-')}/a{self.agents}-d{comm_label(self.comm)}"


@dataclass
class GeneralisationStudy:
    """Outcome of :func:`generalisation_study`.

    Attributes:
        cells: the cells in table order.
        planners: planner labels.
        reference: the first reference planner (the figure's).
        summaries: the per-cell :class:`~reports.tables.Summary`.
        table: the Markdown table.
        references: every reference planner, one set of paired columns each.
    """

    cells: list[Cell]
    planners: list[str]
    reference: str
    summaries: dict[Cell, Summary]
    table: str
    references: tuple[str, ...] = ()


def study_families() -> tuple[str, ...]:
    """The terrain families a cell can fly: every terrain kind but ``raster`` (which needs a
    file)."""
    return tuple(kind for kind in terrain_kinds() if kind != "raster")


def check_families(families: Sequence[str], what: str = "families") -> None:
    """Refuse (ValueError, naming ``what`` and the value) a family that is no terrain kind a
    cell can fly, before anything flies or is written."""
    known = study_families()
    for family in families:
        if family not in known:
            raise ValueError(f"{what}: unknown terrain kind {family!r}; known families: "
                             f"{', '.join(known)}")


def study_cells(families: Sequence[str] = ("split", "blobs", "fractal", "real"),
                team_families: Sequence[str] = ("split", "blobs"),
                settings: Sequence[tuple[int, float]] = NINE_SETTINGS,
                family_setting: tuple[int, float] = (4, 25.0)) -> list[Cell]:
    """The cells: every family at ``family_setting`` (``real``: one cell per test raster),
    then every team setting on each of ``team_families`` (the family cell not repeated).
    ValueError on an unknown family (:func:`check_families`)."""
    check_families(families, "families")
    check_families(team_families, "team_families")
    cells: list[Cell] = []
    agents, comm = family_setting
    for family in families:
        if family == "real":
            cells += [Cell("real", agents, comm, name) for name in real_raster_names("test")]
        else:
            cells.append(Cell(family, agents, comm))
    for family in team_families:
        cells += [Cell(family, a, c) for a, c in settings
                  if Cell(family, a, c) not in cells]
    return cells


def _paired_text(paired: Paired | None) -> str:
    if paired is None or not math.isfinite(paired.mean):
        return "-"
    se = f" ± {paired.se:.3f}" if math.isfinite(paired.se) else ""
    text = f"{paired.mean:+.3f}{se} ({100 * paired.win_rate:.0f} %)"
    # Strictly ahead: a planner that flies the reference's missions identically (mean and
    # SE 0) is level, not ahead.
    ahead = math.isfinite(paired.se) and paired.mean < 0 and paired.mean <= -2 * paired.se
    return f"**{text}**" if ahead else text


def _tables(cells: list[Cell], planners: list[str], references: Sequence[str],
            summaries: dict[Cell, Summary]) -> tuple[str, str, str]:
    header = ["terrain", "UAVs", "D"] + [f"{p} H" for p in planners] + [
        f"{p} − {r}" for r in references for p in planners if p != r]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * 3 + "---:|" * (len(header) - 3)]
    # The first reference's columns keep their names and places, and later ones go at the
    # end, so readers of the one-reference file keep working.
    first = references[0]
    csv_rows = ["terrain,agents,comm,planner,entropy_final_mean,entropy_final_std,"
                f"minus_{first}_mean,minus_{first}_se,win_rate,missions" + "".join(
                    f",minus_{r}_mean,minus_{r}_se,win_rate_vs_{r}" for r in references[1:])]
    tex_rows = []
    for cell in cells:
        summary = summaries[cell]
        step = summary.budget
        means = {p: summary.stat(p, "entropy", step) for p in planners}
        best = min(s.mean for s in means.values())
        cells_text = [cell.label, str(cell.agents), format_comm(cell.comm)]
        for p in planners:
            text = f"{means[p].mean:.3f}"
            cells_text.append(f"**{text}**" if means[p].mean == best else text)
        pairs = {r: summary.paired_to.get(r, {}) for r in references}
        cells_text += [_paired_text(pairs[r].get(p)) for r in references
                       for p in planners if p != r]
        lines.append("| " + " | ".join(cells_text) + " |")
        tex_rows.append(" & ".join(c.replace("**", "").replace("%", r"\%").replace("_", r"\_")
                                   .replace("±", r"$\pm$") for c in cells_text) + r" \\")
        for p in planners:
            values = [_paired_csv(pairs[r].get(p)) for r in references]
            csv_rows.append(f"{cell.label},{cell.agents},{comm_label(cell.comm)},{p},"
                            f"{means[p].mean:.6g},{means[p].std:.6g},{values[0]},"
                            f"{means[p].n}" + "".join(f",{v}" for v in values[1:]))
    tex = "\n".join([r"% requires \usepackage{booktabs}", r"\begin{tabular}{lrr"
                     + "r" * (len(header) - 3) + "}", r"\toprule",
                     " & ".join(h.replace("_", r"\_").replace("−", "$-$") for h in header)
                     + r" \\", r"\midrule", *tex_rows, r"\bottomrule", r"\end{tabular}"])
    return "\n".join(lines) + "\n", "\n".join(csv_rows) + "\n", tex + "\n"


def _paired_csv(paired: Paired | None) -> str:
    """Mean, SE and win rate as three CSV fields (empty for the reference's own row)."""
    if paired is None:
        return ",,"
    return f"{paired.mean:.6g},{paired.se:.6g},{paired.win_rate:.6g}"


def _figure(cells: list[Cell], planners: list[str], reference: str,
            summaries: dict[Cell, Summary], stem: Path) -> list[Path]:
    others = [p for p in planners if p != reference]
    figure = _new_figure(max(6.0, 0.55 * len(cells)), 3.4)
    ax = figure.subplots(1, 1)
    x = np.arange(len(cells))
    width = 0.8 / max(len(others), 1)
    for k, planner in enumerate(others):
        paired = [summaries[c].paired_to.get(reference, {}).get(planner) for c in cells]
        means = [p.mean if p else np.nan for p in paired]
        errors = [2 * p.se if p and math.isfinite(p.se) else 0.0 for p in paired]
        ax.bar(x + (k - (len(others) - 1) / 2) * width, means, width, yerr=errors,
               label=planner, color=_colour(k), capsize=2)
    ax.axhline(0.0, color="black", linewidth=0.8)
    ax.set_xticks(x, [f"{c.label}\nN={c.agents} D={comm_label(c.comm)}" for c in cells],
                  fontsize=6, rotation=60, ha="right")
    ax.set(ylabel=f"final entropy − {reference}'s (± 2 SE)")
    ax.legend(fontsize=7)
    return save_figure(figure, stem)


def generalisation_study(planners: str | Sequence[str | PlannerSpec]
                         = ",".join(DEFAULT_PLANNERS),
                         cells: Sequence[Cell] | None = None, trials: int = 50, seed: int = 0,
                         out: str | os.PathLike[str] = "results/generalisation",
                         workers: int = 1, resolution: float | None = None,
                         budget: int | None = None,
                         reference: str | Sequence[str] | None = None,
                         progress: bool = True,
                         note: Callable[[str], None] | None = None, backend: str = "local",
                         address: str | None = None) -> GeneralisationStudy:
    """Fly every planner in every cell and write the study's tables and figure into ``out``.

    Args:
        planners: comma-separated names, or a sequence of names and
            :class:`~ipp_toolkit.planning.specs.PlannerSpec` (planners with options); must
            include a reference.
        cells: the grid (default :func:`study_cells`).
        trials: test missions per cell (each ``real`` mission a different map).
        seed: run seed of the missions.
        out: the study folder; one resumable ``ipp-compare`` folder per cell inside.
        workers: evaluation processes.
        resolution, budget: overrides of the protocol's r_M = 0.1 m and B = 15.
        reference: the planners the paired columns compare with, one set of columns each:
            a label, comma-separated labels or a sequence, each of which must be flown. None:
            ``ig`` and ``ig_spatial``, each that is not flown left out (at least one must
            be). The figure compares with the first.
        progress: show progress bars.
        note: receives notes (skipped planners); default stderr.
        backend: ``"local"`` or ``"ray"``: every mission a Ray task, on one Ray for the
            whole study (the same results).
        address: with ``backend="ray"``, the cluster's head (``HOST:PORT``); None starts a
            local Ray with ``workers`` CPUs.

    Raises:
        ValueError: bad input (an unknown planner, a named reference not among the
            planners, or no default one), checked before anything is written.
        ipp_toolkit.runs.ray_backend.RayUnavailableError: ``backend="ray"`` without Ray.
        ConnectionError: no Ray cluster answers at ``address``.
    """
    check_backend(backend, address)
    references = _study_references(
        reference, planners, [spec.effective_label for spec in as_specs(planners)])
    out = Path(out)
    cells = list(study_cells() if cells is None else cells)
    check_families([cell.terrain for cell in cells], "cells")
    if backend == "ray":
        from .compare import resolve_planners

        resolve_planners(planners, note)  # a bad planner fails before Ray starts
    summaries: dict[Cell, Summary] = {}
    labels: list[str] = []
    with backend_session(backend, address, workers):
        for cell in cells:
            terrain = {"kind": cell.terrain}
            if cell.real_source:
                terrain["real_sources"] = cell.real_source
            config = EnvConfig().replace(terrain=terrain)
            comparison = compare(agents=cell.agents, comm=cell.comm, planners=planners,
                                 trials=trials, seed=seed, workers=workers,
                                 out=out / cell.folder, config=config, resolution=resolution,
                                 budget=budget, progress=progress, note=note,
                                 reference=references, backend=backend, address=address)
            summaries[cell] = comparison.summary
            labels = list(comparison.summary.planners)
    markdown, csv_text, tex = _tables(cells, labels, references, summaries)
    first = references[0]
    caption = (f"Final entropy (mean over {trials} test missions per cell, seed {seed}; lower "
               f"is better) and each planner's paired difference to {' and to '.join(references)}"
               " on the same missions: mean ± standard error (share of missions ahead); bold "
               "where ahead by two standard errors. real:NAME cells: crops of one test raster "
               f"never trained on, one map per mission. generalisation.png plots the differences"
               f" to {first} only.\n\n")
    atomic_write_text(out / "generalisation.md", caption + markdown)
    atomic_write_text(out / "generalisation.csv", csv_text)
    atomic_write_text(out / "generalisation.tex", tex)
    _figure(cells, labels, first, summaries, out / "generalisation")
    return GeneralisationStudy(cells, labels, first, summaries, caption + markdown, references)


def _study_references(reference: str | Sequence[str] | None,
                      planners: str | Sequence[str | PlannerSpec],
                      labels: list[str]) -> tuple[str, ...]:
    """The reference planners of the study (see :func:`reports.tables.flown_references`);
    without names, at least one default must be flown: the study is about beating one."""
    flown = flown_references(reference, labels)
    if not flown:
        raise ValueError(f"the reference planner {DEFAULT_REFERENCES[0]!r} is not among the "
                         f"planners {planners!r} (nor is {DEFAULT_REFERENCES[1]!r}); name one "
                         "that is flown with reference")
    return flown
