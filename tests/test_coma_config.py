"""COMAConfig's nested warm-start section: the nested form is written, the old flat names
(``warm_start`` = planner, ``warm_start_missions``, ``warm_start_epochs``) are still read, from
files, presets, recipes and ``--set``; bad values are named."""

from __future__ import annotations

import json

import pytest
from helpers import small_config

from coma.cli import build_parser, configs_from_args, main, stage_configs
from coma.config import COMAConfig, WarmStartConfig, from_dict, nested_fields, preset
from coma.persistence import (
    CHECKPOINT_KIND,
    SHIPPED_POLICIES,
    build_networks,
    load_policy,
    resolve_policy,
    save_policy,
)
from coma.run_files import resume_fields
from ipp_toolkit.io import load_torch

_FLAT = ("warm_start_missions", "warm_start_epochs")


def _args(*argv: str):
    return build_parser().parse_args(["--out", "unused", *argv])


def test_nested_config_round_trips_through_json():
    config = COMAConfig(width=8, warm_start=WarmStartConfig(
        planner="coverage", missions=7, missions_per_batch=3, epochs=2, minibatch_size=40,
        lr=3e-3, holdout=0.25), comm_ranges=(0.0, float("inf")))
    values = config.to_dict()
    assert values["warm_start"] == {"planner": "coverage", "missions": 7,
                                    "missions_per_batch": 3, "epochs": 2,
                                    "minibatch_size": 40, "lr": 3e-3, "holdout": 0.25}
    assert not set(_FLAT) & set(values)
    assert from_dict(json.loads(json.dumps(values))) == config
    assert COMAConfig(**values) == config
    assert hash(config) == hash(from_dict(values))


def test_old_flat_dicts_load_to_the_same_config():
    flat = {**COMAConfig().to_dict(), "warm_start": "coverage", "warm_start_missions": 7,
            "warm_start_epochs": 3}
    nested = COMAConfig(warm_start=WarmStartConfig(planner="coverage", missions=7, epochs=3))
    assert from_dict(flat) == nested
    # A flat last.pt resumes under the nested config (the fields compare alike).
    assert resume_fields(from_dict(flat)) == resume_fields(nested)
    # No warm start stays expressible, in every spelling.
    off = WarmStartConfig(planner="")
    for config in (from_dict({"warm_start": ""}), COMAConfig(warm_start=""),
                   COMAConfig().replace(warm_start=""), preset("paper")):
        assert config.warm_start == off and not config.warm_start.enabled
    assert COMAConfig().warm_start.enabled


def test_shipped_checkpoints_keep_their_flat_warm_start_settings():
    # The shipped files were written with the flat names: planner and size are still read.
    wanted = {"paper-actor": "ig"}
    assert set(wanted) <= set(SHIPPED_POLICIES)  # later files store the nested form
    for name, planner in wanted.items():
        path = resolve_policy(f"shipped:{name}")
        stored = load_torch(path, CHECKPOINT_KIND)["coma_config"]
        assert stored["warm_start"] == planner and stored["warm_start_missions"] == 1500
        networks, _ = load_policy(path)
        assert networks.coma_config.warm_start == WarmStartConfig(planner=planner)
        # The shipped JSON record reads to the same config (but for the run length).
        record = path.with_suffix(".json")
        coma = json.loads(record.read_text()).get("coma_config")
        if coma is not None:
            assert from_dict(coma).replace(missions=1) \
                == networks.coma_config.replace(missions=1)


def test_saving_writes_the_nested_form(tmp_path):
    env = small_config(n_agents=2, resolution=1.0)
    config = COMAConfig(width=8, hidden=16, warm_start={"planner": "", "missions": 9})
    save_policy(tmp_path / "p.pt", build_networks(config, env))
    stored = load_torch(tmp_path / "p.pt", CHECKPOINT_KIND)["coma_config"]
    assert stored["warm_start"]["missions"] == 9 and not set(_FLAT) & set(stored)
    assert load_policy(tmp_path / "p.pt")[0].coma_config == config


