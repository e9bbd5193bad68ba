"""Tests of the report layer: summary tables, figures and the compare() building blocks."""

from __future__ import annotations

import csv
import importlib.util
import io
import math
import os
import time
from types import SimpleNamespace

import numpy as np
import pytest

from ipp_toolkit.config.schema import EnvConfig
from reports.compare import Comparison, build_config, safe_name
from reports.plots import curves_from_rows, plot_curves, plot_trajectories
from reports.tables import (
    Summary,
    budget_steps,
    paired_differences,
    summarise,
    to_csv,
    to_latex,
    to_markdown,
    write_tables,
)

BUDGET = 6  # summarised steps: 2, 4, 6
NOISE = 5.0  # value at every other step: would change the means if those steps leaked in

# Hand-picked values at the summarised steps, per planner, metric and step (3 missions).
VALUES = {
    ("ig", "entropy", 2): [0.9, 0.8, 0.7],  # mean 0.8, std 0.1
    ("ig", "entropy", 4): [0.5, 0.5, 0.8],  # mean 0.6, std sqrt(0.03) = 0.173
    ("ig", "entropy", 6): [0.2, 0.3, 0.4],  # mean 0.3, std 0.1 -> best at 100 %
    ("ig", "f1", 2): [0.2, 0.4, 0.6],  # mean 0.4, std 0.2 -> best at 33 %
    ("ig", "f1", 4): [0.5, 0.5, 0.5],
    ("ig", "f1", 6): [0.7, 0.7, 0.7],
    ("random", "entropy", 2): [0.6, 0.6, 0.6],  # mean 0.6, std 0 -> best at 33 %
    ("random", "entropy", 4): [0.7, 0.7, 0.7],
    ("random", "entropy", 6): [0.5, 0.6, 0.7],  # mean 0.6
    ("random", "f1", 2): [0.1, 0.1, 0.1],
    ("random", "f1", 4): [0.6, 0.7, 0.8],  # mean 0.7 -> best at 67 %
    ("random", "f1", 6): [0.8, 0.8, 0.8],  # mean 0.8 -> best at 100 %
}
PLAN_MS = {"ig": lambda s: 2.0 * s, "random": lambda s: 0.5}  # ig: mean of 2..12 = 7.0


def synthetic_rows(planners=("ig", "random"), missions: int = 3, comm: float = 25.0) -> list:
    """Tidy rows like evaluate()'s, with the hand-picked VALUES at steps 2, 4 and 6."""
    rows = []
    for planner in planners:
        for mission in range(missions):
            for step in range(BUDGET + 1):
                row = {"planner": planner, "agents": 4, "comm": comm, "terrain": "split",
                       "seed": 0, "mission": mission, "step": step, "rmse": 0.5,
                       "reward": math.nan if step == 0 else 1.0,
                       "plan_ms": math.nan if step == 0 else PLAN_MS[planner](step)}
                for metric in ("entropy", "f1"):
                    values = VALUES.get((planner, metric, step))
                    row[metric] = values[mission] if values else NOISE
                rows.append(row)
    return rows


def markdown_cells(text: str) -> dict[str, list[str]]:
    """Rows of the Markdown table by planner (first column), header row under 'Planner'."""
    table = {}
    for line in text.splitlines():
        if line.startswith("| ") and not line.startswith("|:"):
            cells = [c.strip() for c in line.strip("|").split(" | ")]
            table[cells[0]] = cells[1:]
    return table


@pytest.fixture
def summary() -> Summary:
    return summarise(synthetic_rows())


def test_budget_steps():
    assert budget_steps(15) == (5, 10, 15)
    assert budget_steps(6) == (2, 4, 6)
    assert budget_steps(3) == (1, 2, 3)
    assert budget_steps(10) == (3, 7, 10)
    assert budget_steps(1) == (1,)
    with pytest.raises(ValueError):
        budget_steps(-1)


