"""Values of the wrong type or shape (config fields, output paths, actions): each refused in
one line naming the field or path and the value, exit code 2 from a command, never a
traceback, and nothing written."""

from __future__ import annotations

import numpy as np
import pytest

from ipp_toolkit import EnvConfig, IPPEnv
from ipp_toolkit.config.files import config_from_dict
from ipp_toolkit.sim.mission import InvalidActionError
from ipp_toolkit.vec import make_sb3_vec_env
from reports.cli import compare_main, simulate_main, train_main

COMMANDS = {
    "compare": lambda config, out: compare_main(["--config", config, "--planners", "random",
                                                 "--no-progress", "--out", out]),
    "simulate": lambda config, out: simulate_main(["--config", config, "--out", out]),
    "coma": lambda config, out: train_main(["coma", "--config", config, "--out", out]),
    "ppo": lambda config, out: train_main(["ppo", "--config", config, "--out", out]),
}

WRONG_TYPES = [
    ("world: {prior: abc}", "world.prior = 'abc': must be a number"),
    ("sensor: {fov_deg: wide}", "sensor.fov_deg = 'wide': must be a number"),
    ("world: {altitudes: 5}", "world.altitudes = 5: must be a list of numbers"),
    ("world: {resolution: {a: 1}}", "world.resolution = {'a': 1}: must be a number"),
    ("features: {gain: 'no'}", "features.gain = 'no': must be true or false"),
    ("team: {budget: true}", "team.budget = True: must be an integer"),
    ("reward: {alpha: false}", "reward.alpha = False: must be a number"),
]


def last_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err
    return err.splitlines()[-1]


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("text, message", WRONG_TYPES)
def test_wrong_typed_config_values_are_named_by_every_command(tmp_path, capsys, command,
                                                              text, message):
    config = tmp_path / "config.yaml"
    config.write_text(text + "\n")
    out = tmp_path / "out"
    assert COMMANDS[command](str(config), str(out)) == 2
    assert message in last_line(capsys)
    assert not out.exists()


@pytest.mark.parametrize("text, message", WRONG_TYPES)
def test_wrong_typed_values_are_named_from_python(text, message):
    import yaml

    with pytest.raises(ValueError, match="invalid config: " + message.split(":")[0]):
        config_from_dict(yaml.safe_load(text))


@pytest.mark.parametrize("command", sorted(COMMANDS))
@pytest.mark.parametrize("shape", ["empty", "file", "below-file"])
def test_output_paths_that_are_not_folders_are_refused(tmp_path, capsys, command, shape):
    config = tmp_path / "config.yaml"
    config.write_text("world: {resolution: 1.0}\n")
    afile = tmp_path / "afile"
    afile.write_text("keep")
    out = {"empty": "", "file": str(afile), "below-file": str(afile / "sub")}[shape]
    before = sorted(p.name for p in tmp_path.iterdir())
    assert COMMANDS[command](str(config), out) == 2
    line = last_line(capsys)
    assert ("must name a folder" in line) if shape == "empty" else (str(afile) in line)
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    assert afile.read_text() == "keep"


def test_simulate_refuses_an_output_file_that_is_a_folder_before_flying(tmp_path, capsys):
    (tmp_path / "out" / "final.png").mkdir(parents=True)
    assert simulate_main(["--resolution", "1", "--out", str(tmp_path / "out")]) == 2
    assert "final.png' exists and is not a file" in last_line(capsys)
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["final.png"]


def test_sections_given_as_dicts_or_of_the_wrong_type():
    assert EnvConfig(world={"resolution": 0.5}).world.resolution == 0.5
    with pytest.raises(ValueError, match="section 'team' must be a TeamConfig"):
        EnvConfig(team=None)
    with pytest.raises(ValueError, match="world.prior"):
        EnvConfig(world={"prior": "abc"})


@pytest.mark.parametrize("call, message", [
    (lambda env: env.step({"uav_0": 2 ** 70, "uav_1": 0}), "is out of range"),
    (lambda env: env.step({"uav_0": 1.5, "uav_1": 0}), "must be an integer"),
    (lambda env: env.critic_observations({"uav_0": -1, "uav_1": 0}), "action -1 is out of"),
    (lambda env: env.critic_observations([0, 9]), "'uav_1': action 9 is out of range"),
    (lambda env: env.critic_observations([0]), "one action per agent"),
    (lambda env: env.critic_observations({"uav_0": 0}), r"no action for agent\(s\)"),
])
def test_actions_out_of_range_are_refused_by_agent(call, message):
    env = IPPEnv(EnvConfig().replace(world={"resolution": 1.0}, team={"n_agents": 2}))
    env.reset(seed=0)
    with pytest.raises(InvalidActionError, match=message):
        call(env)


def test_the_sb3_view_refuses_an_action_out_of_range_by_slot():
    venv = make_sb3_vec_env(EnvConfig().replace(world={"resolution": 1.0},
                                                team={"n_agents": 2}), 1, 0)
    try:
        venv.reset()
        with pytest.raises(InvalidActionError, match="'slot 0': action 7 is out of range"):
            venv.step(np.array([7, 0]))
    finally:
        venv.close()
