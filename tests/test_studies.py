"""Study commands run end to end on a tiny configuration."""

from __future__ import annotations

import json
import math

import pytest

from reports.cli import study_main
from reports.studies import robustness_study


@pytest.mark.slow
def test_robustness_study_writes_table_and_figure(tmp_path):
    study = robustness_study("random,coverage", agents=(2,), comms=(0.0, math.inf),
                             trials=2, resolution=1.0, out=tmp_path, progress=False,
                             failures=(0, 1))
    assert study.settings == [(2, 0.0, 0), (2, 0.0, 1), (2, math.inf, 0), (2, math.inf, 1)]
    rows = [line for line in (tmp_path / "robustness.md").read_text().splitlines()
            if line.startswith("| 2")]
    assert len(rows) == 4 and all(row.count("**") == 4 for row in rows)
    csv_lines = (tmp_path / "robustness.csv").read_text().splitlines()
    assert len(csv_lines) == 1 + 4 * 2
    assert (tmp_path / "robustness.png").stat().st_size > 5_000
    assert (tmp_path / "a2-dinf" / "results.csv").exists()
    stored = json.loads((tmp_path / "a2-dinf-f1" / "config.json").read_text())
    assert stored["config"]["team"]["random_failures"] == 1


def test_ipp_study_cli_bad_input(tmp_path, capsys):
    assert study_main(["robustness", "--comm", "far", "--out", str(tmp_path)]) == 2
    assert "far" in capsys.readouterr().err
    # Two of two UAVs failing leaves none: refused before any mission is flown.
    assert study_main(["robustness", "--agents", "2", "--comm", "0", "--failures", "0,2",
                       "--out", str(tmp_path / "f"), "--no-progress"]) == 2
    assert "random_failures" in capsys.readouterr().err
    assert not (tmp_path / "f").exists()
    assert study_main(["robustness", "--planners", "nosuch", "--trials", "1",
                       "--out", str(tmp_path / "x"), "--no-progress"]) == 2


@pytest.mark.slow
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


@pytest.mark.slow
def test_ablation_study_end_to_end(tmp_path):
    from reports.studies import ablation_study

    tiny = {"width": 8, "hidden": 16, "missions_per_update": 2, "minibatch_size": 60,
            "eval_missions": 1, "warm_start": ""}
    study = ablation_study(["masking", "own_position", "gain"], missions=2, overrides=tiny,
                           train_resolution=1.0, trials=1, eval_resolution=1.0,
                           out=tmp_path, progress=False)
    # gain planes are off in the training mission: the run adds them and says so
    from coma.persistence import load_policy

    assert set(study.policies) == {"full", "-masking", "-own_position", "+gain"}
    with_gain, _ = load_policy(study.policies["+gain"])
    assert with_gain.env_config.features.gain

    masked_off, _ = load_policy(study.policies["-masking"])
    assert masked_off.env_config.team.invalid_action == "hold"
    no_own, _ = load_policy(study.policies["-own_position"])
    assert not no_own.env_config.features.own_position
    assert "| -masking |" in (tmp_path / "ablation.md").read_text()
    assert study_main(["ablation", "--ablations", "nosuch", "--out", str(tmp_path / "x")]) == 2


@pytest.mark.slow
def test_studies_train_each_run_once_per_seed_and_summarise_over_seeds(tmp_path):
    import numpy as np

    from coma.persistence import load_policy
    from reports.studies import credit_assignment_study, seed_table
    from reports.tables import Stat, Summary

    tiny = {"width": 8, "hidden": 16, "missions_per_update": 2, "minibatch_size": 60,
            "eval_missions": 1, "warm_start": ""}
    study = credit_assignment_study(["coma"], missions=2, overrides=tiny, train_resolution=1.0,
                                    trials=2, eval_resolution=1.0, out=tmp_path,
                                    progress=False, seeds=[3, 5])
    assert set(study.policies) == {"coma@s3", "coma@s5"}
    for seed in (3, 5):
        networks, _ = load_policy(study.policies[f"coma@s{seed}"])
        assert networks.coma_config.seed == seed
    text = (tmp_path / "credit.md").read_text()
    assert "training seeds 3, 5" in text and "Over training seeds" in text
    assert "| coma | 2 |" in text and "| coma@s3 |" in text
    with pytest.raises(ValueError, match="not both"):
        credit_assignment_study(["coma"], overrides={"seed": 1}, seeds=[0, 1], out=tmp_path)
    with pytest.raises(ValueError, match=r"distinct non-negative integers, got \[1, 1\]"):
        credit_assignment_study(["coma"], seeds=[1, 1], out=tmp_path)
    assert study_main(["credit", "--seeds", "0,x", "--out", str(tmp_path / "x")]) == 2

    # The table's numbers: mean and sample std over seeds of the per-seed means.
    stats = {("a@s0", "entropy", 2): Stat(0.4, 0.1, 5), ("a@s1", "entropy", 2): Stat(0.6, 0.1, 5),
             ("b@s0", "entropy", 2): Stat(0.3, 0.1, 5), ("b@s1", "entropy", 2): Stat(0.3, 0.1, 5),
             ("a@s0", "f1", 2): Stat(0.7, 0.1, 5), ("a@s1", "f1", 2): Stat(0.9, 0.1, 5),
             ("b@s0", "f1", 2): Stat(0.5, 0.1, 5), ("b@s1", "f1", 2): Stat(0.5, 0.1, 5)}
    summary = Summary(planners=("a@s0", "a@s1", "b@s0", "b@s1"), metrics=("entropy", "f1"),
                      steps=(2,), budget=2, stats=stats, plan_ms={}, missions=5, agents=(4,),
                      comm=(25.0,))
    table = seed_table(summary, ["a", "b"], [0, 1])
    spread = np.std([0.4, 0.6], ddof=1)
    assert f"| a | 2 | 0.500 ± {spread:.3f} | **0.800 ± {np.std([0.7, 0.9], ddof=1):.3f}** |" \
        in table
    assert "| b | 2 | **0.300 ± 0.000** | 0.500 ± 0.000 |" in table


@pytest.mark.slow
def test_generalisation_study_end_to_end_on_a_tiny_grid(tmp_path):
    from reports.generalisation import Cell, generalisation_study, study_cells

    cells = study_cells(["split", "real"], ["blobs"], [(2, 0.0)])
    assert [c.label for c in cells] == ["split", "real:bcsd_air_temperature",
                                        "real:jacksboro_dem", "blobs"]
    study = generalisation_study("ig,random", cells[:2] + [Cell("blobs", 2, 0.0)], trials=2,
                                 out=tmp_path, resolution=1.0, budget=3, progress=False)
    for suffix in ("md", "csv", "tex", "png", "pdf"):
        assert (tmp_path / f"generalisation.{suffix}").is_file()
    assert (tmp_path / "real-bcsd_air_temperature" / "a4-d25" / "results.csv").is_file()
    rows = (tmp_path / "generalisation.csv").read_text().splitlines()
    assert rows[0].startswith("terrain,agents,comm,planner") and len(rows) == 1 + 3 * 2
    paired = study.summaries[cells[0]].paired["random"]
    assert paired.n == 2 and "random − ig" in study.table
    with pytest.raises(ValueError, match="reference planner 'ig'"):
        generalisation_study("random,coverage", cells[:1], trials=1, out=tmp_path / "x")
    assert not (tmp_path / "x").exists()
