"""Reading a shared SB3 policy back from any of its files: :func:`load_sb3_policy`.

One entry for every file the ``sb3`` and ``ppo`` planners fly: ``ipp-train sb3`` files (formats
``ipp-toolkit/sb3`` and ``ipp-toolkit/sb3-training``, :mod:`baselines.sb3.policies`),
``ipp-train ppo`` files (``ipp-toolkit/ppo`` and ``ipp-toolkit/ppo-training``,
:mod:`baselines.sb3.ppo`) and SB3's own ``model.save`` zips (:mod:`baselines.sb3.zips`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from stable_baselines3.common.policies import BasePolicy

from ipp_toolkit.config.files import config_from_dict
from ipp_toolkit.io import CheckpointError, built_from_checkpoint, load_torch, load_weights
from ipp_toolkit.sim.team import N_ACTIONS

from .policies import (
    SB3_POLICY_KIND,
    SB3_TRAINING_KIND,
    LoadedPolicy,
    PolicyArchitecture,
    build_policy,
    canonical_algo,
    check_shapes,
)
from .ppo import CHECKPOINT_KIND as PPO_KIND
from .ppo import TRAINING_KIND as PPO_TRAINING_KIND
from .ppo import load_policy as load_ppo_policy
from .zips import is_sb3_zip, load_sb3_zip

__all__ = ["load_sb3_policy"]

#: ``algo`` values of ``ipp-toolkit/ppo`` files.
_PPO_FILE_ALGOS = {"ppo": "PPO", "maskable_ppo": "MaskablePPO"}


def _format_tag(path: Path) -> Any:
    """The format tag of a plain-weights file, or None when it cannot be read as one."""
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception:  # noqa: BLE001 - load_torch names the problem just after
        return None
    return data.get("format") if isinstance(data, dict) else None


def load_sb3_policy(path: str | Path, device: str = "cpu") -> tuple[BasePolicy, LoadedPolicy]:
    """Rebuild the policy of an ``ipp-train sb3`` (or ``ipp-train ppo``) file and load its weights.

    Reads ``policy.pt`` and ``checkpoint.pt`` files of the formats ``ipp-toolkit/sb3``,
    ``ipp-toolkit/sb3-training``, ``ipp-toolkit/ppo`` and ``ipp-toolkit/ppo-training``, and
    the zips of SB3's ``model.save`` (:func:`baselines.sb3.zips.load_sb3_zip`).

    Returns:
        (policy in eval mode, :class:`LoadedPolicy`).

    Raises:
        CheckpointError: a missing, empty, corrupt or foreign file; an unsupported algorithm;
            another action count than the simulator's; an observation shape that its feature
            planes cannot give; weights that do not fit (each message names the file and, for
            shapes, both values).
    """
    path = Path(path)
    if is_sb3_zip(path):
        return load_sb3_zip(path, device)
    accepted = (SB3_POLICY_KIND, SB3_TRAINING_KIND, PPO_KIND, PPO_TRAINING_KIND)
    tag = _format_tag(path) if path.is_file() and path.stat().st_size > 0 else None
    if tag is None:
        load_torch(path, SB3_POLICY_KIND)  # raises: missing, empty or corrupt
    if tag not in accepted:
        raise CheckpointError(f"checkpoint {str(path)!r} is not a policy of ipp-train sb3 or "
                              f"ipp-train ppo, nor an SB3 model zip (format tag: {tag!r}; "
                              f"expected one of {', '.join(accepted)})")
    if tag in (PPO_KIND, PPO_TRAINING_KIND):
        return _load_ppo_file(path, device)
    data = load_torch(path, tag)
    missing = [key for key in ("policy", "algo", "obs_shape", "n_actions", "architecture",
                               "env_config") if key not in data]
    if missing:
        raise CheckpointError(f"checkpoint {str(path)!r} lacks {missing}")
    try:
        algo = canonical_algo(data["algo"])
        architecture = PolicyArchitecture.from_dict(data["architecture"])
        env_config = config_from_dict(data["env_config"])
        obs_shape = tuple(int(d) for d in data["obs_shape"])
        n_actions = int(data["n_actions"])
    except (TypeError, ValueError) as error:
        raise CheckpointError(f"checkpoint {str(path)!r} holds invalid records: "
                              f"{error}") from None
    meta = LoadedPolicy(algo=algo, obs_shape=obs_shape, n_actions=n_actions,  # type: ignore[arg-type]
                        architecture=architecture, env_config=env_config,
                        num_timesteps=int(data.get("num_timesteps", 0)), format=tag,
                        record={k: data[k] for k in ("sb3_config",) if k in data})
    check_shapes(path, meta)
    policy = built_from_checkpoint(  # networks over the parameter limit: CheckpointError
        path, lambda: build_policy(algo, architecture, obs_shape, n_actions, device))
    load_weights(policy, data["policy"], path,
                 f"the weights do not fit the {algo} policy its records describe")
    policy.set_training_mode(False)
    return policy, meta


def _load_ppo_file(path: Path, device: str) -> tuple[BasePolicy, LoadedPolicy]:
    policy, ppo_meta = load_ppo_policy(path, device)
    config = ppo_meta["ppo_config"]
    algo = _PPO_FILE_ALGOS.get(ppo_meta["algo"], "MaskablePPO" if config.masked else "PPO")
    meta = LoadedPolicy(
        algo=algo, obs_shape=ppo_meta["obs_shape"], n_actions=N_ACTIONS,
        architecture=PolicyArchitecture(width=config.width, features_dim=config.features_dim,
                                        hidden=config.hidden),
        env_config=ppo_meta["env_config"], num_timesteps=ppo_meta["num_timesteps"],
        format=PPO_KIND, record={"ppo_config": config.to_dict()})
    check_shapes(path, meta)
    return policy, meta
