"""The shared actor, the centralised critic and the bounded softmax policy.

Both networks are the paper's shape: three valid convolutions (kernels 5, 4, 4; an 11 x 11
input shrinks to 7, 4, 1), a hidden fully connected layer, and an output head. The width is a
field of :class:`~coma.config.COMAConfig`; the agent id is an input plane, so one set of
weights serves every agent.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from torch import nn

from ipp_toolkit.sim.features import option_gain_cells, relative_option_gains
from ipp_toolkit.sim.team import N_ACTIONS

__all__ = ["ConvNet", "GainPriorActor", "bfloat16_hardware", "bounded_softmax", "epsilon_at",
           "greedy_actions", "in_input_layout", "learning_forward", "masked_logits",
           "mixed_precision"]

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
        self.side = side
        self.channels_last = False

    def use_channels_last(self) -> None:
        """Keep the convolutions (and convert their inputs) channels-last.

        On a CPU, PyTorch's convolutions of large batches run faster so (a COMA update of the
        ``cpu`` preset, one core: 8.96 s -> 7.72 s and 9.79 s -> 8.39 s in two paired runs; the
        rollout's batches of N agents are not faster). A last convolution whose kernel covers
        its whole input (``side == 1``, the paper's 11 x 11 grid) is then computed as the
        matrix product it is, over the same weights: mkldnn runs that 1 x 1-output
        convolution's backward pass at a fifth of its matrix-product rate. The outputs equal
        the default layout's up to float rounding. The trainer switches it on; the planners
        keep the default layout, so flying a policy gives the same numbers as before.
        """
        self.to(memory_format=torch.channels_last)
        self.channels_last = True

    def forward(self, planes: torch.Tensor) -> torch.Tensor:
        if not self.channels_last:
            return self._head(self.encoder(planes))
        features = planes.contiguous(memory_format=torch.channels_last)
        if self.side != 1:
            return self._head(self.encoder(features))
        *convolutions, last, last_relu, _flatten = self.encoder
        for layer in convolutions:
            features = layer(features)
        assert isinstance(last, nn.Conv2d)
        # Channels-last (B, C, k, k) and (out, C, k, k) are (B, k k C) and (out, k k C)
        # row-major: both views are free, and the product sums the convolution's terms.
        weight = last.weight.permute(0, 2, 3, 1).reshape(last.out_channels, -1)
        flat = features.permute(0, 2, 3, 1).reshape(len(features), -1)
        return self._head(last_relu(nn.functional.linear(flat, weight, last.bias)))

    def _head(self, features: torch.Tensor) -> torch.Tensor:
        """The fully connected head, in float32 even under mixed precision
        (:func:`mixed_precision`): bfloat16's 8-bit mantissa would round a Q-value of 10 to
        the nearest 0.06, coarser than the differences between actions that the
        counterfactual advantage is made of. The head is a sliver of the work."""
        device = features.device.type
        if not torch.is_autocast_enabled(device):
            return self.head(features)
        with torch.autocast(device, enabled=False):
            return self.head(features.float())


def in_input_layout(network: nn.Module, planes: torch.Tensor) -> torch.Tensor:
    """``planes`` (B, C, G, G) in the memory layout ``network``'s convolutions take:
    channels-last once :meth:`ConvNet.use_channels_last` switched them, else as they are.

    The same values either way. The trainer converts a rollout's planes once, so that the
    mini-batches indexed from them (indexing keeps the layout) need no copy each.
    """
    if any(isinstance(module, ConvNet) and module.channels_last
           for module in network.modules()):
        return planes.contiguous(memory_format=torch.channels_last)
    return planes


def mixed_precision(precision: str, device: torch.device) -> contextlib.AbstractContextManager[Any]:
    """The context of a learning pass's forward passes (:attr:`coma.config.COMAConfig.precision`).

    ``float32``: none. ``bfloat16``: torch's autocast on ``device``'s type, which runs the
    convolutions in bfloat16 and keeps the parameters (hence the gradients and the
    optimiser's state) in float32; :class:`ConvNet`'s fully connected head stays float32.
    The backward pass runs outside it (as torch advises).
    """
    if precision == "float32":
        return contextlib.nullcontext()
    return torch.autocast(device.type, dtype=torch.bfloat16)


def bfloat16_hardware(device: torch.device) -> bool | None:
    """Whether ``device`` computes in bfloat16 itself (None where that is not known).

    A CPU with AVX512-BF16 or AMX-BF16 does (``torch.cpu.get_capabilities``; on another CPU
    torch converts to float32 around each operation, which costs more than it saves), as does
    a GPU for which ``torch.cuda.is_bf16_supported()`` holds.
    """
    try:
        if device.type == "cuda":
            return bool(torch.cuda.is_bf16_supported())
        if device.type == "cpu":
            capabilities = torch.cpu.get_capabilities()
            if "avx512_bf16" not in capabilities:
                return None  # not an x86 CPU torch knows the flags of
            return bool(capabilities["avx512_bf16"] or capabilities.get("amx_bf16"))
    except (AttributeError, RuntimeError):
        pass
    return None


def learning_forward(module: nn.Module, planes: torch.Tensor, precision: str) -> torch.Tensor:
    """``module(planes)`` in ``precision`` (:func:`mixed_precision`). The output is float32
    either way (:class:`ConvNet`'s head runs in float32), so the losses are float32 too."""
    with mixed_precision(precision, planes.device):
        return module(planes)


class GainPriorActor(nn.Module):
    """Actor whose logits are a learned residual over the ``ig`` planner's objective.

    ``logits(u) = ConvNet(planes)(u) + beta * gain(u) / |max_u' gain(u')|``, where ``gain(u)`` is
    read from the agent-centred ``gain`` planes (:func:`ipp_toolkit.sim.features.gain_planes`) at
    option u's waypoint: the horizontal moves next to the centre of ``gain_level``, up and
    down at the centre of ``gain_up`` / ``gain_down``. The ConvNet's output layer starts at
    zero, so the starting greedy policy is the best option by expected gain (``ig``'s choice
    up to its discount of teammates' same-step footprints) and COMA trains only the
    correction.
    ``beta`` is learned (as ``log_beta``); it sets how sharply the starting policy samples.

    Args:
        in_channels: C, the actor's planes (the gain planes among them).
        grid: G, the side of the planes.
        gain_channels: channel indices of ``gain_level``, ``gain_up``, ``gain_down``.
        width, hidden: sizes of the residual ConvNet.
        beta: starting weight of the gain (> 0).

    Shapes: ``forward`` maps (B, C, G, G) float32 to (B, 6) logits.
    """

    def __init__(self, in_channels: int, grid: int, gain_channels: Sequence[int], width: int,
                 hidden: int, beta: float):
        super().__init__()
        if not beta > 0 or not math.isfinite(beta):
            raise ValueError(f"GainPriorActor: beta = {beta!r} must be a positive number")
        self.residual = ConvNet(in_channels, grid, N_ACTIONS, width, hidden)
        last = self.residual.head[-1]
        assert isinstance(last, nn.Linear)
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
        self.log_beta = nn.Parameter(torch.tensor(math.log(beta)))
        channel, row, col = option_gain_cells(gain_channels, grid)
        # Buffers, not parameters: rebuilt from the configs, not stored.
        self.register_buffer("option_channel", torch.from_numpy(channel), persistent=False)
        self.register_buffer("option_row", torch.from_numpy(row), persistent=False)
        self.register_buffer("option_col", torch.from_numpy(col), persistent=False)
        self.in_channels = in_channels
        self.grid = grid

    def plane_gains(self, planes: torch.Tensor) -> torch.Tensor:
        """(B, C, G, G) planes -> (B, 6) each option's expected gain as the planes hold it.
        Options outside the area read 0 (and are masked)."""
        return planes[:, self.option_channel, self.option_row, self.option_col]

    def option_gains(self, planes: torch.Tensor) -> torch.Tensor:
        """(B, C, G, G) planes -> (B, 6) expected gain of each option over the best one's.

        Relative gains keep ``beta``'s effect the same late in a mission, when every
        option's absolute gain has shrunk.
        """
        return relative_option_gains(self.plane_gains(planes))

    def parts(self, planes: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, C, G, G) planes -> the (B, 6) residual and prior logits (their sum: forward)."""
        return self.residual(planes), self.log_beta.exp() * self.option_gains(planes)

    def forward(self, planes: torch.Tensor) -> torch.Tensor:
        residual, prior = self.parts(planes)
        return residual + prior


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


def greedy_actions(actor: nn.Module, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """Each agent's likeliest valid action on its own (eps = 0), for a batch of planes.

    The ``coma`` planner and COMA's validation add the same-step rule on top
    (:func:`masked_logits`, then :func:`ipp_toolkit.sim.team.choose_in_order`).

    Args:
        actor: the actor network.
        observations: (B, C, G, G) float32 actor planes.
        masks: (B, 6) valid actions.

    Returns:
        (B,) int64 actions, always valid.
    """
    return masked_logits(actor, observations, masks).argmax(axis=-1)


def masked_logits(actor: nn.Module, observations: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """The deployed policy's scores (eps = 0): the ``coma`` planner and COMA's validation take
    the likeliest valid action of each UAV in agent order
    (:func:`ipp_toolkit.sim.team.choose_in_order`).

    Args:
        actor: the actor network.
        observations: (B, C, G, G) float32 actor planes.
        masks: (B, 6) valid actions.

    Returns:
        (B, 6) float32 logits, -inf on invalid actions.
    """
    with torch.no_grad():
        logits = actor(torch.as_tensor(observations, dtype=torch.float32))
    logits = logits.masked_fill(~torch.as_tensor(masks, dtype=torch.bool), -math.inf)
    return logits.numpy()
