"""What the learned planners of a plain shared network have in common:
:class:`SharedPolicyPlanner` checks the planning grid at each mission, notes what differs
from training, and chooses every UAV's best valid move in agent order."""

from __future__ import annotations

import abc
from pathlib import Path
from typing import Any

import numpy as np

from ..config.schema import EnvConfig
from ..io import CheckpointError
from ..sim.features import actor_plane_names
from . import AgentView, Planner, check_policy_transfer, choose_for_views, policy_inputs

__all__ = ["SharedPolicyPlanner"]


class SharedPolicyPlanner(Planner):
    """A deterministic planner flying one shared policy network for every agent.

    Subclasses implement :meth:`load` and :meth:`scores`; class attributes :attr:`kind` name
    the policy in messages and :attr:`wanted` say what ``checkpoint`` must be.

    Args:
        checkpoint: the policy's file (or run folder), as :meth:`load` reads it.
        device: torch device of the forward pass.

    Raises:
        CheckpointError: no checkpoint (saying how to get one), or a missing, corrupt or
            foreign file.
    """

    kind = "shared"
    wanted = "a policy file"
    needs_observations = True
    needs_local_maps = False

    def __init__(self, checkpoint: str | Path | None = None, device: str = "cpu") -> None:
        import torch

        torch.set_num_threads(1)  # batches of N observations: more threads only spin
        if checkpoint is None:
            raise CheckpointError(f"the {self.name} planner needs {self.wanted}")
        self.device = device
        self.checkpoint, self.policy, self.meta = self.load(checkpoint, device)
        self.obs_shape: tuple[int, int, int] = tuple(self.meta_obs_shape())  # type: ignore[assignment]
        self.observation_features = self.meta.env_config.features
        self.transfer_notes: list[str] = []

    @staticmethod
    @abc.abstractmethod
    def load(checkpoint: str | Path, device: str) -> tuple[Path, Any, Any]:
        """(the file, the network in eval mode, its records with ``env_config``)."""

    @abc.abstractmethod
    def meta_obs_shape(self) -> tuple[int, int, int]:
        """The (C, G, G) planes the policy was trained on, from :attr:`meta`."""

    @abc.abstractmethod
    def scores(self, planes: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """(N, 6) values of the agents' moves (higher is better) from (N, C, G, G) planes and
        (N, 6) bool masks."""

    def reset(self, config: EnvConfig, seed: int) -> None:
        """Start a mission of ``config``: refuse another planning grid, note other transfers
        (``seed`` is unused: the planner is deterministic).

        Raises:
            CheckpointError: naming the policy's observation shape and the mission's.
        """
        grid = int(config.world.grid_points)
        shape = (len(actor_plane_names(self.observation_features)), grid, grid)
        if shape != self.obs_shape:
            raise CheckpointError(
                f"{self.kind} policy {str(self.checkpoint)!r} was trained on observations of "
                f"shape {self.obs_shape}; missions of this config give {shape} (another "
                "planning grid)")
        self.transfer_notes = check_policy_transfer(self.meta.env_config, config,
                                                    str(self.checkpoint))

    def act(self, views: list[AgentView]) -> np.ndarray:
        """(N,) greedy valid actions from the agents' (C, G, G) planes and (6,) masks, chosen
        in agent order under the same-step rule
        (:func:`~ipp_toolkit.planning.choose_for_views`), like the other learned planners."""
        planes, masks = policy_inputs(views, self.obs_shape,
                                      f"{self.kind} policy {str(self.checkpoint)!r}")
        return choose_for_views(self.scores(planes, masks), views)
