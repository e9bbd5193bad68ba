"""TorchRL collectors with ``policy=None`` follow the masks; the MAPPO example's policy flies
as the ``torchrl`` planner."""

from __future__ import annotations

import warnings

import pytest
import torch

pytest.importorskip("torchrl", reason="torchrl is not installed (optional extra 'torchrl')")

from torchrl.collectors import Collector  # noqa: E402
from torchrl.envs import FlattenObservation  # noqa: E402

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
