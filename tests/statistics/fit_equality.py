"""Helpers of the tests that hold psyop's fast fit paths to the former code bit for bit
(test_psychometric_fast_paths.py, test_psychometric_zoom_fast_paths.py): byte equality of arrays,
field-by-field equality of two fits, and random 2AFC datasets on the detection levels."""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from psyop.statistics.psychometric import PsychometricFit
from psyop.statistics.simulate import DETECTION_LEVELS_D, pc_2afc

LEVELS = np.array(DETECTION_LEVELS_D)


def same_bits(a, b) -> bool:
    """Same shape, dtype and bytes (a -0.0 is not a 0.0, a NaN equals the same NaN)."""
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def same_fit(a: PsychometricFit, b: PsychometricFit) -> bool:
    """Every field equal, floats bit for bit."""
    for f in fields(a):
        u, v = getattr(a, f.name), getattr(b, f.name)
        if isinstance(u, float):
            if not same_bits(np.float64(u), np.float64(v)):
                return False
        elif u != v:
            return False
    return True


def fit_datasets(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """``n`` random (level, correct, trials) blocks on the detection levels: thresholds inside and outside
    the range, widths 0.05-0.5, lapses 0-0.4, 5 to 1000 trials per level."""
    out = []
    for _ in range(n):
        sigma, thr, lapse = rng.uniform(0.05, 0.5), rng.uniform(-0.2, 1.2), rng.choice([0.0, 0.05, 0.2, 0.4])
        n_per_level = int(rng.choice([5, 15, 40, 1000]))
        out.append(np.c_[LEVELS, rng.binomial(n_per_level, pc_2afc(LEVELS, thr, sigma, lapse)), np.full(5, n_per_level)])
    return out
