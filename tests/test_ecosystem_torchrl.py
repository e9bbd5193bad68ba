"""TorchRL collectors with ``policy=None`` or a random policy follow the masks, over one copy,
serial copies and worker processes (``parallel=True``); the MAPPO example's policy flies as the
``torchrl`` planner."""

from __future__ import annotations

import warnings

import pytest
import torch

pytest.importorskip("torchrl", reason="torchrl is not installed (optional extra 'torchrl')")

from torchrl.collectors import Collector  # noqa: E402
from torchrl.envs import FlattenObservation  # noqa: E402
from torchrl.envs.utils import RandomPolicy  # noqa: E402

from ipp_toolkit.torchrl_env import GROUP, make_torchrl_env  # noqa: E402

SMALL = {"world": {"resolution": 1.0}, "team": {"n_agents": 2}}


@pytest.mark.parametrize("num_envs", [1, 2])
def test_a_collector_without_a_policy_draws_only_valid_actions(num_envs):
    torch.manual_seed(0)
    # FlattenObservation added after the mask: the action spec still follows the masks.
    flatten = FlattenObservation(-3, -1, in_keys=[(GROUP, "observation", "observation")])
    env = make_torchrl_env(SMALL, num_envs=num_envs, seed=0, invalid_action="raise",
                           transforms=[flatten])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # TorchRL's notes on its own defaults
        collector = Collector(env, policy=None, frames_per_batch=30 * num_envs,
                              total_frames=120 * num_envs)
    try:
        drawn = 0
        for batch in collector:
            actions = batch[GROUP, "action"].unsqueeze(-1)
            assert batch[GROUP, "action_mask"].gather(-1, actions).all()
            drawn += actions.numel()
        assert drawn == 2 * 120 * num_envs
    finally:
        collector.shutdown()  # closes the env too


@pytest.mark.slow  # about 50 s: two worker processes start and import the toolkit
def test_collectors_over_worker_processes_draw_only_valid_actions():
    # TorchRL's ParallelEnv crashed on a collector's first reset (a partial tensordict under
    # the nested ("uav", "observation", "observation") key), with or without a policy.
    torch.manual_seed(0)
    env = make_torchrl_env(SMALL, num_envs=2, seed=0, parallel=True, invalid_action="raise")
    try:
        for policy in (None, RandomPolicy(env.full_action_spec)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # TorchRL's notes on its own defaults
                collector = Collector(env, policy=policy, frames_per_batch=60,
                                      total_frames=120)
            drawn = 0
            for batch in collector:
                actions = batch[GROUP, "action"].unsqueeze(-1)
                masks = batch[GROUP, "action_mask"]
                assert not masks.all()  # some actions were masked: the check below has teeth
                assert masks.gather(-1, actions).all()
                drawn += actions.numel()
            # 120 frames of 2 UAVs, past the resets of the 15-step missions.
            assert drawn == 2 * 120
            collector.shutdown(close_env=False)
    finally:
        env.close(raise_if_closed=False)  # the last collector may have closed it


def test_the_mappo_actor_is_saved_and_flies_as_the_torchrl_planner(tmp_path):
    from torch import nn
    from torchrl.modules import MultiAgentMLP

    from baselines.torchrl.planner import TorchRLPlanner
    from baselines.torchrl.policy import save_torchrl_policy
    from ipp_toolkit import EnvConfig
    from ipp_toolkit.io import CheckpointError
    from ipp_toolkit.runs.evaluation import evaluate

    config = EnvConfig().replace(**SMALL)
    torch.manual_seed(0)
    actor = MultiAgentMLP(7 * 11 * 11, 6, 2, centralized=False, share_params=True, depth=2,
                          num_cells=16, activation_class=nn.Tanh)
    path = save_torchrl_policy(tmp_path / "policy.pt", actor, config, iterations=0)
    planner = TorchRLPlanner(path)
    planes = torch.rand(2, 7, 11, 11)
    expected = actor(planes.flatten(1)).detach().numpy()
    got = planner.scores(planes.numpy(), torch.ones(2, 6, dtype=torch.bool).numpy())
    assert abs(expected - got).max() < 1e-5
    result = evaluate(config, f"ig,mine:torchrl={path}", missions=2, seed=0, progress=False)
    assert {row["planner"] for row in result.rows} == {"ig", "mine"}
    with pytest.raises(ValueError, match="centralized"):
        save_torchrl_policy(tmp_path / "c.pt", MultiAgentMLP(
            7 * 11 * 11, 6, 2, centralized=True, share_params=True, depth=1, num_cells=8),
            config)
    with pytest.raises(CheckpointError, match="another planning grid"):
        planner.reset(config.replace(world={"grid_spacing": 10.0}), 0)
    with pytest.raises(CheckpointError, match="torchrl planner needs a policy file"):
        TorchRLPlanner()
