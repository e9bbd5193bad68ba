"""The ``torchrl`` planner: flies the shared actor of a TorchRL run saved with
:func:`baselines.torchrl.policy.save_torchrl_policy`.

``ipp-compare --planners ig,torchrl=RUN/policy.pt`` (``examples/05_torchrl_mappo.py --out
RUN`` writes one) flies it greedily for every UAV: the argmax of its logits over the valid
moves, chosen in agent order under the same-step rule like the other learned planners.
Inference only: torch, never TorchRL.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch

from ipp_toolkit.planning.shared_policy import SharedPolicyPlanner

from .policy import load_torchrl_policy

__all__ = ["TorchRLPlanner"]


class TorchRLPlanner(SharedPolicyPlanner):
    """Greedy shared TorchRL actor for every agent (one batched forward per step), built
    as :class:`~ipp_toolkit.planning.shared_policy.SharedPolicyPlanner` is, from ``checkpoint``:
    a file of :func:`~baselines.torchrl.policy.save_torchrl_policy`."""

    name = "torchrl"
    kind = "TorchRL"
    wanted = ("a policy file: train one with `python examples/05_torchrl_mappo.py --out RUN` "
              "and pass torchrl=RUN/policy.pt (checkpoint='RUN/policy.pt')")

    @staticmethod
    def load(checkpoint: str | Path, device: str) -> tuple[Path, Any, Any]:
        """The file, its MLP and its records."""
        return (Path(checkpoint), *load_torchrl_policy(checkpoint, device))

    def meta_obs_shape(self) -> tuple[int, int, int]:
        return self.meta.obs_shape

    def scores(self, planes: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """(N, 6) logits of the flattened (N, C, G, G) planes (the choice applies the
        masks)."""
        with torch.no_grad():
            logits = self.policy(torch.as_tensor(planes, device=self.device).flatten(1))
        return logits.cpu().numpy()
