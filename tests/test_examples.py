"""The teaching examples run (in their reduced mode) and say what they claim."""

from __future__ import annotations

import ast
import re
import runpy
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
DOCS = Path(__file__).resolve().parent.parent / "docs"


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
    # Without --out: into its own folder under the working directory, named at the end.
    monkeypatch.chdir(tmp_path)
    out = run_example("02_uav_advantages.py", ["--checkpoint", str(run.best_policy),
                                               "--step", "2"], monkeypatch, capsys)
    rows = [line for line in out.splitlines() if line.startswith("uav_")]
    assert len(rows) == 2 and all(row.count("*") == 1 for row in rows)
    figure = Path("examples-output", "02_uav_advantages", "uav_advantages.png")
    assert out.splitlines()[-1] == f"figure: {figure}"
    assert (tmp_path / figure).stat().st_size > 10_000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["examples-output", "run"]


def _argument_default(example: Path, flag: str) -> object:
    """The ``default=`` of ``parser.add_argument(flag, ...)`` in ``example``'s source."""
    for node in ast.walk(ast.parse(example.read_text(encoding="utf-8"))):
        if (isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "add_argument"
                and node.args and getattr(node.args[0], "value", None) == flag):
            default = next(k.value for k in node.keywords if k.arg == "default")
            if isinstance(default, ast.Call):  # Path("...")
                default = default.args[0]
            return ast.literal_eval(default)
    return None


WRITERS = ["02_uav_advantages.py", "04_real_terrain.py", "05_torchrl_mappo.py",
           "06_rllib_action_masking.py"]


@pytest.mark.parametrize("name", sorted(p.name for p in EXAMPLES.glob("*.py")))
def test_an_example_that_writes_files_names_its_own_folder(name, monkeypatch, capsys):
    source = (EXAMPLES / name).read_text(encoding="utf-8")
    default = _argument_default(EXAMPLES / name, "--out")
    if name not in WRITERS:
        assert default is None and "savefig" not in source and ".save(" not in source
        return
    assert default == f"examples-output/{Path(name).stem}"
    if name == "05_torchrl_mappo.py":
        pytest.importorskip("torchrl", reason="torchrl is not installed (optional extra)")
    if name == "06_rllib_action_masking.py":
        pytest.importorskip("ray.rllib", reason="RLlib is not installed (optional extra)")
    monkeypatch.setenv("COLUMNS", "300")  # argparse would break the path at its hyphen
    with pytest.raises(SystemExit) as exit_:
        run_example(name, ["--help"], monkeypatch, capsys)
    assert exit_.value.code == 0
    assert f"default: {default}" in " ".join(capsys.readouterr().out.split())


def test_the_docs_name_the_step_example_02_draws_by_default():
    step = _argument_default(EXAMPLES / "02_uav_advantages.py", "--step")
    text = (DOCS / "credit-assignment.md").read_text(encoding="utf-8")
    # The prose (not the command that asks for another --step) names the default.
    section = text[text.index("## 2. A mission"):text.index("## 3.")].split("```")[-1]
    assert set(re.findall(r"\bstep (\d+)", section)) == {str(step)}


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
