"""The SB3 view of the simulator (ipp_toolkit.vec): seeds, masks, terminals, errors, exit."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from gymnasium import spaces
from helpers import small_config
from stable_baselines3.common.vec_env import VecMonitor

from ipp_toolkit.env import IPPEnv
from ipp_toolkit.vec import IPPVecEnv, make_sb3_vec_env

torch = pytest.importorskip("torch")
torch.set_num_threads(1)

ROOT = Path(__file__).resolve().parents[1]


def _random_actions(masks: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return (rng.random(masks.shape) * masks).argmax(axis=1)


def _rollout(vec: IPPVecEnv, steps: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    frames = [vec.reset()]
    for _ in range(steps):
        obs, _, _, _ = vec.step(_random_actions(vec.action_masks(), rng))
        frames.append(obs)
    return frames


def test_spaces_and_masks_match_the_env():
    config = small_config(n_agents=2)
    vec = make_sb3_vec_env(config, n_envs=3, seed=7)
    try:
        obs = vec.reset()
        assert vec.num_envs == 6
        assert isinstance(vec.observation_space, spaces.Box)
        assert vec.observation_space.shape == (7, 11, 11)
        assert obs.shape == (6, 7, 11, 11) and obs.dtype == np.float32
        masks = vec.action_masks()
        assert masks.shape == (6, 6) and masks.dtype == bool
        # Copy c is run seed + c of the plain env: same planes, same masks.
        for copy in range(3):
            env = IPPEnv(config)
            direct, _ = env.reset(seed=7 + copy)
            for k, agent in enumerate(env.possible_agents):
                np.testing.assert_array_equal(obs[2 * copy + k], direct[agent]["observation"])
                np.testing.assert_array_equal(masks[2 * copy + k],
                                              direct[agent]["action_mask"].astype(bool))
        # MaskablePPO reaches the masks through VecMonitor's has_attr/env_method.
        monitor = VecMonitor(vec)
        assert monitor.has_attr("action_masks")
        np.testing.assert_array_equal(np.stack(monitor.env_method("action_masks")), masks)
        assert monitor.get_attr("render_mode") == [None] * 6
    finally:
        vec.close()


def test_copies_differ_and_the_same_seed_reproduces():
    config = small_config(n_agents=2)
    runs = []
    for seed in (3, 3, 4):
        vec = make_sb3_vec_env(config, n_envs=2, seed=seed)
        try:
            runs.append(_rollout(vec, 20))  # crosses one auto-reset (budget 15)
        finally:
            vec.close()
    for a, b in zip(runs[0], runs[1], strict=True):
        np.testing.assert_array_equal(a, b)
    first = runs[0][0]
    assert not np.array_equal(first[0:2], first[2:4]), "copies replay the same mission"
    assert not all(np.array_equal(a, b) for a, b in zip(runs[0], runs[2], strict=True))


# The vec env of test_worker_processes_give_the_same_missions_as_one_process, on 2 worker
# processes, in a fresh interpreter that saves its frames to sys.argv[1] and exits with the
# env open: its workers must not hold the interpreter.
_WORKER_ROLLOUT = f"""
import sys
sys.path[:0] = [{str(ROOT)!r}, {str(ROOT / "tests")!r}]
import numpy as np
from helpers import small_config
from test_vec import _rollout
from ipp_toolkit.vec import make_sb3_vec_env
vec = make_sb3_vec_env(small_config(n_agents=2), n_envs=4, seed=11, num_cpus=2)
np.save(sys.argv[1], np.stack(_rollout(vec, 3)))
"""


def test_worker_processes_give_the_same_missions_as_one_process(tmp_path):
    # SuperSuit alone gives overlapping seeds with several workers; the adapter must not.
    # The workers are forked from a fresh interpreter: forked from a test process grown by
    # a whole run, they took 10 to 20 s to start and stop.
    saved = tmp_path / "frames.npy"
    result = subprocess.run([sys.executable, "-c", _WORKER_ROLLOUT, str(saved)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr  # and within the timeout: no hang at exit
    vec = make_sb3_vec_env(small_config(n_agents=2), n_envs=4, seed=11)
    try:
        frames = _rollout(vec, 3)
    finally:
        vec.close()
    workers = np.load(saved)
    assert workers.shape == (len(frames), *frames[0].shape)
    for a, b in zip(frames, workers, strict=True):
        np.testing.assert_array_equal(a, b)
    copies = [workers[0][2 * c: 2 * c + 2] for c in range(4)]
    assert all(not np.array_equal(copies[i], copies[j])
               for i in range(4) for j in range(i + 1, 4))


def test_budget_end_is_terminated_not_truncated():
    config = small_config(n_agents=2)
    budget = config.team.budget
    vec = make_sb3_vec_env(config, n_envs=2, seed=0)
    try:
        vec.reset()
        rng = np.random.default_rng(0)
        for step in range(1, budget + 1):
            obs, rewards, dones, infos = vec.step(_random_actions(vec.action_masks(), rng))
            assert rewards.shape == (4,) and rewards.dtype == np.float32
            if step < budget:
                assert not dones.any()
        assert dones.all()
        for info in infos:
            assert info["TimeLimit.truncated"] is False
            terminal = info["terminal_observation"]
            assert isinstance(terminal, np.ndarray) and terminal.shape == (7, 11, 11)
            assert "action_mask" not in info or info["action_mask"].shape == (6,)
        # The auto-reset observation starts a fresh mission with the full budget.
        assert not np.array_equal(obs[0], infos[0]["terminal_observation"])
    finally:
        vec.close()


def test_ppo_seed_reaches_the_vec_env():
    from sb3_contrib import MaskablePPO

    vec = make_sb3_vec_env(small_config(n_agents=2), n_envs=2, seed=0)
    try:
        MaskablePPO("MlpPolicy", VecMonitor(vec), n_steps=8, batch_size=16, seed=5)
        assert vec._seeds == [5, 5, 6, 6]
    finally:
        vec.close()


@pytest.mark.parametrize("n_envs", [0, -1, 1.5, True, "2"])
def test_bad_n_envs(n_envs):
    with pytest.raises(ValueError, match=f"n_envs must be an integer >= 1, got {n_envs!r}"):
        make_sb3_vec_env(small_config(), n_envs=n_envs, seed=0)


def test_bad_arguments():
    with pytest.raises(ValueError, match="seed must be an integer >= 0, got -1"):
        make_sb3_vec_env(small_config(), 1, seed=-1)
    with pytest.raises(ValueError, match="num_cpus must be an integer >= 0, got -2"):
        make_sb3_vec_env(small_config(), 1, seed=0, num_cpus=-2)
    with pytest.raises(ValueError, match=r"one team size.*n_agents \[2, 4\]"):
        make_sb3_vec_env([small_config(2), small_config(4)], 2, seed=0)
    with pytest.raises(ValueError, match="config must be an EnvConfig, a dict .* got int"):
        make_sb3_vec_env(3, 1, seed=0)


def test_adapter_refuses_mixed_team_sizes():
    import supersuit as ss

    venv = ss.concat_vec_envs_v1(ss.pettingzoo_env_to_vec_env_v1(IPPEnv(small_config(2))), 3)
    with pytest.raises(ValueError, match="holds 6 agent slots, not 2 copies x 4 agents"):
        IPPVecEnv(venv, n_agents=4, n_copies=2)


@pytest.mark.slow  # a clean exit with the workers running is tested fast above
def test_no_hang_at_exit_with_worker_processes_after_an_error():
    script = textwrap.dedent(f"""
        import sys
        sys.path[:0] = [{str(ROOT)!r}, {str(ROOT / "tests")!r}]
        from helpers import small_config
        from ipp_toolkit.vec import make_sb3_vec_env
        vec = make_sb3_vec_env(small_config(n_agents=2), n_envs=2, seed=0, num_cpus=2)
        vec.reset()
        raise RuntimeError("boom")
    """)
    result = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 1, result.stderr


def test_maskable_ppo_never_takes_a_masked_action():
    from sb3_contrib import MaskablePPO

    vec = make_sb3_vec_env(small_config(n_agents=4), n_envs=2, seed=1, invalid_action="raise")
    taken = {"steps": 0, "invalid": 0}
    step_async = vec.step_async

    def checked(actions):
        actions = np.asarray(actions)
        taken["steps"] += actions.size
        taken["invalid"] += int((~vec.action_masks()[np.arange(actions.size), actions]).sum())
        step_async(actions)

    vec.step_async = checked
    try:
        model = MaskablePPO("MlpPolicy", VecMonitor(vec), n_steps=128, batch_size=256,
                            n_epochs=1, seed=0)
        model.learn(3072)  # with invalid_action='raise' a masked action would also raise
    finally:
        vec.close()
    assert taken["steps"] >= 3072 and taken["invalid"] == 0


@pytest.mark.parametrize("algo", ["A2C", "DQN"])
def test_algorithms_that_cannot_mask_train_on_the_default_view(algo):
    import stable_baselines3

    vec = make_sb3_vec_env(small_config(n_agents=2), n_envs=1, seed=0)
    try:
        kwargs = {"learning_starts": 0, "buffer_size": 500} if algo == "DQN" else {"n_steps": 8}
        model = getattr(stable_baselines3, algo)("MlpPolicy", VecMonitor(vec), seed=0, **kwargs)
        model.learn(200)  # the untrained policy samples masked actions: they are held
    finally:
        vec.close()


def test_invalid_actions_are_held_counted_and_penalised():
    from ipp_toolkit.sim.mission import InvalidActionError

    config = small_config(n_agents=2)
    vec = make_sb3_vec_env(config, n_envs=1, seed=0, invalid_penalty=0.5)
    plain = make_sb3_vec_env(config, n_envs=1, seed=0)
    strict = make_sb3_vec_env(config, n_envs=1, seed=0, invalid_action="raise")
    try:
        vec.reset(), plain.reset(), strict.reset()
        masks = vec.action_masks()
        assert not masks.all(), "a start position with a masked action is needed"
        actions = np.array([int(np.flatnonzero(~m)[0]) if not m.all() else 0 for m in masks])
        invalid = ~masks[np.arange(len(actions)), actions]
        _, rewards, _, infos = vec.step(actions)
        _, plain_rewards, _, _ = plain.step(actions)
        assert [info["invalid_action"] for info in infos] == invalid.tolist()
        np.testing.assert_allclose(rewards, plain_rewards - 0.5 * invalid, atol=1e-6)
        with pytest.raises(InvalidActionError, match="masked"):
            strict.step(actions)
        with pytest.raises(ValueError, match="invalid_action"):
            make_sb3_vec_env(config, n_envs=1, seed=0, invalid_action="skip")
    finally:
        vec.close(), plain.close(), strict.close()
