"""keyed_rng (the simulated eye's and observers' per-trial generators) gives the stream
np.random.default_rng gave on the list of masked keys, for keys of every length and size."""

from __future__ import annotations

import numpy as np

from psyop.session.gaze.keyed import KeyedGenerator, keyed_poisson_uniforms, keyed_rng, keyed_state


def test_keyed_rng_equals_default_rng_on_the_key_list():
    picks = np.random.default_rng(0)
    cases = [(0,), (0, 0), (0xFFFFFFFF, 0, 1), (-1, 2**40 + 5, 3), (1, 2, 3, 4, 5, 6)]
    cases += [tuple(int(k) for k in picks.integers(-2**33, 2**33, int(picks.integers(1, 7)))) for _ in range(500)]
    for keys in cases:
        ours, before = keyed_rng(*keys), np.random.default_rng([k & 0xFFFFFFFF for k in keys])
        assert ours.bit_generator.state == before.bit_generator.state, keys
        assert np.array_equal(ours.normal(0.0, 1.0, 8), before.normal(0.0, 1.0, 8)), keys


def _cases(seed: int, n: int) -> list[tuple[int, ...]]:
    picks = np.random.default_rng(seed)
    cases = [(0,), (0, 0), (0xFFFFFFFF, 0, 1), (-1, 2**40 + 5, 3), (1, 2, 3, 4, 5, 6), (2**63 - 1, 2**32, 7, 11)]
    return cases + [tuple(int(k) for k in picks.integers(-2**40, 2**40, int(picks.integers(1, 8)))) for _ in range(n)]


def test_keyed_state_is_default_rngs_starting_state():
    for keys in _cases(1, 3000):
        state = np.random.default_rng([k & 0xFFFFFFFF for k in keys]).bit_generator.state["state"]
        assert keyed_state(*keys) == (state["state"], state["inc"]), keys


def test_a_keyed_generator_reseeded_in_place_gives_fresh_streams():
    """Re-seeding one Generator (after draws of every kind, a 32-bit draw left half used) starts each stream
    exactly where a fresh default_rng does: normals, uniforms, gammas, Poisson counts and integers."""
    scratch = KeyedGenerator()
    for keys in _cases(2, 400):
        ours, fresh = scratch.at(*keys), np.random.default_rng([k & 0xFFFFFFFF for k in keys])
        for draw in (lambda g: g.normal(0.0, 0.08, (5, 3)), lambda g: g.uniform(0, 1, 4), lambda g: g.gamma(4.0, 0.075),
                     lambda g: g.poisson(0.25, 3), lambda g: g.integers(0, 2**31, 3, dtype=np.int32)):
            assert np.array_equal(draw(ours), draw(fresh)), keys
        ours.integers(0, 10, dtype=np.int32)  # leaves a spare 32-bit word in the generator: at() must drop it


def test_keyed_poisson_uniforms_are_numpys_draws():
    for keys in _cases(3, 2000):
        fresh = [k & 0xFFFFFFFF for k in keys]
        for lam in (0.25, 3.0, 9.5, 12.0, 0.0):
            rng = np.random.default_rng(fresh)
            expected = rng.uniform(0, 1, int(rng.poisson(lam))).tolist()
            assert keyed_poisson_uniforms(lam, *keys) == expected, (keys, lam)
    counts = [len(keyed_poisson_uniforms(3.0, 9, w)) for w in range(400)]
    assert max(counts) >= 6 and min(counts) == 0  # the loop's both ends are exercised


def test_keyed_uniform_is_the_streams_first_uniform():
    from psyop.session.gaze.keyed import keyed_uniform

    for keys in _cases(4, 3000):
        assert keyed_uniform(*keys) == np.random.default_rng([k & 0xFFFFFFFF for k in keys]).uniform(), keys
