"""The teaching examples run (in their reduced mode) and say what they claim."""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def run_example(name: str, args: list[str], monkeypatch: pytest.MonkeyPatch,
                capsys: pytest.CaptureFixture[str]) -> str:
    monkeypatch.setattr(sys, "argv", [name, *args])
    runpy.run_path(str(EXAMPLES / name), run_name="__main__")
    return capsys.readouterr().out


def test_matrix_game_shows_the_counterfactual_credit(monkeypatch, capsys):
    out = run_example("01_matrix_game.py", ["--quick"], monkeypatch, capsys)
    # The joint action (1, 2): agent 1 chose well, its teammate blundered.
    row = next(line for line in out.splitlines() if line.strip().startswith("(1, 2)"))
    assert "A1  -9.50" in row and "A1  +0.50" in row
    learned = {line.split("agent 1")[0].strip(): float(line.split("= ")[1].split()[0])
               for line in out.splitlines() if "P(best action)" in line}
    assert learned["counterfactual (COMA)"] > learned["shared reward"] + 0.2


def test_uav_advantages_prints_and_draws(tmp_path, monkeypatch, capsys):
    from helpers import small_config

    from coma.config import COMAConfig
    from coma.learner import train

    run = train(COMAConfig(width=8, hidden=16, missions=2, missions_per_update=2,
                           minibatch_size=60, eval_missions=1, warm_start=""),
                small_config(n_agents=2, resolution=1.0), tmp_path / "run", progress=False,
                tensorboard=False)
    figure = tmp_path / "adv.png"
    out = run_example("02_uav_advantages.py", ["--checkpoint", str(run.best_policy),
                                               "--step", "2", "--out", str(figure)],
                      monkeypatch, capsys)
    rows = [line for line in out.splitlines() if line.startswith("uav_")]
    assert len(rows) == 2 and all(row.count("*") == 1 for row in rows)
    assert figure.stat().st_size > 10_000


def test_credit_assignment_study_runs_every_variant(monkeypatch, capsys):
    out = run_example("03_credit_assignment_study.py", ["--quick"], monkeypatch, capsys)
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines()[1:] if line}
    assert set(rows) == {"coma", "central_qv", "actor_independent", "decentralised"}
    for values in rows.values():
        entropy, f1 = float(values[1]), float(values[2])
        assert 0 <= entropy <= 1 and 0 <= f1 <= 1


def test_real_terrain_example(tmp_path, monkeypatch, capsys, placeholder_figures):
    out = run_example("04_real_terrain.py", ["--quick", "--planners", "ig,coverage",
                                             "--out", str(tmp_path)], monkeypatch, capsys)
    assert "of the area lies above 550 m" in out
    assert "| ig |" in out and "| coverage |" in out
    assert (tmp_path / "compare" / "summary.md").exists()


def test_torchrl_mappo_trains_with_masks_and_a_failure(tmp_path, monkeypatch, capsys):
    pytest.importorskip("torchrl", reason="torchrl is not installed (optional extra 'torchrl')")
    # The example flies with invalid_action="raise": a masked action would stop it.
    out = run_example("05_torchrl_mappo.py", ["--quick", "--out", str(tmp_path)], monkeypatch,
                      capsys)
    assert (tmp_path / "policy.pt").is_file() and f"torchrl={tmp_path}" in out
    lines = [line for line in out.splitlines() if line.startswith("iteration ")]
    assert len(lines) == 2
    for line in lines:
        entropy = float(line.split("final entropy ")[1].split(",")[0])
        assert 0 < entropy < 1
