"""A mission's configuration as nested dicts and YAML files: read, check, build, write.

:mod:`ipp_toolkit.config.schema` owns the dataclasses and their validation; this module owns their
plain form (what a ``--config`` file, a run folder's ``config.json`` and the result folders
hold). Unknown sections and keys are refused by name, and the file's name is in every
message about a file.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from dataclasses import fields
from pathlib import Path
from typing import Any

import yaml

from ..io import atomic_write, read_yaml
from .limits import check_limit
from .schema import _SECTIONS, EnvConfig, _build

__all__ = ["read_config_file", "load_config", "save_config", "config_from_dict",
           "config_to_dict", "as_env_config", "ConfigLike", "changed_fields",
           "env_config_changes", "check_same_run"]

ConfigLike = EnvConfig | Mapping[str, Any] | str | os.PathLike[str] | None
"""What an env constructor takes as its config (:func:`as_env_config`)."""


def _check_config_size(size: int, label: str) -> None:
    """LimitError when a config file of ``size`` bytes is over the ``config_bytes`` limit."""
    check_limit("config_bytes", size, label, estimate=False)


def _check_keys(values: Mapping[str, Any]) -> None:
    """Refuse keys that are not strings, unknown sections, sections that are not mappings
    and unknown keys."""
    _check_string_keys(values, "")
    for name, section in values.items():
        if isinstance(section, Mapping):
            _check_string_keys(section, f" in section {name!r}")
    unknown = sorted(set(values) - set(_SECTIONS))
    if unknown:
        raise ValueError(f"invalid config: unknown section(s) {unknown}; "
                         f"known sections: {sorted(_SECTIONS)}")
    for name, section in values.items():
        if not isinstance(section, Mapping):
            raise ValueError(f"invalid config: section {name!r} must be a mapping, "
                             f"got {section!r}")
        known = {f.name for f in fields(_SECTIONS[name])}
        unknown = sorted(set(section) - known)
        if unknown:
            raise ValueError(f"invalid config: unknown key(s) {unknown} in section {name!r}; "
                             f"known keys: {sorted(known)}")


def _check_string_keys(values: Mapping[Any, Any], where: str) -> None:
    """ValueError naming the first key of ``values`` that is not a string (``1: 2`` in YAML,
    or mixed ``1`` and ``a`` keys, which cannot even be sorted for a message)."""
    for key in values:
        if not isinstance(key, str):
            raise ValueError(f"invalid config: key {key!r:.80}{where} is not a name (a "
                             f"string) but of type {type(key).__name__}")


def config_from_dict(values: Mapping[str, Any] | None) -> EnvConfig:
    """Build an :class:`EnvConfig` from nested dicts; unknown sections or keys are rejected."""
    values = dict(values or {})
    _check_keys(values)
    return EnvConfig(**{name: _build(cls, values[name], name)
                        for name, cls in _SECTIONS.items() if name in values})


def config_to_dict(config: EnvConfig) -> dict[str, Any]:
    """Nested plain dict of a config (tuples as lists, inf as the string 'inf'), YAML/JSON-safe."""

    def plain(value: Any) -> Any:
        if isinstance(value, tuple):
            return [plain(v) for v in value]
        if isinstance(value, float) and math.isinf(value):
            return "inf"
        return value

    return {name: {k: plain(v) for k, v in dataclasses.asdict(getattr(config, name)).items()}
            for name in _SECTIONS}


def read_config_file(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The sections a YAML config file writes, as nested dicts, checked but not filled.

    Raises:
        ValueError: the file cannot be read, is not YAML, writes a key twice, is not a mapping
            of sections, or has an unknown section or key (the message names the file).
    """
    path = Path(path)
    values = read_yaml(path, "config file", check_size=_check_config_size)
    if values is None:
        return {}
    if not isinstance(values, Mapping):
        raise ValueError(f"config file {str(path)!r} must hold a mapping of sections")
    try:
        _check_keys(values)
    except ValueError as err:
        raise ValueError(f"{err} (in config file {str(path)!r})") from None
    return {name: dict(section) for name, section in values.items()}