def test_summarise_means_and_stds_at_the_right_steps(summary):
    assert summary.planners == ("ig", "random")
    assert summary.steps == (2, 4, 6) and summary.budget == BUDGET
    assert summary.missions == 3 and summary.agents == (4,) and summary.comm == (25.0,)
    for (planner, metric, step), values in VALUES.items():
        stat = summary.stat(planner, metric, step)
        assert stat.n == 3
        assert stat.mean == pytest.approx(sum(values) / 3)
        assert stat.std == pytest.approx(np.std(values, ddof=1))
    assert summary.stat("ig", "entropy", 2).std == pytest.approx(0.1)
    assert summary.stat("ig", "entropy", 4).std == pytest.approx(math.sqrt(0.03))
    assert summary.plan_ms["ig"] == pytest.approx(7.0)  # s = 1..6, NaN at s = 0 ignored
    assert summary.plan_ms["random"] == pytest.approx(0.5)


def test_summarise_options_and_errors():
    rows = synthetic_rows(missions=1)
    single = summarise(rows, steps=[0, 6], metrics=("rmse",))
    assert single.steps == (0, 6) and single.metrics == ("rmse",)
    assert single.stat("ig", "rmse", 6).std == 0.0  # one mission: std 0, not NaN
    assert math.isnan(single.stat("ig", "entropy", 6).mean)  # not summarised
    # An EvaluationResult-like object is accepted too.
    assert summarise(SimpleNamespace(rows=rows)).planners == ("ig", "random")
    with pytest.raises(ValueError, match="empty"):
        summarise([])
    with pytest.raises(ValueError, match="'mission'"):
        summarise([{"planner": "x", "step": 0}])


def test_best_goes_to_lowest_entropy_and_highest_f1(summary):
    assert summary.best("entropy", 2) == {"random"}
    assert summary.best("entropy", 4) == {"ig"}
    assert summary.best("entropy", 6) == {"ig"}
    assert summary.best("f1", 2) == {"ig"}
    assert summary.best("f1", 4) == {"random"}
    assert summary.best("f1", 6) == {"random"}


def test_markdown_table(summary):
    text = to_markdown(summary)
    caption = text.splitlines()[0]
    assert "3 missions" in caption and "4 UAVs" in caption and "D = 25 m" in caption
    cells = markdown_cells(text)
    assert cells["Planner"] == ["Entropy 33 % (s=2)", "Entropy 67 % (s=4)", "Entropy 100 % (s=6)",
                                "F1 33 % (s=2)", "F1 67 % (s=4)", "F1 100 % (s=6)", "Δ vs ig",
                                "ms/step"]
    assert cells["ig"] == ["0.800 ± 0.100", "**0.600 ± 0.173**", "**0.300 ± 0.100**",
                           "**0.400 ± 0.200**", "0.500 ± 0.000", "0.700 ± 0.000", "-", "7.0"]
    # random - ig at the end: 0.5-0.2, 0.6-0.3, 0.7-0.4 = 0.3 each: +0.3, SE 0, ahead in 0 %.
    assert cells["random"] == ["**0.600 ± 0.000**", "0.700 ± 0.000", "0.600 ± 0.100",
                               "0.100 ± 0.000", "**0.700 ± 0.100**", "**0.800 ± 0.000**",
                               "+0.300 ± 0.000 (0 %)", "0.500"]


