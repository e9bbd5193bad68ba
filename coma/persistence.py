"""COMA networks on disk: plain state dicts plus the configs that rebuild them.

A policy file holds the actor, the critic (the teaching examples need it) and, for
``central_qv``, the state-value critic, with the :class:`~coma.config.COMAConfig` and the
mission's :class:`~ipp_toolkit.config.schema.EnvConfig` as plain dicts. Training checkpoints add the
optimisers, the target critic, the sampling generator and the progress counters. Files are
written atomically and read with ``torch.load(weights_only=True)``.

Transfer (the paper's robustness study): a policy trained with N agents and range D
may run with other team sizes, ranges, budgets and map resolutions, because its inputs do not
depend on them; it always observes with its own feature planes, and the planning grid must
match (see :func:`check_transfer`).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import torch

from ipp_toolkit.config.files import config_from_dict, config_to_dict
from ipp_toolkit.config.limits import check_parameters
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import (
    CheckpointError,
    built_from_checkpoint,
    first_line,
    load_torch,
    load_weights,
    save_torch,
)
from ipp_toolkit.planning import check_policy_transfer as check_transfer
from ipp_toolkit.planning import resolve_shipped
from ipp_toolkit.sim.features import actor_plane_names, gain_plane_channels
from ipp_toolkit.sim.team import N_ACTIONS

from .config import COMAConfig, from_dict
from .inputs import critic_channels, value_channels
from .networks import ConvNet, GainPriorActor

# The shipped policies' names need no torch: ipp-train coma's flags read them from there.
from .shipped import DEFAULT_SHIPPED, SHIPPED_POLICIES, SHIPPED_POLICY

__all__ = ["CHECKPOINT_KIND", "COMANetworks", "build_networks", "save_policy", "load_policy",
           "check_transfer", "shipped_policy", "resolve_policy", "SHIPPED_POLICIES",
           "DEFAULT_SHIPPED", "SHIPPED_POLICY", "untrained_reason"]

CHECKPOINT_KIND = "ipp-toolkit/coma"


@dataclass
class COMANetworks:
    """The networks of one COMA run and the configs that built them.

    Attributes:
        actor: (B, C_actor, G, G) -> (B, 6) logits.
        critic: (B, C_critic, G, G) -> (B, 6) Q(s, (u_-i, a)).
        value: (B, C_value, G, G) -> (B, 1) V(s); only for ``central_qv``.
        coma_config: the training hyper-parameters.
        env_config: the mission the networks were trained on.
    """

    actor: ConvNet
    critic: ConvNet
    value: ConvNet | None
    coma_config: COMAConfig
    env_config: EnvConfig

    def state_dicts(self) -> dict[str, Any]:
        """Plain state dicts of the networks (``value`` is None without a V critic)."""
        return {"actor": self.actor.state_dict(), "critic": self.critic.state_dict(),
                "value": None if self.value is None else self.value.state_dict()}


def build_networks(coma_config: COMAConfig, env_config: EnvConfig) -> COMANetworks:
    """Fresh networks sized for ``env_config``'s feature planes (torch's global RNG inits).

    Raises:
        ipp_toolkit.config.limits.LimitError: the networks' parameters exceed the limit
            (counted on torch's meta device, where nothing is allocated or drawn).
    """
    check_network_size(coma_config, env_config)
    return _construct(coma_config, env_config)


def check_network_size(coma_config: COMAConfig, env_config: EnvConfig) -> None:
    """Refuse (LimitError) networks whose parameters exceed the limit, counted on torch's
    meta device: nothing is allocated and no random number is drawn."""
    with torch.device("meta"):
        probe = _construct(coma_config, env_config)
    check_parameters(sum(p.numel() for name in ("actor", "critic", "value")
                         if (module := getattr(probe, name)) is not None
                         for p in module.parameters()),
                     f"COMA (width {coma_config.width}, hidden {coma_config.hidden})")


def _construct(coma_config: COMAConfig, env_config: EnvConfig) -> COMANetworks:
    features = env_config.features
    grid = env_config.world.grid_points
    width, hidden = coma_config.width, coma_config.hidden
    names = actor_plane_names(features)
    if coma_config.gain_prior > 0:
        if not features.gain:
            raise ValueError(f"invalid COMA config: gain_prior = {coma_config.gain_prior!r} "
                             "needs the gain planes in the actor's input "
                             "(features.gain = true, --feature gain=true)")
        actor: torch.nn.Module = GainPriorActor(
            len(names), grid, gain_plane_channels(features), width, hidden,
            coma_config.gain_prior)
    else:
        actor = ConvNet(len(names), grid, N_ACTIONS, width, hidden)
    critic = ConvNet(critic_channels(coma_config.variant, features), grid, N_ACTIONS, width,
                     hidden)
    value = (ConvNet(value_channels(features), grid, 1, width, hidden)
             if coma_config.variant == "central_qv" else None)
    return COMANetworks(actor, critic, value, coma_config, env_config)


def save_policy(path: str | os.PathLike[str], networks: COMANetworks,
                extra: dict[str, Any] | None = None) -> None:
    """Atomically write the networks and their configs (plus ``extra`` plain data)."""
    payload = {"coma_config": networks.coma_config.to_dict(),
               "env_config": config_to_dict(networks.env_config),
               **networks.state_dicts(), **(extra or {})}
    save_torch(path, payload, CHECKPOINT_KIND)


def load_policy(path: str | os.PathLike[str]) -> tuple[COMANetworks, dict[str, Any]]:
    """Rebuild the networks of a policy or training checkpoint.

    Returns:
        the networks (in eval mode) and the raw file contents (for training state).

    Raises:
        CheckpointError: the file is missing, corrupt, foreign, or its weights do not fit its
            own configs.
    """
    data = load_torch(path, CHECKPOINT_KIND)
    try:
        coma_config = from_dict(data["coma_config"])
        env_config = config_from_dict(data["env_config"])
    except (KeyError, TypeError, ValueError) as error:
        raise CheckpointError(f"checkpoint {str(path)!r} has no valid configs: {error}") \
            from None
    # networks over the size limit, or a grid too small: CheckpointError
    networks = built_from_checkpoint(path, lambda: build_networks(coma_config, env_config))
    for name in ("actor", "critic", "value"):
        module = getattr(networks, name)
        if module is None:
            continue
        if name not in data:
            raise CheckpointError(f"checkpoint {str(path)!r}: the {name} weights do not fit "
                                  f"its configs ({first_line(KeyError(name))})")
        load_weights(module, data[name], path, f"the {name} weights do not fit its configs")
        module.eval()
    return networks, data


def untrained_reason(path: str | os.PathLike[str]) -> str | None:
    """Why the policy file ``path`` is not a policy COMA's training moved, or None.

    A shipped policy must be one: its JSON record (``path`` with ``.json``) gives a
    ``best_update`` > 0 (a checkpoint after the start beat the start on validation), and its
    actor's weights differ from the start that its configs and seed build (a random or
    gain-prior start; a warm start's imitation is itself trained, and checked by the record).
    """
    path = Path(path)
    record_path = path.with_suffix(".json")
    try:
        record = json.loads(record_path.read_text())
    except (OSError, ValueError) as error:
        return f"its record {str(record_path)!r} cannot be read ({error})"
    best_update = record.get("best_update") if isinstance(record, dict) else None
    if not isinstance(best_update, int) or best_update <= 0:
        return f"its record gives best_update = {best_update!r}: training never beat the start"
    networks, _ = load_policy(path)
    torch.manual_seed(networks.coma_config.seed)
    start = build_networks(networks.coma_config, networks.env_config)
    trained = networks.actor.state_dict()
    if all(torch.equal(trained[k], v) for k, v in start.actor.state_dict().items()):
        return "its actor's weights equal the start its configs and seed build"
    return None


def shipped_policy(name: str = SHIPPED_POLICY) -> Path:
    """Path of a policy file shipped with the package (default: 4 agents, D = 25 m)."""
    return Path(str(resources.files("coma") / "checkpoints" / name))


def resolve_policy(policy: str | os.PathLike[str]) -> Path:
    """A policy as named by a user: ``shipped:NAME`` (:data:`SHIPPED_POLICIES`), or a path.

    Raises:
        ValueError: ``shipped:`` with an unknown name (the message lists the names).
    """
    return resolve_shipped(policy, {name: shipped_policy(file)
                                    for name, file in SHIPPED_POLICIES.items()}, "coma")

