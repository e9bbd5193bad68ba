"""Figures of an evaluation: metric curves per planner and the paths of single missions.

Everything is drawn on :class:`matplotlib.figure.Figure` objects with an Agg canvas, never
through pyplot, so nothing leaks into pyplot's global state (no open figures, no backend
switch). Every file is written atomically: saved under a temporary name in the target folder,
then renamed. With ``reuse=True`` a figure keeps a digest of what it shows beside it
(``<stem>.figure.json``: its data, title and this module's source) and is not drawn again
while they are the same and its files are there.

Maps are indexed ``[y, x]`` with row 0 at y = 0 and drawn with ``origin="lower"`` and
``extent=[0, area, 0, area]``, so pixels and paths share metric axes with y pointing up.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Rectangle

from ipp_toolkit.io import atomic_write, write_json

from .tables import METRIC_NAMES

__all__ = ["plot_curves", "plot_trajectories", "curves_from_rows", "curve_style", "save_figure",
           "FORMATS"]

FORMATS = ("png", "pdf")
"""File formats written for every figure."""

_TERRAIN_CMAP = ListedColormap(["#d9dde3", "#b5532f"], name="terrain2")


def _colour(index: int, cmap: str = "tab10") -> tuple[float, float, float, float]:
    colours = colormaps[cmap]
    return colours(index % colours.N)


# The curves of two planners can be identical (the same planner under two labels, two that
# decide alike): colour alone would leave only the one drawn last. So every planner also gets a
# dash pattern and a marker of its own, lines narrow from the first planner drawn to the last
# (an earlier line shows at the sides of a later one and in its gaps), and each planner's
# markers sit on other steps than the others'. Only the first planner is solid.
_DASHES: tuple[tuple[float, tuple[float, ...]], ...] = (
    (0, ()), (0, (6, 2)), (0, (2, 1.5)), (0, (6, 2, 1.5, 2)), (0, (3, 3)), (0, (1, 3)),
    (0, (8, 2, 1.5, 2, 1.5, 2)), (0, (12, 3)), (0, (4, 1.5, 1, 1.5, 1, 1.5)), (0, (1, 1.5)))
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "<", ">", "h", "*")
_WIDEST, _NARROWEST = 3.0, 1.0  # line widths of the first and the last planner, points


def curve_style(index: int, count: int, steps: int) -> dict[str, Any]:
    """Line2D keywords of planner ``index`` of ``count`` on a curve of ``steps`` points.

    Each of colour, dash pattern and marker differs between any two of the first ten
    planners; the three together between any two of the first 990 (cycles of 10, 9 and 11,
    the first planner's solid line aside). The markers of planner ``index`` sit every
    ``period`` steps from step ``index % period`` (``period``: the number of planners, at
    most ``steps``).
    """
    dash = _DASHES[0] if index == 0 else _DASHES[1 + (index - 1) % (len(_DASHES) - 1)]
    width = _WIDEST - (_WIDEST - _NARROWEST) * index / max(count - 1, 1)
    period = max(1, min(count, steps))
    return {"color": _colour(index), "linestyle": dash, "linewidth": width,
            "marker": _MARKERS[index % len(_MARKERS)], "markersize": 5.5,
            "markevery": (index % period, period)}


def save_figure(figure: Figure, stem: str | os.PathLike[str],
                formats: Sequence[str] = FORMATS, dpi: int = 150) -> list[Path]:
    """Save ``figure`` as ``stem.<format>`` for every format, each file atomically.

    A figure with a layout engine (constrained layout) is laid out once, at ``dpi``, and
    saved without its engine, which it does not get back: with an engine, ``savefig`` draws
    a figure twice per format (once to lay it out) and lays it out again each time. The
    PNG is the same, byte for byte.

    Returns:
        the written paths, in the order of ``formats``.
    """
    engine = figure.get_layout_engine()
    if engine is not None:
        own_dpi = figure.dpi
        figure.dpi = dpi  # the text is measured at the resolution it is drawn at
        try:
            engine.execute(figure)
        finally:
            figure.dpi = own_dpi
        figure.set_layout_engine(None)
    paths = []
    for fmt in formats:
        target = Path(f"{os.fspath(stem)}.{fmt}")
        atomic_write(target, lambda handle, fmt=fmt: figure.savefig(
            handle, format=fmt, dpi=dpi))
        paths.append(target)
    return paths


def _new_figure(width: float, height: float) -> Figure:
    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def _rows_of(result_or_rows: Any) -> list[Mapping[str, Any]]:
    return list(getattr(result_or_rows, "rows", result_or_rows))


def _value(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def curves_from_rows(rows: Iterable[Mapping[str, Any]],
                     metric: str) -> dict[str, np.ndarray]:
    """Per planner, a (missions, B + 1) array of ``metric`` over steps (NaN where missing).

    Planners keep the order of their first row; missions are sorted by index.
    """
    table = list(rows)
    if not table:
        return {}
    budget = max(int(r["step"]) for r in table)
    planners: dict[str, dict[int, np.ndarray]] = {}
    for row in table:
        per_mission = planners.setdefault(str(row["planner"]), {})
        curve = per_mission.get(int(row["mission"]))
        if curve is None:
            curve = per_mission[int(row["mission"])] = np.full(budget + 1, np.nan)
        curve[int(row["step"])] = _value(row.get(metric))
    return {p: np.stack([m[k] for k in sorted(m)]) for p, m in planners.items()}


def _mean_std(curves: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    finite = np.isfinite(curves)
    counts = finite.sum(axis=0)
    filled = np.where(finite, curves, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = filled.sum(axis=0) / counts
        squares = np.where(finite, (curves - mean) ** 2, 0.0).sum(axis=0)
        std = np.where(counts > 1, np.sqrt(squares / np.maximum(counts - 1, 1)), 0.0)
    mean = np.where(counts > 0, mean, np.nan)
    return mean, np.where(counts > 0, std, np.nan)


def _describe(rows: Sequence[Mapping[str, Any]]) -> str:
    agents = sorted({int(float(r["agents"])) for r in rows if r.get("agents") not in (None, "")})
    comm = sorted({_value(r["comm"]) for r in rows if r.get("comm") not in (None, "")})
    missions = len({int(r["mission"]) for r in rows})
    parts = []
    if agents:
        parts.append("/".join(str(a) for a in agents) + " UAVs")
    if comm:
        parts.append("D = " + "/".join("inf" if math.isinf(c) else f"{c:g} m" for c in comm))
    parts.append(f"{missions} mission{'s' if missions != 1 else ''}")
    return ", ".join(parts)


def plot_curves(result_or_rows: Any, out_dir: str | os.PathLike[str],
                metrics: Sequence[str] = ("entropy", "f1"),
                stem: str = "curves", reuse: bool = False) -> list[Path]:
    """Plot each metric against the step, one line (mean) and band (± std) per planner.

    Args:
        result_or_rows: an ``EvaluationResult`` or its tidy rows.
        out_dir: folder for ``curves.png`` and ``curves.pdf`` (created if needed).
        metrics: one panel per metric, side by side.
        stem: file name without extension.
        reuse: keep the files drawn before from the same curves and title (module docstring).

    Returns:
        the figure's paths, written now or before.
    """
    rows = _rows_of(result_or_rows)
    if not rows:
        raise ValueError("no rows to plot")
    # One panel per requested metric, in order (a metric asked for twice gets two panels).
    panels = [(metric, curves_from_rows(rows, metric)) for metric in metrics]
    title = f"Mean ± std per step: {_describe(rows)}"
    inputs: dict[str, Any] | None = None
    if reuse:
        inputs = {"title": title, "metrics": "|".join(metrics)}
        for metric, by_planner in panels:
            inputs[f"{metric} planners"] = "|".join(by_planner)  # their order sets the colours
            inputs.update({f"{metric} {planner}": curves
                           for planner, curves in by_planner.items()})
    return _save_once(Path(out_dir) / stem, inputs,
                      lambda: _draw_curves(panels, title, Path(out_dir) / stem))


def _draw_curves(panels: Sequence[tuple[str, Mapping[str, np.ndarray]]], title: str,
                 stem: Path) -> list[Path]:
    figure = _new_figure(5.0 * len(panels), 4.0)
    axes = figure.subplots(1, len(panels), squeeze=False)[0]
    for ax, (metric, by_planner) in zip(axes, panels, strict=True):
        for index, (planner, curves) in enumerate(by_planner.items()):
            mean, std = _mean_std(curves)
            steps = np.arange(len(mean))
            style = curve_style(index, len(by_planner), len(steps))
            ax.plot(steps, mean, label=planner, **style)
            ax.fill_between(steps, mean - std, mean + std, color=style["color"], alpha=0.2,
                            linewidth=0)
        ax.set_xlabel("step s")
        ax.set_ylabel(METRIC_NAMES.get(metric, metric) + (" (bits)" if metric == "entropy"
                                                         else ""))
        ax.set_title(METRIC_NAMES.get(metric, metric))
        ax.grid(alpha=0.3)
        ax.xaxis.get_major_locator().set_params(integer=True)
    axes[0].legend(title="planner", handlelength=4.0)  # long enough to show the dashes
    figure.suptitle(title)
    return save_figure(figure, stem)


def _paths(ax: Any, positions: np.ndarray, footprints: np.ndarray | None,
           resolution: float | None, min_altitude: float) -> None:
    altitudes = np.unique(positions[:, :, 2])
    for k in range(positions.shape[1]):
        colour = _colour(k)
        x, y, z = positions[:, k, 0], positions[:, k, 1], positions[:, k, 2]
        ax.plot(x, y, "-", color=colour, linewidth=1.5, alpha=0.9, zorder=3, clip_on=False)
        for rank, altitude in enumerate(altitudes):
            at = z == altitude
            # Lower (smaller) markers above higher ones, whichever UAV: a place visited at
            # two altitudes is always a ring (the legend says so), never one hidden marker.
            ax.scatter(x[at], y[at], s=12.0 * (altitude / min_altitude) ** 2, color=colour,
                       edgecolors="black", linewidths=0.5, alpha=0.85, clip_on=False,
                       zorder=4 + 0.5 * (len(altitudes) - rank) / len(altitudes))
        ax.scatter(x[:1], y[:1], s=160, marker="*", color=colour, edgecolors="black",
                   linewidths=0.8, zorder=5, clip_on=False)
        if footprints is not None and resolution:
            r0, r1, c0, c1 = (float(v) * resolution for v in footprints[-1, k])
            ax.add_patch(Rectangle((c0, r0), c1 - c0, r1 - r0, fill=False, edgecolor=colour,
                                   linestyle="--", linewidth=1.0, zorder=3))


def plot_trajectories(trajectory: Mapping[str, Any], out_path_stem: str | os.PathLike[str],
                      title: str = "", reuse: bool = False) -> list[Path]:
    """Plot one mission of one planner: terrain and final global map with every UAV's path.

    Args:
        trajectory: a recorded mission (the ``trajectories/<label>_mission<k>.npz`` content):
            ``ground_truth`` (H, W) bool, ``final_prob`` (H, W), ``positions`` (B + 1, N, 3)
            metres, optional ``footprints`` (B + 1, N, 4) half-open map-cell rectangles
            (row0, row1, col0, col1), ``area_size`` and ``resolution`` in metres.
        out_path_stem: output path without extension; ``.png`` and ``.pdf`` are written.
        title: figure title.
        reuse: keep the files drawn before from the same mission and title (module
            docstring).

    Returns:
        the written paths. Paths are lines in the UAV's colour with one marker per step
        (marker area grows with altitude; a place passed at several altitudes shows the
        smaller marker inside the larger, a ring); a star marks the start; the dashed
        rectangles on the right are the camera footprints of the last step. The legend
        explains each of them.
    """
    inputs = {**trajectory, "title": title} if reuse else None
    return _save_once(Path(out_path_stem), inputs,
                      lambda: _draw_trajectories(trajectory, out_path_stem, title))


def _draw_trajectories(trajectory: Mapping[str, Any], out_path_stem: str | os.PathLike[str],
                       title: str) -> list[Path]:
    truth = np.asarray(trajectory["ground_truth"]).astype(bool)
    prob = np.asarray(trajectory["final_prob"], dtype=np.float32)
    positions = np.asarray(trajectory["positions"], dtype=np.float64)
    if positions.ndim != 3 or positions.shape[2] != 3:
        raise ValueError(f"positions must be (steps, agents, 3), got {positions.shape}")
    area = float(np.asarray(trajectory.get("area_size", truth.shape[1])))
    resolution = trajectory.get("resolution")
    resolution = float(np.asarray(resolution)) if resolution is not None else area / truth.shape[1]
    footprints = trajectory.get("footprints")
    footprints = np.asarray(footprints) if footprints is not None else None
    altitudes = np.unique(positions[:, :, 2])
    min_altitude = float(altitudes.min()) if altitudes.size and altitudes.min() > 0 else 1.0
    extent = (0.0, area, 0.0, area)

    figure = _new_figure(11.0, 5.2)
    left, right = figure.subplots(1, 2)
    left.imshow(truth.astype(np.uint8), origin="lower", extent=extent, cmap=_TERRAIN_CMAP,
                vmin=0, vmax=1, interpolation="nearest")
    left.set_title("ground truth and paths")
    image = right.imshow(prob, origin="lower", extent=extent, cmap="RdBu_r", vmin=0.0, vmax=1.0,
                         interpolation="nearest")
    right.set_title("final global map and paths")
    figure.colorbar(image, ax=right, label="P(interesting)", shrink=0.85)
    _paths(left, positions, None, None, min_altitude)
    _paths(right, positions, footprints, resolution, min_altitude)
    for ax in (left, right):
        ax.set_xlim(0.0, area)
        ax.set_ylim(0.0, area)
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
    handles: list[Any] = [Patch(facecolor=_TERRAIN_CMAP(1), label="interesting"),
                          Patch(facecolor=_TERRAIN_CMAP(0), label="not interesting")]
    handles += [Line2D([], [], color=_colour(k), marker="o", markeredgecolor="black",
                      label=f"UAV {k}") for k in range(positions.shape[1])]
    handles.append(Line2D([], [], linestyle="", marker="*", markersize=12, color="grey",
                          markeredgecolor="black", label="start"))
    handles += [_altitude_marker(z, min_altitude, f"{z:g} m") for z in altitudes]
    labels = [handle.get_label() for handle in handles]
    if _has_rings(positions):
        # Two altitudes' markers, one drawn over the other, as on the maps.
        handles.append((_altitude_marker(altitudes[-1], min_altitude),
                        _altitude_marker(altitudes[0], min_altitude)))
        labels.append(RING_LABEL)
    if footprints is not None:
        handles.append(Patch(fill=False, edgecolor="grey", linestyle="--"))
        labels.append(FOOTPRINT_LABEL)
    figure.legend(handles, labels, loc="outside right center", fontsize="small")
    if title:
        figure.suptitle(title)
    return save_figure(figure, out_path_stem)


RING_LABEL = "ring: one place at 2+ altitudes"
"""Legend entry of a trajectory figure whose paths pass one place at several altitudes."""
FOOTPRINT_LABEL = "camera footprint, last step"
"""Legend entry of the dashed rectangles (the right panel's last footprints)."""


def _altitude_marker(altitude: float, min_altitude: float, label: str = "") -> Line2D:
    """A legend marker of the size the maps draw ``altitude`` at (``s`` is points squared)."""
    return Line2D([], [], linestyle="", marker="o", color="grey", markeredgecolor="black",
                  markersize=math.sqrt(12.0) * altitude / min_altitude, label=label)


def _has_rings(positions: np.ndarray) -> bool:
    """Whether some (x, y) is flown over at two or more altitudes (by any UAVs)."""
    points = positions.reshape(-1, 3)
    return len(np.unique(points[:, :2], axis=0)) < len(np.unique(points, axis=0))


_STAMP_FORMAT = "ipp-toolkit figure inputs v1"


def _save_once(stem: Path, inputs: Mapping[str, Any] | None,
               draw: Callable[[], list[Path]]) -> list[Path]:
    """``draw()`` the figure of ``stem``, unless ``inputs`` (None: always draw) are those it
    was drawn from, as ``<stem>.figure.json`` records, and every file of it is there."""
    if inputs is None:
        return draw()
    paths = [Path(f"{stem}.{fmt}") for fmt in FORMATS]
    stamp_path = Path(f"{stem}.figure.json")
    stamp = {"format": _STAMP_FORMAT, "inputs": _digest(inputs)}
    with contextlib.suppress(OSError, UnicodeDecodeError, ValueError):
        if (all(path.is_file() for path in paths)
                and json.loads(stamp_path.read_text(encoding="utf-8")) == stamp):
            return paths
    with contextlib.suppress(FileNotFoundError):
        stamp_path.unlink()  # no stamp while the figure is half redrawn
    paths = draw()
    write_json(stamp_path, stamp)
    return paths


def _digest(inputs: Mapping[str, Any]) -> str:
    """sha256 of this module's source and of ``inputs`` (strings, or arrays by name, dtype,
    shape and bytes), in the order of their names."""
    digest = hashlib.sha256(_source_digest())
    for name in sorted(inputs):
        value = inputs[name]
        if isinstance(value, str):
            kind, data = "str", value.encode()
        else:
            array = np.ascontiguousarray(value)
            kind, data = f"{array.dtype.str}{array.shape}", array.tobytes()
        digest.update(f"{name}|{kind}|{len(data)}|".encode())
        digest.update(data)
    return digest.hexdigest()


@functools.cache
def _source_digest() -> bytes:
    return hashlib.sha256(Path(__file__).read_bytes()).digest()
