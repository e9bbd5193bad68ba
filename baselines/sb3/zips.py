"""SB3 model zips (``model.save(PATH)``) for the ``sb3`` planner, read without unpickling.

An SB3 zip holds ``data`` (JSON: spaces, ``policy_class`` and ``policy_kwargs``; whatever is
not JSON-safe is a cloudpickle blob beside a readable description) and ``policy.pth`` (the
policy's state dict). This module reads only the JSON's readable parts and the weights with
``torch.load(weights_only=True)``; the blobs are never unpickled. The policy is rebuilt from
the classes it knows by name (SB3's and sb3-contrib's policies of the algorithms in
:data:`~baselines.sb3.policies.ALGORITHMS`, their default ``MlpPolicy``, and the toolkit's
:class:`~baselines.sb3.ppo.SmallCNN`), and everything else is refused by name: a custom features
extractor, ``MultiInputPolicy`` or ``CnnPolicy`` (they need other observations than the
(C, G, G) planes the planner feeds), another action space, an unknown ``policy_kwargs`` key,
frame-stacked observations. A zip trained under ``VecNormalize`` flies with the statistics
beside it (:mod:`baselines.sb3.normalization`) and is refused without them.
"""

from __future__ import annotations

import io
import json
import re
import zipfile
from pathlib import Path
from typing import Any

import torch
from gymnasium import spaces
from sb3_contrib.ars.policies import ARSLinearPolicy, ARSPolicy
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from sb3_contrib.common.recurrent.policies import RecurrentActorCriticPolicy
from sb3_contrib.qrdqn.policies import QRDQNPolicy
from stable_baselines3.common.policies import ActorCriticPolicy, BasePolicy
from stable_baselines3.dqn.policies import DQNPolicy

from ipp_toolkit.config.limits import LimitError, check_limit
from ipp_toolkit.io import CheckpointError, check_regular_file

from .normalization import zip_normalization
from .policies import LoadedPolicy, PolicyArchitecture, check_shapes
from .ppo import NoOptimizer, SmallCNN

__all__ = ["is_sb3_zip", "load_sb3_zip"]

#: Policy classes by name: (class, algorithm label for greedy actions).
_POLICIES: dict[str, tuple[type[BasePolicy], str]] = {
    "ActorCriticPolicy": (ActorCriticPolicy, "PPO"),
    "MaskableActorCriticPolicy": (MaskableActorCriticPolicy, "MaskablePPO"),
    "RecurrentActorCriticPolicy": (RecurrentActorCriticPolicy, "RecurrentPPO"),
    "DQNPolicy": (DQNPolicy, "DQN"),
    "QRDQNPolicy": (QRDQNPolicy, "QRDQN"),
    "ARSPolicy": (ARSPolicy, "ARS"),
    "ARSLinearPolicy": (ARSLinearPolicy, "ARS"),
}
#: Features extractors by name (None: the policy's default, a flatten layer).
_EXTRACTORS: dict[str, type | None] = {"FlattenExtractor": None, "SmallCNN": SmallCNN}
#: ``torch.nn`` activations a policy may name.
_ACTIVATIONS = ("ReLU", "Tanh", "ELU", "LeakyReLU", "SiLU", "GELU", "Sigmoid", "Softplus")
#: JSON-valued ``policy_kwargs`` that only shape the network (or do not matter for acting).
_PLAIN_KWARGS = ("net_arch", "features_extractor_kwargs", "ortho_init", "normalize_images",
                 "share_features_extractor", "log_std_init", "full_std", "use_expln",
                 "squash_output", "lstm_hidden_size", "n_lstm_layers", "shared_lstm",
                 "enable_critic_lstm", "lstm_kwargs", "n_quantiles", "with_bias",
                 "optimizer_kwargs")
_CLASS_NAME = re.compile(r"<class '([^']+)'>")


def is_sb3_zip(path: str | Path) -> bool:
    """Whether ``path`` is a zip with SB3's ``data`` and ``policy.pth`` members (False for
    anything but a regular file: the checkpoint loader then refuses it by name)."""
    try:
        check_regular_file(path, "SB3 zip")
        with zipfile.ZipFile(path) as archive:
            names = set(archive.namelist())
    except (OSError, ValueError, zipfile.BadZipFile):
        return False
    return {"data", "policy.pth"} <= names


