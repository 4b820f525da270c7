"""First uniform doubles of ``numpy.random.default_rng(key)`` for many keys at once.

``numpy.random.default_rng(key).random()`` seeds PCG64 through ``SeedSequence(key)`` and draws
one double. Constructing a ``SeedSequence`` (and a ``Generator``) per object is the costly part,
so this module computes the same numbers directly: the ``SeedSequence`` hash mixing (pool of
four 32-bit words, constants and order as in numpy's ``bit_generator.pyx``) is vectorised over
all keys with ``uint32`` arrays, and the PCG64 (XSL-RR 128/64) seeding and first step use Python
integers. Tests compare the result with numpy for many keys.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

U32Array = npt.NDArray[np.uint32]

_POOL_SIZE = 4
_INIT_A = 0x43B0D7E5
_MULT_A = 0x931E8875
_INIT_B = 0x8B51F9DD
_MULT_B = 0x58F38DED
_MIX_MULT_L = 0xCA01F9DD
_MIX_MULT_R = 0x4973F715
_XSHIFT = np.uint32(16)
_MASK32 = (1 << 32) - 1
_MASK64 = (1 << 64) - 1
_MASK128 = (1 << 128) - 1
_PCG_MULT = 0x2360ED051FC65DA44385DF649FCCF645


def int_words(value: int) -> list[int]:
    """Little-endian 32-bit words of a non-negative int, as ``SeedSequence`` splits it."""
    if value < 0:
        msg = f"seed key entries must be non-negative, got {value}"
        raise ValueError(msg)
    words = [value & _MASK32]
    value >>= 32
    while value:
        words.append(value & _MASK32)
        value >>= 32
    return words


def _hash_constants(start: int, mult: int, count: int) -> list[np.uint32]:
    """The ``count`` multipliers ``start * mult**k`` (mod 2**32) that hashing goes through."""
    out: list[np.uint32] = []
    const = start
    for _ in range(count):
        const = (const * mult) & _MASK32
        out.append(np.uint32(const))
    return out


def _hashmix(value: U32Array, const_before: int, const_after: np.uint32) -> U32Array:
    out: U32Array = (value ^ np.uint32(const_before)) * const_after
    return out ^ (out >> _XSHIFT)


def seed_sequence_states(entropy: U32Array) -> list[tuple[int, int, int, int]]:
    """``SeedSequence(key).generate_state(4, np.uint64)`` for each row of ``entropy``.

    ``entropy`` is ``(m, w) uint32``: one row of key words per key (see :func:`int_words`), every
    row the same length ``w`` (so no padding rule of numpy applies; ``w`` may be below or above
    the pool size). Returns the four 64-bit state words of each key as Python ints.
    """
    count, width = entropy.shape
    steps = _POOL_SIZE * _POOL_SIZE + max(width - _POOL_SIZE, 0) * _POOL_SIZE
    consts = _hash_constants(_INIT_A, _MULT_A, steps)
    befores = [_INIT_A] + [int(c) for c in consts[:-1]]
    step = 0
    with np.errstate(over="ignore"):
        pool: list[U32Array] = []
        for i in range(_POOL_SIZE):
            word = entropy[:, i] if i < width else np.zeros(count, dtype=np.uint32)
            pool.append(_hashmix(word, befores[step], consts[step]))
            step += 1
        left, right = np.uint32(_MIX_MULT_L), np.uint32(_MIX_MULT_R)
        for i_src in range(_POOL_SIZE):
            for i_dst in range(_POOL_SIZE):
                if i_src != i_dst:
                    hashed = _hashmix(pool[i_src], befores[step], consts[step])
                    step += 1
                    mixed = left * pool[i_dst] - right * hashed
                    pool[i_dst] = mixed ^ (mixed >> _XSHIFT)
        for i_src in range(_POOL_SIZE, width):
            for i_dst in range(_POOL_SIZE):
                hashed = _hashmix(entropy[:, i_src], befores[step], consts[step])
                step += 1
                mixed = left * pool[i_dst] - right * hashed
                pool[i_dst] = mixed ^ (mixed >> _XSHIFT)
        out_consts = _hash_constants(_INIT_B, _MULT_B, 2 * 4)
        out_befores = [_INIT_B] + [int(c) for c in out_consts[:-1]]
        halves: list[list[int]] = []
        for i_dst in range(2 * 4):
            word = _hashmix(pool[i_dst % _POOL_SIZE], out_befores[i_dst], out_consts[i_dst])
            halves.append(word.tolist())
    return [
        (
            h[0] | h[1] << 32,
            h[2] | h[3] << 32,
            h[4] | h[5] << 32,
            h[6] | h[7] << 32,
        )
        for h in zip(*halves, strict=True)
    ]


def pcg64_first_double(state: tuple[int, int, int, int]) -> float:
    """First ``random()`` double of PCG64 seeded with the four ``SeedSequence`` state words.

    The first two words are the initial state and the last two the increment; one step, add
    the state, one step, then one step per output (XSL-RR output, 53 high bits).
    """
    words = state
    init = (words[0] << 64) | words[1]
    inc = (((words[2] << 64) | words[3]) << 1 | 1) & _MASK128
    value_state = (inc + init) & _MASK128
    value_state = (value_state * _PCG_MULT + inc) & _MASK128
    value_state = (value_state * _PCG_MULT + inc) & _MASK128
    rot = value_state >> 122
    xored = ((value_state >> 64) ^ value_state) & _MASK64
    value = ((xored >> rot) | (xored << ((64 - rot) & 63))) & _MASK64
    return (value >> 11) * (1.0 / 9007199254740992.0)


def first_doubles(keys: list[list[int]]) -> list[float]:
    """``numpy.random.default_rng(key).random()`` for every key (lists of non-negative ints).

    Keys are grouped by their number of 32-bit words so each group is hashed in one pass.
    """
    rows = [[w for v in key for w in int_words(v)] for key in keys]
    out: list[float] = [0.0] * len(keys)
    groups: dict[int, list[int]] = {}
    for k, row in enumerate(rows):
        groups.setdefault(len(row), []).append(k)
    for members in groups.values():
        entropy = np.array([rows[k] for k in members], dtype=np.uint32)
        for k, state in zip(members, seed_sequence_states(entropy), strict=True):
            out[k] = pcg64_first_double(state)
    return out
