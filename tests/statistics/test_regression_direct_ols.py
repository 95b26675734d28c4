"""``linear_fit`` fits ``sm.OLS`` on the [1, x] design matrix directly; it must give the results of the
former ``smf.ols("y ~ x")`` formula fit (kept here as ``_old_linear_fit``, run beside it on the same machine)
on many random datasets, edge cases included (3 rows, constant x, constant y, exact lines, huge and tiny
scales, NaN rows dropped, integer and bool columns, a non-default index).

Equal to the fits' own rounding, not bit for bit: the formula API hands OLS a differently laid-out design
matrix, and on a CPU with AVX-512 kernels (numpy's, OpenBLAS's) the two round differently in the last bits.
On a CPU with AVX2 only they agree bit for bit (measured on the machine the fast path was written on)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import statsmodels.formula.api as smf

from psyop.statistics.regression import LinearFit, _clean, linear_fit

pytestmark = pytest.mark.cross_cpu


def _old_linear_fit(data: pd.DataFrame, x: str, y: str) -> LinearFit:
    d = _clean(data, [x, y]).rename(columns={x: "x", y: "y"}).astype(float)
    if len(d) < 3:
        raise ValueError(f"need at least 3 complete rows for a line, have {len(d)}")
    m = smf.ols("y ~ x", data=d).fit()
    ci = m.conf_int()
    return LinearFit(
        slope=float(m.params["x"]), slope_se=float(m.bse["x"]), slope_ci_low=float(ci.loc["x", 0]),
        slope_ci_high=float(ci.loc["x", 1]), slope_p=float(m.pvalues["x"]),
        intercept=float(m.params["Intercept"]), intercept_se=float(m.bse["Intercept"]),
        intercept_ci_low=float(ci.loc["Intercept", 0]), intercept_ci_high=float(ci.loc["Intercept", 1]),
        intercept_p=float(m.pvalues["Intercept"]), r2=float(m.rsquared), n=int(m.nobs),
    )


#: the fields compared as estimates (y units, or y per x units) and as p values
ESTIMATES = ("slope", "slope_se", "slope_ci_low", "slope_ci_high", "intercept", "intercept_se", "intercept_ci_low",
             "intercept_ci_high")
P_VALUES = ("slope_p", "intercept_p")
#: estimates agree to 1e-9 relative, or to 1e-12 of the data's y scale (per unit of x's range for the slope)
#: in absolute terms: a near-exact line's standard errors are themselves rounding noise (1e-16 of y), which
#: the two layouts round differently by whole percent (measured: 1.6 % of an SE of 1.2e-16 on y of 4.5)
EST_RTOL, EST_ATOL_OF_Y = 1e-9, 1e-12
#: p values to 1e-6 relative (reported to 3 significant digits; measured worst 1e-9, on p = 5e-118)
P_RTOL = 1e-6


def _assert_close(new: LinearFit, old: LinearFit, frame: pd.DataFrame) -> None:
    x = frame["cond"].astype(float)
    y = frame["thr"].astype(float)
    y_scale = float(np.nanmax(np.abs(y)))
    x_range = float(np.nanmax(x) - np.nanmin(x))
    assert (new.n, math.isnan(new.r2)) == (old.n, math.isnan(old.r2)), frame
    if not math.isnan(old.r2):
        assert math.isclose(new.r2, old.r2, rel_tol=EST_RTOL, abs_tol=1e-12), (frame, new.r2, old.r2)
    for name in ESTIMATES + P_VALUES:
        a, b = getattr(new, name), getattr(old, name)
        if math.isnan(b) or math.isnan(a):
            assert math.isnan(a) and math.isnan(b), (name, a, b, frame)
            continue
        per_x = 1.0 / x_range if name.startswith("slope") and x_range > 0 else 1.0
        rtol, atol = (P_RTOL, 0.0) if name in P_VALUES else (EST_RTOL, EST_ATOL_OF_Y * y_scale * max(per_x, 1.0))
        assert math.isclose(a, b, rel_tol=rtol, abs_tol=atol), (name, a, b, frame)


def _datasets():
    rng = np.random.default_rng(20261203)
    for i in range(400):
        n = int(rng.integers(3, 60))
        scale = 10.0 ** rng.uniform(-8, 8)
        x = rng.choice([rng.normal(size=n), rng.integers(0, 5, n).astype(float), np.repeat([1.0, 2.0, 3.0], n)[:n]])
        y = rng.normal(size=n) * scale + rng.normal() * x
        if i % 7 == 0:
            y = 2.0 * x + 1.0  # an exact line
        if i % 11 == 0:
            y = np.full(n, 3.5)  # constant y: r2 NaN
        if i % 13 == 0:
            x = np.full(n, 1.25)  # constant x: singular design
        frame = pd.DataFrame({"cond": x, "thr": y, "other": rng.normal(size=n)}, index=rng.permutation(n) + 100)
        if i % 5 == 0 and n > 4:
            frame.iloc[int(rng.integers(n)), 1] = np.nan  # a dropped row
        yield frame
    yield pd.DataFrame({"cond": [1, 2, 3, 4], "thr": [1, 3, 2, 5]})  # integer columns
    yield pd.DataFrame({"cond": [True, False, True, False, True], "thr": [0.1, 0.4, 0.2, 0.5, 0.3]})


@pytest.mark.filterwarnings("ignore")
def test_linear_fit_equals_formula_fit():
    for frame in _datasets():
        with np.errstate(all="ignore"):
            old, new = _old_linear_fit(frame, "cond", "thr"), linear_fit(frame, "cond", "thr")
        _assert_close(new, old, frame)


@pytest.mark.filterwarnings("ignore")
def test_the_fit_comparison_can_fail():
    """A slope off by 1e-8 relative, or a p value off by 1e-5, is caught."""
    from dataclasses import replace

    frame = pd.DataFrame({"cond": [1.0, 2.0, 3.0, 4.0], "thr": [1.0, 3.0, 2.0, 5.0]})
    fit = linear_fit(frame, "cond", "thr")
    for changed in (replace(fit, slope=fit.slope * (1 + 1e-8)), replace(fit, slope_p=fit.slope_p * (1 + 1e-5))):
        with pytest.raises(AssertionError):
            _assert_close(changed, fit, frame)


def test_too_few_rows_still_raise():
    frame = pd.DataFrame({"cond": [1.0, 2.0, math.nan], "thr": [1.0, 2.0, 3.0]})
    with pytest.raises(ValueError, match="at least 3"):
        linear_fit(frame, "cond", "thr")