def read_member(archive: zipfile.ZipFile, name: str, where: str) -> bytes:
    """The bytes of member ``name``, refused (LimitError) above the ``zip_member_bytes``
    limit before they are inflated: a few kilobytes of zip can inflate to gigabytes."""
    check_limit("zip_member_bytes", archive.getinfo(name).file_size,
                f"member {name!r} of {where}", estimate=False)
    # zipfile inflates no more than the header's size (a header that understates it fails
    # the member's CRC check): the check above bounds the memory.
    return archive.read(name)


def _class_name(text: Any) -> str:
    """``"<class 'a.b.Name'>"`` -> ``"a.b.Name"`` (the readable form of a pickled class)."""
    match = _CLASS_NAME.fullmatch(str(text).strip())
    return match.group(1) if match else str(text)


def _policy_class(data: dict[str, Any], where: str) -> tuple[type[BasePolicy], str]:
    record = data.get("policy_class")
    if not isinstance(record, dict):
        raise CheckpointError(f"{where} records no policy_class")
    # The readable part of the pickled class lists its own methods: "<function Name.__init__".
    match = re.match(r"<function (\w+)\.__init__", str(record.get("__init__", "")))
    name = match.group(1) if match else "?"
    module = record.get("__module__", "?")
    if name not in _POLICIES or _POLICIES[name][0].__module__ != module:
        raise CheckpointError(f"{where} holds a {name} policy "
                              f"(module {module}); the sb3 planner flies "
                              f"{', '.join(_POLICIES)} with an MLP or SmallCNN on the "
                              f"(C, G, G) planes")
    return _POLICIES[name]


def _algorithm(data: dict[str, Any], label: str) -> str:
    """The algorithm's name from its recorded fields (the planner only needs the policy's)."""
    if label != "PPO":
        return label
    if "cg_max_steps" in data:
        return "TRPO"
    return "PPO" if "clip_range" in data else "A2C"


def _policy_kwargs(data: dict[str, Any], where: str) -> dict[str, Any]:
    """The policy's constructor kwargs, from the readable part of ``policy_kwargs`` only."""
    record = data.get("policy_kwargs") or {}
    if not isinstance(record, dict):
        raise CheckpointError(f"{where}: unreadable policy_kwargs {record!r}")
    kwargs: dict[str, Any] = {}
    for key, value in record.items():
        if key in (":type:", ":serialized:", "optimizer_class", "optimizer_kwargs"):
            continue  # acting needs no optimiser
        if key == "features_extractor_class":
            name = _class_name(value).rsplit(".", 1)[-1]
            if name not in _EXTRACTORS:
                raise CheckpointError(
                    f"{where} uses the features extractor {_class_name(value)}; the sb3 "
                    f"planner rebuilds only {', '.join(_EXTRACTORS)} (fly a custom "
                    "extractor's policy with your own code)")
            if _EXTRACTORS[name] is not None:
                kwargs[key] = _EXTRACTORS[name]
        elif key == "activation_fn":
            full = _class_name(value)
            name = full.rsplit(".", 1)[-1]
            if not full.startswith("torch.nn.") or name not in _ACTIVATIONS:
                raise CheckpointError(f"{where} uses the activation {full}; the sb3 planner "
                                      f"knows torch.nn's {', '.join(_ACTIVATIONS)}")
            kwargs[key] = getattr(torch.nn, name)
        elif key in _PLAIN_KWARGS and not isinstance(value, str):
            kwargs[key] = value
        else:
            raise CheckpointError(f"{where}: policy_kwargs {key}={value!r} cannot be rebuilt "
                                  "without unpickling; the sb3 planner refuses it")
    return kwargs


def _spaces(data: dict[str, Any], where: str) -> tuple[tuple[int, ...], int]:
    """(observation shape, action count); CheckpointError unless Box planes and Discrete."""
    obs, act = data.get("observation_space") or {}, data.get("action_space") or {}
    obs_type, act_type = _class_name(obs.get(":type:")), _class_name(act.get(":type:"))
    if not obs_type.endswith(".Box"):
        raise CheckpointError(f"{where} was trained on {obs_type} observations; the sb3 "
                              "planner feeds Box (C, G, G) planes (MultiInputPolicy models "
                              "of Dict observations are not flown)")
    if not act_type.endswith(".Discrete"):
        hint = (" (a model of the whole team, ipp_toolkit/UAVTeam-v0: the sb3 planner flies "
                "one shared policy of one UAV's moves; train on gymnasium.make("
                "'ipp_toolkit/UAV-v0') or make_sb3_vec_env)") if act_type.endswith(
                    ".MultiDiscrete") else ""
        raise CheckpointError(f"{where} has a {act_type} action space; the UAVs take one of "
                              f"6 discrete moves{hint}")
    try:
        shape = tuple(int(d) for d in obs["_shape"])
        n_actions = int(act["n"])
    except (KeyError, TypeError, ValueError):
        raise CheckpointError(f"{where}: unreadable observation or action space") from None
    _check_frame_stack(shape, where)
    return shape, n_actions


