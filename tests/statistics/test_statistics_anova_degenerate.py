"""Degenerate repeated-measures data: flagged or refused with a message naming what and whom,
never a negative or astronomic F, an invented eps = 1, a KeyError or numpy warnings."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pingouin as pg
import pytest

from psyop.errors import UserError
from psyop.statistics.anova import AnovaInputError, error_sums_of_squares, posthoc_paired, rm_anova


def _oneway(values: dict[str, list[float]]) -> pd.DataFrame:
    rows = [{"participant": f"s{i}", "mode": m, "v": v} for m, vs in values.items() for i, v in enumerate(vs)]
    return pd.DataFrame(rows)


def _effect_plus_offset(n: int = 6) -> pd.DataFrame:
    """Level effect plus an exact subject offset: zero error variance (the old code: F = -1.26e17, p_GG = 1)."""
    rng = np.random.default_rng(0)
    offsets = rng.normal(size=n)
    return _oneway({m: list(0.1 * k + offsets) for k, m in enumerate(["conventional", "ocular", "reversed"])})


def test_zero_error_variance_is_flagged_not_a_huge_or_negative_F():
    res = rm_anova(_effect_plus_offset(), "v", "mode")
    row = res.effect("mode")
    assert row["status"] == "zero_error_variance"
    assert np.isnan(row["F"]) and np.isnan(row["p_gg"]) and np.isnan(row["eps_gg"])


def test_exact_zero_error_is_flagged_too():
    data = _oneway({"a": [1.0, 2, 3], "b": [2.0, 3, 4], "c": [3.0, 4, 5]})
    row = rm_anova(data, "v", "mode").effect("mode")
    assert row["status"] == "zero_error_variance" and np.isnan(row["eps_gg"])


def test_two_way_zero_interaction_error_only_flags_that_effect():
    rng = np.random.default_rng(1)
    rows = []
    for s in range(6):
        u = rng.normal()
        for i, a in enumerate(["a1", "a2", "a3"]):
            for j, b in enumerate(["b1", "b2"]):
                rows.append({"participant": f"s{s}", "A": a, "B": b, "v": u + i + 0.5 * j + rng.normal(0, 0.3) * (i == 0)})
    table = rm_anova(pd.DataFrame(rows), "v", ["A", "B"]).table.set_index("effect")
    assert table.loc["A", "status"] == "ok" and np.isfinite(table.loc["A", "F"])


def test_error_sums_of_squares_match_pingouin():
    rng = np.random.default_rng(2)
    data = _oneway({m: list(rng.normal(size=7) + k) for k, m in enumerate("abcd")})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        aov = pg.rm_anova(data, dv="v", within="mode", subject="participant", detailed=True)
    assert error_sums_of_squares(data, "v", ["mode"], "participant")["mode"] == pytest.approx(aov["SS"].iloc[1])


def test_constant_data_is_a_clear_error_not_a_keyerror():
    data = _oneway({"a": [0.5] * 5, "b": [0.5] * 5, "c": [0.5] * 5})
    with pytest.raises(AnovaInputError, match="same value .* every subject and cell"):
        rm_anova(data, "v", "mode")
    assert issubclass(AnovaInputError, UserError) and issubclass(AnovaInputError, ValueError)


def test_level_name_typo_names_subject_and_level():
    data = _oneway({"conventional": [0.5, 0.6, 0.7, 0.4], "ocular": [0.7, 0.8, 0.75, 0.6], "reversed": [0.6, 0.7, 0.6, 0.5]})
    data.loc[(data["participant"] == "s2") & (data["mode"] == "ocular"), "mode"] = "oculr"
    with pytest.raises(AnovaInputError, match=r"subject s2 has mode=oculr but lacks mode=ocular"):
        rm_anova(data, "v", "mode")
    with pytest.raises(AnovaInputError, match=r"subject s2 has mode=oculr"):
        posthoc_paired(data, "v", "mode")


def test_posthoc_with_one_subject_is_a_clear_error():
    data = _oneway({"a": [0.5], "b": [0.7]})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(AnovaInputError, match=r"1 complete subject\(s\) \(s0\).*needs at least 2"):
            posthoc_paired(data, "v", "mode")


def test_posthoc_on_zero_variance_differences_is_flagged_not_p_1e112():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ph = posthoc_paired(_effect_plus_offset(), "v", "mode")
    assert (ph["status"] == "zero_variance").all()
    assert ph["p_unc"].isna().all() and ph["T"].isna().all() and (ph["stars"] == "").all()


def test_degenerate_rows_are_spelled_out_in_the_paper_form():
    from psyop.statistics.formatting import format_anova, format_ttest

    row = rm_anova(_effect_plus_offset(), "v", "mode").effect("mode")
    assert format_anova(row).startswith("not testable: zero error variance")
    ph = posthoc_paired(_effect_plus_offset(), "v", "mode")
    assert format_ttest(ph.iloc[0]).startswith("not testable")
