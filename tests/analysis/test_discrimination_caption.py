"""The discrimination figure's caption names the models actually fitted (issue 29): the drawn least-squares
line with its df and flag, and the censored-data line beside it, or that it was not fitted and why."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "analysis"))

from fig_discrimination_thresholds import line_caption


def test_the_caption_names_both_lines_with_their_df_and_flags() -> None:
    text = line_caption(12, 0, {"line": {"df_interval": 5, "low_df": False, "n_clusters": 6}})
    assert "least-squares fit of the 12 usable fits (t on 10 df); 0 fits left out" in text
    assert "censored-normal (Tobit) line, participant-clustered SEs, t on 5 df." in text
    assert "FLAGGED" not in text


def test_too_few_df_are_flagged_and_an_unfitted_censored_line_says_why() -> None:
    text = line_caption(4, 2, {"text_mean": "not computed: every fit is censored"})
    assert "(t on 2 df) [FLAGGED: low_df]; 2 fits left out" in text
    assert "Tobit) line NOT FITTED (not computed: every fit is censored)" in text
