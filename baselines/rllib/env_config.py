"""The ``env_config`` of the RLlib env :data:`ENV_NAME`, read without Ray.

RLlib hands an env creator one dict, its ``env_config`` (``PPOConfig().environment(ENV_NAME,
env_config={...})``). Every key has a default, so ``{}`` (RLlib's own default) is the paper's
mission; an unknown key is refused, naming it, instead of being ignored:

=================== ======================================================================
key                 meaning (default)
=================== ======================================================================
``env``             the mission: an ``EnvConfig``, a dict of config sections
                    (``{"team": {"n_agents": 2}}``) or a YAML file's path (None: the
                    paper's defaults)
``observation``     ``dict``, ``box`` or ``rllib`` (RLlib's action-masking layout,
                    ``{"observations", "action_mask"}``); None: the mission's
                    ``features.observation``
``base_seed``       copy ``v`` of env runner ``w`` flies missions 0, 1, ... of run
                    ``base_seed + w * envs_per_runner + v`` (0)
``envs_per_runner`` the env copies each runner steps (RLlib's ``num_envs_per_env_runner``):
                    the stride of the runs above, so that copies never share one (1)
``invalid_action``  what a masked action does: ``hold`` (the UAV stays for the step) or
                    ``raise`` (an error: for checking that a policy never takes one)
                    (``hold``)
=================== ======================================================================
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ipp_toolkit.config.files import as_env_config
from ipp_toolkit.config.schema import OBSERVATION_KINDS, EnvConfig, check_int
from ipp_toolkit.env import INVALID_ACTION_POLICIES

__all__ = ["ENV_NAME", "ENV_CONFIG_DEFAULTS", "RLlibEnvSettings", "env_settings"]

ENV_NAME = "ipp_toolkit_multi_agent"
"""The name the multi-agent env is registered under with RLlib (Ray Tune's registry)."""

ENV_CONFIG_DEFAULTS: dict[str, Any] = {"env": None, "observation": None, "base_seed": 0,
                                       "envs_per_runner": 1, "invalid_action": "hold"}
"""Every ``env_config`` key and its default (see the module docstring)."""


@dataclass(frozen=True)
class RLlibEnvSettings:
    """An ``env_config`` read and checked: the mission, the observation kind, the seeds."""

    env: EnvConfig
    observation: str
    base_seed: int
    envs_per_runner: int
    invalid_action: str


def env_settings(env_config: Mapping[str, Any] | None) -> RLlibEnvSettings:
    """The settings an ``env_config`` stands for, defaults filled in.

    Raises:
        ValueError: not a dict, an unknown key (each named, with the known keys), or a bad
            value (named).
    """
    if env_config is None:
        env_config = {}
    if not isinstance(env_config, Mapping):
        raise ValueError(f"the env_config of {ENV_NAME!r} must be a dict, got "
                         f"{type(env_config).__name__}")
    unknown = sorted(map(str, set(env_config) - set(ENV_CONFIG_DEFAULTS)))
    if unknown:
        raise ValueError(f"unknown env_config key(s) {unknown} for {ENV_NAME!r}; the keys are "
                         f"{sorted(ENV_CONFIG_DEFAULTS)}")
    values = {**ENV_CONFIG_DEFAULTS, **env_config}
    env = as_env_config(values["env"], "env_config['env']")
    observation = values["observation"]
    if observation is None:
        observation = env.features.observation
    elif observation not in OBSERVATION_KINDS:
        raise ValueError(f"env_config['observation'] must be one of {OBSERVATION_KINDS} or "
                         f"None, got {observation!r}")
    invalid_action = values["invalid_action"]
    if invalid_action not in INVALID_ACTION_POLICIES:
        raise ValueError(f"env_config['invalid_action'] must be one of "
                         f"{INVALID_ACTION_POLICIES}, got {invalid_action!r}")
    return RLlibEnvSettings(
        env=env, observation=observation,
        base_seed=check_int("env_config['base_seed']", values["base_seed"], 0),
        envs_per_runner=check_int("env_config['envs_per_runner']",
                                  values["envs_per_runner"], 1),
        invalid_action=invalid_action)
