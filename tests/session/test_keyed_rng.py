"""keyed_rng (the simulated eye's and observers' per-trial generators) gives the stream
np.random.default_rng gave on the list of masked keys, for keys of every length and size."""

from __future__ import annotations

import numpy as np

from psyop.session.gaze.simulated import keyed_rng


def test_keyed_rng_equals_default_rng_on_the_key_list():
    picks = np.random.default_rng(0)
    cases = [(0,), (0, 0), (0xFFFFFFFF, 0, 1), (-1, 2**40 + 5, 3), (1, 2, 3, 4, 5, 6)]
    cases += [tuple(int(k) for k in picks.integers(-2**33, 2**33, int(picks.integers(1, 7)))) for _ in range(500)]
    for keys in cases:
        ours, before = keyed_rng(*keys), np.random.default_rng([k & 0xFFFFFFFF for k in keys])
        assert ours.bit_generator.state == before.bit_generator.state, keys
        assert np.array_equal(ours.normal(0.0, 1.0, 8), before.normal(0.0, 1.0, 8)), keys
