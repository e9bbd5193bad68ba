"""The ``rllib`` planner: flies the shared policy an ``ipp-train rllib`` run exported.

``ipp-compare --planners ig,rllib=RUN`` (or ``rllib=RUN/policy.pt``) loads ``RUN/policy.pt``
(:mod:`baselines.rllib.policy`, plain weights read with ``torch.load(weights_only=True)``)
and flies it greedily for every UAV. Inference only: this module needs torch, never Ray, and
never imports the training code (:mod:`baselines.rllib.training`, :mod:`baselines.rllib.module`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from ipp_toolkit.planning.shared_policy import SharedPolicyPlanner

from .policy import load_rllib_policy, policy_file_of

__all__ = ["RLlibPlanner"]


class RLlibPlanner(SharedPolicyPlanner):
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
    kind = "RLlib"
    wanted = ("a run folder: train one with `ipp-train rllib --algo PPO --out RUN` and pass "
              "rllib=RUN (checkpoint='RUN')")

    @staticmethod
    def load(checkpoint: str | Path, device: str) -> tuple[Path, Any, Any]:
        """The ``policy.pt`` of a run folder or file, its network and its records."""
        path = policy_file_of(checkpoint)
        return (path, *load_rllib_policy(path, device))

    def meta_obs_shape(self) -> tuple[int, int, int]:
        arch = self.meta.architecture
        return (arch.channels, arch.grid, arch.grid)

    def scores(self, planes: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """(N, 6) masked logits of (N, C, G, G) planes and (N, 6) masks."""
        with torch.no_grad():
            logits = self.policy(torch.as_tensor(planes, device=self.device),
                                 torch.as_tensor(masks, device=self.device))
        return logits.cpu().numpy()
