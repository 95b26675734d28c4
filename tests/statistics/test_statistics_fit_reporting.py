"""What the threshold analyses report about each fit: open or out-of-range intervals counted
(psychometric.interval_report), and every fit's fate in each analysis (censored.fit_fates)."""

from __future__ import annotations

import numpy as np
import pandas as pd

from psyop.statistics.censored import fit_fates
from psyop.statistics.psychometric import interval_report


def _fits() -> pd.DataFrame:
    return pd.DataFrame({
        "participant": ["S1", "S1", "S2", "S2", "S3", "S3"],
        "back_D": [1.0, 2.0, 1.0, 2.0, 1.0, 2.0],
        "status": ["ok", "no_upper_bound", "ok", "censored_below", "bimodal", "ok"],
        "flags": ["ci_below_range", "", "ci_below_range;ci_above_range", "censored_below;ci_below_range",
                  "bimodal;ci_above_range", ""],
        "threshold_D": [0.3, 0.5, 0.4, np.nan, np.nan, 0.45],
        "threshold_bound_D": [np.nan, np.nan, np.nan, 0.2, np.nan, np.nan],
        "threshold_ci_low_D": [0.1, 0.3, 0.1, 0.0, 0.2, 0.35],
        "threshold_ci_high_D": [0.6, np.inf, 1.3, 0.3, 1.4, 0.55],
    })


def test_interval_report_counts_used_fits_with_open_or_out_of_range_intervals_once_each():
    """A no_upper_bound status counts whether or not its flags repeat it; censored and ambiguous fits,
    whose intervals the analyses never use as numbers, are not counted."""
    r = interval_report(_fits())
    assert r["n_used"] == 4
    assert r["by_flag"] == {"no_upper_bound": 1, "ci_below_range": 2, "ci_above_range": 1}
    assert r["n_open_or_out_of_range"] == 3  # S1/1, S1/2 and S2/1 (two flags, counted once)
    assert r["text"].startswith("3 of 4 fits used as numbers have an open or out-of-range 95 % CI "
                                "(no_upper_bound: 1, ci_below_range: 2, ci_above_range: 1): kept at their threshold")


def test_interval_report_says_so_when_every_interval_is_closed_and_in_range():
    fits = _fits().assign(status="ok", flags="")
    r = interval_report(fits)
    assert r["n_open_or_out_of_range"] == 0 and r["text"] == ("all 6 fits used as numbers have a closed 95 % CI "
                                                              "inside the tested levels")


def test_fit_fates_lists_every_fit_with_what_each_analysis_did_with_it():
    fates = fit_fates(_fits(), "back_D")
    assert [(f["participant"], f["back_D"]) for f in fates] == list(zip(_fits()["participant"], _fits()["back_D"]))
    assert [f["in_censored_model"] for f in fates] == ["observed", "observed", "observed", "censored_below",
                                                       "left out (bimodal)", "observed"]
    assert [f["in_plain_analysis"] for f in fates] == [True, True, True, False, False, True]
    assert fates[3]["threshold_bound_D"] == 0.2 and fates[1]["threshold_ci_D"][1] == np.inf


def test_a_censored_fit_without_a_bound_is_said_to_be_left_out_not_entered():
    fits = _fits()
    fits.loc[3, "threshold_bound_D"] = np.nan
    assert fit_fates(fits, "back_D")[3]["in_censored_model"] == "left out (censored, no bound recorded)"
