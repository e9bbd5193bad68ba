"""Mission animations: one GIF per planner (``ipp-compare --animate``)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from PIL import Image

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.io import atomic_write
from ipp_toolkit.planning import Planner
from ipp_toolkit.runs.evaluation import run_mission
from ipp_toolkit.sim.mission import MissionState
from ipp_toolkit.sim.rendering import render_state

__all__ = ["animate_mission"]


def animate_mission(config: EnvConfig, planner: Planner, path: str | os.PathLike[str],
                    seed: int = 0, mission: int = 0, namespace: str = "test",
                    frame_ms: int = 500) -> Path:
    """Fly one mission with ``planner`` and write it as an animated GIF (one frame per step).

    Each frame shows the terrain, the team's global map with the UAVs and their footprints,
    and every UAV's own map (:func:`ipp_toolkit.sim.rendering.render_state`).

    Args:
        config: the mission configuration.
        planner: the planner (reset by the mission run).
        path: the GIF to write (atomically).
        seed, mission, namespace: which mission (the same as in ``ipp-compare``).
        frame_ms: display time of each frame in milliseconds.

    Returns:
        the written path.
    """
    frames: list[np.ndarray] = []

    def record(state: MissionState) -> None:
        frames.append(render_state(state))

    run_mission(config, planner, seed, mission, namespace=namespace, observer=record)
    images = [Image.fromarray(frame) for frame in frames]
    # The last frame lingers so the final map can be read.
    durations = [frame_ms] * (len(images) - 1) + [frame_ms * 4]

    def write(handle) -> None:
        images[0].save(handle, format="GIF", save_all=True, append_images=images[1:],
                       duration=durations, loop=0)

    atomic_write(path, write)
    return Path(path)
