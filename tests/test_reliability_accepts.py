"""Input that used to be accepted without a word is refused by name: a reward scale that
overflows the returns, a planner label with a control character, ``agent_id_scale: 0``, a
planner registered over an installed one, and stored results with NaN metrics or of another
seed."""

from __future__ import annotations

import csv
import json

import pytest

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.config.settings import build_env_config
from ipp_toolkit.planning import Planner, planner_factory, register_planner
from ipp_toolkit.planning.specs import PlannerSpec
from ipp_toolkit.runs.evaluation import evaluate
from ipp_toolkit.runs.evaluation_result import load_results
from ipp_toolkit.runs.result_store import EvaluationError
from reports.cli import compare_main

QUICK = ["--planners", "random", "--no-progress", "--trials", "1", "--resolution", "1",
         "--budget", "2", "--agents", "2"]


@pytest.mark.parametrize("reward, message", [
    ({"alpha": 1e308}, "reward.alpha = 1e+308: must be at most 1e+06"),
    ({"beta": -1e308}, "reward.beta = -1e+308: must be finite, between"),
])
def test_a_reward_scale_that_overflows_the_returns_is_refused(tmp_path, capsys, reward,
                                                             message):
    with pytest.raises(ValueError, match=message.replace("+", r"\+")):
        EnvConfig().replace(reward=reward)
    config = tmp_path / "config.yaml"
    key, value = next(iter(reward.items()))
    config.write_text(f"reward: {{{key}: {value:.1e}}}\n")  # 1.0e+308: YAML 1.1's float
    assert compare_main([*QUICK, "--config", str(config), "--out", str(tmp_path / "o")]) == 2
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("label", ["two\nlines", "tab\there", "bell\x07", "del\x7f"])
def test_a_planner_label_with_a_control_character_is_refused(tmp_path, capsys, label):
    with pytest.raises(ValueError, match="holds a control character"):
        PlannerSpec("random", label=label)
    out = tmp_path / "out"
    assert compare_main([*QUICK, "--planners", f"{label}:random", "--out", str(out)]) == 2
    assert "holds a control character" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("scale", [0, -1])
def test_agent_id_scale_below_one_is_refused_not_replaced(tmp_path, scale):
    config = tmp_path / "config.yaml"
    config.write_text(f"features: {{agent_id_scale: {scale}}}\n")
    with pytest.raises(ValueError, match=f"features.agent_id_scale = {scale}: must be an "
                                         "integer >= 1"):
        build_env_config(config)
    config.write_text("features: {agent_id_scale: 2}\n")  # a valid scale still fits the team
    assert build_env_config(config, agents=4).features.agent_id_scale == 4


def test_registering_over_an_installed_planner_needs_replace(monkeypatch):
    from ipp_toolkit import planning

    class Mine(Planner):
        def act(self, views):
            raise NotImplementedError

    builtin = planner_factory("ig")
    with pytest.raises(ValueError, match="'ig' is already registered by .*replace=True"):
        register_planner("ig")(Mine)
    assert planner_factory("ig") is builtin
    monkeypatch.setattr(planning, "_REGISTRY", {})  # as before the installed one is loaded
    with pytest.raises(ValueError, match="'ig' is taken by the installed planner .*replace"):
        register_planner("ig")(Mine)
    assert "ig" not in planning._REGISTRY
    register_planner("ig", replace=True)(Mine)  # said explicitly: replaced in this process
    assert planner_factory("ig") is Mine


@pytest.fixture
def stored(tmp_path):
    config = EnvConfig().replace(world={"resolution": 1.0}, team={"n_agents": 2, "budget": 2})
    out = tmp_path / "out"
    evaluate(config, ["random"], missions=2, seed=3, progress=False, out_dir=out)
    return config, out


def test_a_shard_with_a_nan_metric_is_flown_again(stored):
    config, out = stored
    shard = out / "shards" / "random" / "mission_00001.json"
    data = json.loads(shard.read_text())
    data["rows"][2]["entropy"] = float("nan")
    shard.write_text(json.dumps(data))
    with pytest.warns(UserWarning, match="entropy = nan, not a finite number"):
        result = evaluate(config, ["random"], missions=2, seed=3, progress=False, out_dir=out)
    assert all(row["entropy"] == row["entropy"] for row in result.rows)


@pytest.mark.parametrize("column, value, message", [
    ("seed", "7", "is of seed 7, the folder's config.json says 3"),
    ("f1", "nan", "f1 = nan, not a finite number"),
    ("reward", "inf", "reward = inf, not a finite number"),
])
def test_load_results_refuses_rows_of_another_seed_or_not_finite(stored, column, value,
                                                                 message):
    _, out = stored
    path = out / "results.csv"
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    rows[3][rows[0].index(column)] = value  # mission 0, step 2
    with open(path, "w", newline="") as handle:
        csv.writer(handle).writerows(rows)
    with pytest.raises(EvaluationError, match=f"results.csv' line 4 .*{message}"):
        load_results(out)
