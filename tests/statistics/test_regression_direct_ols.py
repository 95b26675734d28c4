"""``linear_fit`` fits ``sm.OLS`` on the [1, x] design matrix directly; it must give the same bits as the
former ``smf.ols("y ~ x")`` formula fit (kept here as ``_old_linear_fit``) on many random datasets, edge
cases included (3 rows, constant x, constant y, exact lines, huge and tiny scales, NaN rows dropped,
integer and bool columns, a non-default index)."""

from __future__ import annotations

import math
from dataclasses import astuple

import numpy as np
import pandas as pd
import pytest
import statsmodels.formula.api as smf

from psyop.statistics.regression import LinearFit, _clean, linear_fit


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


def _bits(fit: LinearFit) -> tuple:
    return tuple(np.float64(v).tobytes() if isinstance(v, float) else v for v in astuple(fit))


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
def test_linear_fit_equals_formula_fit_bit_for_bit():
    for frame in _datasets():
        with np.errstate(all="ignore"):
            old, new = _old_linear_fit(frame, "cond", "thr"), linear_fit(frame, "cond", "thr")
        assert _bits(new) == _bits(old), frame


def test_too_few_rows_still_raise():
    frame = pd.DataFrame({"cond": [1.0, 2.0, math.nan], "thr": [1.0, 2.0, 3.0]})
    with pytest.raises(ValueError, match="at least 3"):
        linear_fit(frame, "cond", "thr")
