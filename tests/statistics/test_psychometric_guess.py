"""Psychometric fits with other guess rates (psyop.statistics.psychometric, "Response kinds"): nAFC with
guess 1/n (threshold at guess + (1 - guess) / 2) and yes/no with a fixed or free guess rate (threshold at
the midpoint of the unscaled sigmoid).

- 2AFC, the default, is unchanged: fits equal those of the former module (psychometric.py as of
  :data:`FORMER_COMMIT`, written to a file under tmp_path and imported beside today's) field by field,
  floats bit for bit.
- Coverage: simulated 4AFC and yes/no (free guess) observers, 7 levels x 40 trials, 200 seeds each; the
  95 % CI must cover the true threshold at a rate a 95 % interval gives with probability > 0.001
  (one-sided binomial: ``binom.cdf(covered, n, 0.95) > 0.001``). Measured: 4AFC 188/200 (0.94),
  yes/no free guess 189/200 (0.945), yes/no guess fixed at 0.1 190/200 (0.95) over seeds 1000-1199.
- Edge cases get censored statuses and NaN thresholds; bad options raise InvalidFitOptions (a UserError).
"""

from __future__ import annotations

import importlib.util
import math
import subprocess
import sys
from dataclasses import fields
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import special
from scipy.stats import binom

from psyop.errors import UserError
from psyop.statistics import psychometric as psy
from psyop.statistics.psychometric import (
    FitOptions, InvalidFitOptions, fit_psychometric, fit_psychometric_table, nafc_options, yes_no_options,
)
from psyop.statistics.simulate import DETECTION_LEVELS_D, pc_2afc

REPO = Path(__file__).resolve().parents[2]
#: the last commit of psyop/statistics/psychometric.py before the guess rate became an option
FORMER_COMMIT = "ada22827d1652f2fcb53da3486cece8fb246541a"

LEVELS = np.linspace(0.0, 1.2, 7)
N_TRIALS = 40
MU, SIGMA, LAPSE, FALSE_ALARMS = 0.6, 0.2, 0.02, 0.1
FAST = {"n_bootstrap": 0, "estimate_eta": False}


# ---- 2AFC: the former code's fits, bit for bit ---------------------------------------------------------------------

@pytest.fixture(scope="module")
def former(tmp_path_factory):
    """psychometric.py as of FORMER_COMMIT, imported from a file under tmp_path."""
    try:
        text = subprocess.run(["git", "show", f"{FORMER_COMMIT}:psyop/statistics/psychometric.py"], cwd=REPO,
                              capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError) as err:  # no git, or a clone without that commit
        pytest.skip(f"the former psychometric.py ({FORMER_COMMIT[:10]}) is not in this checkout: {err}")
    path = tmp_path_factory.mktemp("former") / "psychometric_former.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("psychometric_former", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses resolve their module by name
    try:
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.modules.pop(spec.name, None)


def _same_bits(a, b) -> bool:
    return np.float64(a).tobytes() == np.float64(b).tobytes()


def _assert_same_fit(new, old) -> None:
    """Every field of the former PsychometricFit equal (floats bit for bit); the new fields at their 2AFC values."""
    for f in fields(old):
        u, v = getattr(new, f.name), getattr(old, f.name)
        if isinstance(v, float):
            assert _same_bits(u, v), (f.name, u, v)
        else:
            assert u == v, (f.name, u, v)
    assert new.guess == 0.5 and new.target_p == 0.75


def _datasets_2afc() -> list[np.ndarray]:
    rng = np.random.default_rng(71)
    levels = np.array(DETECTION_LEVELS_D)
    n5 = np.full(5, 20)
    out = [
        np.c_[levels, n5, n5],  # all correct: censored below
        np.c_[levels, [10, 9, 11, 10, 10], n5],  # chance: censored above / lapse at bound
        np.c_[levels, [10, 12, 13, 13, 12], n5],  # lapse-heavy: plateau near 0.62
        np.c_[levels, [11, 15, 14, 15, 14], n5],  # lapse-heavy, threshold in range
        np.array([[0.5, 10, 15]]),  # one level: no fit
        np.c_[levels, [3, 5, 9, 14, 15], np.full(5, 15)],
    ]
    for thr, sigma, lapse, n in [(0.36, 0.2, 0.0, 40), (0.5, 0.1, 0.15, 25), (1.1, 0.3, 0.05, 60),
                                 (-0.1, 0.2, 0.0, 30), (0.4, 0.15, 0.3, 200)]:
        out.append(np.c_[levels, rng.binomial(n, pc_2afc(levels, thr, sigma, lapse)), np.full(5, n)])
    return out


@pytest.mark.cross_cpu
@pytest.mark.parametrize("options", [{}, {"n_bootstrap": 0, "estimate_eta": False}, {"fixed_lambda": 0.02, "n_bootstrap": 40}],
                         ids=["default", "fast", "lambda-fixed"])
