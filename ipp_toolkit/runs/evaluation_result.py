"""What an evaluation returns, and reading an evaluation folder back.

:class:`EvaluationResult` holds the tidy rows of :func:`ipp_toolkit.runs.evaluation.evaluate`
(one per planner, mission and step) and turns them into per-step curves;
:func:`load_results` reads a folder written by it (the layout:
:mod:`ipp_toolkit.runs.result_store`). Both are importable from
:mod:`ipp_toolkit.runs.evaluation` too.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..config.files import config_from_dict
from ..config.schema import EnvConfig
from .result_store import (
    EvaluationError,
    check_finite_row,
    read_identity,
    read_results_csv,
    read_trajectory,
    trajectory_path,
)

__all__ = ["METRICS", "EvaluationResult", "load_results"]

METRICS = ("entropy", "f1", "rmse", "reward", "plan_ms")
"""The numeric per-step columns that :meth:`EvaluationResult.curves` accepts."""



@dataclass
class EvaluationResult:
    """The outcome of :func:`evaluate` (or of :func:`load_results`).

    Attributes:
        config: the configuration of every mission.
        seed: the run seed.
        rows: one dict per (planner, mission, step) with the keys :data:`RESULT_COLUMNS`,
            ordered by planner (as given), mission, step.
        labels: planner labels in order.
        trajectories: ``(label, mission) -> dict`` of the recorded missions: ``ground_truth``
            (H, W) bool, ``final_prob`` (H, W) float16, ``positions`` (B + 1, N, 3) float
            metres, ``footprints`` (B + 1, N, 4) int, ``area_size`` and ``resolution`` floats.
        out_dir: the results folder, or None for an in-memory evaluation.
        namespace: the random-stream namespace of the missions.
        reused: missions per planner label read back from ``out_dir`` (stored by an earlier
            run) instead of flown; empty for :func:`load_results`.
        flown: missions per planner label flown by this evaluation.
    """

    config: EnvConfig
    seed: int
    rows: list[dict[str, Any]]
    labels: list[str]
    trajectories: dict[tuple[str, int], dict[str, Any]] = field(default_factory=dict)
    out_dir: Path | None = None
    namespace: str = "test"
    reused: dict[str, int] = field(default_factory=dict)
    flown: dict[str, int] = field(default_factory=dict)

    def reuse_note(self) -> str:
        """One line saying which missions were read back from ``out_dir`` and which were
        flown, e.g. ``reused 150 stored missions of 3 planners from results/x; flew 0 new``
        (a rerun of the same settings flies nothing, and should say so); empty without a
        folder."""
        if self.out_dir is None:
            return ""
        reused, flown = sum(self.reused.values()), sum(self.flown.values())

        def planners(counts: dict[str, int]) -> str:
            named = [label for label, count in counts.items() if count]
            listed = f" ({', '.join(named)})" if len(named) <= 4 else ""
            return f"{len(named)} planner{'s' if len(named) != 1 else ''}{listed}"

        text = (f"reused {reused} stored mission{'s' if reused != 1 else ''}"
                + (f" of {planners(self.reused)}" if reused else "")
                + f" from {self.out_dir}; flew {flown} new")
        return text + (f" of {planners(self.flown)}" if flown else "")

    @property
    def missions(self) -> list[int]:
        """Sorted indices of the missions in the rows."""
        return sorted({int(row["mission"]) for row in self.rows})

    def curves(self, metric: str) -> dict[str, np.ndarray]:
        """Per planner label, a (missions, B + 1) float array of ``metric`` over the steps.

        Rows are the planner's missions in increasing index; missing cells are NaN.

        Args:
            metric: one of :data:`METRICS` (``entropy``, ``f1``, ``rmse``, ``reward``,
                ``plan_ms``).
        """
        if metric not in METRICS:
            raise ValueError(f"unknown metric {metric!r}; choose one of {METRICS}")
        steps = self.config.team.budget + 1
        per_label: dict[str, dict[int, np.ndarray]] = {label: {} for label in self.labels}
        for row in self.rows:
            curves = per_label.setdefault(str(row["planner"]), {})
            curve = curves.get(int(row["mission"]))
            if curve is None:
                curve = curves[int(row["mission"])] = np.full(steps, np.nan)
            step = int(row["step"])
            if 0 <= step < steps:
                curve[step] = float(row[metric])
        return {label: (np.stack([curves[k] for k in sorted(curves)]) if curves
                        else np.zeros((0, steps)))
                for label, curves in per_label.items()}


def load_results(out_dir: str | os.PathLike[str]) -> EvaluationResult:
    """Read an evaluation folder back: ``config.json``, ``results.csv`` and the trajectories.

    Raises:
        EvaluationError: the folder has no (or a malformed) ``config.json`` or
            ``results.csv``; the message names the file.
    """
    folder = Path(out_dir)
    stored = read_identity(folder)
    try:
        config = config_from_dict(stored["config"])
        seed = int(stored["seed"])
        namespace = str(stored["namespace"])
    except (TypeError, ValueError) as err:
        raise EvaluationError(f"{str(folder / 'config.json')!r} is malformed: {err}") from None
    rows = read_results_csv(folder / "results.csv")
    for line, row in enumerate(rows, start=2):
        try:
            if row["seed"] != seed:
                raise ValueError(f"is of seed {row['seed']}, the folder's config.json says "
                                 f"{seed}")
            check_finite_row(row, "it")
        except ValueError as err:
            raise EvaluationError(f"{str(folder / 'results.csv')!r} line {line} ({row['planner']}"
                                  f", mission {row['mission']}, step {row['step']}) {err}; "
                                  "run the evaluation again into a new folder") from None
    labels: list[str] = []
    missions: dict[str, set[int]] = {}
    for row in rows:
        label = str(row["planner"])
        if label not in missions:
            labels.append(label)
            missions[label] = set()
        missions[label].add(int(row["mission"]))
    trajectories: dict[tuple[str, int], dict[str, Any]] = {}
    for label in labels:
        for mission in sorted(missions[label]):
            path = trajectory_path(folder, label, mission)
            if path.exists():
                try:
                    trajectories[(label, mission)] = read_trajectory(path)
                except (OSError, ValueError, EOFError) as err:
                    warnings.warn(f"skipping unreadable trajectory {str(path)!r}: {err}",
                                  stacklevel=2)
    return EvaluationResult(config=config, seed=seed, rows=rows, labels=labels,
                            trajectories=trajectories, out_dir=folder, namespace=namespace)