def load_config(path: str | os.PathLike[str]) -> EnvConfig:
    """Read a YAML config; missing sections and keys take their defaults."""
    values = read_config_file(path)
    try:
        return config_from_dict(values)
    except ValueError as err:
        raise ValueError(f"{err} (in config file {os.fspath(path)!r})") from None


def as_env_config(config: ConfigLike, name: str = "config") -> EnvConfig:
    """The :class:`EnvConfig` that ``config`` stands for, as every env constructor reads it.

    Args:
        config: an ``EnvConfig``; a plain dict of sections (``{"team": {"n_agents": 2}}``,
            missing sections and keys take their defaults); the path of a YAML config file; or
            None (the paper's defaults).
        name: the argument's name in messages.

    Raises:
        ValueError: another type (named), or a dict or file with an unknown section or key
            or a bad value (named).
    """
    if config is None:
        return EnvConfig()
    if isinstance(config, EnvConfig):
        return config
    if isinstance(config, Mapping):
        return config_from_dict(config)
    if isinstance(config, str | os.PathLike):
        return load_config(config)
    raise ValueError(f"{name} must be an EnvConfig, a dict of config sections or the path of a "
                     f"YAML config file, got {type(config).__name__}")


def changed_fields(stored: Mapping[str, Any], given: Mapping[str, Any],
                   prefix: str = "") -> list[str]:
    """``"NAME = STORED in the run, GIVEN now"`` for every field that differs, nested
    mappings (config sections) as ``section.name``; what a refused resume names instead of
    printing two whole configs."""
    changes = []
    for name in sorted(set(stored) | set(given), key=str):
        old, new = stored.get(name), given.get(name)
        if isinstance(old, Mapping) and isinstance(new, Mapping):
            changes += changed_fields(old, new, f"{prefix}{name}.")
        elif old != new:
            changes.append(f"{prefix}{name} = {old!r} in the run, {new!r} now")
    return changes


def env_config_changes(stored: EnvConfig, given: EnvConfig) -> list[str]:
    """:func:`changed_fields` of two mission configs (``team.n_agents = 4 in the run, ...``)."""
    return changed_fields(config_to_dict(stored), config_to_dict(given))


def check_same_run(where: str, what: str, stored: Any, given: Any, free: str,
                   stored_env: EnvConfig, given_env: EnvConfig) -> None:
    """Refuse to resume a run of other settings, naming each differing field.

    Args:
        where: the checkpoint, as the message names it.
        what: the learner (``PPO``, ``RLlib``, ...).
        stored, given: the run's config dataclass in the checkpoint and the one given now.
        free: the one field that may change (``total_timesteps``, ``iterations``).
        stored_env, given_env: the mission configs.

    Raises:
        ValueError: ``cannot resume WHERE: its WHAT config differs (n_steps = 32 in the run,
            16 now); ...`` or ``... another env config (team.n_agents = ...)``.
    """
    changes = changed_fields(
        dataclasses.asdict(dataclasses.replace(stored, **{free: getattr(given, free)})),
        dataclasses.asdict(given))
    if changes:
        raise ValueError(f"cannot resume {where!r}: its {what} config differs "
                         f"({'; '.join(changes)}); only {free} may change")
    changes = env_config_changes(stored_env, given_env)
    if changes:
        raise ValueError(f"cannot resume {where!r}: it was trained on another env config "
                         f"({'; '.join(changes)})")


def save_config(config: EnvConfig, path: str | os.PathLike[str]) -> None:
    """Write a config as YAML (atomically: a temporary file renamed into place)."""
    text = yaml.safe_dump(config_to_dict(config), sort_keys=False).encode()
    atomic_write(path, lambda handle: handle.write(text))
