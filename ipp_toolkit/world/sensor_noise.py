"""The sensor noise of one step, all UAVs at once: the numbers of the per-measurement streams.

Each measurement (step s, UAV k) draws its cells' noise from its own stream,
``MissionStreams.sensor(s, k).random(cells, dtype=np.float32)``
(:mod:`ipp_toolkit.world.seeding`): a ``SeedSequence``, a ``PCG64`` and a ``Generator`` built for
every measurement, about 25 us each, and NumPy's draws at about 3 ns a number.
:func:`fill_sensor_noise` gives the
same numbers from one compiled pass (:func:`ipp_toolkit._native.kernels.sensor_noise`, which follows
NumPy's seeding and generator bit for bit); it checks that pass against NumPy once per process
and uses NumPy itself wherever the compiled kernels are off or the check fails (a NumPy whose
streams changed).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._native import kernels
from .seeding import MissionStreams, mission_streams

__all__ = ["fill_sensor_noise", "entropy_prefix", "assembled_entropy", "compiled_noise_ok"]

_POOL_SIZE = 4
_verified: bool | None = None


def _uint32_words(value: object) -> list[int]:
    """NumPy's coercion of a seed (int or nested sequence of ints) to uint32 words."""
    if type(value) is int and 0 <= value <= 0xFFFFFFFF:  # the common case, one word
        return [value]
    if isinstance(value, int | np.integer):
        number = int(value)
        if number < 0:
            raise ValueError(f"a seed must be non-negative, got {number}")
        words = [] if number else [0]
        while number:
            words.append(number & 0xFFFFFFFF)
            number >>= 32
        return words
    return [word for item in value for word in _uint32_words(item)]  # type: ignore[attr-defined]


def entropy_prefix(streams: MissionStreams) -> list[int]:
    """The uint32 words every sensor stream of ``streams`` starts its entropy with.

    The run entropy, padded with zeros to the pool size (a spawned sequence's rule), then the
    spawn key of the sensor root; the stream of (step, k) appends ``step`` and ``k``.
    """
    root = streams.sensor_root
    run = _uint32_words(root.entropy)
    run += [0] * (_POOL_SIZE - len(run))
    return run + _uint32_words(root.spawn_key)


def assembled_entropy(streams: MissionStreams, step: int, agents: Sequence[int],
                      prefix: list[int] | None = None) -> np.ndarray:
    """(len(agents), n) uint32: the entropy ``streams.sensor(step, k)``'s SeedSequence mixes.

    ``prefix`` is :func:`entropy_prefix` of ``streams`` (computed when omitted).
    """
    start = (entropy_prefix(streams) if prefix is None else prefix) + _uint32_words(step)
    return np.array([start + _uint32_words(agent) for agent in agents], dtype=np.uint32)


def _numpy_noise(streams: MissionStreams, step: int, agents: Sequence[int],
                 offsets: np.ndarray, out: np.ndarray) -> None:
    for f, agent in enumerate(agents):
        streams.sensor(step, agent).random(out=out[offsets[f]:offsets[f + 1]],
                                           dtype=np.float32)


def compiled_noise_ok() -> bool:
    """Whether the compiled noise equals NumPy's here (checked once per process)."""
    global _verified
    if _verified is None:
        if not kernels.AVAILABLE:
            return False
        # Seeds of one and of two words, a long spawn key, both halves of PCG64's outputs.
        ok = True
        for seed, mission, step, agent in ((0, 0, 0, 0), (2**40 + 3, 7, 15, 5)):
            streams = mission_streams("test", seed, mission)
            offsets = np.array([0, 37], dtype=np.int64)
            expected, got = np.empty(37, np.float32), np.empty(37, np.float32)
            _numpy_noise(streams, step, [agent], offsets, expected)
            kernels.sensor_noise(assembled_entropy(streams, step, [agent]), offsets, got)
            ok &= bool(np.array_equal(expected.view(np.uint32), got.view(np.uint32)))
        _verified = ok
    return _verified and kernels.AVAILABLE


def fill_sensor_noise(streams: MissionStreams, step: int, agents: Sequence[int],
                      offsets: np.ndarray, out: np.ndarray,
                      prefix: list[int] | None = None) -> None:
    """``out[offsets[f]:offsets[f + 1]]`` = the float32 noise of measurement (step, agents[f]).

    Args:
        streams: the mission's streams.
        step: the step of the measurements.
        agents: the measuring UAVs.
        offsets: (len(agents) + 1,) int64 where each UAV's cells start in ``out``, and the end.
        out: (offsets[-1],) float32, filled in place.
        prefix: :func:`entropy_prefix` of ``streams``, if the caller keeps it.
    """
    if len(agents) and streams.sensor_root.pool_size == _POOL_SIZE and compiled_noise_ok():
        kernels.sensor_noise(assembled_entropy(streams, step, agents, prefix), offsets, out)
    else:
        _numpy_noise(streams, step, agents, offsets, out)