def test_2afc_fits_equal_the_former_code(former, options):
    assert FitOptions(**options).experiment == "nAFC" and FitOptions(**options).guess == 0.5
    datasets = _datasets_2afc()
    statuses = set()
    with np.errstate(invalid="ignore"):
        for data in datasets:
            new = fit_psychometric(data, FitOptions(**options))
            old = former.fit_psychometric(data, former.FitOptions(**options))
            _assert_same_fit(new, old)
            # nafc_options(2) is the same fit as the default
            _assert_same_fit(fit_psychometric(data, nafc_options(2, **options)), old)
            statuses.add(old.status)
    assert {"censored_below", "no_fit", "ok"} <= statuses and statuses & {"censored_above", "lapse_at_bound"}


def test_2afc_options_and_table_equal_the_former_code(former):
    new_defaults, old_defaults = FitOptions(), former.FitOptions()
    # repr: the former GridSpec is another class with the same fields
    assert all(repr(getattr(new_defaults, f.name)) == repr(getattr(old_defaults, f.name)) for f in fields(old_defaults))
    rng = np.random.default_rng(5)
    levels = np.repeat(np.array(DETECTION_LEVELS_D), 20)
    trials = pd.DataFrame({
        "participant": np.repeat(["p1", "p2"], len(levels)), "back_D": 0.0, "level_D": np.tile(levels, 2),
        "correct": rng.random(2 * len(levels)) < np.tile(pc_2afc(levels, 0.4, 0.2, 0.02), 2),
    })
    new = fit_psychometric_table(trials, options=FitOptions(n_bootstrap=20))
    old = former.fit_psychometric_table(trials, options=former.FitOptions(n_bootstrap=20))
    pd.testing.assert_frame_equal(new, old, check_exact=True)
    assert "guess" not in new and "target_p" not in new
    yes_no = fit_psychometric_table(trials, options=yes_no_options(None, **FAST))
    assert {"guess", "target_p"} <= set(yes_no.columns) and (yes_no["guess"] < 0.5).all()


# ---- recovery and coverage of simulated observers -----------------------------------------------------------------

def _observer(kind: str) -> tuple[np.ndarray, float, FitOptions]:
    """True p per level, true threshold and the fit options for a simulated observer."""
    z = special.ndtr((LEVELS - MU) / SIGMA)
    if kind == "4AFC":  # threshold where p = 1/4 + (1 - 1/4) / 2 = 0.625
        return 0.25 + (0.75 - LAPSE) * z, MU + SIGMA * float(special.ndtri(0.375 / (0.75 - LAPSE))), \
            nafc_options(4, **FAST)
    guess = None if kind == "yes/no free" else FALSE_ALARMS
    return FALSE_ALARMS + (1.0 - FALSE_ALARMS - LAPSE) * z, MU, yes_no_options(guess, **FAST)


def _fits(kind: str, seeds: range):
    p, truth, options = _observer(kind)
    out = []
    for seed in seeds:
        k = np.random.default_rng(1000 + seed).binomial(N_TRIALS, p)
        out.append(fit_psychometric(np.c_[LEVELS, k, np.full(len(LEVELS), N_TRIALS)], options))
    return out, truth


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["4AFC", "yes/no free", "yes/no fixed"])
def test_ci_covers_the_true_threshold(kind):
    """Rule: with n fits and c covering the truth, binom.cdf(c, n, 0.95) > 0.001 (a true 95 % interval
    covers this rarely with probability <= 0.001); and the point estimates are unbiased to 0.03 D."""
    fits, truth = _fits(kind, range(200))
    covered = sum(f.threshold_ci_low_D <= truth <= f.threshold_ci_high_D for f in fits)
    assert binom.cdf(covered, len(fits), 0.95) > 0.001, (kind, covered, len(fits))
    usable = [f for f in fits if f.usable]
    assert len(usable) >= 0.9 * len(fits), [f.status for f in fits]
    assert abs(np.mean([f.threshold_D for f in usable]) - truth) < 0.03
    for f in usable[:10]:  # the MAP curve is at target_p at the threshold
        assert f.proportion_correct(np.array([f.threshold_D]))[0] == pytest.approx(f.target_p, abs=1e-9)
    if kind == "4AFC":
        assert all(f.guess == 0.25 and f.target_p == 0.625 for f in fits)
    elif kind == "yes/no fixed":
        assert all(f.guess == FALSE_ALARMS for f in fits)
    else:
        # the free guess rate recovers g = 0.1: psignifit's Beta(1, 10) prior on [0, 0.5] shrinks the MAP towards
        # 0 (measured mean 0.080, sd 0.04 over 200 seeds). Stated tolerance: mean within 0.035 of g, and 90 % of
        # fits within 0.1 of g.
        guesses = np.array([f.guess for f in fits])
        assert abs(guesses.mean() - FALSE_ALARMS) < 0.035, guesses.mean()
        assert np.mean(np.abs(guesses - FALSE_ALARMS) < 0.1) >= 0.9
        assert all(f.target_p == pytest.approx(f.guess + (1 - f.guess - f.lapse) / 2) for f in fits)


