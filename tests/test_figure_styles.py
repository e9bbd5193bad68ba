"""What the figures of a comparison show: every planner's curve stays visible when two are
identical, and the trajectory figures' legend explains each mark on the maps."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.legend import Legend
from matplotlib.lines import Line2D

from reports import plots

PLANNERS = ("coma", "ig", "ig_copy", "coverage", "random", "ppo", "coma_prior", "sb3")
TWINS = {"ig_copy": "ig", "coma_prior": "coma"}  # the same curves as another planner's
RATES = {"coma": 0.10, "ig": 0.13, "coverage": 0.11, "random": 0.04, "ppo": 0.12, "sb3": 0.07}


def _rows(steps: int = 16) -> list[dict]:
    rows = []
    for planner in PLANNERS:
        rate = RATES[TWINS.get(planner, planner)]
        for mission in range(2):
            for step in range(steps):
                entropy = 0.95 * np.exp(-rate * step) + 0.01 * mission
                rows.append({"planner": planner, "mission": mission, "step": step,
                             "entropy": entropy, "f1": 1.0 - entropy, "agents": 4, "comm": 25})
    return rows


def _drawn(monkeypatch: pytest.MonkeyPatch, draw: Callable[[], object]) -> Figure:
    """The figure ``draw`` builds, caught where it would be saved."""
    figures: list[Figure] = []

    def keep(figure, stem, *args, **kwargs):
        figures.append(figure)
        return []

    monkeypatch.setattr(plots, "save_figure", keep)
    draw()
    (figure,) = figures
    return figure


def _dashes(line: Line2D) -> tuple:
    # The pattern the line is drawn with (get_linestyle() says only "-" or "--").
    offset, pattern = line._unscaled_dash_pattern
    return offset, tuple(pattern or ())


def test_every_planner_has_its_own_line_style_and_marker_steps(monkeypatch, tmp_path):
    figure = _drawn(monkeypatch, lambda: plots.plot_curves(_rows(), tmp_path))
    for ax in figure.axes[:2]:
        lines = ax.get_lines()
        assert [line.get_label() for line in lines] == list(PLANNERS)
        for cue in (lambda line: line.get_color(), _dashes, lambda line: line.get_marker()):
            assert len({str(cue(line)) for line in lines}) == len(PLANNERS)
        # Markers on other steps than any other planner's, so twins' markers both show.
        marked = [frozenset(np.arange(16)[line.get_markevery()[0]::line.get_markevery()[1]])
                  for line in lines]
        assert all(marked) and sum(map(len, marked)) == len(frozenset().union(*marked))
        # Drawn later, narrower: an earlier line shows at the sides of a later identical one.
        widths = [line.get_linewidth() for line in lines]
        assert widths == sorted(widths, reverse=True) and len(set(widths)) == len(widths)
        assert _dashes(lines[0])[1] == () and all(_dashes(line)[1] for line in lines[1:])
    legend = figure.axes[0].get_legend()
    assert [text.get_text() for text in legend.get_texts()] == list(PLANNERS)


def test_a_curve_under_an_identical_one_stays_visible(monkeypatch, tmp_path):
    """Rendered: each twin's own colour covers many pixels of the panel (legend removed)."""
    figure = _drawn(monkeypatch, lambda: plots.plot_curves(_rows(), tmp_path,
                                                           metrics=("entropy",)))
    ax = figure.axes[0]
    ax.get_legend().remove()
    figure.canvas.draw()
    image = np.asarray(figure.canvas.buffer_rgba())[..., :3].astype(int)
    lines = {line.get_label(): line for line in ax.get_lines()}
    for twin, original in TWINS.items():
        for planner in (twin, original):
            colour = np.array([round(255 * c) for c in lines[planner].get_color()[:3]])
            pixels = int((np.abs(image - colour).max(axis=-1) <= 8).sum())
            assert pixels > 300, f"{planner} (twin of {twin}) is hidden: {pixels} pixels"


def test_curve_styles_stay_distinct_for_many_planners():
    styles = [plots.curve_style(index, 200, 16) for index in range(200)]
    for cue in ("color", "linestyle", "marker"):  # each cue alone, for the first ten
        assert len({str(style[cue]) for style in styles[:10]}) == 10
    keys = {(tuple(s["color"]), str(s["linestyle"]), s["marker"]) for s in styles}
    assert len(keys) == 200


def _trajectory(positions: list, footprints: bool = True) -> dict:
    cells = 50
    truth = np.zeros((cells, cells), dtype=bool)
    truth[:25, :17] = True
    positions = np.asarray(positions, dtype=float)
    trajectory = {"ground_truth": truth, "final_prob": np.full((cells, cells), 0.5),
                  "positions": positions, "area_size": np.array(50.0),
                  "resolution": np.array(1.0)}
    if footprints:
        boxes = np.zeros((*positions.shape[:2], 4), dtype=int)
        boxes[...] = [5, 15, 5, 15]
        trajectory["footprints"] = boxes
    return trajectory


def _legend_labels(figure: Figure) -> list[str]:
    (legend,) = [child for child in figure.get_children() if isinstance(child, Legend)]
    return [text.get_text() for text in legend.get_texts()]


# UAV 1 passes (30, 30) at 5 m, where UAV 0 was at 15 m: a small marker in a large one.
RINGED = [[[10, 10, 15], [40, 30, 5]], [[30, 30, 15], [35, 30, 5]], [[35, 35, 15], [30, 30, 5]]]
# Every place once, at one altitude each.
PLAIN = [[[10, 10, 5], [40, 30, 10]], [[15, 10, 5], [45, 30, 10]]]


def test_the_trajectory_legend_explains_footprints_and_rings(monkeypatch, tmp_path):
    figure = _drawn(monkeypatch, lambda: plots.plot_trajectories(_trajectory(RINGED),
                                                                 tmp_path / "t"))
    labels = _legend_labels(figure)
    assert labels[-2:] == [plots.RING_LABEL, plots.FOOTPRINT_LABEL]
    assert {"UAV 0", "UAV 1", "start", "5 m", "15 m"} <= set(labels)
    # The dashed rectangles the entry explains are on the right panel.
    right = figure.axes[1]
    assert any(patch.get_linestyle() == "--" for patch in right.patches)
    # The smaller marker is drawn above the larger one, so the ring shows.
    sizes_by_order = sorted((c.get_zorder(), float(c.get_sizes()[0]))
                            for c in right.collections if len(c.get_offsets())
                            and c.get_paths()[0].vertices.shape[0] > 20)  # circles, not stars
    assert [size for _, size in sizes_by_order] == sorted(
        (size for _, size in sizes_by_order), reverse=True)


def test_the_legend_names_only_what_the_figure_shows(monkeypatch, tmp_path):
    figure = _drawn(monkeypatch, lambda: plots.plot_trajectories(
        _trajectory(PLAIN, footprints=False), tmp_path / "t"))
    labels = _legend_labels(figure)
    assert plots.RING_LABEL not in labels and plots.FOOTPRINT_LABEL not in labels
    assert {"UAV 0", "UAV 1", "start", "5 m", "10 m"} <= set(labels)
