"""Every shipped COMA policy has a recipe that reproduces its training configs."""

from __future__ import annotations

import dataclasses
import json

import pytest

from coma import recipes
from coma.cli import build_parser, main, stage_configs
from coma.persistence import SHIPPED_POLICIES, load_policy, resolve_policy
from ipp_toolkit.config.files import config_to_dict

# Fields a recipe does not fix: how long the recorded run was meant to go (it was stopped at
# the documented mission count) and where the shipped file's start lay on its author's disk.
_FREE = {"missions", "init_policy"}


@pytest.mark.parametrize("name", sorted(SHIPPED_POLICIES))
def test_the_recipe_of_every_shipped_policy_matches_its_stored_configs(name):
    networks, _ = load_policy(resolve_policy(f"shipped:{name}"))
    stage, coma_config, env_config = stage_configs(
        build_parser().parse_args(["--out", "x", "--preset", name]))[-1]
    stored = dataclasses.asdict(networks.coma_config)
    made = dataclasses.asdict(coma_config)
    assert {k: v for k, v in made.items() if k not in _FREE} == {
        k: v for k, v in stored.items() if k not in _FREE}
    assert config_to_dict(env_config) == config_to_dict(networks.env_config)
    # A stage that starts from the previous one learns its start when it runs.
    assert bool(coma_config.init_policy) == (stage.init or "").startswith("shipped:")


def test_unknown_recipe_and_recipe_flags(capsys):
    with pytest.raises(ValueError, match="no recipe named 'nope'"):
        recipes.recipe("nope")
    stages = stage_configs(build_parser().parse_args(
        ["--out", "x", "--preset", "scratch", "--missions", "50", "--seed", "3"]))
    assert [s.name for s, _, _ in stages] == ["scratch"]
    assert all(c.missions == 50 and c.seed == 3 for _, c, _ in stages)
    assert not stages[0][2].features.own_position  # the recipe's own mission change


def test_a_removed_policys_recipe_is_refused_with_its_record(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--out", "x", "--preset", "prior-mixture"])
    err = capsys.readouterr().err
    assert "shipped:prior-mixture" in err
    assert "experiments/shipped-policies/coma_prior_mixture_4agents_d25.json" in err


def test_a_two_stage_recipe_runs_and_resumes(tmp_path, monkeypatch):
    tiny = {"width": 8, "hidden": 16, "missions_per_update": 2, "eval_missions": 1,
            "minibatch_size": 60, "warm_start": "", "missions": 2}
    monkeypatch.setitem(recipes.RECIPES, "tiny", (
        recipes.Stage("first", tiny, {"team": {"n_agents": 2}, "world": {"resolution": 1.0}}),
        recipes.Stage("second", {**tiny, "lr_actor": 1e-5},
                      {"team": {"n_agents": 2}, "world": {"resolution": 1.0}},
                      init="previous"),
    ))
    out = tmp_path / "run"
    argv = ["--preset", "tiny", "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    first, second = out / "stage-1-first", out / "stage-2-second"
    assert (first / "best.pt").exists() and (second / "best.pt").exists()
    networks, _ = load_policy(second / "last.pt")
    assert networks.coma_config.init_policy == str(first / "best.pt")
    assert main(argv) == 2  # the folder holds a run: never overwritten without --resume
    assert main(argv + ["--resume"]) == 0  # both stages finished: nothing more to do
    assert main(["--preset", "tiny", "--out", str(tmp_path / "none"), "--resume"]) == 2
    assert not (tmp_path / "none").exists()  # refused: no folder left behind
    assert json.loads((out / "run.json").read_text())["command"] == "ipp-train coma"
