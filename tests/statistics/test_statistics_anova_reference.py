"""psyop's rm ANOVA against afex (R) golden values and pingouin's JASP-derived example."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pingouin as pg
import pytest

from psyop.statistics.anova import rm_anova

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "r"
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
        np.testing.assert_allclose(result[col].astype(float), golden[col].astype(float), rtol=1e-6, err_msg=col)


def test_golden_set_contains_a_sphericity_violation():
    golden = pd.read_csv(FIXTURES / "golden_twoway3x3.csv")
    assert (golden["mauchly_p"] < 0.05).all() and (golden["eps_gg"] < 0.65).all()


def test_pingouin_jasp_example_with_listwise_deletion_made_visible():
    wide = pg.read_dataset("rm_anova_wide")
    wide["participant"] = [f"s{i:02d}" for i in range(len(wide))]
    long = wide.melt(id_vars="participant", var_name="time", value_name="score")
    res = rm_anova(long, "score", "time")
    row = res.effect("time")
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
