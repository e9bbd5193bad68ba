"""How close COMA's update is to this core's arithmetic limit (run by hand, one thread).

    python benchmarks/coma_update_floor.py

Prints a large float32 matrix product's GFLOP/s (the core's practical peak) and the GFLOP/s
of one forward and backward pass of the ``cpu`` preset's actor (7 planes) and critic (17
planes) networks on a mini-batch of 600 (channels-last, as the trainer runs them), plus the
floating-point work of one update per agent-transition and the update rate the peak would
allow. experiments/performance/README.md ("COMA training's update: the floor on this CPU")
has the figures.
"""

from __future__ import annotations

import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import torch  # noqa: E402
from torch import nn  # noqa: E402

KERNELS = (5, 4, 4)


def matmul_gflops(size: int = 1536, repeats: int = 5) -> float:
    """GFLOP/s of (size x size) @ (size x size) in float32."""
    a, b = torch.randn(size, size), torch.randn(size, size)
    a @ b
    start = time.perf_counter()
    for _ in range(repeats):
        a @ b
    return 2 * size ** 3 * repeats / (time.perf_counter() - start) / 1e9


def forward_macs(channels: int, width: int = 64, hidden: int = 128, grid: int = 11) -> int:
    """Multiply-adds of one sample's forward pass through the ConvNet of coma.networks."""
    macs, side, inputs = 0, grid, channels
    for kernel in KERNELS:
        side -= kernel - 1
        macs += side * side * width * inputs * kernel * kernel
        inputs = width
    return macs + width * side * side * hidden + hidden * 6


def first_layer_macs(channels: int, width: int = 64, grid: int = 11) -> int:
    side = grid - KERNELS[0] + 1
    return side * side * width * channels * KERNELS[0] ** 2


def train_flops(channels: int) -> int:
    """FLOPs of one sample's forward and backward pass (no input gradient for layer 1)."""
    return 2 * (3 * forward_macs(channels) - first_layer_macs(channels))


def network(channels: int, width: int = 64, hidden: int = 128) -> nn.Module:
    layers: list[nn.Module] = []
    inputs = channels
    for kernel in KERNELS:
        layers += [nn.Conv2d(inputs, width, kernel), nn.ReLU()]
        inputs = width
    return nn.Sequential(*layers, nn.Flatten(), nn.Linear(width, hidden), nn.ReLU(),
                         nn.Linear(hidden, 6)).to(memory_format=torch.channels_last)


def pass_gflops(channels: int, batch: int = 600, repeats: int = 6) -> float:
    model = network(channels)
    planes = torch.randn(batch, channels, 11, 11).contiguous(memory_format=torch.channels_last)
    model(planes).sum().backward()
    start = time.perf_counter()
    for _ in range(repeats):
        model.zero_grad()
        model(planes).sum().backward()
    seconds = (time.perf_counter() - start) / repeats
    return batch * train_flops(channels) / seconds / 1e9


def main() -> None:
    torch.set_num_threads(1)
    torch.manual_seed(0)
    peak = matmul_gflops()
    print(f"float32 matrix product (1536 x 1536): {peak:6.1f} GFLOP/s")
    for name, channels in (("actor", 7), ("critic", 17)):
        print(f"{name:6s} ({channels:2d} planes) forward+backward, batch 600: "
              f"{pass_gflops(channels):6.1f} GFLOP/s")
    epochs = 4  # the cpu preset
    per_transition = epochs * (train_flops(7) + train_flops(17)) + 2 * forward_macs(17)
    print(f"one update: {per_transition / 1e6:.0f} MFLOP per agent-transition; at the matrix "
          f"product's rate at most {peak * 1e9 / per_transition:.0f} agent-transitions/s")


if __name__ == "__main__":
    main()
