"""The shared RLlib policy's network and its plain-weights file, in torch alone (no Ray).

``ipp-train rllib`` (:mod:`baselines.rllib.training`) trains :class:`MaskedConvPolicy` inside
an RLlib ``RLModule`` (:mod:`baselines.rllib.module`) and exports its state dict to
``OUT/policy.pt`` (format ``ipp-toolkit/rllib``, loaded with ``torch.load(weights_only=True)``)
with a JSON record ``OUT/policy.json``. The ``rllib`` planner (:mod:`baselines.rllib.planner`)
rebuilds the network from this module and flies it: flying needs torch, not Ray.

The network: conv 3x3 (pad 1) -> conv 3x3 (stride 2, pad 1) -> linear ``features_dim`` (the
encoder of the (C, G, G) planes, as the SB3 policies' ``SmallCNN``), then a policy head and a
value head of one hidden layer each. Masked actions get the logit :data:`MASKED_LOGIT`, so
they are never sampled nor chosen.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn

from ipp_toolkit.config.field_types import check_integers
from ipp_toolkit.config.files import config_from_dict, config_to_dict
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import CheckpointError, load_torch, save_checkpoint
from ipp_toolkit.sim.team import N_ACTIONS

# The algorithms' names need no torch: the command line reads them from train_config.
from .train_config import RLLIB_ALGORITHMS, canonical_rllib_algo

__all__ = ["RLLIB_POLICY_KIND", "RLLIB_ALGORITHMS", "MASKED_LOGIT", "RLlibArchitecture",
           "canonical_rllib_algo", "MaskedConvPolicy", "RLlibPolicyFile",
           "save_rllib_policy", "load_rllib_policy", "policy_file_of"]

RLLIB_POLICY_KIND = "ipp-toolkit/rllib"
"""Format tag of ``OUT/policy.pt`` written by ``ipp-train rllib``."""
MASKED_LOGIT = -1e9
"""The logit of a masked action: exp() of it is 0 in float32, and it stays finite."""


@dataclass(frozen=True)
class RLlibArchitecture:
    """Sizes of :class:`MaskedConvPolicy`.

    Attributes:
        channels: input planes C.
        grid: the planes' side G.
        width: channels of both convolutions.
        features_dim: output size of the encoder.
        hidden: hidden layer width of each head.
    """

    channels: int
    grid: int
    width: int = 32
    features_dim: int = 128
    hidden: int = 64

    def __post_init__(self) -> None:
        check_integers(self, dict.fromkeys(asdict(self), 1),
                       "RLlib policy {name} must be an integer >= {minimum}, got {value!r}",
                       numpy=False)

    def to_dict(self) -> dict[str, int]:
        """JSON-safe dict."""
        return asdict(self)

    @classmethod
    def from_dict(cls, values: Mapping[str, Any]) -> RLlibArchitecture:
        """Inverse of :meth:`to_dict`; unknown keys are refused (ValueError naming them)."""
        unknown = set(values) - set(cls.__dataclass_fields__)
        if unknown:
            raise ValueError(f"unknown RLlib architecture keys {sorted(unknown)}")
        return cls(**values)


class MaskedConvPolicy(nn.Module):
    """Shared actor-critic of one UAV's (C, G, G) planes and (6,) action mask.

    Args:
        architecture: the sizes.
    """

    def __init__(self, architecture: RLlibArchitecture) -> None:
        super().__init__()
        self.architecture = architecture
        a = architecture
        self.encoder = nn.Sequential(
            nn.Conv2d(a.channels, a.width, 3, padding=1), nn.ReLU(),
            nn.Conv2d(a.width, a.width, 3, stride=2, padding=1), nn.ReLU(),
            nn.Flatten())
        side = (a.grid + 1) // 2  # the stride-2 convolution's output side
        self.linear = nn.Sequential(nn.Linear(a.width * side * side, a.features_dim), nn.ReLU())
        self.pi = nn.Sequential(nn.Linear(a.features_dim, a.hidden), nn.Tanh(),
                                nn.Linear(a.hidden, N_ACTIONS))
        self.vf = nn.Sequential(nn.Linear(a.features_dim, a.hidden), nn.Tanh(),
                                nn.Linear(a.hidden, 1))

    def features(self, planes: torch.Tensor) -> torch.Tensor:
        """(B, features_dim) encodings of (B, C, G, G) planes."""
        return self.linear(self.encoder(planes.float()))

    def logits(self, features: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """(B, 6) action logits with masked actions (``mask`` 0) set to :data:`MASKED_LOGIT`."""
        logits = self.pi(features)
        return torch.where(mask > 0, logits, torch.full_like(logits, MASKED_LOGIT))

    def value(self, features: torch.Tensor) -> torch.Tensor:
        """(B,) state values."""
        return self.vf(features).squeeze(-1)

    def forward(self, planes: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """(B, 6) masked logits of (B, C, G, G) planes and (B, 6) masks."""
        return self.logits(self.features(planes), mask)


# --------------------------------------------------------------------------------------------
# Files


@dataclass(frozen=True)
class RLlibPolicyFile:
    """What a ``policy.pt`` of ``ipp-train rllib`` says besides its weights.

    Attributes:
        algo: the RLlib algorithm that trained it.
        architecture: the network's sizes.
        env_config: the mission config it trained on (its features are the policy's planes).
        agent_steps: agent-steps sampled when it was exported.
        iteration: training iterations done when it was exported.
    """

    algo: str
    architecture: RLlibArchitecture
    env_config: EnvConfig
    agent_steps: int
    iteration: int


def save_rllib_policy(path: str | Path, policy: MaskedConvPolicy, meta: RLlibPolicyFile,
                      **extra: Any) -> Path:
    """Write ``policy``'s state dict and records to ``path`` and ``path.with_suffix('.json')``,
    atomically (``extra``, JSON-safe, goes into the JSON record only)."""
    path = Path(path)
    record = {"algo": meta.algo, "architecture": meta.architecture.to_dict(),
              "env_config": config_to_dict(meta.env_config),
              "agent_steps": int(meta.agent_steps), "iteration": int(meta.iteration)}
    state = {k: v.detach().cpu().clone() for k, v in policy.state_dict().items()}
    return save_checkpoint(path, {"policy": state, **record}, RLLIB_POLICY_KIND,
                           {"format": RLLIB_POLICY_KIND, **record, **extra})


def policy_file_of(checkpoint: str | Path) -> Path:
    """The ``policy.pt`` of a run folder (``DIR``), or ``checkpoint`` itself when a file."""
    path = Path(checkpoint)
    return path / "policy.pt" if path.is_dir() else path


def load_rllib_policy(checkpoint: str | Path, device: str = "cpu"
                      ) -> tuple[MaskedConvPolicy, RLlibPolicyFile]:
    """The network (eval mode) and records of an ``ipp-train rllib`` run folder or policy file.

    Raises:
        CheckpointError: missing, corrupt or foreign file, or weights that do not fit the
            recorded architecture.
    """
    path = policy_file_of(checkpoint)
    data = load_torch(path, RLLIB_POLICY_KIND)
    try:
        architecture = RLlibArchitecture.from_dict(data["architecture"])
        meta = RLlibPolicyFile(algo=str(data["algo"]), architecture=architecture,
                               env_config=config_from_dict(data["env_config"]),
                               agent_steps=int(data["agent_steps"]),
                               iteration=int(data["iteration"]))
        policy = MaskedConvPolicy(architecture)
        policy.load_state_dict(data["policy"])
    except (KeyError, TypeError, ValueError, RuntimeError) as error:
        first = (str(error).splitlines() or [""])[0][:200]
        raise CheckpointError(f"RLlib policy {str(path)!r} does not fit its own record "
                              f"({type(error).__name__}: {first})") from None
    return policy.to(device).eval(), meta
