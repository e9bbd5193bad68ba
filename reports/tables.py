"""Summary tables of an evaluation: the paper's Table I from tidy per-step rows.

:func:`summarise` reduces the rows of :func:`ipp_toolkit.runs.evaluation.evaluate` (one per planner,
mission and step) to mean and standard deviation per planner and metric at 33 / 67 / 100 % of
the budget, plus the mean planning time per step. The writers render a :class:`Summary` as
Markdown, CSV or LaTeX (pure functions returning strings); :func:`write_tables` writes all
three atomically.

Table layout: one row per planner, one column per (metric, budget fraction), cells
``mean ± std`` over missions (sample standard deviation, ddof = 1; 0 for a single mission), the
best mean of every column in bold (lowest entropy / RMSE, highest F1 / reward; ties at the
printed precision are all bold), one paired column per reference planner (final entropy
minus the reference's on the same missions: mean ± paired standard error and the share of
missions ahead; by default against ``ig``, the paper's baseline, and ``ig_spatial``, the best
heuristic, each where it is in the rows), and a last column with the mean planning time per
step.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ipp_toolkit.config.settings import format_comm
from ipp_toolkit.io import atomic_write

__all__ = [
    "Stat",
    "Paired",
    "paired_differences",
    "DEFAULT_REFERENCES",
    "reference_labels",
    "flown_references",
    "Summary",
    "summarise",
    "budget_steps",
    "to_markdown",
    "to_csv",
    "to_latex",
    "write_tables",
    "atomic_write_text",
    "LOWER_IS_BETTER",
    "METRIC_NAMES",
]

LOWER_IS_BETTER: dict[str, bool] = {"entropy": True, "rmse": True, "f1": False, "reward": False}
"""Direction of every known metric: True when the lowest mean is the best."""

METRIC_NAMES: dict[str, str] = {"entropy": "Entropy", "f1": "F1", "rmse": "RMSE",
                                "reward": "Reward"}
"""Display names of the metrics in table headers."""

DIGITS = 3
"""Decimals of the means and standard deviations in Markdown and LaTeX."""

DEFAULT_REFERENCES: tuple[str, ...] = ("ig", "ig_spatial")
"""The planners of the paired columns when none is named: IG (the paper's baseline) and
``ig_spatial`` (the best heuristic), so a table shows what a learned planner adds over both."""


@dataclass(frozen=True)
class Stat:
    """Mean and sample standard deviation of one metric over missions.

    Attributes:
        mean: mean over the missions (NaN when ``n`` is 0).
        std: sample standard deviation (ddof = 1; 0 for one mission, NaN for none).
        n: number of missions with a finite value.
    """

    mean: float
    std: float
    n: int


@dataclass(frozen=True)
class Paired:
    """A planner's paired difference to a reference planner on the same missions.

    With d_k = metric of the planner minus the reference's on mission k:

    Attributes:
        mean: mean of d over missions (negative = lower than the reference).
        se: standard error sd(d, ddof=1) / sqrt(n) (NaN for fewer than two missions).
        win_rate: share of missions where the planner is better (d < 0 for a metric where
            lower is better, d > 0 otherwise).
        n: number of paired missions.
    """

    mean: float
    se: float
    win_rate: float
    n: int


def paired_differences(rows: Iterable[Mapping[str, Any]] | Any, reference: str,
                       metric: str = "entropy", step: int | None = None,
                       by: Sequence[str] = ("mission",)) -> dict[str, Paired]:
    """Paired differences of every planner to ``reference`` at one step (common missions).

    Args:
        rows: tidy per-step rows (``planner``, ``step``, the ``by`` keys and ``metric``).
        reference: the reference planner's label (e.g. ``"ig"``).
        metric: the compared metric.
        step: the compared step (default: the largest step in the rows, the budget).
        by: the keys that identify one mission (add e.g. ``"agents"`` when rows of several
            settings are pooled).

    Returns:
        ``{planner: Paired}`` for every planner but the reference that shares at least one
        mission with it; empty when the reference is not in the rows.
    """
    table = _rows_of(rows)
    if not table:
        return {}
    step = max(int(r["step"]) for r in table) if step is None else int(step)
    values: dict[str, dict[tuple, float]] = {}
    for row in table:
        if int(row["step"]) == step:
            value = _float(row.get(metric))
            if math.isfinite(value):
                key = tuple(str(row.get(k)) for k in by)
                values.setdefault(str(row["planner"]), {})[key] = value
    base = values.get(reference)
    if base is None:
        return {}
    sign = -1.0 if LOWER_IS_BETTER.get(metric, False) else 1.0
    result = {}
    for planner, by_mission in values.items():
        common = sorted(set(by_mission) & set(base))
        if planner == reference or not common:
            continue
        d = np.array([by_mission[k] - base[k] for k in common])
        se = float(d.std(ddof=1) / math.sqrt(len(d))) if len(d) > 1 else math.nan
        result[planner] = Paired(float(d.mean()), se, float(np.mean(sign * d > 0)), len(d))
    return result


def reference_labels(reference: str | Sequence[str] | None) -> tuple[str, ...]:
    """The reference planners named by ``reference``, in order, repeats and blanks dropped.

    Args:
        reference: one label, comma-separated labels (``"ig,ig_spatial"``, as the command
            lines take them) or a sequence of labels; None: :data:`DEFAULT_REFERENCES`.
    """
    if reference is None:
        return DEFAULT_REFERENCES
    items = reference.split(",") if isinstance(reference, str) else list(reference)
    return tuple(dict.fromkeys(str(item).strip() for item in items if str(item).strip()))


def flown_references(reference: str | Sequence[str] | None,
                     labels: Sequence[str]) -> tuple[str, ...]:
    """The reference planners among the planners flown (``labels``), in order.

    Every planner ``reference`` names must be flown: a paired column the user asked for never
    vanishes silently. None's defaults (:data:`DEFAULT_REFERENCES`) that are not flown are
    left out.

    Raises:
        ValueError: a named reference is not flown (the message names it), or ``reference``
            names none.
    """
    if reference is None:
        return tuple(r for r in DEFAULT_REFERENCES if r in labels)
    named = reference_labels(reference)
    if not named:
        raise ValueError(f"the reference names no planner: {reference!r}")
    for label in named:
        if label not in labels:
            raise ValueError(f"the reference planner {label!r} is not among the planners "
                             f"flown ({', '.join(labels)})")
    return named


@dataclass(frozen=True)
class Summary:
    """Per-planner statistics of an evaluation at a few steps of the budget.

    Attributes:
        planners: planner labels in the order they first appear in the rows.
        metrics: the summarised metrics, e.g. ``("entropy", "f1")``.
        steps: the summarised steps, e.g. ``(5, 10, 15)`` for a budget of 15.
        budget: the budget B (largest step in the rows).
        stats: ``stats[(planner, metric, step)]`` -> :class:`Stat`.
        plan_ms: mean planning time per step in milliseconds, per planner (NaN if unknown).
        missions: number of distinct missions in the rows.
        agents: distinct team sizes in the rows (one value for a single evaluation).
        comm: distinct communication ranges in metres (``inf`` allowed).
        terrain: distinct terrain kinds.
        reference: the first planner with a paired column ("" when there is none).
        paired: final-entropy :class:`Paired` difference of each other planner to
            ``reference`` (``paired_to[reference]``).
        checkpoints: ``{planner: "name sha256:HEX"}`` of the learned planners' weights.
        paired_to: ``{reference: {planner: Paired}}``, one paired column per reference in
            table order; a summary built with only ``reference`` and ``paired`` gets that one.
    """

    planners: tuple[str, ...]
    metrics: tuple[str, ...]
    steps: tuple[int, ...]
    budget: int
    stats: Mapping[tuple[str, str, int], Stat]
    plan_ms: Mapping[str, float]
    missions: int
    agents: tuple[int, ...] = ()
    comm: tuple[float, ...] = ()
    terrain: tuple[str, ...] = ()
    reference: str = ""
    paired: Mapping[str, Paired] = field(default_factory=dict)
    checkpoints: Mapping[str, str] = field(default_factory=dict)
    paired_to: Mapping[str, Mapping[str, Paired]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        # Either spelling builds the same summary, so the writers read ``paired_to`` only
        # and code that knows one reference keeps reading ``reference`` and ``paired``.
        if not self.paired_to and self.reference and self.paired:
            object.__setattr__(self, "paired_to", {self.reference: self.paired})
        elif self.paired_to and not self.reference:
            first = next(iter(self.paired_to))
            object.__setattr__(self, "reference", first)
            object.__setattr__(self, "paired", self.paired_to[first])

    @property
    def references(self) -> tuple[str, ...]:
        """The planners with a paired column, in table order."""
        return tuple(self.paired_to)

    def stat(self, planner: str, metric: str, step: int) -> Stat:
        """The :class:`Stat` of one cell (NaN, n = 0 when the rows had none)."""
        return self.stats.get((planner, metric, step), Stat(math.nan, math.nan, 0))

    def fraction(self, step: int) -> str:
        """The budget fraction of ``step`` as a label, e.g. ``"33 %"``."""
        return f"{100.0 * step / self.budget:.0f} %" if self.budget else "-"

    def best(self, metric: str, step: int) -> frozenset[str]:
        """Planners with the best mean of a column at the printed precision.

        Lowest for metrics in :data:`LOWER_IS_BETTER` marked True (entropy, RMSE), highest
        otherwise (F1, reward and unknown metrics). Empty when no planner has a value.
        """
        means = {p: round(self.stat(p, metric, step).mean, DIGITS) for p in self.planners}
        finite = {p: m for p, m in means.items() if math.isfinite(m)}
        if not finite:
            return frozenset()
        pick = min if LOWER_IS_BETTER.get(metric, False) else max
        target = pick(finite.values())
        return frozenset(p for p, m in finite.items() if m == target)

    def caption(self) -> str:
        """One line naming the team size, communication range, missions and budget."""
        parts = []
        if self.agents:
            agents = "/".join(str(a) for a in self.agents)
            parts.append(f"{agents} UAV{'s' if self.agents != (1,) else ''}")
        if self.comm:
            parts.append("D = " + "/".join(format_comm(c) for c in self.comm))
        if self.terrain:
            parts.append("terrain " + "/".join(self.terrain))
        parts.append(f"budget B = {self.budget} steps")
        fractions = "/".join(self.fraction(s).replace(" %", "") for s in self.steps)
        directions = ", ".join(
            f"{'lowest' if LOWER_IS_BETTER.get(m, False) else 'highest'} {_metric_word(m)}"
            for m in self.metrics)
        return (f"Mean ± std over {self.missions} mission{'s' if self.missions != 1 else ''} "
                f"at {fractions} % of the budget ({', '.join(parts)}). "
                f"Bold: best per column ({directions}).{self._paired_caption()} "
                "ms/step: mean planning time per step.")

    def _paired_caption(self) -> str:
        """The sentence explaining the paired columns ("" without any)."""
        if not self.paired_to:
            return ""
        if len(self.paired_to) == 1:
            whose = f"{self.reference}'s"
        else:
            whose = "that planner's"
        columns = ", ".join(f"Δ vs {r}" for r in self.paired_to)
        return (f" {columns}: final entropy minus {whose} on the same missions, mean ± "
                "standard error (share of missions ahead).")


def _metric_word(metric: str) -> str:
    name = METRIC_NAMES.get(metric, metric)
    return name if name.isupper() else name.lower()


def budget_steps(budget: int) -> tuple[int, ...]:
    """The steps at 33, 67 and 100 % of a budget: ``round(B/3), round(2B/3), B``.

    Duplicates (tiny budgets) are dropped and step 0 is never chosen unless B is 0.
    """
    if budget < 0:
        raise ValueError(f"budget must be >= 0, got {budget}")
    raw = [math.floor(budget / 3 + 0.5), math.floor(2 * budget / 3 + 0.5), budget]
    steps: list[int] = []
    for step in raw:
        step = max(step, min(1, budget))
        if step not in steps:
            steps.append(step)
    return tuple(steps)


def _float(value: Any) -> float:
    if value is None or value == "":
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _rows_of(rows_or_result: Any) -> list[Mapping[str, Any]]:
    rows = getattr(rows_or_result, "rows", rows_or_result)
    return list(rows)


def _distinct(values: Iterable[Any]) -> tuple[Any, ...]:
    seen: list[Any] = []
    for value in values:
        if value not in seen:
            seen.append(value)
    return tuple(seen)


def summarise(rows: Iterable[Mapping[str, Any]] | Any, steps: Sequence[int] | None = None,
              metrics: Sequence[str] = ("entropy", "f1"),
              reference: str | Sequence[str] | None = DEFAULT_REFERENCES,
              checkpoints: Mapping[str, str] | None = None) -> Summary:
    """Reduce tidy per-step rows to a :class:`Summary`.

    Args:
        rows: dicts with at least ``planner``, ``mission``, ``step`` and the metrics (the
            ``rows`` of an ``EvaluationResult``, which may also be passed directly); optional
            ``plan_ms``, ``agents``, ``comm`` and ``terrain`` feed the planning-time column
            and the caption.
        steps: steps to summarise; default :func:`budget_steps` of the largest step.
        metrics: metric columns, each summarised at every step.
        reference: the planners of the paired columns (final entropy minus theirs, per
            mission), a label, comma-separated labels or a sequence (None: the default
            ``ig`` and ``ig_spatial``); no column for one that is not in the rows.
        checkpoints: ``{planner: "name sha256:HEX"}`` to print under the table.

    Returns:
        the summary; mean and sample std (ddof = 1) over missions for every
        (planner, metric, step), and the mean of ``plan_ms`` over all steps s >= 1.

    Raises:
        ValueError: no rows, or a row lacks ``planner``, ``mission`` or ``step``.
    """
    table = _rows_of(rows)
    if not table:
        raise ValueError("cannot summarise an empty list of rows")
    for key in ("planner", "mission", "step"):
        if key not in table[0]:
            raise ValueError(f"rows need a {key!r} column; got {sorted(table[0])}")
    planners = _distinct(str(row["planner"]) for row in table)
    budget = max(int(row["step"]) for row in table)
    chosen = tuple(int(s) for s in steps) if steps is not None else budget_steps(budget)
    wanted = set(chosen)
    values: dict[tuple[str, str, int], list[float]] = {}
    timings: dict[str, list[float]] = {p: [] for p in planners}
    missions = set()
    for row in table:
        planner, step = str(row["planner"]), int(row["step"])
        missions.add(int(row["mission"]))
        if step >= 1:
            ms = _float(row.get("plan_ms"))
            if math.isfinite(ms):
                timings[planner].append(ms)
        if step in wanted:
            for metric in metrics:
                values.setdefault((planner, metric, step), []).append(_float(row.get(metric)))
    stats: dict[tuple[str, str, int], Stat] = {}
    for key, samples in values.items():
        finite = np.asarray([v for v in samples if math.isfinite(v)], dtype=np.float64)
        if finite.size == 0:
            stats[key] = Stat(math.nan, math.nan, 0)
        else:
            std = float(finite.std(ddof=1)) if finite.size > 1 else 0.0
            stats[key] = Stat(float(finite.mean()), std, int(finite.size))
    plan_ms = {p: float(np.mean(t)) if t else math.nan for p, t in timings.items()}
    agents = tuple(sorted({int(float(r["agents"])) for r in table if _has(r, "agents")}))
    comm = tuple(sorted({_float(r["comm"]) for r in table if _has(r, "comm")}))
    terrain = _distinct(str(r["terrain"]) for r in table if _has(r, "terrain"))
    paired_to = {}
    for label in reference_labels(reference):
        paired = paired_differences(table, label, "entropy", budget)
        if paired:  # a reference that was not flown (or flew alone) has no column
            paired_to[label] = paired
    return Summary(planners=planners, metrics=tuple(metrics), steps=chosen, budget=budget,
                   stats=stats, plan_ms=plan_ms, missions=len(missions), agents=agents,
                   comm=comm, terrain=terrain, checkpoints=dict(checkpoints or {}),
                   paired_to=paired_to)


def _has(row: Mapping[str, Any], key: str) -> bool:
    return row.get(key) not in (None, "")


def _cell(stat: Stat, sep: str) -> str:
    if stat.n == 0 or not math.isfinite(stat.mean):
        return "-"
    return f"{stat.mean:.{DIGITS}f}{sep}{stat.std:.{DIGITS}f}"


def _ms(value: float) -> str:
    return "-" if not math.isfinite(value) else f"{value:.{1 if value >= 1 else 3}f}"


def _columns(summary: Summary) -> list[tuple[str, int]]:
    return [(metric, step) for metric in summary.metrics for step in summary.steps]


def to_markdown(summary: Summary) -> str:
    """The summary as a caption line and a Markdown table (best cells ``**bold**``)."""
    columns = _columns(summary)
    header = ["Planner"] + [
        f"{METRIC_NAMES.get(m, m)} {summary.fraction(s)} (s={s})" for m, s in columns
    ] + [f"Δ vs {r}" for r in summary.paired_to] + ["ms/step"]
    lines = [summary.caption(), "",
             "| " + " | ".join(header) + " |",
             "|" + "|".join([":---"] + ["---:"] * (len(header) - 1)) + "|"]
    best = {(m, s): summary.best(m, s) for m, s in columns}
    for planner in summary.planners:
        cells = [planner.replace("|", "\\|")]
        for m, s in columns:
            text = _cell(summary.stat(planner, m, s), " ± ")
            cells.append(f"**{text}**" if planner in best[(m, s)] else text)
        cells += [_paired_cell(pairs.get(planner), " ± ", "%")
                  for pairs in summary.paired_to.values()]
        cells.append(_ms(summary.plan_ms.get(planner, math.nan)))
        lines.append("| " + " | ".join(cells) + " |")
    if summary.checkpoints:
        lines += ["", "Weights: " + "; ".join(f"{p}: {c}"
                                              for p, c in summary.checkpoints.items())]
    return "\n".join(lines) + "\n"


def _paired_cell(paired: Paired | None, sep: str, percent: str) -> str:
    if paired is None:
        return "-"
    se = f"{sep}{paired.se:.{DIGITS}f}" if math.isfinite(paired.se) else ""
    return f"{paired.mean:+.{DIGITS}f}{se} ({100 * paired.win_rate:.0f} {percent})"


def _csv_number(value: float) -> str:
    return "" if not math.isfinite(value) else repr(float(value))


def to_csv(summary: Summary) -> str:
    """The summary as CSV: one row per planner, a mean and a std column per table cell.

    Columns: ``planner``, then ``{metric}_{pct}pct_s{step}_mean`` / ``..._std`` for every
    metric and step, then ``missions`` and ``plan_ms_per_step``, then per reference planner R
    ``entropy_final_minus_R_mean``, ``entropy_final_minus_R_se`` and ``win_rate_vs_R`` (the
    first reference's first, as before there were several), then ``checkpoint`` where the
    summary names weights. Numbers at full precision, empty where unknown (a reference's
    own row).
    """
    columns = _columns(summary)
    header = ["planner"]
    for m, s in columns:
        pct = f"{100.0 * s / summary.budget:.0f}" if summary.budget else "0"
        header += [f"{m}_{pct}pct_s{s}_mean", f"{m}_{pct}pct_s{s}_std"]
    header += ["missions", "plan_ms_per_step"]
    for reference in summary.paired_to:
        header += [f"entropy_final_minus_{reference}_mean",
                   f"entropy_final_minus_{reference}_se", f"win_rate_vs_{reference}"]
    if summary.checkpoints:
        header += ["checkpoint"]
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    for planner in summary.planners:
        row = [planner]
        for m, s in columns:
            stat = summary.stat(planner, m, s)
            row += [_csv_number(stat.mean), _csv_number(stat.std)]
        n = max((summary.stat(planner, m, s).n for m, s in columns), default=0)
        row += [str(n), _csv_number(summary.plan_ms.get(planner, math.nan))]
        for pairs in summary.paired_to.values():
            paired = pairs.get(planner)
            row += ["", "", ""] if paired is None else [
                _csv_number(paired.mean), _csv_number(paired.se), _csv_number(paired.win_rate)]
        if summary.checkpoints:
            row += [summary.checkpoints.get(planner, "")]
        writer.writerow(row)
    return buffer.getvalue()


_LATEX_SPECIAL = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#",
                  "_": r"\_", "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}",
                  "^": r"\textasciicircum{}"}


def _latex_escape(text: str) -> str:
    return "".join(_LATEX_SPECIAL.get(ch, ch) for ch in text)


def to_latex(summary: Summary, label: str = "tab:compare") -> str:
    """The summary as a LaTeX ``table`` (booktabs rules; best cells ``\\textbf{}``)."""
    columns = _columns(summary)
    k = len(summary.steps)
    spec = "l" + "".join(" " + "c" * k for _ in summary.metrics) + \
        " r" * len(summary.paired_to) + " r"
    delta = "".join(rf"$\Delta$ vs {_latex_escape(r)} & " for r in summary.paired_to)
    groups = " & ".join(
        rf"\multicolumn{{{k}}}{{c}}{{{_latex_escape(METRIC_NAMES.get(m, m))}}}"
        for m in summary.metrics)
    rules = "".join(rf"\cmidrule(lr){{{2 + i * k}-{1 + (i + 1) * k}}}"
                    for i in range(len(summary.metrics)))
    fractions = " & ".join(summary.fraction(s).replace(" %", r"\,\%") for _, s in columns)
    best = {(m, s): summary.best(m, s) for m, s in columns}
    caption = _latex_escape(summary.caption()).replace("±", r"$\pm$")
    lines = [
        r"% requires \usepackage{booktabs}",
        r"\begin{table}[t]",
        r"\centering",
        rf"\caption{{{caption}}}",
        rf"\label{{{label}}}",
        rf"\begin{{tabular}}{{{spec}}}",
        r"\toprule",
        rf" & {groups} & {'& ' * len(summary.paired_to)}\\",
        rules,
        rf"Planner & {fractions} & {delta}ms/step \\",
        r"\midrule",
    ]
    for planner in summary.planners:
        cells = [_latex_escape(planner)]
        for m, s in columns:
            text = _cell(summary.stat(planner, m, s), r" $\pm$ ")
            cells.append(rf"\textbf{{{text}}}" if planner in best[(m, s)] else text)
        cells += [_paired_cell(pairs.get(planner), r" $\pm$ ", r"\%")
                  for pairs in summary.paired_to.values()]
        cells.append(_ms(summary.plan_ms.get(planner, math.nan)))
        lines.append(" & ".join(cells) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}", r"\end{table}"]
    return "\n".join(lines) + "\n"


def atomic_write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (``ipp_toolkit.io.atomic_write``)."""
    data = text.encode("utf-8")
    atomic_write(path, lambda handle: handle.write(data))
    return Path(path)


def write_tables(summary: Summary, out_dir: str | os.PathLike[str]) -> dict[str, Path]:
    """Write ``summary.md``, ``summary.csv`` and ``summary.tex`` into ``out_dir`` atomically.

    Returns:
        the written paths by format (``"md"``, ``"csv"``, ``"tex"``).
    """
    out = Path(out_dir)
    return {
        "md": atomic_write_text(out / "summary.md", to_markdown(summary)),
        "csv": atomic_write_text(out / "summary.csv", to_csv(summary)),
        "tex": atomic_write_text(out / "summary.tex", to_latex(summary)),
    }
