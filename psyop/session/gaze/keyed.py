"""Keyed random streams: ``np.random.default_rng([k & 0xFFFFFFFF for k in keys])``, cheaper.

The simulated eye and observers draw from one stream per (session, trial), (session, window) or
(session, plan): thousands of short streams per session, each a few draws long. Building a
``Generator`` for each costs about 25 us, most of it numpy's ``SeedSequence.generate_state`` (a Python
loop over numpy scalars inside ``np.errstate``), while the draws themselves cost 1-2 us. The same
streams, cheaper:

- :func:`keyed_state` is the PCG64 state ``default_rng`` starts in: the SeedSequence's entropy pool
  mixed by numpy itself (``SeedSequence(words).pool``), then ``generate_state(4, uint64)`` and PCG64's
  seeding (``pcg64_set_seed``: ``state = ((inc + initstate) * M + inc) mod 2**128``) in Python integers;
- :class:`KeyedGenerator` is one ``Generator`` put into that state in place (``bit_generator.state``), for
  a caller that draws at once and keeps nothing;
- :func:`keyed_poisson_uniforms` steps PCG64 (XSL-RR output) in Python integers for a blink window's draws,
  which need no table: ``Generator.uniform(0, 1)`` is ``(next_uint64 >> 11) * 2**-53``, and
  ``Generator.poisson(lam)`` for ``0 < lam < 10`` is numpy's multiplication method over those doubles.

Every function is held to numpy's own streams in tests/session/test_keyed_rng.py (states, uniforms,
normals and Poisson counts for thousands of keys). numpy documents PCG64 and SeedSequence as stable
streams; a numpy that changed them would fail those tests, not shift the simulation silently.
"""

from __future__ import annotations

import math

import numpy as np

_M32 = 0xFFFFFFFF
_M64 = (1 << 64) - 1
_M128 = (1 << 128) - 1
_INIT_B, _MULT_B = 0x8B51F9DD, 0x58F38DED  # SeedSequence.generate_state's hash constants


def _hash_pairs(init: int, mult: int, n: int) -> list[tuple[int, int]]:
    """The (xor, multiply) constants of ``n`` successive ``generate_state`` hashes (they depend on the position only)."""
    pairs, h = [], init
    for _ in range(n):
        pairs.append((h, (h * mult) & _M32))
        h = pairs[-1][1]
    return pairs


(_A0, _B0), (_A1, _B1), (_A2, _B2), (_A3, _B3), (_A4, _B4), (_A5, _B5), (_A6, _B6), (_A7, _B7) = \
    _hash_pairs(_INIT_B, _MULT_B, 8)
_PCG_MULT = (2549297995355413924 << 64) | 4865540595714422341  # PCG_DEFAULT_MULTIPLIER_128
_DOUBLE = 1.0 / 9007199254740992.0  # 2**-53: next_double's scale


def _words(keys: tuple[int, ...]) -> np.ndarray:
    return np.array([k & _M32 for k in keys], dtype=np.uint32)


def keyed_state(*keys: int) -> tuple[int, int]:
    """The PCG64 ``(state, inc)`` that ``np.random.default_rng([k & 0xFFFFFFFF for k in keys])`` starts in.

    Examples
    --------
    >>> state = np.random.default_rng([7, 8]).bit_generator.state["state"]
    >>> keyed_state(7, 8) == (state["state"], state["inc"])
    True
    """
    p0, p1, p2, p3 = np.random.SeedSequence(_words(keys)).pool.tolist()
    # generate_state(4, uint64): word i hashes pool[i % 4] with the i-th pair of hash constants (unrolled)
    v0, v1 = ((p0 ^ _A0) * _B0) & _M32, ((p1 ^ _A1) * _B1) & _M32
    v2, v3 = ((p2 ^ _A2) * _B2) & _M32, ((p3 ^ _A3) * _B3) & _M32
    v4, v5 = ((p0 ^ _A4) * _B4) & _M32, ((p1 ^ _A5) * _B5) & _M32
    v6, v7 = ((p2 ^ _A6) * _B6) & _M32, ((p3 ^ _A7) * _B7) & _M32
    # little-endian uint64 pairs of the words (each word's final xorshift applied here)
    initstate = ((v0 ^ (v0 >> 16)) | (v1 ^ (v1 >> 16)) << 32) << 64 | ((v2 ^ (v2 >> 16)) | (v3 ^ (v3 >> 16)) << 32)
    initseq = ((v4 ^ (v4 >> 16)) | (v5 ^ (v5 >> 16)) << 32) << 64 | ((v6 ^ (v6 >> 16)) | (v7 ^ (v7 >> 16)) << 32)
    inc = ((initseq << 1) | 1) & _M128
    return (((inc + initstate) & _M128) * _PCG_MULT + inc) & _M128, inc


