"""One builder from user settings (flags, a YAML file, Python keywords) to an ``EnvConfig``.

Every command of the toolkit (``ipp-compare``, ``ipp-simulate``, ``ipp-train``, the studies)
and the Python faces (:func:`reports.compare_planners`) build their mission config here, with
one precedence rule::

    explicit value (a flag or keyword that is not None)  >  the config file  >  defaults

"Defaults" are the paper's (:class:`~ipp_toolkit.config.schema.EnvConfig`) with a tool's own
defaults on top (``ipp-train coma`` trains at r_M = 0.5 m with the own-position plane, for
example). A key the YAML file does not write is not "set" by it: the tool's default applies.

Two rules follow the team size wherever it came from: a team without documented fixed start
positions in this world starts at random cells (unless the file itself asks for ``fixed``
for that very team), and the agent-id plane's scale grows to the team size.

This module also owns the small text forms every command shares: :func:`parse_comm`,
:func:`comm_label`, :func:`format_comm` and :func:`safe_name`.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from .files import config_from_dict, config_to_dict, read_config_file
from .schema import (
    EnvConfig,
    FeatureConfig,
    TeamConfig,
    TerrainConfig,
    WorldConfig,
    start_for_team_size,
    terrain_kinds,
)

__all__ = [
    "build_env_config",
    "describe_config",
    "setting_line",
    "parse_comm",
    "comm_label",
    "format_comm",
    "safe_name",
    "named_terrain_kinds",
    "parse_feature_flags",
    "merge_sections",
]


def parse_comm(text: str | float, name: str = "--comm") -> float:
    """A communication range from text: metres (>= 0) or ``inf``; ValueError naming ``name``."""
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be metres or 'inf', got {text!r}") from None
    if math.isnan(value) or value < 0:
        raise ValueError(f"{name} must be >= 0 metres or 'inf', got {text!r}")
    return value


def comm_label(value: float) -> str:
    """A range as a file-name word: ``25``, ``0`` or ``inf``."""
    return "inf" if math.isinf(value) else f"{value:g}"


def format_comm(value: float) -> str:
    """A range for people: ``25 m``, ``0 m`` or ``inf``."""
    return "inf" if math.isinf(value) else f"{value:g} m"


def safe_name(label: str) -> str:
    """``label`` reduced to a file-name-safe word (letters, digits, ``.``, ``_``, ``-``)."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", label).strip("._") or "planner"


def named_terrain_kinds() -> tuple[str, ...]:
    """Terrain kinds selectable by name (a raster is selected by giving its file)."""
    return tuple(kind for kind in terrain_kinds() if kind != "raster")


def merge_sections(base: Mapping[str, Any], top: Mapping[str, Any]) -> dict[str, Any]:
    """Section-wise merge of two nested config dicts; ``top`` wins key by key."""
    merged = {name: dict(values) for name, values in base.items()}
    for name, values in top.items():
        if isinstance(values, Mapping) and isinstance(merged.get(name), dict):
            merged[name] = {**merged[name], **values}
        else:
            merged[name] = values
    return merged


def _check_raster_file(name: str, nan_policy: str) -> str:
    path = Path(name)
    if not path.exists():
        raise ValueError(f"cannot read terrain file {name!r}: no such file (terrain is one of "
                         f"{', '.join(named_terrain_kinds())} or a raster FILE)")
    if not path.is_file():
        raise ValueError(f"cannot read terrain file {name!r}: not a file")
    from ..world.terrain import load_raster, prepare_raster

    try:
        prepare_raster(load_raster(path), nan_policy, repr(name))
    except OSError as err:
        raise ValueError(f"cannot read terrain file {name!r}: {err.strerror}") from err
    return str(path.resolve())


def _terrain_overrides(terrain: str | os.PathLike[str] | None, threshold: float | None,
                       layered: Mapping[str, Any]) -> dict[str, Any]:
    section: dict[str, Any] = {}
    if threshold is not None:
        if isinstance(threshold, bool) or not math.isfinite(float(threshold)):
            raise ValueError(f"threshold must be a finite number, got {threshold!r}")
        section["threshold"] = float(threshold)
    if terrain is None:
        return section
    name = os.fspath(terrain)
    if name in named_terrain_kinds():
        return {**section, "kind": name, "raster": None}
    current = layered.get("terrain", {})
    if name == "raster":
        if not current.get("raster"):
            raise ValueError("terrain 'raster' needs a raster file: give the FILE as terrain "
                             "(or a config with terrain.raster)")
        name = current["raster"]
    nan_policy = current.get("nan_policy", TerrainConfig.nan_policy)
    return {**section, "kind": "raster", "raster": _check_raster_file(name, nan_policy)}


