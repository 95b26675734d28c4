"""Paper-form strings, the dataset loader, and post-hoc tables."""

from __future__ import annotations

import json
from pathlib import Path

import pyarrow as pa

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from psyop.errors import UserError
from psyop.statistics.anova import cell_means, posthoc_paired, significance_stars
from psyop.statistics.dataset import load_dataset, load_trials, write_dataset
from psyop.statistics.formatting import format_anova, format_binomial, format_p
from psyop.statistics.goodness import binomial_deviance
from psyop.statistics.simulate import simulate_detection, simulate_ordinal


def test_format_anova_paper_examples():
    mode = {"F": 17.98, "df1": 2, "df2": 36, "df1_gg": 1.70, "df2_gg": 30.65, "eps_gg": 0.85,
            "p_gg": 2e-6, "p_unc": 1e-7}
    assert format_anova(mode) == "F(1.70, 30.65) = 17.98, p < 0.0001, eps = 0.85"
    dist = {"F": 8.14, "df1": 1, "df2": 18, "df1_gg": 1, "df2_gg": 18, "eps_gg": 1.0, "p_gg": 0.0106, "p_unc": 0.0106}
    assert format_anova(dist) == "F(1, 18) = 8.14, p = 0.011"
    inter = {"F": 0.42, "df1": 2, "df2": 36, "df1_gg": 1.78, "df2_gg": 31.96, "eps_gg": 0.89, "p_gg": 0.64, "p_unc": 0.66}
    assert format_anova(inter) == "F(1.78, 31.96) = 0.42, p = 0.64, eps = 0.89"


def test_format_binomial_and_p():
    row = {"proportion": 0.768, "k": 219, "n": 285, "p": 1e-20}
    assert format_binomial(row) == "76.8% (219/285), p < 0.0001, one-tailed binomial test"
    assert format_p(0.0005) == "p < 0.001" and format_p(float("nan")) == "p = n/a"


@settings(max_examples=40)
@given(st.lists(st.tuples(st.integers(1, 30), st.floats(0.01, 0.99)), min_size=1, max_size=6))
def test_deviance_is_nonnegative_and_zero_at_saturation(cells):
    n = np.array([c[0] for c in cells])
    p = np.array([c[1] for c in cells])
    k = np.round(n * p)
    assert binomial_deviance(k, n, p) >= -1e-9
    saturated = np.clip(k / n, 1e-12, 1 - 1e-12)
    assert binomial_deviance(k, n, saturated) == pytest.approx(0.0, abs=1e-6)


def test_stars_thresholds():
    assert [significance_stars(p) for p in (0.0005, 0.001, 0.005, 0.05, 0.051)] == ["***", "***", "**", "*", ""]


def test_dataset_round_trip_and_simulated_flag(tmp_path):
    rng = np.random.default_rng(0)
    det = simulate_detection(rng, n_subjects=3)
    det.loc[det["participant"] == "02", "session"] = 2
    det["practice"] = False
    det.loc[det.index[:4], "practice"] = True
    write_dataset(tmp_path, {"detection": det}, simulated=True)
    ds = load_dataset(tmp_path, "detection")
    assert ds.simulated and ds.n_sessions == 3
    trials = load_trials(tmp_path, "detection")
    assert len(trials) == len(det) - 4 and trials.attrs["n_practice_dropped"] == 4
    assert len(load_trials(tmp_path, "detection", include_practice=True)) == len(det)
    assert trials["participant"].dtype == object or str(trials["participant"].dtype) == "str"
    assert set(trials["participant"]) == {"01", "02", "03"}
    assert json.loads((tmp_path / "dataset_description.json").read_text())["simulated"] is True


def test_missing_study_is_a_user_error(tmp_path):
    with pytest.raises(UserError, match="no sessions"):
        load_trials(tmp_path, "ordinal")


