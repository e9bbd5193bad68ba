"""Sizes a file or a flag can ask for, and the limits they are held to.

A config file, a flag or a checkpoint can ask for more than a machine holds (a 1e-5 m map
resolution, a budget of 1e9 steps, a 20000 x 20000 raster, a network 10^6 channels wide).
Each such size is estimated before anything is built and refused above its limit with the
estimate in the message, instead of swapping the machine to a halt or failing deep inside.
Every limit is lifted by an environment variable (a number, or ``inf`` for none); the table
is in docs/environment.md.

This module owns the limits and the estimates; the places that build things call its checks.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .schema import EnvConfig

#: The largest ``reward.alpha`` and ``|reward.beta|``: a return sums budget x (alpha + |beta|),
#: and 1e308 overflows to inf.
MAX_REWARD_SCALE = 1e6

__all__ = ["LimitError", "Limit", "LIMITS", "limit_value", "check_limit",
           "mission_bytes", "check_mission", "check_rollout", "check_result_rows",
           "check_layer_size", "check_parameters", "check_raster_cells", "check_resampling"]

GIB = 1024 ** 3


class LimitError(ValueError):
    """A size over its limit (the message gives the estimate and how to lift the limit)."""


@dataclass(frozen=True)
class Limit:
    """One limit: its default and the environment variable that overrides it."""

    env: str
    default: float
    unit: str
    what: str


LIMITS = {
    "mission_memory": Limit("IPP_MAX_MISSION_GB", 8.0, "GiB",
                            "estimated memory of the missions flown at once"),
    "result_rows": Limit("IPP_MAX_RESULT_ROWS", 5_000_000, "rows",
                         "result rows of one evaluation ((budget + 1) x missions x planners)"),
    "layer_size": Limit("IPP_MAX_LAYER_SIZE", 65_536, "units",
                        "width, hidden or features_dim of a network"),
    "parameters": Limit("IPP_MAX_PARAMETERS", 100_000_000, "parameters",
                        "parameters of the networks of one policy or run"),
    "raster_cells": Limit("IPP_MAX_RASTER_CELLS", 100_000_000, "cells",
                          "cells of a raster file read as terrain"),
    "resample_weights": Limit("IPP_MAX_RESAMPLE_WEIGHTS", 100_000_000, "weights",
                              "overlap weights of resampling a raster of h x w pixels onto "
                              "the H x W map: H x h + W x w"),
    "rollout_memory": Limit("IPP_MAX_ROLLOUT_GB", 8.0, "GiB",
                            "estimated memory of a trainer's rollout of observations"),
    "mission_steps": Limit("IPP_MAX_MISSION_STEPS", 100_000, "UAV-steps",
                           "steps of one mission times its UAVs: budget x n_agents"),
    "config_bytes": Limit("IPP_MAX_CONFIG_BYTES", 4 * 1024 ** 2, "bytes",
                          "size of a YAML config file"),
    "zip_member_bytes": Limit("IPP_MAX_ZIP_MEMBER_BYTES", 2 * GIB, "bytes",
                              "inflated size of one member of an SB3 zip or .npz file"),
}

# Bytes per map cell for each of the N + 1 maps (agents' and global: value index, gain
# planes, scratch), and per cell once (terrain, ground truth, geometry); measured peak
# resident memory of ig missions at 0.1 and 0.05 m with 2 and 8 UAVs was 28 B per map cell.
_BYTES_PER_MAP_CELL = 32
_BYTES_PER_CELL = 32
_BYTES_PER_AGENT_STEP = 4096  # planes, history and trajectory of one UAV step
_BYTES_PER_WAYPOINT = 64  # per waypoint and altitude: footprints, blocks, gain totals
# Measured: random actions with 4 UAVs at the default 0.1 m took 4.3 ms per step, ~1 ms per
# UAV-step; a planner adds its own time on top.
_SECONDS_PER_UAV_STEP = 1e-3


def limit_value(name: str) -> float:
    """The limit ``name`` of :data:`LIMITS` in force (its environment variable, else the
    default); ValueError naming the variable when it is not a positive number or ``inf``."""
    limit = LIMITS[name]
    text = os.environ.get(limit.env)
    if text is None or text.strip() == "":
        return float(limit.default)
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not value > 0:
        raise ValueError(f"environment variable {limit.env}={text!r} must be a positive number "
                         "or inf")
    return value


def _format(value: float, unit: str) -> str:
    if unit == "GiB":
        return f"{value:.3g} GiB"
    return f"{value:,.0f} {unit}" if value < 1e15 else f"{value:.3g} {unit}"


def check_limit(name: str, value: float, what: str, estimate: bool = True) -> None:
    """LimitError when ``value`` (in the limit's unit) exceeds the limit ``name``; the message
    says ``what`` needs the value (``estimate``) or is over the limit."""
    bound = limit_value(name)
    if value > bound:
        limit = LIMITS[name]
        head = f"{what} needs {_format(value, limit.unit)}, over" if estimate else \
            f"{what} is over"
        raise LimitError(f"{head} the limit of {_format(bound, limit.unit)} ({limit.what}); "
                         f"lower it, or set {limit.env} (a number, or inf) to lift the limit")


def mission_bytes(config: EnvConfig) -> float:
    """Estimated peak memory in bytes of one mission of ``config`` (map cells x maps x planes,
    waypoints x altitudes x maps, budget x agents); a float, so that absurd sizes do not
    overflow."""
    side = _ratio(config.world.area_size, config.world.resolution)
    cells = side * side  # not ** 2: a float power raises OverflowError past 1e308, * gives inf
    maps = config.team.n_agents + 1
    altitudes = len(config.world.altitudes)
    per_map = _BYTES_PER_MAP_CELL + 4 * max(0, altitudes - 3)
    steps = float(config.team.budget) * config.team.n_agents * _BYTES_PER_AGENT_STEP
    grid = _ratio(config.world.area_size, config.world.grid_spacing) + 1
    waypoints = grid * grid * altitudes
    return (cells * (per_map * maps + _BYTES_PER_CELL) + steps
            + waypoints * (_BYTES_PER_WAYPOINT + 16 * maps))


def _ratio(size: float, step: float) -> float:
    """``size / step`` as a float, inf where it overflows (1e200 m at 1e-300 m), never an
    OverflowError: the estimates must refuse absurd sizes, not fail on them."""
    try:
        return float(size) / float(step)
    except (OverflowError, ZeroDivisionError):
        return math.inf


def check_mission(config: EnvConfig, at_once: int = 1) -> None:
    """LimitError when ``at_once`` missions of ``config`` would not fit the memory limit, or
    one mission would take more UAV-steps than the ``mission_steps`` limit."""
    estimate = mission_bytes(config) * max(1, at_once)
    cells = _ratio(config.world.area_size, config.world.resolution)
    grid = _ratio(config.world.area_size, config.world.grid_spacing) + 1
    what = (f"a mission of {cells:.6g} x {cells:.6g} map cells (area {config.world.area_size:g}"
            f" m at r_M = {config.world.resolution:g} m), {grid:.6g} x {grid:.6g} waypoints, "
            f"{config.team.n_agents} UAVs and a budget of {config.team.budget}")
    if at_once > 1:
        what += f", {at_once} at once,"
    check_limit("mission_memory", estimate / GIB, what)
    uav_steps = float(config.team.budget) * config.team.n_agents
    hours = uav_steps * _SECONDS_PER_UAV_STEP / 3600
    check_limit("mission_steps", uav_steps,
                f"a mission of budget {config.team.budget} with {config.team.n_agents} UAVs "
                f"(about {hours:.2g} h per mission for the simulator alone, more with a "
                "planner)")


def check_rollout(transitions: float, channels: int, grid: int, what: str,
                  copies: float = 2.0) -> None:
    """LimitError when ``transitions`` stored observations of ``channels`` x ``grid`` x
    ``grid`` float32 planes, ``copies`` times over (a buffer and the minibatches cut from it;
    a critic's inputs beside the actor's), would not fit the ``rollout_memory`` limit; checked
    before a trainer allocates them (``--n-steps 10000000`` asked for 505 GiB at once)."""
    per_transition = float(channels) * float(grid) * float(grid) * 4.0 * copies + 64.0
    check_limit("rollout_memory", float(transitions) * per_transition / GIB, what)


def check_result_rows(budget: int, missions: int, planners: int) -> None:
    """LimitError when an evaluation's rows would exceed the limit."""
    rows = (float(budget) + 1) * float(missions) * float(planners)
    check_limit("result_rows", rows, f"{missions} missions x {planners} planners of "
                f"{budget} steps")


def check_layer_size(name: str, value: Any, where: str) -> None:
    """LimitError when a network size ``name`` = ``value`` exceeds the limit (``where``: the
    config or file it comes from)."""
    if isinstance(value, int) and not isinstance(value, bool):
        check_limit("layer_size", value, f"{where}: {name} = {value}", estimate=False)


def check_parameters(count: float, where: str) -> None:
    """LimitError when networks of ``count`` parameters exceed the limit."""
    check_limit("parameters", count, f"the networks of {where}")


def check_raster_cells(shape: tuple[int, ...], where: str) -> None:
    """LimitError when a raster of ``shape`` exceeds the limit (checked before reading it)."""
    cells = float(math.prod(int(s) for s in shape))
    check_limit("raster_cells", cells, f"raster {where} ({' x '.join(map(str, shape))})")


def check_resampling(source: tuple[int, int], target: tuple[int, int], where: str) -> None:
    """LimitError when resampling a raster of ``source`` (h, w) pixels onto a map of ``target``
    (H, W) cells needs more overlap weights (H x h + W x w, 8 B each and their temporaries)
    than the limit: a thin raster (1 x 10,000,000) passes the cell limit but not this one."""
    (h, w), (height, width) = source, target
    weights = float(height) * float(h) + float(width) * float(w)
    check_limit("resample_weights", weights,
                f"resampling raster {where} ({h} x {w}) onto the {height} x {width} map")
