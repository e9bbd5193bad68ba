"""Study commands run end to end on a tiny configuration."""

from __future__ import annotations

import math

from reports.cli import study_main
from reports.studies import robustness_study


def test_robustness_study_writes_table_and_figure(tmp_path):
    study = robustness_study("random,coverage", agents=(2,), comms=(0.0, math.inf),
                             trials=2, resolution=1.0, out=tmp_path, progress=False)
    assert study.settings == [(2, 0.0), (2, math.inf)]
    rows = [line for line in (tmp_path / "robustness.md").read_text().splitlines()
            if line.startswith("| 2")]
    assert len(rows) == 2 and all(row.count("**") == 4 for row in rows)
    csv_lines = (tmp_path / "robustness.csv").read_text().splitlines()
    assert len(csv_lines) == 1 + 2 * 2
    assert (tmp_path / "robustness.png").stat().st_size > 5_000
    assert (tmp_path / "a2-dinf" / "results.csv").exists()


def test_ipp_study_cli_bad_input(tmp_path, capsys):
    assert study_main(["robustness", "--comm", "far", "--out", str(tmp_path)]) == 2
    assert "far" in capsys.readouterr().err
    assert study_main(["robustness", "--planners", "nosuch", "--trials", "1",
                       "--out", str(tmp_path / "x"), "--no-progress"]) == 2


def test_credit_assignment_study_end_to_end(tmp_path):
    from reports.studies import credit_assignment_study

    tiny = {"width": 8, "hidden": 16, "missions_per_update": 2, "minibatch_size": 60,
            "eval_missions": 1, "warm_start": ""}
    study = credit_assignment_study(["coma", "decentralised"], missions=2, overrides=tiny,
                                    train_resolution=1.0, trials=1, eval_resolution=1.0,
                                    out=tmp_path, progress=False)
    assert set(study.policies) == {"coma", "decentralised"}
    assert all(path.exists() for path in study.policies.values())
    table = (tmp_path / "credit.md").read_text()
    assert "| coma |" in table and "| decentralised |" in table
    assert (tmp_path / "compare" / "curves.png").exists()
    assert study_main(["credit", "--variants", "comma", "--out", str(tmp_path / "x")]) == 2


def test_ablation_study_end_to_end(tmp_path):
    from reports.studies import ablation_study

    tiny = {"width": 8, "hidden": 16, "missions_per_update": 2, "minibatch_size": 60,
            "eval_missions": 1, "warm_start": ""}
    study = ablation_study(["masking", "own_position"], missions=2, overrides=tiny,
                           train_resolution=1.0, trials=1, eval_resolution=1.0,
                           out=tmp_path, progress=False)
    assert set(study.policies) == {"full", "-masking", "-own_position"}
    from coma.persistence import load_policy

    masked_off, _ = load_policy(study.policies["-masking"])
    assert masked_off.env_config.team.invalid_action == "hold"
    no_own, _ = load_policy(study.policies["-own_position"])
    assert not no_own.env_config.features.own_position
    assert "| -masking |" in (tmp_path / "ablation.md").read_text()
    assert study_main(["ablation", "--ablations", "nosuch", "--out", str(tmp_path / "x")]) == 2
