"""A toolkit policy file as an SB3 model zip: :func:`export_sb3_zip`.

The toolkit writes plain-weights policy files (``ipp-train ppo``, ``ipp-train sb3``, the shipped
``shipped:NAME`` PPO policies), which SB3's ``MaskablePPO.load`` / ``PPO.load`` cannot read.
:func:`export_sb3_zip` rebuilds the SB3 model of such a file (its algorithm, hyper-parameters,
policy class and network, on the per-UAV spaces of ``ipp_toolkit/UAV-v0``), loads its weights
and writes ``model.save(PATH)``: ``MaskablePPO.load(PATH)`` then gives the same policy, to fine-tune
or to use in your own code (a policy with the toolkit's own classes, such as its ``SmallCNN``
extractor, needs the toolkit installed to load).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ipp_toolkit.io import CheckpointError
from ipp_toolkit.uav_env import IPPUAVEnv

from .loading import load_sb3_policy
from .ppo import PPOTrainConfig, policy_class, policy_kwargs, resolve_policy

__all__ = ["export_sb3_zip"]


def _ppo_model(config: PPOTrainConfig, env: Any) -> Any:
    from sb3_contrib import MaskablePPO
    from stable_baselines3 import PPO

    return (MaskablePPO if config.masked else PPO)(
        policy_class(config), env, learning_rate=config.lr, n_steps=config.n_steps,
        batch_size=config.batch_size, n_epochs=config.n_epochs, gamma=config.gamma,
        gae_lambda=config.gae_lambda, clip_range=config.clip_range, ent_coef=config.ent_coef,
        vf_coef=config.vf_coef, max_grad_norm=config.max_grad_norm,
        policy_kwargs=policy_kwargs(config, env.config), seed=config.seed, device="cpu")


def export_sb3_zip(checkpoint: str | Path, zip_path: str | Path) -> Path:
    """Write the SB3 model of a toolkit policy file as an SB3 zip.

    Args:
        checkpoint: a ``policy.pt`` (or ``checkpoint.pt``) of ``ipp-train ppo`` or
            ``ipp-train sb3``, or a shipped PPO policy (``shipped:NAME``).
        zip_path: the zip to write (SB3 adds ``.zip`` when it has no suffix).

    Returns:
        the zip's path; ``MaskablePPO.load`` (or the algorithm's ``load``) reads it, on the
        spaces of ``gymnasium.make("ipp_toolkit/UAV-v0", config=...)`` and of
        :func:`ipp_toolkit.vec.make_sb3_vec_env`.

    Raises:
        CheckpointError: a missing, corrupt or foreign file, or an SB3 zip (already one).
    """
    from .training import SB3TrainConfig, make_sb3_model  # training code: only when exporting

    path = resolve_policy(checkpoint)
    policy, meta = load_sb3_policy(path)
    if meta.env_config is None:
        raise CheckpointError(f"{str(path)!r} is already an SB3 zip")
    env = IPPUAVEnv(meta.env_config)
    if "ppo_config" in meta.record:
        model = _ppo_model(PPOTrainConfig.from_dict(meta.record["ppo_config"]), env)
    else:
        model = make_sb3_model(SB3TrainConfig.from_dict(meta.record["sb3_config"]), env)
    model.policy.load_state_dict(policy.state_dict())
    model.num_timesteps = meta.num_timesteps
    zip_path = Path(zip_path)
    model.save(zip_path)
    return zip_path if zip_path.suffix else zip_path.with_suffix(".zip")
