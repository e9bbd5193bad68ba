import dataclasses
import math
import warnings

import numpy as np
import pytest
from helpers import small_config
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test
from pettingzoo.utils.conversions import parallel_to_aec

from ipp_toolkit.config.schema import ACTOR_PLANES, FeatureConfig
from ipp_toolkit.env import IPPEnv
from ipp_toolkit.sim.features import (
    GAIN_PLANES,
    actor_plane_names,
    critic_plane_names,
    state_plane_names,
)
from ipp_toolkit.sim.mission import InvalidActionError
from ipp_toolkit.vec import make_sb3_vec_env

TEAMS = [2, 4, 8]
RANGES = [0.0, 25.0, math.inf]


@pytest.mark.parametrize("n_agents", TEAMS)
@pytest.mark.parametrize("comm_range", RANGES)
def test_pettingzoo_conformance(n_agents, comm_range):
    config = small_config(n_agents=n_agents, comm_range=comm_range)
    with warnings.catch_warnings():
        # api_test warns that Dict observations are not Box; that is by design (masks).
        warnings.simplefilter("ignore", UserWarning)
        parallel_api_test(IPPEnv(config), num_cycles=100)
        api_test(parallel_to_aec(IPPEnv(config)), num_cycles=100)
    # The seed test samples actions without masks: a masked one holds (the default).
    parallel_seed_test(lambda: IPPEnv(config), num_cycles=100)


def test_spaces_and_observation_contents():
    env = IPPEnv(small_config())
    obs, infos = env.reset(seed=0)
    space = env.observation_space("uav_0")
    assert space is env.observation_space("uav_0")
    assert space["observation"].shape == (7, 11, 11)
    for agent in env.agents:
        assert space.contains(obs[agent])
        assert obs[agent]["action_mask"].dtype == np.int8
        assert (obs[agent]["action_mask"] == env.action_mask(agent)).all()
    planes = obs["uav_0"]["observation"]
    names = actor_plane_names(env.config.features)
    assert planes[names.index("budget")].max() == 1.0
    assert planes[names.index("agent_id")][0, 0] == pytest.approx(1 / 8)
    assert obs["uav_3"]["observation"][names.index("agent_id")][0, 0] == pytest.approx(4 / 8)
    position = planes[names.index("position")]
    assert position[5, 5] == pytest.approx(1.0)  # itself at the centre, top level
    assert position[0, 0] == -1 and position[5, 7] == 0  # (0, 0) m lies outside the window
    assert env.state().shape == env.state_space.shape == (5, 11, 11)
    assert env.state_space.contains(env.state())


def test_position_window_shows_heard_teammates():
    config = small_config(n_agents=2, comm_range=math.inf)
    env = IPPEnv(config)
    obs, _ = env.reset(seed=0)  # (10, 10) and (40, 40): 6 cells apart, outside the window
    names = actor_plane_names(config.features)
    position = obs["uav_0"]["observation"][names.index("position")]
    assert np.count_nonzero(position > 0) == 1
    env.mission.positions[1, :2] = [4, 3]  # (20, 15): 2 east, 1 north of uav_0
    env.mission.heard[:] = True
    obs = env._observe()
    position = obs["uav_0"]["observation"][names.index("position")]
    assert position[6, 7] == pytest.approx(1.0)
    env.mission.heard[0, 1] = False
    obs = env._observe()
    assert obs["uav_0"]["observation"][names.index("position")][6, 7] == 0


def test_budget_end_is_terminal_not_truncation():
    env = IPPEnv(small_config())
    obs, _ = env.reset(seed=1)
    rng = np.random.default_rng(0)
    for step in range(15):
        actions = {a: int(rng.choice(np.flatnonzero(obs[a]["action_mask"]))) for a in env.agents}
        obs, rewards, terminations, truncations, infos = env.step(actions)
        assert len(set(rewards.values())) == 1  # one team reward
        assert not any(truncations.values())
        assert all(terminations.values()) == (step == 14)
    assert env.agents == []
    names = actor_plane_names(env.config.features)
    assert obs["uav_0"]["observation"][names.index("budget")].max() == 0.0
    assert infos["uav_0"]["entropy"] < 1.0


INFO_KEYS = {"step": int, "blocked": bool, "invalid_action": bool, "entropy": float, "f1": float,
             "rmse": float}


