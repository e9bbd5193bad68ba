"""The simulator as a TorchRL env whose masks survive transforms and batching.

TorchRL's ``PettingZooWrapper`` masks the action spec of the env it wraps, but a
``TransformedEnv`` or a batched env (``SerialEnv`` / ``ParallelEnv``) keeps its own copy of
that spec, so ``rand_action`` and collectors there draw unmasked actions. And a UAV that fails
(``team.failures``) leaves PettingZoo's ``agents``, which ends the whole TorchRL episode
(``done_on_any``) or, with ``done_on_any=False``, makes the wrapper send it actions it no
longer takes. :func:`make_torchrl_env` builds the env so that neither happens:

* every copy is an :class:`~ipp_toolkit.env.IPPEnv` with ``keep_failed=True``: a failed UAV
  keeps its slot until the mission ends (zero planes, an all-valid mask, reward 0, its
  actions ignored), so every agent is done together after ``budget`` steps and the group
  ``uav`` keeps N agents;
* TorchRL's ``ActionMask`` transform comes first on top of everything (the batched env
  included), so the action spec seen by policies, collectors and ``rand_action`` follows
  ``("uav", "action_mask")`` at every step; the caller's transforms follow it. TorchRL's
  ``RandomPolicy`` (a collector's ``policy=None``) samples from a copy of the action spec
  made when the collector starts; here every copy of the UAVs' action spec is that spec
  itself, so random collection follows the masks too;
* ``parallel=True`` batches the copies in a ``ParallelEnv`` that completes the nesting of the
  tensordicts a collector resets it with (see :func:`_complete_resets`): TorchRL's own
  crashes on them (``TypeError: Multiple dispatch failed for 'torch.Tensor.copy_'``), since
  the observation key ``("uav", "observation", "observation")`` nests a leaf under a
  sub-tensordict of the same name.

Keys (group ``uav``, N agents): ``("uav", "observation", "observation")`` (C, G, G) planes,
``("uav", "action_mask")`` (6,) bool, ``("uav", "action")``, ``("uav", "reward")``,
``("uav", "info", KEY)`` and the critic's global planes at ``"state"``.
Needs the optional extra ``torchrl`` (``pip install -c constraints.txt -e ".[torchrl]"``).
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Sequence
from typing import Any

from .config.files import ConfigLike, as_env_config
from .config.schema import EnvConfig, check_int
from .env import IPPEnv
from .extras import install_command, require_extra

__all__ = ["GROUP", "make_torchrl_env"]

GROUP = "uav"
"""The TorchRL group of every UAV."""


def _one_copy(config: EnvConfig, seed: int, namespace: str, invalid_action: str,
              device: str) -> Any:
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    with warnings.catch_warnings():
        # TorchRL warns that it was tested on another PettingZoo version.
        warnings.filterwarnings("ignore", message="PettingZoo in TorchRL", category=UserWarning)
        return PettingZooWrapper(
            env=IPPEnv(config, namespace=namespace, keep_failed=True,
                       invalid_action=invalid_action, observation="dict"),
            return_state=True, categorical_actions=True, seed=seed, device=device)


def make_torchrl_env(config: ConfigLike = None, *, num_envs: int = 1, seed: int = 0,
                     parallel: bool = False, transforms: Sequence[Any] = (),
                     namespace: str = "train", invalid_action: str = "hold",
                     device: str = "cpu") -> Any:
    """A ``TransformedEnv`` over one or ``num_envs`` copies of the simulator, masks kept.

    Args:
        config: the mission configuration (default: the paper's): an ``EnvConfig``, a dict
            of sections or a YAML file's path.
        num_envs: copies; more than one are batched (batch size ``(num_envs,)``).
        seed: run seed; copy c flies missions 0, 1, ... of run ``seed + c``.
        parallel: batch the copies in worker processes (``ParallelEnv``) instead of in this
            one (``SerialEnv``).
        transforms: TorchRL transforms applied after ``ActionMask`` (e.g.
            ``FlattenObservation``, ``RewardSum``).
        namespace: random-stream namespace (``train``, ``validation`` or ``test``).
        invalid_action: what a masked action does if one still gets through (``hold``, the
            env's default, or ``raise``).
        device: TorchRL device of the env.

    Returns:
        a ``torchrl.envs.TransformedEnv``; close it when done.

    Raises:
        ImportError: torchrl is not installed (one line saying how to install it).
        ValueError: a bad ``num_envs`` or ``seed``.
    """
    envs = require_extra("torchrl.envs", "make_torchrl_env", install_command("torchrl"),
                         package="torchrl")
    config = as_env_config(config)
    num_envs = check_int("num_envs", num_envs, 1)
    seed = check_int("seed", seed, 0)
    makers = [functools.partial(_one_copy, config, seed + copy, namespace, invalid_action,
                                device) for copy in range(num_envs)]
    if num_envs == 1:
        base = makers[0]()
    else:
        base = (_complete_resets(envs) if parallel else envs.SerialEnv)(num_envs, makers,
                                                                         device=device)
    mask = _following_action_mask(envs)
    env = envs.TransformedEnv(base, envs.Compose(mask, *transforms))
    mask.action_spec  # noqa: B018  (makes the spec follow the masks before any collector)
    return env


def _complete_resets(envs: Any) -> type:
    """TorchRL's ``ParallelEnv``, resettable with a partial tensordict (a collector's).

    A collector resets with ``{"_reset", "uav": {}}``. ``ParallelEnv._reset`` copies it into
    its shared buffers with tensordict's ``apply_(..., default=None)``, which stands in for
    a missing sub-tensordict with an empty copy of the *parent* level: under
    ``("uav", "observation")`` that stand-in holds ``observation`` as a sub-tensordict where
    the buffer holds the planes, and ``Tensor.copy_(TensorDict)`` raises. Given every
    sub-tensordict of the buffers (empty where the caller had none), it finds no stand-in
    to make; the leaves sent to the workers are the caller's alone, as before.
    """

    class CompleteResetParallelEnv(envs.ParallelEnv):
        def _reset(self, tensordict: Any, **kwargs: Any) -> Any:
            if tensordict is not None and not tensordict.is_empty():
                full = self.shared_tensordict_parent.empty(recurse=True)
                full.update(tensordict)
                tensordict = full
            return super()._reset(tensordict, **kwargs)

    return CompleteResetParallelEnv


def _following_action_mask(envs: Any) -> Any:
    """TorchRL's ``ActionMask`` on the UAVs' actions, whose masked spec every copy shares.

    TorchRL's ``RandomPolicy`` (what a collector flies with ``policy=None``) samples from a
    copy of the env's action spec made when the collector starts, so ``ActionMask``'s updates
    of the env's spec never reach it and it draws masked actions. Here the action spec's
    ``clone()`` returns the spec itself, so those copies follow the masks too.
    """
    from torchrl.data import Categorical

    class SharedMaskCategorical(Categorical):
        """A ``Categorical`` whose copies are itself: they follow its mask."""

        def clone(self) -> SharedMaskCategorical:
            return self

    class FollowingActionMask(envs.ActionMask):
        @property
        def action_spec(self) -> Any:
            spec = super().action_spec
            if type(spec) is Categorical:  # rebuilt specs (a transform added) are shared again
                spec.__class__ = SharedMaskCategorical
            return spec

        def transform_input_spec(self, input_spec: Any) -> Any:
            input_spec = super().transform_input_spec(input_spec)
            spec = input_spec["full_action_spec"][self.in_keys[0]]
            if type(spec) is Categorical:
                spec.__class__ = SharedMaskCategorical
            return input_spec

    return FollowingActionMask(action_key=(GROUP, "action"), mask_key=(GROUP, "action_mask"))
