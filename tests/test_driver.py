"""The mission driver (ipp_toolkit.sim.driver), and COMA's observations against IPPEnv's.

COMA's rollouts fly their missions through the driver and build the actor planes with
``ipp_toolkit.sim.features.actor_observations``; the PettingZoo view (``IPPEnv``) steps the same
``MissionState`` one step at a time. Replaying a rollout's actions in the env must show every
agent, at every step, the very planes and masks the rollout recorded (and give the same
rewards). The one documented difference: the env's ``keep_failed`` view zeroes a failed UAV's
planes and opens its mask ("black death"), where COMA would record its raw planes (COMA
refuses to train with failures, ``coma.learner``).
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from helpers import random_valid_actions, small_config

from coma.config import COMAConfig
from coma.persistence import build_networks
from coma.rollout import Rollout, collect_rollout
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.env import IPPEnv
from ipp_toolkit.planning import make_planner
from ipp_toolkit.sim.driver import fly_missions, start_missions
from ipp_toolkit.sim.mission import MissionGeometry, reset_mission, step_mission

SEED, FIRST, MISSIONS = 5, 3, 2


def _env_configs() -> dict[str, EnvConfig]:
    return {
        "default-planes": small_config(n_agents=2, resolution=1.0, team={"budget": 4}),
        "own-position-gain-inf": small_config(
            n_agents=3, comm_range=float("inf"), resolution=1.0, team={"budget": 4},
            features={"own_position": True, "gain": True}),
    }


def _rollout(config: EnvConfig, mode: str) -> Rollout:
    torch.manual_seed(0)
    networks = build_networks(COMAConfig(width=8, hidden=16, warm_start=""), config)
    demonstrators = ([make_planner("ig") for _ in range(MISSIONS)] if mode == "demonstrated"
                     else None)
    return collect_rollout(networks, config, MissionGeometry(config), SEED, FIRST, MISSIONS,
                           0.5, demonstrators=demonstrators)


def _replay(config: EnvConfig, rollout: Rollout, e: int, keep_failed: bool = False):
    """Yield (step, env observations, env) while the env flies mission ``FIRST + e`` with the
    rollout's actions; then check the rewards and the final entropy."""
    env = IPPEnv(config, keep_failed=keep_failed)
    observations, _ = env.reset(seed=SEED, options={"mission": FIRST + e})
    steps = rollout.actions.shape[2]
    for t in range(steps):
        yield t, observations, env
        actions = {agent: int(rollout.actions[e, k, t]) for k, agent in
                   enumerate(env.possible_agents) if agent in env.agents}
        observations, rewards, terminations, _, infos = env.step(actions)
        # The team reward (agent 0 flies on in every test here; a failed UAV gets 0).
        assert np.float32(rewards[env.possible_agents[0]]) == rollout.rewards[e, t].item()
    assert all(terminations.values()) and not env.agents
    assert infos[env.possible_agents[0]]["entropy"] == rollout.final_entropy[e]


@pytest.mark.parametrize("mode", ["sampled", "demonstrated"])
@pytest.mark.parametrize("name", list(_env_configs()))
def test_coma_observations_equal_the_env_observations(name, mode):
    config = _env_configs()[name]
    rollout = _rollout(config, mode)
    e_count, n, steps = rollout.actions.shape
    assert (e_count, n, steps) == (MISSIONS, config.team.n_agents, config.team.budget)
    for e in range(MISSIONS):
        for t, observations, env in _replay(config, rollout, e):
            assert list(observations) == env.possible_agents  # nobody fails here
            for k, agent in enumerate(env.possible_agents):
                planes = observations[agent]["observation"]
                assert planes.dtype == np.float32 == rollout.actor_obs.numpy().dtype
                assert planes.shape == env.observation_space(agent)["observation"].shape
                # Same layout, same channel order, bit for bit.
                np.testing.assert_array_equal(planes, rollout.actor_obs[e, k, t].numpy())
                np.testing.assert_array_equal(observations[agent]["action_mask"].astype(bool),
                                              rollout.masks[e, k, t].numpy())


def test_failed_uavs_are_zeroed_by_the_env_and_only_there():
    config = small_config(n_agents=2, resolution=1.0, team={"budget": 4, "failures": [[1, 2]]})
    rollout = _rollout(config, "sampled")
    seen_failed = False
    for t, observations, env in _replay(config, rollout, 0, keep_failed=True):
        alive = env.mission.alive
        for k, agent in enumerate(env.possible_agents):
            planes, mask = observations[agent]["observation"], observations[agent]["action_mask"]
            if alive[k]:
                np.testing.assert_array_equal(planes, rollout.actor_obs[0, k, t].numpy())
                np.testing.assert_array_equal(mask.astype(bool), rollout.masks[0, k, t].numpy())
            else:  # the env's black death; the rollout holds the raw planes
                seen_failed = True
                assert not planes.any() and mask.all()
                assert rollout.actor_obs[0, k, t].abs().sum() > 0
    assert seen_failed


# ------------------------------------------------------------------------------ the driver


def test_driver_flies_as_a_hand_loop_does():
    config = small_config(n_agents=2, resolution=1.0, team={"budget": 5})
    rngs = [np.random.default_rng(m) for m in range(3)]
    seen = []

    def policy(states):
        assert [s.step for s in states] == [len(seen) - 1] * 3
        return [random_valid_actions(s.masks(), rng) for s, rng in zip(states, rngs, strict=True)]

    flight = fly_missions(start_missions(config, 7, 2, 3, "validation"), policy,
                          observer=lambda states: seen.append([s.step for s in states]))
    assert seen == [[t] * 3 for t in range(6)]
    assert flight.rewards.shape == (3, 5) and flight.rewards.dtype == np.float64
    for e in range(3):
        rng = np.random.default_rng(e)
        state = reset_mission(config, 7, 2 + e, "validation")
        rewards = [step_mission(state, random_valid_actions(state.masks(), rng))
                   for _ in range(5)]
        assert flight.rewards[e].tolist() == rewards
        assert flight.curve("entropy")[e].tolist() == [m.entropy for m in state.history]
        assert flight.curve("f1")[e].tolist() == [m.f1 for m in state.history]
        total = 0.0
        for r in rewards:
            total += r
        assert flight.returns()[e] == total
        np.testing.assert_array_equal(flight.states[e].positions, state.positions)


def test_driver_rejects_bad_flights():
    config = small_config(n_agents=2, resolution=1.0, team={"budget": 2})
    hold = np.array([[5, 5]])  # both descend: valid from the start
    with pytest.raises(ValueError, match="returned 2 joint actions for 1 missions"):
        fly_missions(start_missions(config, 0, 0, 1), lambda states: [[5, 5], [5, 5]])
    stepped = start_missions(config, 0, 0, 1)
    step_mission(stepped[0], [5, 5])
    with pytest.raises(ValueError, match="from step 0"):
        fly_missions(stepped, lambda states: hold)
    with pytest.raises(ValueError, match="at least one mission"):
        fly_missions([], lambda states: hold)
    longer = start_missions(config.replace(team={"budget": 3}), 0, 0, 1)
    with pytest.raises(ValueError, match=r"budgets \[2, 3\]"):
        fly_missions(start_missions(config, 0, 0, 1) + longer, lambda states: [[5, 5]] * 2)
    with pytest.raises(ValueError, match="metric must be"):
        fly_missions(start_missions(config, 0, 0, 1), lambda states: hold).curve("reward")
