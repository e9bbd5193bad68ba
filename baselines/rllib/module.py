"""What ``ipp-train rllib`` hands to RLlib: the multi-agent env, the masked RLModule, the
episode callback. Imports Ray: the command line imports this module only once Ray is known
to be importable; the default install never does.

Importing it registers the env with RLlib (``register_env``) as :data:`ENV_NAME`
(``ipp_toolkit_multi_agent``), so ``PPOConfig().environment("ipp_toolkit_multi_agent",
env_config={...})`` and ``Algorithm.from_checkpoint(RUN/checkpoint)`` find it, as RLlib's
docs show for custom envs (a checkpoint of ``ipp-train rllib`` imports it itself: its
RLModule's class lives here).

* :class:`IPPMultiAgentEnv`: :class:`ipp_toolkit.env.IPPEnv` as an RLlib ``MultiAgentEnv``.
  Each UAV is one agent (``uav_0`` ...); ``ipp-train rllib`` maps all to the one shared
  policy (:data:`SHARED_POLICY`). Every agent gets the team reward. Its ``env_config``
  (every key has a default; :mod:`baselines.rllib.env_config`): ``env``, ``observation``,
  ``base_seed``, ``envs_per_runner``, ``invalid_action``. Seeding: copy ``v`` of env runner
  ``w`` flies missions 0, 1, 2, ... of run ``base_seed + w * envs_per_runner + v``
  (``ipp-train rllib``'s ``base_seed`` is the run seed plus the agent-steps done before a
  resume).
* :class:`IPPMaskedRLModule`: a ``TorchRLModule`` around
  :class:`baselines.rllib.policy.MaskedConvPolicy` (the conv encoder of the (C, 11, 11)
  planes, masked logits, a value head); it implements the ``ValueFunctionAPI`` (PPO, APPO,
  IMPALA) and the ``TargetNetworkAPI`` (APPO).
* :class:`TeamMetricsCallback`: logs each finished mission's team return, final entropy and
  F1 (RLlib's own ``episode_return_mean`` sums the returns of all agents of an episode).
"""

from __future__ import annotations

import itertools
from collections import defaultdict
from typing import Any

import numpy as np
from ray._private import worker as ray_worker
from ray.rllib.callbacks.callbacks import RLlibCallback
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.utils import make_target_network
from ray.rllib.core.rl_module.apis import (
    TARGET_NETWORK_ACTION_DIST_INPUTS,
    TargetNetworkAPI,
    ValueFunctionAPI,
)
from ray.rllib.core.rl_module.torch import TorchRLModule
from ray.rllib.env.multi_agent_env import MultiAgentEnv
from ray.tune.registry import register_env

from ipp_toolkit.env import IPPEnv

from .env_config import ENV_NAME, env_settings
from .policy import MaskedConvPolicy, RLlibArchitecture

__all__ = ["SHARED_POLICY", "ENV_NAME", "IPPMultiAgentEnv", "make_env", "IPPMaskedRLModule",
           "TeamMetricsCallback"]

SHARED_POLICY = "shared"
"""The id of the one policy (RLModule) every UAV maps to."""

_COPIES: dict[int, itertools.count] = defaultdict(itertools.count)
"""Per env-runner index: env copies made in this process so far (their vector index)."""


