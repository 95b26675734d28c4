"""Helpers of the tests that hold psyop's fast fit paths to the former code bit for bit
(test_psychometric_fast_paths.py, test_psychometric_zoom_fast_paths.py): byte equality of arrays,
field-by-field equality of two fits, former definitions patched into every fit module, and random 2AFC
datasets on the detection levels."""

from __future__ import annotations

from dataclasses import fields

import numpy as np

from psyop.statistics import posterior_modes, psignifit_grid, psignifit_posterior, psychometric
from psyop.statistics import psignifit_grid as engine
from psyop.statistics.psychometric import PsychometricFit
from psyop.statistics.simulate import DETECTION_LEVELS_D, pc_2afc

LEVELS = np.array(DETECTION_LEVELS_D)


#: The modules of a fit: psychometric (the public API) and the posterior-grid engine it calls.
FIT_MODULES = (psychometric, psignifit_grid, psignifit_posterior, posterior_modes)


def patch_everywhere(monkeypatch, name: str, value) -> None:
    """Set ``name`` to ``value`` in every fit module that holds it: each module looks its callees up in
    its own namespace, so a former definition patched into all of them replaces every call site."""
    held = [m for m in FIT_MODULES if hasattr(m, name)]
    assert held, f"no fit module defines {name!r}"
    for module in held:
        monkeypatch.setattr(module, name, value)


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


def random_data(rng: np.random.Generator, n_levels: int | None = None) -> np.ndarray:
    """Random (level, correct, trials) rows: 2-8 levels (some outside 0-1), 1-59 trials each, some rows with
    no correct answer and some all correct."""
    n_levels = int(rng.integers(2, 9)) if n_levels is None else n_levels
    levels = np.sort(rng.choice(np.r_[np.linspace(0, 1, 11), rng.uniform(-0.5, 1.5, 5)], n_levels, replace=False))
    n = rng.integers(1, 60, n_levels).astype(float)
    p = rng.uniform(0.0, 1.0, n_levels)
    k = rng.binomial(n.astype(int), p).astype(float)
    k[rng.random(n_levels) < 0.2] = 0.0  # rows with no correct answer
    full = rng.random(n_levels) < 0.3
    k[full] = n[full]  # and rows all correct
    return np.c_[levels, k, n]


def fit_grid(rng: np.random.Generator, eta_free: bool = False) -> dict[str, np.ndarray]:
    """A posterior grid over psignifit's usual parameter ranges."""
    return {
        "eta": np.sort(rng.uniform(0.0, 0.9, 3)) if eta_free else np.array([0.0]),
        "gamma": np.array([0.5]),
        "lambda": np.linspace(0.0, rng.uniform(0.05, 0.5), int(rng.integers(1, 9))),
        "threshold": np.linspace(*np.sort(rng.uniform(-0.3, 1.3, 2)), int(rng.integers(1, 12))),
        "width": np.linspace(*np.sort(rng.uniform(0.05, 3.0, 2)), int(rng.integers(1, 12))),
    }


def tabulated_priors(data: np.ndarray) -> dict:
    """psignifit's tabulated 2AFC priors for the levels of ``data`` (psyop's cached tabulation)."""
    import psignifit

    conf = psignifit.Configuration(experiment_type="2AFC", sigmoid="norm", verbose=False)
    return engine._bounds_and_priors(conf, data[:, 0], None)[1]
