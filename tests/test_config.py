import math

import pytest

from ipp_toolkit.config import EnvConfig, config_to_dict, load_config, save_config
from ipp_toolkit.env import IPPEnv


def test_defaults_reproduce_the_paper():
    config = EnvConfig()
    assert config.world.map_cells == 500 and config.world.grid_points == 11
    assert config.team.n_agents == 4 and config.team.budget == 15
    assert config.team.comm_range == 25.0
    assert config.sensor.accuracy == (0.99, 0.735, 0.625)
    assert (config.reward.alpha, config.reward.beta) == (22.0, -0.5)


def test_yaml_round_trip(tmp_path):
    config = EnvConfig().replace(team={"n_agents": 8, "comm_range": math.inf},
                                 world={"resolution": 0.5})
    path = tmp_path / "c.yaml"
    save_config(config, path)
    assert load_config(path) == config
    assert config_to_dict(config)["team"]["comm_range"] == "inf"


def test_yaml_partial_and_inf(tmp_path):
    path = tmp_path / "c.yaml"
    path.write_text("team:\n  comm_range: .inf\n  n_agents: 2\n")
    config = load_config(path)
    assert config.team.comm_range == math.inf and config.world.resolution == 0.1


@pytest.mark.parametrize("text,match", [
    ("team:\n  n_agnets: 3\n", r"unknown key\(s\) \['n_agnets'\] in section 'team'"),
    ("teams:\n  n_agents: 3\n", r"unknown section\(s\) \['teams'\]"),
    ("team: 3\n", "section 'team' must be a mapping"),
    ("- a\n- b\n", "must hold a mapping"),
    ("team: [\n", "not valid YAML"),
])
def test_yaml_errors(tmp_path, text, match):
    path = tmp_path / "c.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        load_config(path)


def test_missing_file(tmp_path):
    with pytest.raises(ValueError, match="cannot read config file .*nope.yaml"):
        load_config(tmp_path / "nope.yaml")


@pytest.mark.parametrize("sections,match", [
    ({"team": {"n_agents": 0}}, r"team.n_agents = 0"),
    ({"team": {"n_agents": 122, "start": "random"}}, r"team.n_agents = 122.*121 2-D cells"),
    ({"team": {"comm_range": -5.0}}, r"team.comm_range = -5.0"),
    ({"team": {"comm_range": "far"}}, r"team.comm_range = 'far'"),
    ({"team": {"n_agents": 3}}, r"team.start = 'fixed'.*use start: random"),
    ({"team": {"start_altitude": 12.0}}, r"team.start_altitude = 12.0: unknown altitude"),
    ({"team": {"budget": 0}}, r"team.budget = 0"),
    ({"team": {"invalid_action": "ignore"}}, r"team.invalid_action = 'ignore'"),
    ({"terrain": {"kind": "mountains"}}, r"terrain.kind = 'mountains': unknown terrain kind"),
    ({"terrain": {"kind": "raster"}}, r"terrain.raster = None"),
    ({"world": {"resolution": 0.3}}, r"world.resolution = 0.3"),
    ({"world": {"altitudes": (5.0, 12.0, 15.0)}}, r"world.altitudes"),
    ({"sensor": {"accuracy": (0.99, 0.4, 0.6)}}, r"sensor.accuracy"),
    ({"sensor": {"accuracy": (0.99, 0.7)}}, r"sensor.accuracy.*one value per altitude"),
    ({"reward": {"alpha": -1.0}}, r"reward.alpha = -1.0"),
    ({"team": {"n_agents": 12, "start": "random"}}, r"features.agent_id_scale = 8"),
])
def test_invalid_config_names_field_and_value(sections, match):
    with pytest.raises(ValueError, match=match):
        EnvConfig().replace(**sections)


def test_env_rejects_non_config():
    with pytest.raises(ValueError, match="config must be an EnvConfig"):
        IPPEnv({"team": {}})
