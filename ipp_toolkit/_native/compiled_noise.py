"""The Numba sensor-noise kernel of :func:`ipp_toolkit._native.kernels.sensor_noise` (imported on
first use): NumPy's ``SeedSequence``, ``PCG64`` and ``Generator.random(dtype=np.float32)``,
the same numbers (:mod:`ipp_toolkit.world.sensor_noise` checks them against NumPy)."""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

_jit = numba.njit(cache=True, nogil=True, boundscheck=False)

_MASK32 = np.uint64(0xFFFFFFFF)
_INIT_A = np.uint64(0x43B0D7E5)
_MULT_A = np.uint64(0x931E8875)
_INIT_B = np.uint64(0x8B51F9DD)
_MULT_B = np.uint64(0x58F38DED)
_MIX_MULT_L = np.uint64(0xCA01F9DD)
_MIX_MULT_R = np.uint64(0x4973F715)
_XSHIFT = np.uint64(16)
_POOL_SIZE = 4
_PCG_MULTIPLIER = (2549297995355413924 << 64) + 4865540595714422341


@intrinsic
def _pcg64_step(typingctx, high, low, inc_high, inc_low):
    """(state * multiplier + inc) mod 2**128 of 128-bit numbers given as (high, low) uint64."""
    def codegen(context, builder, signature, args):
        i128 = ir.IntType(128)
        i64 = ir.IntType(64)

        def join(high_word, low_word):
            return builder.or_(builder.shl(builder.zext(high_word, i128), i128(64)),
                               builder.zext(low_word, i128))

        state = builder.add(builder.mul(join(args[0], args[1]), i128(_PCG_MULTIPLIER)),
                            join(args[2], args[3]))
        return context.make_tuple(builder, signature.return_type,
                                  [builder.trunc(builder.lshr(state, i128(64)), i64),
                                   builder.trunc(state, i64)])

    u64 = types.uint64
    return types.UniTuple(u64, 2)(u64, u64, u64, u64), codegen


@_jit
def _hashmix(value, hash_const):
    value ^= hash_const
    hash_const = (hash_const * _MULT_A) & _MASK32
    value = (value * hash_const) & _MASK32
    value ^= value >> _XSHIFT
    return value, hash_const


@_jit
def _mix(x, y):
    result = (_MIX_MULT_L * x - _MIX_MULT_R * y) & _MASK32
    return result ^ (result >> _XSHIFT)


@_jit
def _pcg64_seeded(words):
    """PCG64's state and increment, each (high, low), seeded by SeedSequence(words).

    ``words`` (n,) uint32 is the sequence's assembled entropy (run entropy padded to the pool
    size, then the spawn key); this is SeedSequence's mix_entropy and generate_state(4,
    uint64), then pcg64_set_seed.
    """
    pool = np.zeros(_POOL_SIZE, np.uint64)
    hash_const = _INIT_A
    n = words.shape[0]
    for i in range(_POOL_SIZE):
        value = np.uint64(words[i]) if i < n else np.uint64(0)
        pool[i], hash_const = _hashmix(value, hash_const)
    for source in range(_POOL_SIZE):
        for target in range(_POOL_SIZE):
            if source != target:
                hashed, hash_const = _hashmix(pool[source], hash_const)
                pool[target] = _mix(pool[target], hashed)
    for source in range(_POOL_SIZE, n):
        for target in range(_POOL_SIZE):
            hashed, hash_const = _hashmix(np.uint64(words[source]), hash_const)
            pool[target] = _mix(pool[target], hashed)
    seed = np.zeros(4, np.uint64)  # generate_state(4, uint64): 8 words, little-endian pairs
    hash_const = _INIT_B
    for i in range(8):
        value = pool[i % _POOL_SIZE] ^ hash_const
        hash_const = (hash_const * _MULT_B) & _MASK32
        value = (value * hash_const) & _MASK32
        value ^= value >> _XSHIFT
        seed[i // 2] |= value << np.uint64(32 * (i % 2))
    # pcg64_set_seed(seed = (seed[0], seed[1]), inc = (seed[2], seed[3])): srandom.
    one = np.uint64(1)
    inc_high = (seed[2] << one) | (seed[3] >> np.uint64(63))
    inc_low = (seed[3] << one) | one
    high, low = _pcg64_step(np.uint64(0), np.uint64(0), inc_high, inc_low)
    low_sum = low + seed[1]
    high = high + seed[0] + (one if low_sum < low else np.uint64(0))
    high, low = _pcg64_step(high, low_sum, inc_high, inc_low)
    return high, low, inc_high, inc_low


@_jit
def sensor_noise(words, offsets, out):
    """See :func:`ipp_toolkit._native.kernels.sensor_noise`."""
    scale = np.float32(1.0 / 16777216.0)
    shift = np.uint64(8)
    for f in range(words.shape[0]):
        high, low, inc_high, inc_low = _pcg64_seeded(words[f])
        values = out[offsets[f]:offsets[f + 1]]
        buffered = np.uint64(0)
        has_buffered = False
        for i in range(values.shape[0]):
            if has_buffered:
                word = buffered
                has_buffered = False
            else:
                high, low = _pcg64_step(high, low, inc_high, inc_low)
                # PCG64's XSL-RR output of the new state
                mixed = high ^ low
                rotation = high >> np.uint64(58)
                output = (mixed >> rotation) | (mixed << ((np.uint64(64) - rotation)
                                                          & np.uint64(63)))
                word = output & _MASK32
                buffered = output >> np.uint64(32)
                has_buffered = True
            values[i] = np.float32(word >> shift) * scale