def build_env_config(config: EnvConfig | str | os.PathLike[str] | None = None, *,
                     defaults: Mapping[str, Mapping[str, Any]] | None = None,
                     agents: int | None = None, comm: float | None = None,
                     terrain: str | os.PathLike[str] | None = None,
                     threshold: float | None = None,
                     threshold_quantile: float | None = None,
                     resolution: float | None = None,
                     budget: int | None = None, area_size: float | None = None,
                     features: Mapping[str, bool | int | float] | None = None,
                     grid_spacing: float | None = None) -> EnvConfig:
    """The mission config of a command: defaults < ``config`` < explicit keywords.

    Args:
        config: a YAML path (only the keys it writes count as set), an :class:`EnvConfig`
            (every field counts as set) or None.
        defaults: the tool's own defaults over the paper's, as nested section dicts, e.g.
            ``{"world": {"resolution": 0.5}}``.
        agents: team size N (None: not given).
        comm: communication range D in metres, ``math.inf`` for full.
        terrain: a registered kind (``split``, ``split-axis``, ``blobs``, ...), a raster FILE
            (kind ``raster``; needs a threshold) or ``raster`` (the config's file).
        threshold: raster threshold in the raster's units (cells whose mean value is >= it
            are interesting); refused with a synthetic terrain.
        threshold_quantile: the threshold as a quantile q of the values instead (1 - q of the
            cells are interesting): rasters, ``fractal`` and ``real``.
        resolution, budget, area_size: map resolution r_M (m), steps B, side of the area (m).
        grid_spacing: horizontal distance between waypoints (m); the altitudes stay.
        features: feature switches, e.g. ``{"own_position": True}``.

    Raises:
        ValueError: a bad value (the message names it and, for a file, the file), an
            unreadable terrain file, a threshold without a raster or a raster without one, or
            an invalid resulting configuration.
    """
    given, source = _given_sections(config)
    layered = merge_sections(defaults or {}, given)
    flags = _flag_sections(layered, agents=agents, comm=comm, terrain=terrain,
                           threshold=threshold, threshold_quantile=threshold_quantile,
                           resolution=resolution, budget=budget, area_size=area_size,
                           features=features, grid_spacing=grid_spacing)
    layered = merge_sections(layered, flags)
    try:
        draft = config_from_dict(_with_team_rules(layered, team_from_flag=agents is not None,
                                                  start_given="start" in given.get("team", {})))
    except ValueError as err:
        raise ValueError(f"{err} (in {source})" if source and "(in " not in str(err)
                         else str(err)) from None
    if threshold is not None and draft.terrain.kind != "raster":
        raise ValueError(f"threshold {threshold!r} is in a raster's units, but the terrain is "
                         f"{draft.terrain.kind!r}; give a raster FILE as terrain or drop the "
                         "threshold")
    return draft


def _given_sections(config: EnvConfig | str | os.PathLike[str] | None
                    ) -> tuple[dict[str, Any], str]:
    """The sections ``config`` sets, and where they come from (for error messages)."""
    if isinstance(config, EnvConfig):
        return config_to_dict(config), "the given config"
    if config is not None:
        if not isinstance(config, str | os.PathLike):
            raise TypeError(f"config must be an EnvConfig, a YAML file path or None, got "
                            f"{type(config).__name__} {config!r:.80}")
        return read_config_file(config), f"config file {os.fspath(config)!r}"
    return {}, ""


def _flag_sections(layered: dict[str, Any], *, agents: int | None, comm: float | None,
                   terrain: str | os.PathLike[str] | None, threshold: float | None,
                   threshold_quantile: float | None, resolution: float | None,
                   budget: int | None, area_size: float | None,
                   features: Mapping[str, bool | int | float] | None,
                   grid_spacing: float | None) -> dict[str, dict[str, Any]]:
    """The sections the explicit keywords of :func:`build_env_config` set, checked; the
    terrain's read against ``layered`` (the defaults under the config)."""
    if terrain is not None and not isinstance(terrain, str | os.PathLike):
        raise TypeError(f"terrain must be a terrain kind or a raster file path, got "
                        f"{type(terrain).__name__}; to fly an array, save it with numpy.save "
                        "and give the .npy file")
    if agents is not None and (isinstance(agents, bool) or int(agents) != agents or agents < 1):
        raise ValueError(f"agents must be an integer >= 1, got {agents!r}")
    if comm is not None:
        comm = parse_comm(comm, "comm")
    flags: dict[str, dict[str, Any]] = {}
    world = {key: float(value) for key, value in (("resolution", resolution),
                                                 ("area_size", area_size),
                                                 ("grid_spacing", grid_spacing))
             if value is not None}
    if world:
        flags["world"] = world
    team: dict[str, Any] = {}
    if agents is not None:
        team["n_agents"] = int(agents)
    if comm is not None:
        team["comm_range"] = comm
    if budget is not None:
        team["budget"] = budget
    if team:
        flags["team"] = team
    if features:
        flags["features"] = dict(features)
    terrain_section = _terrain_overrides(terrain, threshold, layered)
    if threshold_quantile is not None:
        terrain_section["threshold_quantile"] = threshold_quantile
        terrain_section.setdefault("threshold", None)
    elif threshold is not None:
        terrain_section["threshold_quantile"] = None
    if terrain_section:
        flags["terrain"] = terrain_section
    return flags


