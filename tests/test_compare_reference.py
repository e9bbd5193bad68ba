"""--reference of ipp-compare and ipp-study generalisation: a paired column against each
planner named (ig and ig_spatial by default, where flown), refused when one named is not
flown."""

from __future__ import annotations

import math

import pytest

from ipp_toolkit.config.schema import EnvConfig
from reports.cli import compare_main

SMALL = ["--resolution", "2", "--trials", "2", "--workers", "1", "--no-progress"]

pytestmark = pytest.mark.usefixtures("placeholder_figures")  # the tables are tested here


def test_the_paired_column_compares_with_the_reference_given(tmp_path, capsys):
    out = tmp_path / "run"
    assert compare_main(["--planners", "ig,random", "--reference", "random", "--out", str(out),
                         *SMALL]) == 0
    summary = (out / "summary.md").read_text()
    assert "Δ vs random" in summary and "Δ vs ig" not in summary
    header = (out / "summary.csv").read_text().splitlines()[0]
    assert "entropy_final_minus_random_mean" in header


def test_a_reference_not_flown_is_refused_before_anything_is_written(tmp_path, capsys):
    out = tmp_path / "run"
    assert compare_main(["--planners", "ig,random", "--reference", "ig_spatial",
                         "--out", str(out), *SMALL]) == 2
    err = capsys.readouterr().err
    assert "reference planner 'ig_spatial' is not among the planners flown" in err
    assert not out.exists()


def test_the_generalisation_study_refuses_a_reference_it_does_not_fly(tmp_path, capsys):
    from reports.cli import study_main

    out = tmp_path / "study"
    assert study_main(["generalisation", "--planners", "ig,random", "--reference", "ig_spatial",
                       "--families", "split", "--team-families", "", "--trials", "1",
                       "--out", str(out), "--no-progress"]) == 2
    assert "reference planner 'ig_spatial' is not among the planners" in capsys.readouterr().err
    assert not out.exists()


def test_by_default_ig_is_paired_and_an_unflown_ig_spatial_is_left_out(tmp_path, capsys):
    out = tmp_path / "run"
    assert compare_main(["--planners", "ig,random", "--out", str(out), *SMALL]) == 0
    summary = (out / "summary.md").read_text()
    assert "Δ vs ig" in summary and "Δ vs ig_spatial" not in summary
    header = (out / "summary.csv").read_text().splitlines()[0]
    assert header.endswith(",entropy_final_minus_ig_mean,entropy_final_minus_ig_se,"
                           "win_rate_vs_ig")


def test_each_reference_named_gets_its_column(tmp_path, capsys):
    out = tmp_path / "run"
    assert compare_main(["--planners", "ig,random", "--reference", "random,ig",
                         "--out", str(out), *SMALL]) == 0
    summary = (out / "summary.md").read_text()
    assert "| Δ vs random | Δ vs ig | ms/step |" in summary
    header = (out / "summary.csv").read_text().splitlines()[0]
    assert header.index("win_rate_vs_random") < header.index("entropy_final_minus_ig_mean")


def test_a_named_reference_not_flown_is_refused_in_a_list(tmp_path, capsys):
    out = tmp_path / "run"
    assert compare_main(["--planners", "ig,random", "--reference", "ig,ig_spatial",
                         "--out", str(out), *SMALL]) == 2
    assert "reference planner 'ig_spatial' is not among the planners flown" in \
        capsys.readouterr().err
    assert not out.exists()


def test_the_generalisation_study_refuses_a_list_naming_an_unflown_reference(tmp_path, capsys):
    from reports.cli import study_main

    out = tmp_path / "study"
    assert study_main(["generalisation", "--planners", "ig,random", "--reference",
                       "ig,ig_learned", "--families", "split", "--team-families", "",
                       "--trials", "1", "--out", str(out), "--no-progress"]) == 2
    assert "reference planner 'ig_learned' is not among the planners" in \
        capsys.readouterr().err
    assert not out.exists()


def test_the_generalisation_study_needs_a_default_reference_without_names(tmp_path):
    from reports.generalisation import Cell, generalisation_study

    with pytest.raises(ValueError, match="reference planner 'ig' is not among the planners"):
        generalisation_study("random,coverage", [Cell("split", 2, 0.0)], trials=1,
                             out=tmp_path / "x", progress=False)
    assert not (tmp_path / "x").exists()


def test_the_generalisation_tables_pair_with_ig_and_ig_spatial_by_default(tmp_path):
    import csv

    from reports.generalisation import Cell, generalisation_study

    study = generalisation_study("ig,ig_spatial,random", [Cell("split", 2, 0.0)], trials=2,
                                 out=tmp_path, resolution=2.0, budget=3, progress=False)
    assert study.reference == "ig" and study.references == ("ig", "ig_spatial")
    header = study.table.split("\n\n", 1)[1].splitlines()[0]
    assert header.endswith("| ig_spatial − ig | random − ig | ig − ig_spatial "
                           "| random − ig_spatial |")
    assert "plots the differences to ig only" in study.table
    with open(tmp_path / "generalisation.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert list(rows[0])[6:] == ["minus_ig_mean", "minus_ig_se", "win_rate", "missions",
                                 "minus_ig_spatial_mean", "minus_ig_spatial_se",
                                 "win_rate_vs_ig_spatial"]
    by_planner = {row["planner"]: row for row in rows}
    paired = study.summaries[Cell("split", 2, 0.0)].paired_to
    assert float(by_planner["random"]["minus_ig_spatial_mean"]) == pytest.approx(
        paired["ig_spatial"]["random"].mean, rel=1e-5)
    assert by_planner["ig_spatial"]["minus_ig_spatial_mean"] == ""  # its own column
    assert by_planner["ig"]["minus_ig_mean"] == "" and by_planner["ig"]["minus_ig_spatial_mean"]
    assert r"ig\_spatial $-$ ig" in (tmp_path / "generalisation.tex").read_text()


def test_the_generalisation_study_flies_planners_with_options(tmp_path):
    """Specs with options and labels are flown under their labels, and the options act."""
    from ipp_toolkit.planning.specs import PlannerSpec
    from reports.generalisation import Cell, generalisation_study

    wide = PlannerSpec("ig_spatial", {"sigma": 20.0}, label="wide")
    study = generalisation_study(["ig_spatial", wide], [Cell("split", 2, 0.0)], trials=2,
                                 out=tmp_path, resolution=2.0, budget=4, progress=False)
    assert study.references == ("ig_spatial",)
    summary = study.summaries[Cell("split", 2, 0.0)]
    assert list(summary.planners) == ["ig_spatial", "wide"]
    assert "wide − ig_spatial" in study.table


def test_a_policy_flown_off_its_training_setting_is_noted_before_flying():
    from reports.compare import _checked_planners

    notes: list[str] = []
    config = EnvConfig().replace(team={"n_agents": 8, "comm_range": math.inf})
    _checked_planners("ig,coma", config, notes.append)
    assert len(notes) == 1 and notes[0].startswith(
        "note: planner 'coma' flies off its training setting: team.n_agents: trained 4, "
        "running 8; team.comm_range: trained 25.0, running inf")
