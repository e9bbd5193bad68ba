"""Random streams of a mission, derived from (namespace, seed, mission index).

Each mission has separate streams for terrain, start positions, sensor noise, message
drops and UAV failures, so that mission k is the same for every planner and any number of
workers: planners face the same terrain and, where they fly the same path, the same sensor
noise. A planner is reset for mission k with :func:`planner_seed`, a further stream of the
same mission.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from ..config.field_types import is_integer

__all__ = ["NAMESPACES", "MissionStreams", "check_namespace", "mission_streams", "planner_seed"]

NAMESPACES = {"train": 0, "validation": 1, "test": 2}
"""Training, in-training evaluation (checkpoint choice) and held-out test (``ipp-compare``)."""


def check_namespace(namespace: object) -> str:
    """``namespace`` if it names a random-stream namespace: ``train``, ``validation``, ``test``
    or a name of your own (a string with more than blanks); ValueError naming it otherwise."""
    if not isinstance(namespace, str) or not namespace.strip():
        raise ValueError(f"namespace must be 'train', 'validation', 'test' or a name of your "
                         f"own, got {namespace!r}")
    return namespace


def _namespace_id(namespace: str) -> int:
    if namespace in NAMESPACES:
        return NAMESPACES[namespace]
    check_namespace(namespace)
    # A user's own namespace: a stable id well away from the built-in ones.
    return 1000 + zlib.crc32(namespace.encode())


@dataclass(frozen=True)
class MissionStreams:
    """Seed sequences of one mission; call :meth:`sensor` for a measurement's own stream."""

    terrain: np.random.SeedSequence
    starts: np.random.SeedSequence
    sensor_root: np.random.SeedSequence
    drops: np.random.SeedSequence
    failures: np.random.SeedSequence

    def generator(self, name: str) -> np.random.Generator:
        """A fresh Generator of the ``terrain``, ``starts``, ``drops`` or ``failures`` stream."""
        return np.random.Generator(np.random.PCG64(getattr(self, name)))

    def sensor(self, step: int, agent: int) -> np.random.Generator:
        """Noise stream of one measurement (step, agent): common random numbers across planners."""
        seq = np.random.SeedSequence(self.sensor_root.entropy,
                                     spawn_key=(*self.sensor_root.spawn_key, step, agent))
        return np.random.Generator(np.random.PCG64(seq))


def mission_streams(namespace: str, seed: int, mission: int) -> MissionStreams:
    """The independent streams of mission ``mission`` of run ``seed`` in ``namespace``."""
    for name, value in (("seed", seed), ("mission", mission)):
        if not is_integer(value, 0):
            raise ValueError(f"{name} must be a non-negative integer, got {value!r}")
    root = np.random.SeedSequence([_namespace_id(namespace), int(seed), int(mission)])
    terrain, starts, sensor, drops = root.spawn(4)
    # Child 4 is the planner's (planner_seed); child 5 the UAV failures.
    failures = np.random.SeedSequence(root.entropy, spawn_key=(*root.spawn_key, 5))
    return MissionStreams(terrain, starts, sensor, drops, failures)


def planner_seed(seed: int, mission: int, namespace: str = "test") -> int:
    """The seed a planner is reset with for mission ``mission`` of run ``seed``.

    Derived from ``(namespace, seed, mission)`` only (a stream independent of the mission's
    terrain, start, sensor and message streams), so it is the same for every planner and any
    number of workers.
    """
    root = mission_streams(namespace, seed, mission).terrain
    # The terrain stream is child 0 of the mission's root; child 4 is never used by a mission.
    child = np.random.SeedSequence(root.entropy, spawn_key=(*root.spawn_key[:-1], 4))
    return int(child.generate_state(1, np.uint32)[0])