def _with_team_rules(layered: dict[str, Any], team_from_flag: bool,
                     start_given: bool) -> dict[str, Any]:
    """The fixed-start fallback and the id-scale rule applied to a layered config dict."""
    team = layered.get("team", {})
    n_agents = team.get("n_agents", TeamConfig.n_agents)
    if isinstance(n_agents, bool) or not isinstance(n_agents, int):
        return layered  # the config's own validation names the bad value
    try:
        world = WorldConfig(**{key: tuple(value) if isinstance(value, list) else value
                               for key, value in layered.get("world", {}).items()})
    except (TypeError, ValueError):
        return layered  # the config's own validation names the bad value
    rules: dict[str, dict[str, Any]] = {}
    start = team.get("start", TeamConfig.start)
    if team_from_flag or not start_given:
        fitted = start_for_team_size(start, n_agents, world)
        if fitted != start:
            rules["team"] = {"start": fitted}
    features = layered.get("features", {})
    scale = features.get("agent_id_scale", FeatureConfig.agent_id_scale)
    # Only a valid scale is raised to fit the team: 0 or -1 is refused by the config's own
    # validation, not silently replaced.
    if features.get("agent_id", True) and isinstance(scale, int) and not isinstance(scale, bool) \
            and 1 <= scale < n_agents:
        rules["features"] = {"agent_id_scale": n_agents}
    return merge_sections(layered, rules)


def describe_config(config: EnvConfig) -> str:
    """One line naming the setting a command runs: team, range, terrain, map, budget."""
    terrain = config.terrain
    where = terrain.kind
    if terrain.kind == "raster":
        if terrain.threshold is not None:
            level = f">= {terrain.threshold:g}"
        else:
            low, high = terrain.threshold_quantile  # type: ignore[misc]
            level = f">= quantile {low:g}" if low == high else f">= quantile in [{low:g}, {high:g}]"
        where = f"raster {Path(terrain.raster or '').name} {level}"
    return (f"{config.team.n_agents} UAVs ({config.team.start} starts), "
            f"D = {format_comm(config.team.comm_range)}, terrain {where}, "
            f"{config.world.area_size:g} m area at r_M = {config.world.resolution:g} m, "
            f"waypoints every {config.world.grid_spacing:g} m, "
            f"budget {config.team.budget} steps")


def setting_line(config: EnvConfig, config_file: str | os.PathLike[str] | None = None) -> str:
    """The ``setting: ...`` line every command prints (to stderr) before it runs: the setting
    in force (:func:`describe_config`) and the ``--config`` file it was read over, if any."""
    line = f"setting: {describe_config(config)}"
    return line + (f" (config file {str(config_file)!r})" if config_file else "")


_TRUE, _FALSE = ("true", "1", "on", "yes"), ("false", "0", "off", "no")


def parse_feature_flags(items: Sequence[str]) -> dict[str, bool | int | float | str]:
    """``--feature NAME=VALUE`` flags as a ``features`` section, typed by :class:`FeatureConfig`.

    Switches take true/false (also 1/0, on/off, yes/no); ``gain_smoothing`` a number of
    metres; ``agent_id_scale`` and ``gain_false_positive_steps`` integers; ``gain_interest``
    a word or a path, as written.

    Raises:
        ValueError: an unknown feature or a value of the wrong kind (the message names it).
    """
    kinds = {f.name: f.type for f in dataclasses.fields(FeatureConfig)}
    parsed: dict[str, bool | int | float | str] = {}
    for item in items:
        name, sep, raw = (part.strip() for part in item.partition("="))
        if not sep or name not in kinds:
            known = ", ".join(kinds)
            raise ValueError(f"--feature expects NAME=VALUE with NAME one of {known}; "
                             f"got {item!r}")
        kind = kinds[name]
        try:
            if kind in (bool, "bool"):
                if raw.lower() not in _TRUE + _FALSE:
                    raise ValueError
                parsed[name] = raw.lower() in _TRUE
            elif kind in (int, "int"):
                parsed[name] = int(raw)
            elif kind in (str, "str"):
                parsed[name] = raw
            else:
                parsed[name] = float(raw)
        except ValueError:
            wanted = {bool: "true|false", "bool": "true|false", int: "an integer",
                      "int": "an integer"}.get(kind, "a number")
            raise ValueError(f"--feature {item!r}: {name} takes {wanted}") from None
    return parsed
