"""The bounds and tabulated priors a fit reuses (engine._bounds_and_priors) change no fit:
every field of a fit with the cache warm equals the same fit computed with the cache cleared."""

from __future__ import annotations

import math
from dataclasses import asdict

import numpy as np

from psyop.statistics import psignifit_grid as engine
from psyop.statistics.psychometric import FitOptions, fit_psychometric
from psyop.statistics.simulate import DETECTION_LEVELS_D, pc_2afc


def _data(rng, levels, threshold_D, n=15):
    k = rng.binomial(n, pc_2afc(levels, threshold_D, 0.2, 0.0))
    return np.column_stack([levels, k, np.full(len(levels), n)])


def _same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, float) and math.isnan(a):
        return isinstance(b, float) and math.isnan(b)
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b, equal_nan=True)
    return a == b


def test_fits_with_reused_priors_equal_fresh_fits():
    rng = np.random.default_rng(3)
    levels = np.asarray(DETECTION_LEVELS_D, float)
    datasets = [_data(rng, levels, t) for t in (0.2, 0.36, 0.5, 0.36)]
    datasets.append(_data(rng, levels[1:], 0.4))  # another range: another key
    options = (FitOptions(n_bootstrap=0), FitOptions(n_bootstrap=0, fixed_lambda=0.0))
    fresh = []
    for data in datasets:
        for o in options:
            engine._PRIORS_CACHE.clear()
            fresh.append(asdict(fit_psychometric(data, o)))
    engine._PRIORS_CACHE.clear()
    warm = [asdict(fit_psychometric(data, o)) for data in datasets for o in options]
    keys = len(engine._PRIORS_CACHE)
    assert keys < len(warm)  # entries were reused (the same levels and options)
    assert all(_same(a, b) for a, b in zip(fresh, warm))