def _check_frame_stack(shape: tuple[int, ...], where: str) -> None:
    """CheckpointError naming frame stacking for the shapes it gives the (C, G, G) planes:
    (C, G, k G) from SB3's ``VecFrameStack``, (k, C, G, G) from Gymnasium's
    ``FrameStackObservation``."""
    frames = None
    if len(shape) == 3 and shape[1] != shape[2] and shape[2] % shape[1] == 0:
        frames, one = shape[2] // shape[1], (shape[0], shape[1], shape[1])
        how = "stacked on the last axis: SB3's VecFrameStack"
    elif len(shape) == 4 and shape[2] == shape[3]:
        frames, one = shape[0], shape[1:]
        how = "on a new first axis: Gymnasium's FrameStackObservation"
    if frames is not None and frames > 1:
        raise CheckpointError(f"{where} was trained on frame-stacked observations {shape} "
                              f"({frames} frames of {one} planes {how}); the sb3 planner "
                              "feeds one step's planes and does not stack frames: train "
                              "without frame stacking (a RecurrentPPO policy keeps a memory "
                              "and flies)")


def load_sb3_zip(path: str | Path, device: str = "cpu") -> tuple[BasePolicy, LoadedPolicy]:
    """Rebuild the policy of an SB3 ``model.save`` zip and load its weights.

    Returns:
        (policy in eval mode, :class:`~baselines.sb3.policies.LoadedPolicy` with
        ``env_config=None``: a zip does not record the feature switches, so the planner
        observes with the mission's own and checks only the plane shape).

    Raises:
        CheckpointError: an unreadable zip, a policy the planner cannot rebuild (named),
            frame-stacked observations, or a zip trained under ``VecNormalize`` without its
            statistics beside it.
    """
    path = Path(path)
    where = f"SB3 zip {str(path)!r}"
    try:
        check_regular_file(path, "SB3 zip")
        with zipfile.ZipFile(path) as archive:
            data = json.loads(read_member(archive, "data", where))
            weights = torch.load(io.BytesIO(read_member(archive, "policy.pth", where)),
                                 map_location="cpu", weights_only=True)
    except LimitError as error:
        raise CheckpointError(str(error)) from None
    except (OSError, zipfile.BadZipFile, KeyError, ValueError, RuntimeError) as error:
        raise CheckpointError(f"{where} cannot be read: "
                              f"{str(error).splitlines()[0][:200]}") from None
    if not isinstance(data, dict) or not isinstance(weights, dict):
        raise CheckpointError(f"{where} is not an SB3 model (no data record or state dict)")
    policy_cls, label = _policy_class(data, where)
    obs_shape, n_actions = _spaces(data, where)
    kwargs = _policy_kwargs(data, where)
    if "n_quantiles" in data and policy_cls is QRDQNPolicy:
        kwargs.setdefault("n_quantiles", int(data["n_quantiles"]))
    observation_space = spaces.Box(-1.0, 1.0, obs_shape, dtype="float32")
    action_space = spaces.Discrete(n_actions)
    try:
        if issubclass(policy_cls, ARSPolicy):
            policy = policy_cls(observation_space, action_space, **kwargs)
        else:
            policy = policy_cls(observation_space, action_space, lambda _: 1e-4,
                                optimizer_class=NoOptimizer, **kwargs)
        policy.load_state_dict(weights)
    except (RuntimeError, TypeError, ValueError, AssertionError) as error:
        raise CheckpointError(f"{where}: its weights do not fit the {policy_cls.__name__} its "
                              f"records describe ({str(error).splitlines()[0][:200]})") from None
    policy = policy.to(device)
    policy.set_training_mode(False)
    meta = LoadedPolicy(algo=_algorithm(data, label), obs_shape=obs_shape,  # type: ignore[arg-type]
                        n_actions=n_actions, architecture=PolicyArchitecture(),
                        env_config=None, num_timesteps=int(data.get("num_timesteps", 0)),
                        format="sb3-zip", record={"policy_class": policy_cls.__name__},
                        normalization=zip_normalization(path, data, obs_shape))
    check_shapes(path, meta)
    return policy, meta