def keyed_rng(*keys: int) -> np.random.Generator:
    """A fresh ``np.random.default_rng([k & 0xFFFFFFFF for k in keys])`` (a caller that keeps the generator)."""
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(_words(keys))))


class KeyedGenerator:
    """One numpy ``Generator`` re-seeded in place: :meth:`at` puts it into the state :func:`keyed_rng` of the
    same keys starts in and returns it. The next :meth:`at` re-seeds the same object, so it is for a caller
    that draws at once and keeps nothing (each owner has its own)."""

    def __init__(self) -> None:
        self._bits = np.random.PCG64(0)
        self._generator = np.random.Generator(self._bits)

    @property
    def generator(self) -> np.random.Generator:
        """The generator, in whatever state the last :meth:`at` and the draws since left it."""
        return self._generator

    def at(self, *keys: int) -> np.random.Generator:
        state, inc = keyed_state(*keys)
        self._bits.state = {"bit_generator": "PCG64", "state": {"state": state, "inc": inc},
                            "has_uint32": 0, "uinteger": 0}
        return self._generator


def _next_double(state: int, inc: int) -> tuple[int, float]:
    """One PCG64 step (``state * M + inc``) and its XSL-RR output as numpy's ``next_double``."""
    state = (state * _PCG_MULT + inc) & _M128
    high = state >> 64
    word, rot = (high ^ (state & _M64)), high >> 58
    word = ((word >> rot) | (word << ((-rot) & 63))) & _M64
    return state, (word >> 11) * _DOUBLE


def keyed_uniform(*keys: int) -> float:
    """``keyed_rng(*keys).uniform()``: the stream's first double (``Generator.uniform(0, 1)`` is
    ``0 + 1 * next_double``), stepped in Python integers.

    Examples
    --------
    >>> keyed_uniform(4, 5) == np.random.default_rng([4, 5]).uniform()
    True
    """
    return _next_double(*keyed_state(*keys))[1]


def keyed_poisson_uniforms(lam: float, *keys: int) -> list[float]:
    """``rng.uniform(0, 1, rng.poisson(lam))`` of ``rng = keyed_rng(*keys)``, as Python floats: the same
    count and numbers. numpy's Poisson for ``0 < lam < 10`` multiplies doubles until their product falls to
    ``exp(-lam)`` or below (``random_poisson_mult``); other ``lam`` go through the Generator itself.

    Examples
    --------
    >>> rng = np.random.default_rng([4, 5])
    >>> keyed_poisson_uniforms(3.0, 4, 5) == rng.uniform(0, 1, rng.poisson(3.0)).tolist()
    True
    """
    if not 0.0 < lam < 10.0:
        rng = keyed_rng(*keys)
        return rng.uniform(0, 1, int(rng.poisson(lam))).tolist()
    state, inc = keyed_state(*keys)
    limit, product, count = math.exp(-lam), 1.0, 0
    while True:
        state, u = _next_double(state, inc)
        product *= u
        if product <= limit:
            break
        count += 1
    out = []
    for _ in range(count):
        state, u = _next_double(state, inc)
        out.append(u)
    return out