class IPPMultiAgentEnv(MultiAgentEnv):
    """:class:`ipp_toolkit.env.IPPEnv` as an RLlib multi-agent env (see the module docstring).

    Args:
        env_config: RLlib's env config (:mod:`baselines.rllib.env_config`: ``env``,
            ``observation``, ``base_seed``, ``envs_per_runner``, ``invalid_action``; each
            has a default, so ``{}`` or None is the paper's mission); the runner's
            ``worker_index`` is read from it when it is an ``EnvContext``.

    Raises:
        ValueError: an unknown key (named) or a bad value.
    """

    def __init__(self, env_config: Any = None) -> None:
        super().__init__()
        settings = env_settings(env_config)
        worker = int(getattr(env_config, "worker_index", 0) or 0)
        copy = next(_COPIES[worker])
        self.run_seed = settings.base_seed + worker * settings.envs_per_runner + copy
        self.env = IPPEnv(settings.env, observation=settings.observation,
                          invalid_action=settings.invalid_action)
        self.possible_agents = list(self.env.possible_agents)
        self.agents = list(self.possible_agents)
        self.observation_spaces = {a: self.env.observation_space(a) for a in self.agents}
        self.action_spaces = {a: self.env.action_space(a) for a in self.agents}
        self._seeded = False

    def reset(self, *, seed: int | None = None, options: dict | None = None
              ) -> tuple[dict, dict]:
        """The next mission of this copy's run (RLlib's ``seed`` is not used: see above)."""
        first = not self._seeded
        self._seeded = True
        obs, infos = self.env.reset(seed=self.run_seed if first else None, options=options)
        self.agents = list(self.env.agents)
        return obs, infos

    def step(self, action_dict: dict[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        """One joint step; ``__all__`` ends the episode once no agent is left."""
        obs, rewards, terminated, truncated, infos = self.env.step(
            {a: int(np.asarray(act).reshape(())) for a, act in action_dict.items()})
        self.agents = list(self.env.agents)
        terminated = dict(terminated)
        truncated = dict(truncated)
        terminated["__all__"] = not self.agents and all(terminated.values())
        truncated["__all__"] = not self.agents and not terminated["__all__"]
        return obs, rewards, terminated, truncated, infos

    def close(self) -> None:
        self.env.close()


def make_env(env_config: Any) -> IPPMultiAgentEnv:
    """The env creator registered as :data:`ENV_NAME`."""
    return IPPMultiAgentEnv(env_config)


def _register() -> None:
    register_env(ENV_NAME, make_env)


# At import, as RLlib's docs register a custom env: a script (or Algorithm.from_checkpoint)
# names it by its string; Ray sends the registration to its workers once it starts.
_register()
# Ray keeps a registration in the running cluster only, so after ray.shutdown() the next
# ray.init() of this process (a second run, a resume) would no longer know the name. Ray's own
# registry flushes through the same hooks at every ray.init(); register again there.
# The hook list is private to Ray (pinned by the extra); without it, runs still register in
# algorithm_config().
_HOOKS = getattr(ray_worker, "_post_init_hooks", None)
if isinstance(_HOOKS, list):
    _HOOKS.append(_register)


class IPPMaskedRLModule(TorchRLModule, ValueFunctionAPI, TargetNetworkAPI):
    """The shared policy: :class:`MaskedConvPolicy` over the Dict observation
    ``{"observation": (C, G, G), "action_mask": (6,)}`` (the env's ``observation="dict"``).

    ``model_config``: ``width``, ``features_dim``, ``hidden`` (the sizes of
    :class:`~baselines.rllib.policy.RLlibArchitecture`).
    """

    def setup(self) -> None:
        planes = self.observation_space["observation"].shape
        config = dict(self.model_config or {})
        self.architecture = RLlibArchitecture(
            channels=int(planes[0]), grid=int(planes[1]), width=int(config.get("width", 32)),
            features_dim=int(config.get("features_dim", 128)),
            hidden=int(config.get("hidden", 64)))
        self.net = MaskedConvPolicy(self.architecture)

    def _split(self, batch: dict[str, Any]) -> tuple[Any, Any]:
        obs = batch[Columns.OBS]
        return obs["observation"], obs["action_mask"]

    def _forward(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        planes, mask = self._split(batch)
        features = self.net.features(planes)
        return {Columns.ACTION_DIST_INPUTS: self.net.logits(features, mask)}

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        planes, mask = self._split(batch)
        features = self.net.features(planes)
        return {Columns.ACTION_DIST_INPUTS: self.net.logits(features, mask),
                Columns.EMBEDDINGS: features}

    def compute_values(self, batch: dict[str, Any], embeddings: Any = None) -> Any:
        """(B,) values; ``embeddings`` are the encoder's features when already computed."""
        if embeddings is None:
            embeddings = self.net.features(self._split(batch)[0])
        return self.net.value(embeddings)

    def make_target_networks(self) -> None:
        """APPO's target copy of the whole network."""
        self._target_net = make_target_network(self.net)

    def get_target_network_pairs(self) -> list[tuple[Any, Any]]:
        return [(self.net, self._target_net)]

    def forward_target(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        planes, mask = self._split(batch)
        return {TARGET_NETWORK_ACTION_DIST_INPUTS: self._target_net(planes, mask)}

    def get_non_inference_attributes(self) -> list[str]:
        return ["_target_net"]


class TeamMetricsCallback(RLlibCallback):
    """Logs ``team_return`` (the longest-lived UAV's return: every UAV gets the team reward),
    ``final_entropy`` and ``final_f1`` of each finished mission (means per iteration)."""

    def on_episode_end(self, *, episode: Any, metrics_logger: Any = None,
                       **kwargs: Any) -> None:
        if metrics_logger is None:
            return
        agents = list(episode.agent_episodes.values())
        if not agents:
            return
        metrics_logger.log_value("team_return", max(float(a.get_return()) for a in agents),
                                 reduce="mean")
        infos = [a.get_infos(-1) for a in agents]
        last = max((info for info in infos if "entropy" in info),
                   key=lambda info: info.get("step", 0), default=None)
        if last is not None:
            metrics_logger.log_value("final_entropy", float(last["entropy"]), reduce="mean")
            metrics_logger.log_value("final_f1", float(last["f1"]), reduce="mean")