def test_three_afc_target_and_lapse_limit():
    """3AFC: target 2/3; a plateau far below it (lapse >= 1/3) is lapse_at_bound, never a number."""
    options = nafc_options(3, **FAST)
    assert options.target_p == pytest.approx(2 / 3)
    n = np.full(7, 60)
    fit = fit_psychometric(np.c_[LEVELS, [20, 20, 22, 30, 33, 33, 33], n], options)  # plateau at 0.55
    assert fit.status in ("lapse_at_bound", "censored_above") and math.isnan(fit.threshold_D)
    assert fit.threshold_text.startswith(">")


# ---- edge cases: censored, never a plausible number ----------------------------------------------------------------

def _edge(options: FitOptions, k) -> psy.PsychometricFit:
    n = np.full(len(LEVELS), N_TRIALS)
    return fit_psychometric(np.c_[LEVELS, np.broadcast_to(k, n.shape), n], options)


@pytest.mark.parametrize("options", [nafc_options(4, **FAST), yes_no_options(None, **FAST),
                                     yes_no_options(FALSE_ALARMS, **FAST)], ids=["4AFC", "yes/no free", "yes/no fixed"])
def test_all_correct_or_all_yes_is_censored_below(options):
    fit = _edge(options, N_TRIALS)
    assert fit.status == "censored_below" and math.isnan(fit.threshold_D)
    assert fit.threshold_bound_D == LEVELS[0] and fit.threshold_text == "< 0.00 D"
    assert "all_correct" in fit.flags and not fit.usable


@pytest.mark.parametrize("options, k", [(nafc_options(4, **FAST), 10), (nafc_options(4, **FAST), 0),
                                        (yes_no_options(None, **FAST), 4), (yes_no_options(None, **FAST), 0),
                                        (yes_no_options(FALSE_ALARMS, **FAST), 4),
                                        (yes_no_options(FALSE_ALARMS, **FAST), 0)],
                         ids=["4AFC-chance", "4AFC-none", "yes/no-free-at-guess", "yes/no-free-no",
                              "yes/no-fixed-at-guess", "yes/no-fixed-no"])
def test_performance_at_guess_is_censored_above(options, k):
    fit = _edge(options, k)
    assert fit.status in ("censored_above", "lapse_at_bound") and math.isnan(fit.threshold_D)
    assert fit.threshold_bound_D == LEVELS[-1] and fit.threshold_text == "> 1.20 D" and not fit.usable


def test_one_level_is_no_fit_with_the_kinds_guess():
    data = np.array([[0.5, 10, 40]])
    fixed = fit_psychometric(data, nafc_options(4))
    assert fixed.status == "no_fit" and fixed.guess == 0.25 and fixed.target_p == 0.625
    free = fit_psychometric(data, yes_no_options(None))
    assert free.status == "no_fit" and math.isnan(free.guess) and math.isnan(free.target_p)


def test_new_fields_have_defaults_for_existing_callers():
    nan = float("nan")
    fit = psy.PsychometricFit("ok", 0.4, 0.3, 0.5, nan, 0.4, 0.12, 0.38, 0.02, nan, 1.0, 0.5, 5, 100, 0.0, 1.0, ())
    assert fit.guess == 0.5 and fit.target_p == 0.75
    assert fit.proportion_correct(np.array([0.38]))[0] == pytest.approx(0.5 + 0.48 / 2)


# ---- bad options ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("make", [
    lambda: FitOptions(guess=1.0), lambda: FitOptions(guess=-0.1), lambda: FitOptions(guess=float("nan")),
    lambda: yes_no_options(1.0), lambda: yes_no_options(1.5), lambda: yes_no_options(-0.01),
    lambda: FitOptions(guess=0.3), lambda: FitOptions(guess=None), lambda: FitOptions(guess=0.1),
    lambda: FitOptions(experiment="2IFC"), lambda: nafc_options(1), lambda: nafc_options(9),
    lambda: yes_no_options(0.6, fixed_lambda=0.4), lambda: FitOptions(guess="0.5"),  # type: ignore[arg-type]
], ids=["nafc-1", "nafc-negative", "nan", "yes/no-1", "yes/no-1.5", "yes/no-negative", "nafc-not-1/n",
        "nafc-free", "nafc-1/10", "unknown-kind", "1AFC", "9AFC", "guess+lapse>=1", "string"])
def test_bad_guess_options_raise_a_user_error(make):
    with pytest.raises(InvalidFitOptions) as info:
        make()
    assert isinstance(info.value, UserError) and str(info.value).startswith("FitOptions: ")


def test_yes_no_fixed_guess_above_psignifits_usual_range_fits_quietly(recwarn):
    fit = fit_psychometric(np.c_[LEVELS, [20, 20, 22, 30, 36, 39, 40], np.full(7, 40)], yes_no_options(0.5, **FAST))
    assert fit.guess == 0.5 and fit.status == "ok" and fit.target_p == pytest.approx(0.5 + (0.5 - fit.lapse) / 2)
    assert not [w for w in recwarn if "guess rate gamma" in str(w.message)]