def test_posthoc_per_separation_bonferroni_and_dropping():
    rng = np.random.default_rng(2)
    cm = cell_means(simulate_ordinal(rng), "correct", ["mode", "separation_D"])
    cm = cm[~((cm["participant"] == "03") & (cm["mode"] == "ocular") & (cm["separation_D"] == 2.0))]
    ph = posthoc_paired(cm, "correct", "mode", by="separation_D")
    assert len(ph) == 6 and (ph["m"] == 3).all()
    assert (ph["n_subjects"] == 18).all()  # subject 03 dropped listwise
    np.testing.assert_allclose(ph["p_bonf"], np.minimum(ph["p_unc"] * 3, 1))
    row = ph[(ph["separation_D"] == 2.0) & (ph["A"] == "conventional") & (ph["B"] == "ocular")].iloc[0]
    assert row["p_bonf"] < 0.001 and row["stars"] == "***"
    assert isinstance(ph, pd.DataFrame)


def test_rm_anova_refuses_too_few_complete_subjects():
    from psyop.statistics.anova import rm_anova

    data = pd.DataFrame({"participant": ["a"] * 3 + ["b"] * 3, "m": ["x", "y", "z"] * 2, "v": [1.0, 2, 3, 2, 2, 5]})
    with pytest.raises(ValueError, match="2 complete subject"):
        rm_anova(data, "v", "m")


def test_posthoc_family_all_corrects_over_every_comparison():
    rng = np.random.default_rng(4)
    cm = cell_means(simulate_ordinal(rng, n_subjects=8), "correct", ["mode", "separation_D"])
    ph = posthoc_paired(cm, "correct", "mode", by="separation_D", family="all")
    assert (ph["m"] == 6).all()
    np.testing.assert_allclose(ph["p_bonf"], np.minimum(ph["p_unc"] * 6, 1))


def test_typed_response_columns_and_an_old_session_without_them_reads_the_same(tmp_path):
    """New sessions log response_value (a number where the response is one) and outcome; a session
    logged before them (trials.parquet without the columns) reads with the same columns derived."""
    import subprocess
    import sys

    import pyarrow.parquet as pq

    from psyop.datacontract import with_typed_response
    from psyop.statistics.dataset import load_trials

    root = Path(__file__).resolve().parents[2]
    data = tmp_path / "data"
    subprocess.run([sys.executable, "-m", "psyop", "simulate", "--data", str(data), "--protocols",
                    str(root / "protocols" / "detection.yaml"), "--participants", "1", "--jobs", "1"],
                   check=True, capture_output=True)
    new = load_trials(data, "detection")
    assert new["response_value"].dtype == "float64" and set(new["response_value"].dropna()) <= {1.0, 2.0}
    assert new["response_value"].notna().all() and set(new["outcome"]) == {"answered"}
    (path,) = sorted(data.glob("detection/sub-*/ses-*/trials.parquet"))
    table = pq.read_table(path)
    old = table.drop_columns(["response_value", "outcome"])
    first = int(new["trial"].iloc[0])  # a counted (not practice) trial: it becomes a timeout
    responses = ["timeout" if t == first else r for t, r in zip(old.column("trial").to_pylist(),
                                                                 old.column("response").to_pylist())]
    old = old.set_column(old.schema.get_field_index("response"), "response", pa.array(responses, pa.string()))
    pq.write_table(old.replace_schema_metadata(table.schema.metadata), path)
    subprocess.run([sys.executable, "-m", "psyop", "reseal", str(path.parent), "--reason",
                    "test: rewritten in the format before the typed response columns"], check=True, capture_output=True)
    read = load_trials(data, "detection")  # the loader derives the typed columns, then drops the timeout
    assert read.attrs["n_timeout_dropped"] == 1 and set(read["outcome"]) == {"answered"}
    rest = new[new["trial"] != first]
    assert read["trial"].tolist() == rest["trial"].tolist()
    assert read["response_value"].tolist() == rest["response_value"].tolist()
    typed = with_typed_response(old.to_pandas()).set_index("trial")
    assert typed.loc[first, "outcome"] == "timeout" and pd.isna(typed.loc[first, "response_value"])
