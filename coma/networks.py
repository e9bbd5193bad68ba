"""The shared actor, the centralised critic and the bounded softmax policy.

Both networks are the paper's shape: three valid convolutions (kernels 5, 4, 4; an 11 x 11
input shrinks to 7, 4, 1), a hidden fully connected layer, and an output head. The width is a
field of :class:`~coma.config.COMAConfig`; the agent id is an input plane, so one set of
weights serves every agent.
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["ConvNet", "bounded_softmax", "epsilon_at"]

_KERNELS = (5, 4, 4)


class ConvNet(nn.Module):
    """Conv encoder + MLP head, used for the actor (logits), the critic (Q) and V.

    Args:
        in_channels: C, the feature planes.
        grid: G, the side of the planes (11 for the paper's world).
        outputs: size of the head (6 for the actor and Q, 1 for V).
        width: channels of every convolution.
        hidden: units of the hidden layer.

    Shapes: ``forward`` maps (B, C, G, G) float32 to (B, outputs).
    """

    def __init__(self, in_channels: int, grid: int, outputs: int, width: int, hidden: int):
        super().__init__()
        side = grid - sum(k - 1 for k in _KERNELS)
        if side < 1:
            raise ValueError(f"a {grid} x {grid} grid is too small for convolutions of "
                             f"kernels {_KERNELS} (needs at least 11 waypoints per side)")
        layers: list[nn.Module] = []
        channels = in_channels
        for kernel in _KERNELS:
            layers += [nn.Conv2d(channels, width, kernel), nn.ReLU()]
            channels = width
        self.encoder = nn.Sequential(*layers, nn.Flatten())
        self.head = nn.Sequential(nn.Linear(width * side * side, hidden), nn.ReLU(),
                                  nn.Linear(hidden, outputs))
        self.in_channels = in_channels
        self.grid = grid

    def forward(self, planes: torch.Tensor) -> torch.Tensor:
        return self.head(self.encoder(planes))


def bounded_softmax(logits: torch.Tensor, mask: torch.Tensor, eps: float) -> torch.Tensor:
    """The paper's exploration policy, renormalised over the valid actions.

    ``pi = (1 - eps) softmax(logits) + eps / |U|``, then zero on masked actions and rescaled
    to sum to one, so masked actions are never sampled and every valid action keeps at least
    probability eps / |U| (before renormalisation).

    Args:
        logits: (B, A) actor outputs.
        mask: (B, A) valid actions (bool or 0/1); every row needs one valid action.
        eps: exploration weight in [0, 1].

    Returns:
        (B, A) probabilities, exactly 0 on masked actions.
    """
    mask = mask.to(logits.dtype)
    mixed = (1.0 - eps) * torch.softmax(logits, dim=-1) + eps / logits.shape[-1]
    mixed = mixed * mask
    return mixed / mixed.sum(dim=-1, keepdim=True)


def epsilon_at(missions_done: int, start: float, end: float, anneal_missions: int) -> float:
    """Linear schedule of eps: ``start`` at mission 0, ``end`` from ``anneal_missions`` on."""
    if anneal_missions <= 0 or missions_done >= anneal_missions:
        return end
    return start + (end - start) * missions_done / anneal_missions