def test_a_later_layer_changes_only_the_nested_fields_it_names():
    assert nested_fields({"warm_start": {"planner": "ig", "missions": 5}},
                         {"warm_start": ""}, {"warm_start_epochs": 2},
                         {"warm_start.lr": 0.5}) == {
        "warm_start": {"planner": "", "missions": 5, "epochs": 2, "lr": 0.5}}
    config = COMAConfig().replace(**{"warm_start.missions": 5})
    assert config.replace(warm_start="").warm_start.missions == 5
    paper = preset("paper", **{"warm_start.missions": 5})
    assert paper.warm_start == WarmStartConfig(planner="", missions=5)


@pytest.mark.parametrize("argv", [
    ["--set", "warm_start.missions=100", "--set", "warm_start.epochs=3"],
    ["--set", "warm_start_missions=100", "--set", "warm_start_epochs=3"],
    ["--set", "warm_start_missions=100", "--set", "warm_start.epochs=3",
     "--set", "warm_start=ig"],
])
def test_dotted_and_flat_set_give_the_same_config(argv):
    config, _ = configs_from_args(_args(*argv))
    assert config.warm_start == WarmStartConfig(planner="ig", missions=100, epochs=3)
    assert config == preset("cpu").replace(warm_start={"missions": 100, "epochs": 3})


def test_set_and_warm_start_flag_switch_it_off_and_reach_recipes():
    for argv in (["--warm-start", "none"], ["--set", "warm_start="],
                 ["--set", "warm_start.planner="]):
        config, _ = configs_from_args(_args(*argv))
        assert config.warm_start == WarmStartConfig(planner="")
    config, _ = configs_from_args(_args("--warm-start", "coverage",
                                        "--set", "warm_start.missions=10"))
    assert config.warm_start == WarmStartConfig(planner="coverage", missions=10)
    # A recipe's stages keep their own fields (no warm start) and take the dotted change.
    for _, config, _ in stage_configs(_args("--preset", "scratch",
                                            "--set", "warm_start.epochs=3")):
        assert config.warm_start == WarmStartConfig(planner="", epochs=3)


@pytest.mark.parametrize("argv, named", [
    (["--set", "warm_start.missions=0"], "warm_start.missions = 0"),
    (["--set", "warm_start_missions=0"], "warm_start.missions = 0"),
    (["--set", "warm_start.lr=-1"], "warm_start.lr = -1"),
    (["--set", "warm_start.holdout=1"], "warm_start.holdout = 1"),
    (["--set", "warm_start.planner=7"], "warm_start.planner = 7"),
    (["--set", "warm_start.speed=1"], "unknown key(s) ['warm_start.speed']"),
    (["--set", "warm_starts=ig"], "unknown key(s) ['warm_starts']"),
    (["--warm-start", "nosuch"], "nosuch"),
])
def test_a_bad_warm_start_value_is_named_and_exits_2(tmp_path, capsys, argv, named):
    assert main(["--out", str(tmp_path / "run"), *argv]) == 2
    err = capsys.readouterr().err
    assert named in err and "Traceback" not in err
    assert not (tmp_path / "run").exists()


def test_bad_values_in_python_and_files_are_named():
    with pytest.raises(ValueError, match=r"warm_start = None"):
        from_dict({"warm_start": None})
    with pytest.raises(ValueError, match=r"warm_start = 3"):
        COMAConfig(warm_start=3)
    with pytest.raises(ValueError, match=r"warm_start\.epochs = 0"):
        from_dict({"warm_start": {"epochs": 0}})
    with pytest.raises(ValueError, match=r"warm_start\.planner = 'i g'"):
        WarmStartConfig(planner="i g")
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['warm_start\.bogus'\]"):
        COMAConfig(warm_start={"bogus": 1})
