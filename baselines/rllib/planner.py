"""The ``rllib`` planner: flies the shared policy an ``ipp-train rllib`` run exported.

``ipp-compare --planners ig,rllib=RUN`` (or ``rllib=RUN/policy.pt``) loads ``RUN/policy.pt``
(:mod:`baselines.rllib.policy`, plain weights read with ``torch.load(weights_only=True)``)
and flies it greedily for every UAV. Inference only: this module needs torch, never Ray, and
never imports the training code (:mod:`baselines.rllib.training`, :mod:`baselines.rllib.module`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import CheckpointError
from ipp_toolkit.planning import (
    AgentView,
    Planner,
    check_policy_transfer,
    choose_for_views,
    policy_inputs,
)
from ipp_toolkit.sim.features import actor_plane_names

from .policy import load_rllib_policy, policy_file_of

__all__ = ["RLlibPlanner"]


class RLlibPlanner(Planner):
    """Greedy shared RLlib policy for every agent (one batched forward per step).

    Acts deterministically: the argmax of the masked logits, so a masked action is never
    chosen.

    Args:
        checkpoint: an ``ipp-train rllib`` run folder (``RUN``) or its ``RUN/policy.pt``.
        device: torch device of the forward pass.

    Raises:
        CheckpointError: no checkpoint, or a missing, corrupt or foreign policy file.
    """

    name = "rllib"
    needs_observations = True
    needs_local_maps = False

    def __init__(self, checkpoint: str | Path | None = None, device: str = "cpu") -> None:
        torch.set_num_threads(1)  # batches of N observations: more threads only spin
        if checkpoint is None:
            raise CheckpointError("the rllib planner needs a run folder: train one with "
                                  "`ipp-train rllib --algo PPO --out RUN` and pass rllib=RUN "
                                  "(checkpoint='RUN')")
        self.checkpoint = policy_file_of(checkpoint)
        self.device = device
        self.policy, self.meta = load_rllib_policy(self.checkpoint, device)
        arch = self.meta.architecture
        self.obs_shape: tuple[int, int, int] = (arch.channels, arch.grid, arch.grid)
        self.observation_features = self.meta.env_config.features
        self.transfer_notes: list[str] = []

    def reset(self, config: EnvConfig, seed: int) -> None:
        """Start a mission of ``config``: refuse another planning grid, note other transfers.

        ``seed`` is unused: the planner is deterministic.

        Raises:
            CheckpointError: naming the policy's observation shape and the mission's.
        """
        grid = int(config.world.grid_points)
        shape = (len(actor_plane_names(self.observation_features)), grid, grid)
        if shape != self.obs_shape:
            raise CheckpointError(
                f"RLlib policy {str(self.checkpoint)!r} was trained on observations of shape "
                f"{self.obs_shape}; missions of this config give {shape} (another planning "
                "grid)")
        self.transfer_notes = check_policy_transfer(self.meta.env_config, config,
                                                    str(self.checkpoint))

    def act(self, views: list[AgentView]) -> np.ndarray:
        """(N,) greedy valid actions from the agents' (C, G, G) planes and (6,) masks, chosen
        in agent order under the same-step rule
        (:func:`~ipp_toolkit.planning.choose_for_views`), like the other learned planners."""
        planes, masks = policy_inputs(views, self.obs_shape,
                                      f"RLlib policy {str(self.checkpoint)!r}")
        with torch.no_grad():
            logits = self.policy(torch.as_tensor(planes, device=self.device),
                                 torch.as_tensor(masks, device=self.device))
        return choose_for_views(logits.cpu().numpy(), views)
