"""--reference of ipp-compare and ipp-study generalisation: the paired column against any
planner flown, refused otherwise."""

from __future__ import annotations

from reports.cli import compare_main

SMALL = ["--resolution", "2", "--trials", "2", "--workers", "1", "--no-progress"]


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