def test_paired_differences_on_a_hand_sized_case():
    rows = []
    for mission, (mine, ref) in enumerate([(0.3, 0.4), (0.6, 0.4), (0.1, 0.5)]):
        rows += [{"planner": "mine", "mission": mission, "step": 3, "entropy": mine},
                 {"planner": "ref", "mission": mission, "step": 3, "entropy": ref},
                 {"planner": "ref", "mission": mission, "step": 1, "entropy": 0.9}]
    rows.append({"planner": "mine", "mission": 7, "step": 3, "entropy": 0.0})  # unpaired
    paired = paired_differences(rows, "ref")["mine"]
    # d = -0.1, +0.2, -0.4: mean -0.1, sd 0.3, SE 0.3 / sqrt(3); ahead in 2 of 3.
    assert paired.n == 3 and paired.mean == pytest.approx(-0.1)
    assert paired.se == pytest.approx(0.3 / math.sqrt(3))
    assert paired.win_rate == pytest.approx(2 / 3)
    assert paired_differences(rows, "absent") == {}
    f1 = paired_differences([dict(r, f1=r["entropy"]) for r in rows], "ref", metric="f1")
    assert f1["mine"].win_rate == pytest.approx(1 / 3)  # higher F1 is better


def test_ties_are_all_bold_and_comm_inf_in_caption():
    rows = synthetic_rows(planners=("ig",), comm=math.inf)
    summary = summarise(rows + [dict(r, planner="twin") for r in rows])
    assert summary.best("entropy", 6) == {"ig", "twin"}
    assert "D = inf" in to_markdown(summary).splitlines()[0]


def test_latex_table(summary):
    text = to_latex(summary)
    assert r"\begin{tabular}{l ccc ccc r r}" in text
    assert r"\multicolumn{3}{c}{Entropy} & \multicolumn{3}{c}{F1}" in text
    assert r"\caption{Mean $\pm$ std over 3 missions" in text
    ig = next(line for line in text.splitlines() if line.startswith("ig &"))
    assert ig == (r"ig & 0.800 $\pm$ 0.100 & \textbf{0.600 $\pm$ 0.173} & "
                  r"\textbf{0.300 $\pm$ 0.100} & \textbf{0.400 $\pm$ 0.200} & "
                  r"0.500 $\pm$ 0.000 & 0.700 $\pm$ 0.000 & - & 7.0 \\")
    assert r"\textbf{0.600 $\pm$ 0.000}" in text  # random, entropy at 33 %
    assert "±" not in text
    escaped = to_latex(summarise([dict(r, planner="coma_v2&x") for r in synthetic_rows()]))
    assert r"coma\_v2\&x &" in escaped


def test_csv_table(summary):
    rows = list(csv.DictReader(io.StringIO(to_csv(summary))))
    assert [r["planner"] for r in rows] == ["ig", "random"]
    ig = rows[0]
    assert float(ig["entropy_33pct_s2_mean"]) == pytest.approx(0.8)
    assert float(ig["entropy_33pct_s2_std"]) == pytest.approx(0.1)
    assert float(ig["entropy_67pct_s4_std"]) == pytest.approx(math.sqrt(0.03))
    assert float(rows[1]["f1_100pct_s6_mean"]) == pytest.approx(0.8)
    assert float(ig["plan_ms_per_step"]) == pytest.approx(7.0)
    assert ig["missions"] == "3"


def test_write_tables_is_atomic_and_complete(summary, tmp_path):
    out = tmp_path / "new" / "dir"
    paths = write_tables(summary, out)
    assert sorted(p.name for p in paths.values()) == ["summary.csv", "summary.md", "summary.tex"]
    assert (out / "summary.md").read_text(encoding="utf-8") == to_markdown(summary)
    assert (out / "summary.tex").read_text() == to_latex(summary)
    assert sorted(os.listdir(out)) == ["summary.csv", "summary.md", "summary.tex"]  # no tmp


def _assert_figures(paths, stem):
    assert [p.name for p in paths] == [f"{stem}.png", f"{stem}.pdf"]
    png, pdf = paths
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 1000
    assert pdf.read_bytes()[:5] == b"%PDF-" and pdf.stat().st_size > 1000
    assert not [n for n in os.listdir(png.parent) if n.endswith(".tmp")]


