"""Training curves of a COMA run folder (``progress.csv`` written by ``ipp-train coma``)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ipp_toolkit.runs.progress_csv import read_progress_csv

from .plots import _new_figure, save_figure

__all__ = ["read_progress", "plot_training"]


def read_progress(run_dir: str | os.PathLike[str]) -> dict[str, np.ndarray]:
    """Columns of ``run_dir/progress.csv`` as float arrays (NaN where a cell is empty), read by
    :func:`ipp_toolkit.runs.progress_csv.read_progress_csv`.

    Raises:
        FileNotFoundError: the folder holds no ``progress.csv``.
    """
    path = Path(run_dir) / "progress.csv"
    if not path.is_file():
        raise FileNotFoundError(f"no training log at {str(path)!r}")
    rows = read_progress_csv(path, strict=False)
    if not rows:
        return {}
    return {key: np.array([np.nan if row[key] is None else float(row[key]) for row in rows])
            for key in rows[0]}


def plot_training(run_dir: str | os.PathLike[str], stem: str | os.PathLike[str] | None = None,
                  window: int = 20) -> list[Path]:
    """Draw the team return and the validation metrics against training missions.

    Args:
        run_dir: the run folder.
        stem: output path without extension (default ``run_dir/training``); PNG and PDF.
        window: updates in the moving average of the training return.

    Returns:
        the written files.
    """
    columns = read_progress(run_dir)
    figure = _new_figure(9.0, 3.4)
    left, right = figure.subplots(1, 2)
    if columns:
        missions = columns["missions"]
        returns = columns["return_mean"]
        left.plot(missions, returns, color="0.8", lw=0.6, label="per update")
        if len(returns) >= window:
            smooth = np.convolve(returns, np.ones(window) / window, mode="valid")
            left.plot(missions[window - 1:], smooth, color="C0", lw=1.5,
                      label=f"mean of {window} updates")
        evaluated = ~np.isnan(columns["eval_entropy_final"])
        right.plot(missions[evaluated], columns["eval_entropy_final"][evaluated], "o-",
                   ms=2.5, label="entropy (final)")
        right.plot(missions[evaluated], columns["eval_f1_final"][evaluated], "s-", ms=2.5,
                   label="F1 (final)")
    left.set(xlabel="training missions", ylabel="team return per mission",
             title="training (sampled policy)")
    right.set(xlabel="training missions", ylabel="metric", ylim=(0, 1),
              title="greedy policy on validation missions")
    left.legend(fontsize=8)
    right.legend(fontsize=8)
    return save_figure(figure, stem if stem is not None else Path(run_dir) / "training")