def test_infos_are_flat_scalars_with_the_same_keys_at_reset_and_step():
    # TorchRL's PettingZooWrapper (BenchMARL) builds tensors from the infos: no nested dicts,
    # no key that appears only later, and the mask only in the observation.
    env = IPPEnv(small_config(n_agents=2))
    obs, infos = env.reset(seed=3)
    rng = np.random.default_rng(0)
    steps = 0
    while True:
        assert set(infos) == set(env.possible_agents)
        for agent, info in infos.items():
            assert {key: type(value) for key, value in info.items()} == INFO_KEYS
            assert info["step"] == steps
            assert info["blocked"] == bool(env.mission.blocked[env.possible_agents.index(agent)])
        metrics = env.mission.history[-1].as_dict()
        assert {key: infos["uav_1"][key] for key in metrics} == pytest.approx(metrics)
        if not env.agents:
            break
        actions = {a: int(rng.choice(np.flatnonzero(obs[a]["action_mask"]))) for a in env.agents}
        obs, _, _, _, infos = env.step(actions)
        steps += 1
    assert steps == env.config.team.budget


def test_masked_actions_hold_by_default_and_raise_when_strict():
    config = small_config()
    env = IPPEnv(config)
    obs, infos = env.reset(seed=0)
    assert not any(info["invalid_action"] for info in infos.values())
    held = 0
    env.action_space("uav_0").seed(0)
    while env.agents:  # action_space.sample() ignores the masks, as many tools do
        positions = env.mission.positions.copy()
        masks = {agent: obs[agent]["action_mask"] for agent in env.agents}
        actions = {agent: env.action_space(agent).sample() for agent in env.agents}
        obs, _, _, _, infos = env.step(actions)
        for k, agent in enumerate(env.possible_agents):
            invalid = not masks[agent][actions[agent]]
            assert infos[agent]["invalid_action"] == invalid
            if invalid:
                held += 1
                assert (env.mission.positions[k] == positions[k]).all()
            assert obs[agent]["action_mask"].dtype == np.int8  # masks stay observed
    assert held > 0
    assert env.config == config  # the caller's config (COMA reads its invalid_action) is kept
    strict = IPPEnv(config, invalid_action="raise")
    strict.reset(seed=0)
    with pytest.raises(InvalidActionError, match=r"uav_1.*action 0 \(up\) is masked"):
        strict.step({"uav_0": 1, "uav_1": 0, "uav_2": 1, "uav_3": 1})
    with pytest.raises(ValueError, match="invalid_action must be one of .* got 'skip'"):
        IPPEnv(config, invalid_action="skip")


def test_step_errors_name_agent_and_action():
    env = IPPEnv(small_config(), invalid_action="raise")
    env.reset(seed=0)
    with pytest.raises(InvalidActionError, match=r"uav_1.*action 0 \(up\) is masked"):
        env.step({"uav_0": 1, "uav_1": 0, "uav_2": 1, "uav_3": 1})
    with pytest.raises(InvalidActionError, match="uav_3.*action 7 is out of range"):
        env.step({"uav_0": 1, "uav_1": 1, "uav_2": 1, "uav_3": 7})
    with pytest.raises(InvalidActionError, match=r"no action for agent\(s\) \['uav_3'\]"):
        env.step({"uav_0": 1, "uav_1": 1, "uav_2": 1})
    with pytest.raises(InvalidActionError, match="uav_9"):
        env.step({"uav_0": 1, "uav_1": 1, "uav_2": 1, "uav_3": 1, "uav_9": 1})
    with pytest.raises(InvalidActionError, match="must be an integer"):
        env.step({"uav_0": 1.5, "uav_1": 1, "uav_2": 1, "uav_3": 1})
    with pytest.raises(ValueError, match="unknown agent 'uav_7'"):
        env.action_space("uav_7")


def test_reset_seeding_and_mission_option():
    env = IPPEnv(small_config())
    env.reset(seed=5)
    first = env.mission.ground_truth.copy()
    env.reset()
    second = env.mission.ground_truth.copy()
    assert not (first == second).all()
    env.reset(options={"mission": 0})
    assert (env.mission.ground_truth == first).all()
    other = IPPEnv(small_config())
    other.reset(seed=5)
    other.reset()
    assert (other.mission.ground_truth == second).all()
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        env.reset(seed=-1)


def test_unseeded_copies_differ():
    a, b = IPPEnv(small_config()), IPPEnv(small_config())
    a.reset()
    b.reset()
    assert not (a.mission.ground_truth == b.mission.ground_truth).all()


def test_critic_observations_and_action_planes():
    config = small_config()
    env = IPPEnv(config)
    env.reset(seed=0)
    joint = {"uav_0": 1, "uav_1": 2, "uav_2": 3, "uav_3": 2}
    critic = env.critic_observations(joint)
    names = critic_plane_names(config.features)
    assert critic.shape == (4, len(names), 11, 11)
    east = names.index("other_actions_2")
    # uav_0 sees uav_1 (at (40, 10)) and uav_3 (at (10, 40)) choosing east, not itself.
    assert critic[0, east, 2, 8] == 1 and critic[0, east, 8, 2] == 1
    assert critic[0, east].sum() == 2
    assert critic[1, east, 2, 8] == 0 and critic[1, east].sum() == 1
    assert critic[0, names.index("other_actions_1")].sum() == 0  # only uav_0 chose north
    assert state_plane_names(config.features)[0] == "budget"