def test_curves_from_rows():
    curves = curves_from_rows(synthetic_rows(missions=2), "entropy")
    assert list(curves) == ["ig", "random"]
    assert curves["ig"].shape == (2, BUDGET + 1)
    assert curves["ig"][1, 2] == pytest.approx(0.8)


def test_plot_curves_writes_png_and_pdf(tmp_path):
    import matplotlib.pyplot as plt

    before = plt.get_fignums()
    paths = plot_curves(SimpleNamespace(rows=synthetic_rows()), tmp_path)
    _assert_figures(paths, "curves")
    assert plt.get_fignums() == before  # no pyplot figure leaked
    with pytest.raises(ValueError):
        plot_curves([], tmp_path)


def synthetic_trajectory(n_agents: int = 3, budget: int = 4, cells: int = 50) -> dict:
    rng = np.random.default_rng(0)
    truth = np.zeros((cells, cells), dtype=bool)
    truth[: cells // 2, : cells // 3] = True
    prob = np.full((cells, cells), 0.5, dtype=np.float16)
    prob[: cells // 2] = 0.8
    steps = rng.integers(0, 11, size=(budget + 1, n_agents, 2)) * 5.0
    altitudes = rng.choice([5.0, 10.0, 15.0], size=(budget + 1, n_agents, 1))
    footprints = np.tile(np.array([0, 10, 5, 15]), (budget + 1, n_agents, 1))
    return {"ground_truth": truth, "final_prob": prob,
            "positions": np.concatenate([steps, altitudes], axis=2), "footprints": footprints,
            "area_size": np.array(50.0), "resolution": np.array(1.0)}


def test_plot_trajectories_writes_png_and_pdf(tmp_path):
    paths = plot_trajectories(synthetic_trajectory(), tmp_path / "sub" / "ig_mission0", "ig")
    _assert_figures(paths, "ig_mission0")
    with pytest.raises(ValueError, match="positions"):
        plot_trajectories({**synthetic_trajectory(), "positions": np.zeros((3, 2))},
                          tmp_path / "bad", "")


def test_comparison_writes_tables_and_figures(tmp_path):
    config = EnvConfig().replace(world={"resolution": 1.0})
    result = SimpleNamespace(rows=synthetic_rows(), config=config,
                             trajectories={("ig", 0): synthetic_trajectory(),
                                           ("random", 0): synthetic_trajectory()})
    comparison = Comparison(result=result, summary=summarise(result.rows))
    assert comparison.table == to_markdown(comparison.summary)
    assert comparison.plan_ms == {"ig": pytest.approx(7.0), "random": pytest.approx(0.5)}
    paths = comparison.write(tmp_path)
    names = sorted(str(p.relative_to(tmp_path)) for p in paths)
    assert names == sorted(["summary.md", "summary.csv", "summary.tex", "curves.png",
                            "curves.pdf", "trajectories/ig_mission0.png",
                            "trajectories/ig_mission0.pdf", "trajectories/random_mission0.png",
                            "trajectories/random_mission0.pdf"])
    assert all(p.stat().st_size > 0 for p in paths)


def test_safe_name():
    assert safe_name("coma") == "coma"
    assert safe_name("coma=runs/x/ckpt.pt") == "coma_runs_x_ckpt.pt"


def test_build_config_overrides():
    config = build_config(agents=2, comm=math.inf, resolution=0.5, budget=3)
    assert config.team.n_agents == 2 and config.team.start == "fixed"
    assert math.isinf(config.team.comm_range) and config.team.budget == 3
    assert config.world.map_cells == 100 and config.terrain.kind == "split"
    three = build_config(agents=3, terrain="blobs")
    assert three.team.start == "random" and three.terrain.kind == "blobs"
    twelve = build_config(agents=12)
    assert twelve.team.start == "random" and twelve.features.agent_id_scale == 12
    small = build_config(agents=4, area_size=20.0, resolution=0.5)  # starts snap to waypoints
    assert small.team.start == "fixed" and small.world.area_size == 20.0
    tiny = build_config(agents=4, area_size=10.0, resolution=0.5)  # they would share cells
    assert tiny.team.start == "random"
    base = EnvConfig().replace(team={"n_agents": 8, "comm_range": 10.0})
    kept = build_config(agents=None, comm=None, terrain=None, config=base)
    assert kept.team.n_agents == 8 and kept.team.comm_range == 10.0


def test_build_config_terrain_file(tmp_path):
    raster = tmp_path / "field.npy"
    np.save(raster, np.zeros((10, 10)))
    config = build_config(terrain=str(raster), threshold=0.5)
    assert config.terrain.kind == "raster" and config.terrain.threshold == 0.5
    assert config.terrain.raster == str(raster.resolve())
    with pytest.raises(ValueError, match="needs a threshold"):
        build_config(terrain=str(raster))
    with pytest.raises(ValueError, match="cannot read terrain file .*no such file"):
        build_config(terrain=str(tmp_path / "missing.tif"), threshold=0.5)
    garbage = tmp_path / "garbage.npy"
    garbage.write_text("not an array")
    with pytest.raises(ValueError, match="cannot read raster file"):
        build_config(terrain=str(garbage), threshold=0.5)
    text = tmp_path / "field.csv"
    text.write_text("0,1\n1,0\n")
    with pytest.raises(ValueError, match="unknown extension"):
        build_config(terrain=str(text), threshold=0.5)
    with pytest.raises(ValueError, match="not a file"):
        build_config(terrain=str(tmp_path), threshold=0.5)
    with pytest.raises(ValueError, match="agents must be an integer >= 1"):
        build_config(agents=0)


@pytest.mark.skipif(importlib.util.find_spec("ipp_toolkit.runs.evaluation") is None
                    or importlib.util.find_spec("baselines.heuristics.random_planner") is None,
                    reason="needs ipp_toolkit.runs.evaluation and the random baseline")
def test_compare_in_memory_then_plot(tmp_path):
    from reports import compare_planners

    comparison = compare_planners(agents=2, trials=2, resolution=0.5, budget=2,
                                  planners=["random"], progress=False)
    assert comparison.result.out_dir is None and not list(tmp_path.iterdir())
    assert "| random |" in comparison.table and comparison.summary.steps == (1, 2)
    assert set(comparison.result.trajectories) == {("random", 0)}
    names = sorted(p.name for p in comparison.plot(tmp_path))
    assert names == ["curves.pdf", "curves.png", "random_mission0.pdf", "random_mission0.png"]
    with pytest.raises(ValueError, match="trials must be an integer >= 1"):
        compare_planners(trials=0)
    with pytest.raises(ValueError, match="unknown planner 'astar'"):
        compare_planners(planners="random,astar", trials=1)


def test_compare_animate_writes_one_gif_per_planner(tmp_path, placeholder_figures):
    from PIL import Image

    from reports.compare import compare

    compare(agents=2, comm=0.0, planners="random,coverage", trials=1, resolution=1.0,
            budget=3, out=tmp_path, progress=False, animate=True)
    for label in ("random", "coverage"):
        gif = Image.open(tmp_path / "animations" / f"{label}.gif")
        assert gif.n_frames == 4  # s = 0..3


def test_save_figure_lays_out_once_and_writes_what_savefig_writes(tmp_path):
    """The PNG of a constrained-layout figure saved by save_figure (laid out once, then
    drawn without its layout engine) is matplotlib's own, byte for byte."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from reports.plots import save_figure

    def figure():
        fig = Figure(figsize=(6.0, 3.0), layout="constrained")
        FigureCanvasAgg(fig)
        left, right = fig.subplots(1, 2)
        left.plot([0, 1, 2], [3, 1, 2], label="a line")
        image = right.imshow(np.arange(12.0).reshape(3, 4), origin="lower")
        fig.colorbar(image, ax=right, label="value")
        fig.legend(loc="outside right center")
        fig.suptitle("a title")
        return fig

    expected = io.BytesIO()
    figure().savefig(expected, format="png", dpi=150)
    saved = figure()
    paths = save_figure(saved, tmp_path / "f")
    assert [p.name for p in paths] == ["f.png", "f.pdf"]
    assert (tmp_path / "f.png").read_bytes() == expected.getvalue()
    assert (tmp_path / "f.pdf").read_bytes().startswith(b"%PDF")
    assert saved.get_layout_engine() is None  # laid out once; kept as it was saved


def test_a_trajectory_figure_is_drawn_again_only_when_its_inputs_change(tmp_path,
                                                                        placeholder_figures):
    from reports.compare import draw_trajectory

    config = EnvConfig().replace(world={"resolution": 1.0})
    trajectory = synthetic_trajectory()
    png, pdf = draw_trajectory(tmp_path, config, "ig", 0, trajectory, (0.5, 0.75))
    stamp = tmp_path / "trajectories" / "ig_mission0.figure.json"
    assert png.is_file() and pdf.is_file() and stamp.is_file()

    def drawn_at() -> tuple[int, int]:
        return png.stat().st_mtime_ns, pdf.stat().st_mtime_ns

    first = drawn_at()
    # The same mission and title: nothing is drawn (a finished run reported again).
    assert draw_trajectory(tmp_path, config, "ig", 0, trajectory, (0.5, 0.75)) == [png, pdf]
    assert drawn_at() == first
    # Another title (final metrics), other data, then the same inputs with a missing file or
    # a damaged stamp: drawn again each time.
    halved = {**trajectory, "final_prob": trajectory["final_prob"] * 0.5}
    changes = [
        lambda: draw_trajectory(tmp_path, config, "ig", 0, trajectory, (0.5, 0.8)),
        lambda: draw_trajectory(tmp_path, config, "ig", 0, halved, (0.5, 0.8)),
        lambda: (pdf.unlink(), draw_trajectory(tmp_path, config, "ig", 0, halved, (0.5, 0.8))),
        lambda: (stamp.write_text("{", encoding="utf-8"),
                 draw_trajectory(tmp_path, config, "ig", 0, halved, (0.5, 0.8))),
    ]
    for change in changes:
        before = png.stat().st_mtime_ns
        time.sleep(0.01)  # a new mtime even on coarse clocks
        change()
        assert png.stat().st_mtime_ns != before and pdf.is_file()
    # The figure of the last inputs stands: they are found current again.
    now = drawn_at()
    draw_trajectory(tmp_path, config, "ig", 0, halved, (0.5, 0.8))
    assert drawn_at() == now


def test_a_finished_run_reported_again_keeps_its_figures(tmp_path, placeholder_figures):
    from reports.compare import compare

    arguments = dict(agents=2, comm=0.0, planners="random,coverage", trials=1, resolution=1.0,
                     budget=2, out=tmp_path, progress=False)
    compare(**arguments)
    trajectories = sorted((tmp_path / "trajectories").glob("*.p[dn][gf]"))
    curves = [tmp_path / "curves.png", tmp_path / "curves.pdf"]
    assert len(trajectories) == 4

    def drawn_at(paths: list) -> list[int]:
        return [path.stat().st_mtime_ns for path in paths]

    first, tables = drawn_at(trajectories + curves), drawn_at([tmp_path / "summary.md"])
    time.sleep(0.01)
    compare(**arguments)
    assert drawn_at(trajectories + curves) == first
    assert drawn_at([tmp_path / "summary.md"]) != tables  # the rest is written again
    # Grown by a planner: its figure is new and the curves change; the others stay.
    compare(**{**arguments, "planners": "random,coverage,ig"})
    assert drawn_at(trajectories) == first[:4] and drawn_at(curves) != first[4:]
    assert (tmp_path / "trajectories" / "ig_mission0.png").is_file()
