"""IPPEnv through TorchRL's PettingZooWrapper (the engine under BenchMARL).

Needs the optional extra ``torchrl`` (``pip install -c constraints.txt -e ".[torchrl]"``);
skipped without it.
"""

import warnings

import pytest
import torch

from ipp_toolkit import EnvConfig, IPPEnv

pytest.importorskip("torchrl", reason="torchrl is not installed (optional extra 'torchrl')")

from torchrl.envs.libs.pettingzoo import PettingZooWrapper  # noqa: E402
from torchrl.envs.utils import check_env_specs  # noqa: E402

INFO_KEYS = {"step", "blocked", "invalid_action", "entropy", "f1", "rmse"}


def _wrapped(seed: int = 0) -> PettingZooWrapper:
    config = EnvConfig().replace(world={"resolution": 1.0}, team={"n_agents": 2})
    with warnings.catch_warnings():
        # TorchRL warns that it was tested on another PettingZoo version.
        warnings.filterwarnings("ignore", message="PettingZoo in TorchRL", category=UserWarning)
        return PettingZooWrapper(env=IPPEnv(config), return_state=True,
                                 categorical_actions=True, seed=seed)


def test_pettingzoo_wrapper_specs_and_masked_rollout():
    env = _wrapped()
    assert env.group_map == {"uav": ["uav_0", "uav_1"]}
    check_env_specs(env)

    budget = env._env.config.team.budget
    torch.manual_seed(0)
    # rand_action samples from the action spec, which the wrapper masks at every step.
    rollout = env.rollout(budget + 5)
    n = budget  # the rollout stops at the budget end: every agent is terminated together
    group = rollout["uav"]
    assert rollout.batch_size == (n,)
    assert group["observation", "observation"].shape == (n, 2, 7, 11, 11)
    assert group["action"].shape == (n, 2) and group["action"].dtype == torch.int64
    assert group["action_mask"].shape == (n, 2, 6) and group["action_mask"].dtype == torch.bool
    assert rollout["state"].shape == (n, 5, 11, 11)
    assert set(group["info"].keys()) == INFO_KEYS
    assert rollout["next", "uav", "reward"].shape == (n, 2, 1)

    # No masked action was taken (the masked action spec never draws one).
    taken = group["action_mask"].gather(-1, group["action"].unsqueeze(-1))
    assert taken.all()
    # Masks are real: the top or bottom altitude forbids a move at some step.
    assert not group["action_mask"].all()

    steps = rollout["next", "uav", "info", "step"]
    assert steps[:, 0].tolist() == list(range(1, n + 1))
    done = rollout["next", "done"].squeeze(-1)
    assert done[-1] and not done[:-1].any()
    assert rollout["next", "uav", "terminated"][-1].all()
    assert not rollout["next", "uav", "truncated"].any()
    entropy = rollout["next", "uav", "info", "entropy"][:, 0]
    assert entropy[-1] < group["info", "entropy"][0, 0]
    env.close()


def test_make_torchrl_env_keeps_masks_under_transforms_batching_and_failures():
    from torchrl.envs import FlattenObservation, RewardSum, StepCounter

    from ipp_toolkit.torchrl_env import make_torchrl_env

    config = EnvConfig().replace(world={"resolution": 1.0},
                                 team={"n_agents": 2, "failures": [[1, 5]]})
    obs_key = ("uav", "observation", "observation")
    # invalid_action="raise": any masked action drawn by rand_action would stop the rollout.
    env = make_torchrl_env(config, num_envs=2, seed=3, invalid_action="raise",
                           transforms=[FlattenObservation(-3, -1, in_keys=[obs_key]),
                                       StepCounter(),
                                       RewardSum(in_keys=[("uav", "reward")],
                                                 out_keys=[("uav", "episode_reward")])])
    try:
        check_env_specs(env)
        torch.manual_seed(0)
        budget = config.team.budget
        rollout = env.rollout(2 * budget + 3, break_when_any_done=False)
    finally:
        env.close()
    assert rollout.batch_size == (2, 2 * budget + 3)
    assert rollout[obs_key].shape[-2:] == (2, 7 * 11 * 11)
    taken = rollout["uav", "action_mask"].gather(-1, rollout["uav", "action"].unsqueeze(-1))
    assert taken.all() and not rollout["uav", "action_mask"].all()
    # UAV 1 fails at step 5 but keeps its slot: the episode ends only at the budget.
    done = rollout["next", "done"].squeeze(-1)
    assert done[:, budget - 1].all() and done[:, 2 * budget - 1].all() and done.sum() == 4
    rewards = rollout["next", "uav", "reward"][..., 0]
    assert (rewards[:, 5:budget, 1] == 0).all() and (rewards[:, :budget, 0] != 0).any()
    # The copies fly different missions.
    entropy = rollout["uav", "info", "entropy"][:, 1, 0]
    assert entropy[0] != entropy[1]


def test_make_torchrl_env_refuses_bad_arguments():
    from ipp_toolkit.torchrl_env import make_torchrl_env

    with pytest.raises(ValueError, match="num_envs"):
        make_torchrl_env(num_envs=0)
