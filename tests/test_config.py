import math

import pytest

from ipp_toolkit.config.files import config_to_dict, load_config, save_config
from ipp_toolkit.config.schema import EnvConfig
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
    ({"world": {"altitudes": (5.0, 15.0, 10.0)}}, r"world.altitudes.*increasing"),
    ({"sensor": {"accuracy": (0.99, 0.4, 0.6)}}, r"sensor.accuracy"),
    ({"sensor": {"accuracy": (0.99, 0.7)}}, r"sensor.accuracy.*one value per altitude"),
    ({"reward": {"alpha": -1.0}}, r"reward.alpha = -1.0"),
    ({"team": {"n_agents": 12, "start": "random"}}, r"features.agent_id_scale = 8"),
])
def test_invalid_config_names_field_and_value(sections, match):
    with pytest.raises(ValueError, match=match):
        EnvConfig().replace(**sections)


def test_env_rejects_non_config():
    with pytest.raises(ValueError, match="config must be an EnvConfig, a dict .* got list"):
        IPPEnv([{"team": {}}])
    with pytest.raises(ValueError, match=r"unknown key\(s\) \['agents'\] in section 'team'"):
        IPPEnv({"team": {"agents": 2}})


def test_a_grid_too_fine_for_indices_has_no_fixed_starts_and_no_cast_warning():
    import warnings

    from ipp_toolkit.config.schema import WorldConfig, fixed_start_waypoints

    world = WorldConfig(grid_spacing=1e-300)  # refused later, by the missions' memory check
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert fixed_start_waypoints(world, 4) is None
    assert fixed_start_waypoints(WorldConfig(grid_spacing=1e-6), 4) is not None


def test_altitudes_are_independent_of_the_waypoint_spacing_and_fixed_starts_snap():
    from ipp_toolkit.config.schema import fixed_start_waypoints

    # The paper's real-world field: 40 m at r_M = 8 cm, waypoints every 4 m, levels 5/10/15 m.
    field = EnvConfig().replace(world={"area_size": 40.0, "resolution": 0.08,
                                       "grid_spacing": 4.0})
    assert field.world.grid_points == 11 and field.world.map_cells == 500
    assert field.world.altitudes == (5.0, 10.0, 15.0)
    # (10, 10) m lies halfway between waypoints 8 and 12 m: halves round up; 40 m is one.
    metres = fixed_start_waypoints(field.world, 4) * 4.0
    assert metres.tolist() == [[12, 12], [40, 12], [40, 40], [12, 40]]
    # Where the starts are waypoints (the paper's worlds) they do not move.
    paper = fixed_start_waypoints(EnvConfig().world, 8) * 5.0
    assert paper.tolist() == [[10, 10], [40, 10], [40, 40], [10, 40], [25, 10], [40, 25],
                              [25, 40], [10, 25]]
    # Starts that would share a waypoint are refused, never silently made random.
    with pytest.raises(ValueError, match="team.start = 'fixed'.*distinct waypoints"):
        EnvConfig().replace(world={"area_size": 10.0, "resolution": 0.5, "grid_spacing": 10.0})


def test_the_yaml_functions_still_import_from_config_and_unknown_names_fail():
    import ipp_toolkit.config as config
    import ipp_toolkit.config.files as config_io
    from ipp_toolkit.config import (
        load_config as old_path,  # scripts written before the split
    )

    assert old_path is config_io.load_config
    assert config.config_to_dict is config_io.config_to_dict
    with pytest.raises(AttributeError, match="no attribute 'load_konfig'"):
        config.load_konfig  # noqa: B018
