"""psyop's rm ANOVA against afex (R) golden values and pingouin's JASP-derived example."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pingouin as pg
import pytest

from psyop.statistics.anova import rm_anova

pytestmark = pytest.mark.cross_cpu  # recorded R values: the tolerance must hold on every CPU

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "r"
# Tolerance against afex: 1e-6 relative. The goldens are R 4.2.2 / afex 1.2.1 values written by write.csv
# (15 significant digits, tests/fixtures/r/afex_golden.R); psyop agreed with them to 1.4e-12 at worst
# (twoway3x2; 4e-15 on the one-way designs), measured with numpy's AVX-512 and AVX2 kernels alike. The
# differences come from the F and chi-square tails (scipy against R's pf/pchisq) and the Mauchly
# determinant, whose last digits vary with the library and the CPU; 1e-6 leaves room for those and is
# still far below any formula error (a wrong df, correction or sum of squares moves a value by 1e-3 or more;
# test_the_tolerance_catches_a_small_error checks that a 1e-5 change fails).
RTOL = 1e-6
DESIGNS = {
    "oneway4": ("y", ["time"]),
    "twoway3x2": ("pc", ["mode", "separation"]),
    "twoway3x3": ("y", ["A", "B"]),
    "pingouin_wide_complete": ("y", ["time"]),
}


@pytest.mark.parametrize("design", sorted(DESIGNS))
def test_matches_afex_gg(design):
    dv, within = DESIGNS[design]
    data = pd.read_csv(FIXTURES / f"design_{design}.csv")
    golden = pd.read_csv(FIXTURES / f"golden_{design}.csv").set_index("effect")
    result = rm_anova(data, dv, within).table.set_index("effect")
    assert list(result.index) == list(golden.index)
    for col in ["F", "df1", "df2", "df1_gg", "df2_gg", "eps_gg", "p_unc", "p_gg", "mauchly_W", "mauchly_p"]:
        np.testing.assert_allclose(result[col].astype(float), golden[col].astype(float), rtol=RTOL, err_msg=col)


def test_the_tolerance_catches_a_small_error():
    dv, within = DESIGNS["twoway3x3"]
    result = rm_anova(pd.read_csv(FIXTURES / "design_twoway3x3.csv"), dv, within).table.set_index("effect")
    golden = pd.read_csv(FIXTURES / "golden_twoway3x3.csv").set_index("effect")
    with pytest.raises(AssertionError):
        np.testing.assert_allclose(result["F"].astype(float) * (1 + 1e-5), golden["F"].astype(float), rtol=RTOL)


def test_golden_set_contains_a_sphericity_violation():
    golden = pd.read_csv(FIXTURES / "golden_twoway3x3.csv")
    assert (golden["mauchly_p"] < 0.05).all() and (golden["eps_gg"] < 0.65).all()


def test_pingouin_jasp_example_with_listwise_deletion_made_visible():
    wide = pg.read_dataset("rm_anova_wide")
    wide["participant"] = [f"s{i:02d}" for i in range(len(wide))]
    long = wide.melt(id_vars="participant", var_name="time", value_name="score")
    res = rm_anova(long, "score", "time")
    row = res.effect("time")
    # JASP's published values have 5 decimals: abs=1e-5 is their rounding (half a unit, 5e-6) with room to spare
    assert row["F"] == pytest.approx(5.20065, abs=1e-5)
    assert row["eps_gg"] == pytest.approx(0.69433, abs=1e-5)
    assert row["p_gg"] == pytest.approx(0.01670, abs=1e-5)
    assert (row["df1"], row["df2"]) == (3, 24)
    # three subjects have a missing cell: they are listed with the cell that is missing
    assert list(res.dropped["subject"]) == ["s02", "s06", "s10"]
    assert "time=3 week" in res.dropped.set_index("subject").loc["s02", "reason"]
    assert res.n_subjects == 9


def test_duplicate_cells_are_an_error():
    data = pd.read_csv(FIXTURES / "design_oneway4.csv")
    with pytest.raises(ValueError, match="aggregate"):
        rm_anova(pd.concat([data, data.iloc[:1]]), "y", "time")
