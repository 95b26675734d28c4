"""Issue 29, "Done when": a held-out adaptive study of 4 participants, from a protocol written for the test
(tests/analysis/fixtures/stereo_staircase.yaml: a stereo, weighted up-down staircase over two reference
offsets at 10 deg, whose floor censors some fits; none of the shipped protocols), simulated through
``python -m psyop simulate`` and run through the analysis scripts `make figures` runs for it.

Asserted: no participant silently dropped (every participant x condition is in the fit cache, in the
thresholds JSON's per-fit list with what each analysis did with it, and a censored fit is flagged as
censored and in the censored-data model); every low-df test is flagged; the group model actually fitted
is named in the figure's caption and the JSON; a track is drawn for every participant x condition; the
summary counts the fits with an open or out-of-range CI and says what was done with them."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[2]
FIXTURE = REPO / "tests/analysis/fixtures/stereo_staircase.yaml"
STUDY = "stereo_staircase"
N_PARTICIPANTS, N_TRIALS, CONDITIONS = 4, 24, [1.0, 3.0]  # the fixture's repetitions and offset_D levels


@pytest.fixture(scope="module")
def analysed(tmp_path_factory):
    """Simulate the fixture, then fit, draw the tracks and the thresholds (spies keep the caption and the
    track figure's panels)."""
    root = tmp_path_factory.mktemp("held_out_adaptive")
    data, res = root / "data", root / "results"
    subprocess.run([sys.executable, "-m", "psyop", "simulate", "--data", str(data), "--protocols", str(FIXTURE),
                    "--participants", str(N_PARTICIPANTS), "--jobs", "1"], check=True, capture_output=True, cwd=REPO)
    mp = pytest.MonkeyPatch()
    mp.syspath_prepend(str(REPO / "analysis"))
    seen: dict = {}
    try:
        import adaptive_tracks
        import fig_detection_thresholds
        import fit_psychometric

        from psyop.figures.study_figures import caption as real_caption

        real_tracks = adaptive_tracks.plot_tracks

        def tracks_spy(*args, **kwargs):
            fig = real_tracks(*args, **kwargs)
            seen["panels"] = [[(line.get_xdata(), line.get_ydata()) for line in ax.get_lines()] for ax in fig.axes]
            seen["panel_text"] = [" ".join(t.get_text() for t in ax.texts) for ax in fig.axes]
            return fig

        def caption_spy(fig, text, *args, **kwargs):
            seen.setdefault("captions", []).append(text)
            return real_caption(fig, text, *args, **kwargs)

        mp.setattr(adaptive_tracks, "plot_tracks", tracks_spy)
        mp.setattr(fig_detection_thresholds, "caption", caption_spy, raising=False)
        common = ["--data", str(data), "--results", str(res), "--study", STUDY]
        assert fit_psychometric.main(["--study", STUDY, "--data", str(data), "--out", str(res / f"{STUDY}_fits.csv"),
                                      "--n-jobs", "1", "--n-bootstrap", "20"]) == 0
        assert adaptive_tracks.main(common + ["--out", str(root / "tracks.png")]) == 0
        assert fig_detection_thresholds.main(common + ["--out", str(root / "thresholds.png")]) == 0
    finally:
        mp.undo()
    fits = pd.read_csv(res / f"{STUDY}_fits.csv", dtype={"participant": str}, keep_default_na=False, na_values=[""])
    return {"root": root, "res": res, "fits": fits, "seen": seen,
            "thresholds": json.loads((res / f"{STUDY}_thresholds.json").read_text()),
            "adaptive": json.loads((res / f"{STUDY}_adaptive.json").read_text())}


def test_every_participant_and_condition_is_in_the_fits_and_the_thresholds_results(analysed):
    fits, thresholds = analysed["fits"], analysed["thresholds"]
    pairs = {(p, c) for p in sorted(fits["participant"].unique()) for c in CONDITIONS}
    assert len(pairs) == N_PARTICIPANTS * len(CONDITIONS)
    assert set(zip(fits["participant"], fits["offset_D"])) == pairs
    assert thresholds["n_subjects"] == N_PARTICIPANTS and thresholds["n_fits"] == len(pairs)
    records = thresholds["fits"]
    assert {(r["participant"], r["offset_D"]) for r in records} == pairs and len(records) == len(pairs)
    censored = [r for r in records if r["status"].startswith("censored") or r["status"] == "lapse_at_bound"]
    assert censored, "the fixture's floor (0.4 D) censors at least one fit: the test would not test censoring"
    for r in records:
        if r in censored:  # flagged as censored, out of the plain mean, in the censored-data model at its bound
            assert not r["in_plain_analysis"] and r["in_censored_model"] in ("censored_below", "censored_above")
            assert r["threshold_bound_D"] is not None
        elif r["status"] in ("ok", "no_upper_bound"):
            assert r["in_plain_analysis"] and r["in_censored_model"] == "observed"
        else:
            assert r["in_censored_model"].startswith("left out (")
    c = thresholds["censored"]
    assert c["n_censored_below"] + c["n_censored_above"] == len(censored)
    mean_line = next(v for k, v in thresholds["summary"].items() if "threshold (mean over" in k)
    assert f"of {N_PARTICIPANTS} participants" in mean_line
    without = sorted(set(fits["participant"]) - {r["participant"] for r in records if r["in_plain_analysis"]})
    assert all(p in mean_line for p in without)  # a participant without a usable fit is named


def test_every_low_df_test_is_flagged(analysed):
    summary = analysed["thresholds"]["summary"]
    tests = {k: v for k, v in summary.items() if "rm-ANOVA" in k or "threshold (mean over" in k or "Tobit" in k}
    assert len(tests) == 4, tests  # plain mean, rm-ANOVA, Tobit mean, rm-ANOVA with censored fits at their bounds
    for key, text in tests.items():  # 4 participants: at most 3 df for every one of them
        assert "LOW DF" in text or text.startswith(("not computed", "same as above")), (key, text)
    anova = next(v for k, v in summary.items() if k.endswith("(rm-ANOVA)"))
    dropped = [d["subject"] for d in analysed["thresholds"].get("anova_dropped", [])]
    assert all(s in anova for s in dropped)  # a participant the rm-ANOVA left out is named in its line


def test_the_fitted_group_model_is_named_in_the_caption_and_the_json(analysed):
    thresholds, (caption,) = analysed["thresholds"], analysed["seen"]["captions"]
    model = thresholds["group_model"]
    assert model["name"] in caption.replace("\n", " ")
    if model["fallback"]:
        assert "FALLBACK" in caption and "censored_fits_left_out" in model["flags"]
    else:
        assert model["name"].startswith("censored-normal (Tobit)") and model["model"] == thresholds["censored"]["mean"]["model"]
    assert "low_df" in model["flags"] and "FLAGGED: low_df" in caption
    assert (analysed["root"] / "thresholds.png").stat().st_size > 10_000


def test_a_track_is_drawn_for_every_participant_and_condition(analysed):
    tracks, seen = analysed["adaptive"]["tracks"], analysed["seen"]
    assert len(tracks) == N_PARTICIPANTS * len(CONDITIONS) and all(t["n_trials"] == N_TRIALS for t in tracks)
    assert {t["procedure"] for t in tracks} == {"staircase_weighted_0.75"}
    drawn = [lines for lines in seen["panels"] if lines and len(lines[0][0]) == N_TRIALS]
    assert len(drawn) == N_PARTICIPANTS * len(CONDITIONS)  # one panel per track, its level line of every trial
    n_censored = sum(t["fit_status"].startswith("censored") for t in tracks)
    assert sum("fit: censored" in text for text in seen["panel_text"]) == n_censored
    assert (analysed["root"] / "tracks.png").stat().st_size > 10_000


def test_the_summary_counts_fits_with_an_open_or_out_of_range_interval(analysed):
    """Before issue 29 item 2 the thresholds summary said nothing of them (here most fits' CIs reach
    below the floor: a 24-trial staircase tests few levels)."""
    fits, thresholds = analysed["fits"], analysed["thresholds"]
    used = fits[fits["status"].isin(["ok", "no_upper_bound"])]
    marks = [set(f.split(";")) | {s} for f, s in zip(used["flags"].fillna(""), used["status"])]
    expected = {f: sum(f in m for m in marks) for f in ("no_upper_bound", "ci_below_range", "ci_above_range")}
    n_open = sum(bool(m & set(expected)) for m in marks)
    report = thresholds["fit_intervals"]
    assert report["by_flag"] == expected and report["n_open_or_out_of_range"] == n_open and n_open > 0
    text = thresholds["summary"]["fit intervals"]
    assert text.startswith(f"{n_open} of {len(used)} fits used as numbers have an open or out-of-range 95 % CI")
    assert all(f"{f}: {v}" in text for f, v in expected.items() if v)
    assert "kept at their threshold" in text  # what was done with them


def test_where_the_censored_data_model_cannot_be_fitted_the_caption_names_the_fallback(monkeypatch):
    """One uncensored fit of four: the Tobit mean is refused, and the figure says what it showed instead."""
    from psyop.statistics.censored import censored_report

    monkeypatch.syspath_prepend(str(REPO / "analysis"))
    import fig_detection_thresholds as script

    fits = pd.DataFrame({"participant": ["S1", "S2", "S3", "S4"], "back_D": 1.0,
                         "status": ["ok", "censored_below", "censored_below", "censored_above"],
                         "threshold_D": [0.4, None, None, None], "threshold_bound_D": [None, 0.2, 0.2, 1.0]})
    report = censored_report(fits, "back_D", "D")
    assert report["text_mean"].startswith("not computed")
    model = script._group_model(report, 1)
    assert model["fallback"] and model["flags"] == ["censored_fits_left_out", "low_df"]
    assert model["name"].startswith("t-interval over the participants' usable fits") and "not computed" in model["model"]
    text = script._caption(model)
    assert model["name"] in text and "(FALLBACK)" in text and "censored_fits_left_out" in text