def test_feature_switches_change_channels():
    features = {"local_entropy": False, "measurement_entropy": False, "global_map": False,
                "other_actions": False, "centred": False}
    config = small_config().replace(features=features)
    env = IPPEnv(config)
    obs, _ = env.reset(seed=0)
    assert obs["uav_0"]["observation"].shape == (5, 11, 11)
    names = actor_plane_names(config.features)
    position = obs["uav_0"]["observation"][names.index("position")]
    assert position[2, 2] == pytest.approx(1.0) and position.min() == 0  # absolute grid
    assert env.critic_observations(np.zeros(4, int)).shape == (4, 5 + 3, 11, 11)


#: Every boolean switch of FeatureConfig that adds planes (``centred`` changes the frame of
#: the position plane, not which planes there are). A new switch is checked here by itself.
PLANE_SWITCHES = [f.name for f in dataclasses.fields(FeatureConfig)
                  if f.type in (bool, "bool") and f.name != "centred"]


@pytest.mark.parametrize("switch", PLANE_SWITCHES)
def test_each_plane_switch_adds_the_planes_its_names_say_and_leaves_the_others(switch):
    """Turning one switch on (every actor plane on besides) adds exactly the planes
    ``actor_plane_names`` lists for it, at the place it lists them, leaves every other
    channel's content where its name says, and every view's space follows."""
    on_features = {name: True for name in ACTOR_PLANES} | {switch: True}
    on = small_config().replace(features=on_features)
    off = on.replace(features={switch: False})
    added = list(GAIN_PLANES) if switch == "gain" else [switch]
    on_names, off_names = actor_plane_names(on.features), actor_plane_names(off.features)
    if switch in ACTOR_PLANES:
        assert [n for n in on_names if n not in added] == off_names
        assert sorted(set(on_names) - set(off_names)) == sorted(added)
    else:  # a critic-only plane: the actor sees the same
        assert on_names == off_names
        assert len(critic_plane_names(on.features)) > len(critic_plane_names(off.features))
    observations = {}
    for config, names in ((on, on_names), (off, off_names)):
        env = IPPEnv(config)
        obs, _ = env.reset(seed=0)
        g = config.world.grid_points
        assert obs["uav_0"]["observation"].shape == (len(names), g, g)
        assert env.observation_space("uav_0").contains(obs["uav_0"])
        assert env.state().shape == env.state_space.shape
        assert env.state_space.shape[0] == len(state_plane_names(config.features))
        critic = env.critic_observations(np.zeros(len(env.agents), int))
        assert critic.shape[1] == len(critic_plane_names(config.features))
        observations[names is on_names] = {n: obs["uav_1"]["observation"][k]
                                           for k, n in enumerate(names)}
    for name in off_names:  # the builder appends in ACTOR_PLANES order, as the names say
        np.testing.assert_array_equal(observations[True][name], observations[False][name],
                                      err_msg=name)
    venv = make_sb3_vec_env(on)
    try:
        assert venv.observation_space.shape == (len(on_names), on.world.grid_points,
                                                on.world.grid_points)
    finally:
        venv.close()


def test_gain_planes_pass_the_api_test():
    config = small_config(comm_range=math.inf).replace(features={"gain": True})
    env = IPPEnv(config)
    obs, _ = env.reset(seed=0)
    assert obs["uav_0"]["observation"].shape == (len(actor_plane_names(config.features)),
                                                 11, 11)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        parallel_api_test(IPPEnv(config), num_cycles=20)


def test_own_position_plane_marks_only_the_agent_in_the_absolute_frame():
    config = small_config().replace(features={"own_position": True})
    env = IPPEnv(config)
    obs, _ = env.reset(seed=0)
    names = actor_plane_names(config.features)
    assert names.index("own_position") == names.index("position") + 1
    assert obs["uav_1"]["observation"].shape == (8, 11, 11)
    for k, agent in enumerate(env.agents):
        plane = obs[agent]["observation"][names.index("own_position")]
        x, y, _ = env.mission.positions[k]
        assert plane[y, x] == pytest.approx(1.0)  # 15 m: the top altitude code
        assert np.count_nonzero(plane) == 1
    assert "own_position" not in actor_plane_names(small_config().features)  # off by default


def test_render_rgb_array():
    env = IPPEnv(small_config(), render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert IPPEnv(small_config()).render() is None
    with pytest.raises(ValueError, match="render_mode 'ansi'"):
        IPPEnv(small_config(), render_mode="ansi")
