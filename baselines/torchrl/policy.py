"""A TorchRL run's shared actor as a plain-weights file, read back in torch alone.

A parameter-sharing actor in TorchRL's own modules (a ``MultiAgentMLP`` with
``share_params=True``, ``centralized=False``, on each UAV's flattened (C, G, G) planes, as
``examples/05_torchrl_mappo.py`` trains) is one MLP that every UAV runs. :func:`save_torchrl_policy`
writes its weights, sizes, activation and the mission config to a file of the format
``ipp-toolkit/torchrl`` (read with ``torch.load(weights_only=True)``, nothing unpickled) and a
JSON record beside it; :func:`load_torchrl_policy` rebuilds that MLP as a plain
``torch.nn.Sequential`` for the ``torchrl`` planner (:mod:`baselines.torchrl.planner`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from torch import nn

from ipp_toolkit.config.files import config_from_dict, config_to_dict
from ipp_toolkit.config.limits import check_layer_size, check_parameters
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import (
    CheckpointError,
    built_from_checkpoint,
    load_torch,
    load_weights,
    save_checkpoint,
)
from ipp_toolkit.sim.features import actor_plane_names
from ipp_toolkit.sim.team import N_ACTIONS

__all__ = ["TORCHRL_POLICY_KIND", "ACTIVATIONS", "TorchRLPolicyFile", "save_torchrl_policy",
           "load_torchrl_policy"]

TORCHRL_POLICY_KIND = "ipp-toolkit/torchrl"
"""Format tag of a TorchRL actor's policy file."""
ACTIVATIONS = ("Tanh", "ReLU", "ELU", "LeakyReLU", "SiLU", "GELU")
"""``torch.nn`` activations a saved actor may use (by name)."""


@dataclass(frozen=True)
class TorchRLPolicyFile:
    """What a TorchRL policy file says besides its weights.

    Attributes:
        obs_shape: (C, G, G) planes of one UAV, flattened to C * G * G inputs.
        depth: hidden layers of the MLP.
        num_cells: width of each hidden layer.
        activation: a ``torch.nn`` activation name (:data:`ACTIVATIONS`).
        env_config: the mission config it trained on (its features are the policy's planes).
    """

    obs_shape: tuple[int, int, int]
    depth: int
    num_cells: int
    activation: str
    env_config: EnvConfig


def build_mlp(meta: TorchRLPolicyFile) -> nn.Sequential:
    """The actor's MLP: ``depth`` hidden layers of ``num_cells``, then 6 logits; its layers
    are numbered as ``MultiAgentMLP``'s shared ``params`` (0, 2, 4, ...)."""
    inputs = meta.obs_shape[0] * meta.obs_shape[1] * meta.obs_shape[2]
    sizes = [inputs, *([meta.num_cells] * meta.depth), N_ACTIONS]
    check_parameters(float(sum((a + 1) * b for a, b in zip(sizes, sizes[1:], strict=False))),
                     f"a TorchRL actor (depth {meta.depth}, num_cells {meta.num_cells})")
    layers: list[nn.Module] = []
    for k, (a, b) in enumerate(zip(sizes, sizes[1:], strict=False)):
        layers.append(nn.Linear(a, b))
        if k < meta.depth:
            layers.append(getattr(nn, meta.activation)())
    return nn.Sequential(*layers)


def save_torchrl_policy(path: str | Path, network: Any, env_config: EnvConfig,
                        **extra: Any) -> Path:
    """Write a shared TorchRL actor to ``path`` (and its JSON record beside it), atomically.

    Args:
        path: the policy file (``.pt``).
        network: the actor's ``torchrl.modules.MultiAgentMLP`` (``share_params=True``,
            ``centralized=False``), whose inputs are one UAV's flattened planes and whose
            outputs are the 6 logits.
        env_config: the mission config it trained on.
        extra: JSON-safe records for the JSON file only (command, iterations, ...).

    Returns:
        ``path``.

    Raises:
        ValueError: a network that is not such an actor (named: not shared, centralised,
            another input or output size, an activation not in :data:`ACTIVATIONS`).
    """
    features = env_config.features
    grid = int(env_config.world.grid_points)
    obs_shape = (len(actor_plane_names(features)), grid, grid)
    activation = getattr(getattr(network, "activation_class", None), "__name__", None)
    problems = {
        "share_params": getattr(network, "share_params", None) is True,
        "centralized": getattr(network, "centralized", None) is False,
        f"n_agent_inputs = {obs_shape[0] * grid * grid} (the flattened planes {obs_shape})":
            getattr(network, "n_agent_inputs", None) == obs_shape[0] * grid * grid,
        f"n_agent_outputs = {N_ACTIONS}": getattr(network, "n_agent_outputs", None) == N_ACTIONS,
        f"activation_class in torch.nn's {ACTIVATIONS}": activation in ACTIVATIONS,
    }
    wrong = [name for name, ok in problems.items() if not ok]
    if wrong:
        raise ValueError(f"the torchrl planner flies a MultiAgentMLP with share_params=True, "
                         f"centralized=False, n_agent_inputs, n_agent_outputs and the "
                         f"activation below; this network fails: {', '.join(wrong)}")
    state = {name.removeprefix("params."): tensor.detach().cpu().clone()
             for name, tensor in network.state_dict().items()}
    record = {"obs_shape": list(obs_shape), "depth": int(network.depth),
              "num_cells": int(network.num_cells), "activation": activation,
              "env_config": config_to_dict(env_config)}
    return save_checkpoint(path, {"policy": state, **record}, TORCHRL_POLICY_KIND,
                           {"format": TORCHRL_POLICY_KIND, **record, **extra})


def load_torchrl_policy(path: str | Path, device: str = "cpu"
                        ) -> tuple[nn.Sequential, TorchRLPolicyFile]:
    """The actor's MLP (eval mode) and records of a TorchRL policy file.

    Raises:
        CheckpointError: a missing, corrupt or foreign file, records that do not describe an
            actor (named), or weights that do not fit them.
    """
    data = load_torch(path, TORCHRL_POLICY_KIND)
    try:
        meta = TorchRLPolicyFile(obs_shape=tuple(int(d) for d in data["obs_shape"]),
                                 depth=int(data["depth"]), num_cells=int(data["num_cells"]),
                                 activation=str(data["activation"]),
                                 env_config=config_from_dict(data["env_config"]))
    except (KeyError, TypeError, ValueError) as error:
        raise CheckpointError(f"TorchRL policy {str(path)!r} holds invalid records: "
                              f"{error}") from None
    if meta.activation not in ACTIVATIONS or len(meta.obs_shape) != 3 or meta.depth < 0 \
            or meta.num_cells < 1:
        raise CheckpointError(f"TorchRL policy {str(path)!r} records activation "
                              f"{meta.activation!r}, depth {meta.depth}, num_cells "
                              f"{meta.num_cells} and observations {meta.obs_shape}; expected "
                              f"one of {ACTIVATIONS}, a depth >= 0, num_cells >= 1 and "
                              "(C, G, G)")

    def build() -> nn.Sequential:
        check_layer_size("num_cells", meta.num_cells, f"TorchRL policy {str(path)!r}")
        return build_mlp(meta)

    network = built_from_checkpoint(path, build)
    load_weights(network, data["policy"], path, "the weights do not fit the MLP its records "
                                               "describe")
    return network.to(device).eval(), meta
