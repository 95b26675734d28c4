"""End-to-end: the study analysis scripts on a small simulated dataset (in-process, one run)."""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from psyop.figures.study_figures import SIMULATED_LABEL, plot_preferences
from psyop.statistics import simulate as sim
from psyop.statistics.binomial import pairwise_preferences
from psyop.statistics.dataset import write_dataset

ANALYSIS = Path(__file__).resolve().parents[2] / "analysis"


def paper_protocol_hashes() -> dict[str, str]:
    """study name -> the hash of the shipped paper protocol (what a simulated paper session records)."""
    from psyop.protocol import load_protocol

    return {name: load_protocol(ANALYSIS.parent / "protocols" / f"{name}.yaml").source_sha256
            for name in ("detection", "discrimination", "ordinal", "egocentric", "realism")}


def _script(name: str):
    if str(ANALYSIS) not in sys.path:
        sys.path.insert(0, str(ANALYSIS))
    return importlib.import_module(name)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    root = tmp_path_factory.mktemp("study")
    rng = np.random.default_rng(0)
    det = sim.simulate_detection(rng, n_subjects=3)
    det.loc[(det["participant"] == "03") & (det["back_D"] == 3.0), "correct"] = True  # degenerate: all correct
    tables = {"detection": det, "discrimination": sim.simulate_discrimination(rng, n_subjects=3),
              "ordinal": sim.simulate_ordinal(rng, n_subjects=6), "egocentric": sim.simulate_reach(rng, n_subjects=4),
              "realism": sim.simulate_realism(rng, n_subjects=5)}
    ordinal = tables["ordinal"]
    tables["ordinal"] = ordinal[~((ordinal["participant"] == "02") & (ordinal["mode"] == "reversed")
                                  & (ordinal["separation_D"] == 2.0))]
    data, res, fig = root / "data", root / "results", root / "figures"
    write_dataset(data, tables, simulated=True, protocol_sha256=paper_protocol_hashes())
    common = ["--data", str(data), "--results", str(res)]
    for study in ("detection", "discrimination"):
        assert _script("fit_psychometric").main(
            ["--study", study, "--data", str(data), "--out", str(res / f"{study}_fits.csv"),
             "--n-jobs", "1", "--n-bootstrap", "100"]) == 0
        assert _script("supp_psychometric_functions").main(
            ["--study", study, "--data", str(data), "--fits", str(res / f"{study}_fits.csv"),
             "--out", str(fig / f"supp_psychometric_{study}.png")]) == 0
    assert _script("fig_detection_thresholds").main(common + ["--fits", str(res / "detection_fits.csv"),
                                                              "--out", str(fig / "det.png")]) == 0
    assert _script("fig_discrimination_thresholds").main(common + ["--fits", str(res / "discrimination_fits.csv"),
                                                                   "--out", str(fig / "dis.png")]) == 0
    for name in ("fig_ordinal_depth", "fig_egocentric_reach", "fig_realism"):
        assert _script(name).main(common + ["--out", str(fig / f"{name}.png")]) == 0
    assert _script("results_table").main(["--results", str(res), "--out", str(res / "summary.md")]) == 0
    return root


def test_every_figure_has_png_and_pdf(built):
    pngs = sorted(p.stem for p in (built / "figures").glob("*.png"))
    assert len(pngs) == 7
    for stem in pngs:
        assert (built / "figures" / f"{stem}.pdf").stat().st_size > 1000


def test_fit_cache_flags_the_degenerate_subject(built):
    fits = pd.read_csv(built / "results" / "detection_fits.csv", dtype={"participant": str})
    row = fits[(fits["participant"] == "03") & (fits["back_D"] == 3.0)].iloc[0]
    assert "all_correct" in row["flags"]
    assert fits["simulated"].all()
    assert row["status"] == "censored_below" and np.isnan(row["threshold_D"])  # a bound, not a negative number
    payload = json.loads((built / "results" / "detection_thresholds.json").read_text())
    assert payload["n_left_out"] >= 1 and payload["left_out_by_status"].get("censored_below", 0) >= 1
    assert any(r["participant"] == "03" and r["status"] == "censored_below" for r in payload["left_out"])
    assert "fits left out" in payload["summary"]["detection threshold (mean over subjects and back distances)"]
    report = payload["fit_intervals"]  # the fits whose CI is open or beyond the levels: counted, and the rule said
    assert payload["summary"]["fit intervals"] == report["text"] and "fits used as numbers" in report["text"]
    assert {r["participant"] for r in payload["fits"]} == set(fits["participant"]) and len(payload["fits"]) == len(fits)
    md = (built / "results" / "summary.md").read_text()
    assert f"- fit intervals: {report['text']}" in md
    assert f"{report['n_open_or_out_of_range']} of {report['n_used']} fits used as numbers have an open" in md


def test_summary_collects_every_study_and_says_simulated(built):
    md = (built / "results" / "summary.md").read_text()
    summary = json.loads((built / "results" / "summary.json").read_text())
    assert "Simulated data" in md and summary["simulated"] is True
    assert set(summary["summary"]) == {"detection_thresholds", "discrimination_fit", "ordinal", "egocentric", "realism"}
    assert "eps = " in md or "F(1, " in md
    assert "one-tailed binomial test" in md and "joint F(2, " in md


def test_summary_puts_the_paper_beside_psyop_for_all_five_studies(built):
    """The old summary gave psyop's numbers without the paper's."""
    md = (built / "results" / "summary.md").read_text()
    rows = json.loads((built / "results" / "summary.json").read_text())["paper_comparison"]
    assert {r["study"] for r in rows} == {"detection_thresholds", "discrimination_fit", "ordinal", "egocentric", "realism"}
    assert all(r["agrees"] in ("yes", "no", "n/a") and r["paper"] and r["psyop"] for r in rows)
    for paper_value in ("0.36 D", "F(1.7, 30.65) = 17.98", "1.141", "76.8 %", "0.38 D"):
        assert paper_value in md
    assert "| study | statistic | paper | psyop | agrees | criteria |" in md
    assert "Criterion: A row agrees when every criterion it has passes" in md
    assert all(r["criteria"] for r in rows)
    assert "Bonferroni over the 3 mode pairs within each separation (m = 3)" in md
    assert "--bonferroni-family" in md and "Eta (overdispersion) is fixed at 0" in md
    assert "random intercept and slope per participant" in md


def test_ordinal_listwise_deletion_is_reported(built):
    payload = json.loads((built / "results" / "ordinal.json").read_text())
    assert payload["n_subjects"] == 5
    assert payload["dropped"][0]["subject"] == "02" and "mode=reversed" in payload["dropped"][0]["reason"]
    anova = pd.read_csv(built / "results" / "ordinal_anova.csv")
    assert list(anova["effect"]) == ["mode", "separation_D", "mode * separation_D"]


@pytest.mark.parametrize("simulated", [True, False])
def test_simulated_mark_only_when_simulated(simulated):
    rng = np.random.default_rng(1)
    prefs = pairwise_preferences(sim.simulate_realism(rng, n_subjects=4), [("ocular", "conventional")])
    fig = plot_preferences(prefs, simulated=simulated)
    texts = [t.get_text() for t in fig.texts]
    assert (SIMULATED_LABEL in texts) is simulated


@pytest.mark.parametrize("script, study", [("fig_ordinal_depth", "ordinal"), ("fig_egocentric_reach", "egocentric"),
                                           ("fig_realism", "realism")])
def test_study_scripts_take_a_user_study_name_and_refuse_a_missing_one_in_one_line(tmp_path, script, study):
    """A user's own protocol of a shipped kind has its own study name (data/<name>/); the script takes
    it with --study, and a study with no sessions is one located line and exit 2, not a traceback."""
    import subprocess

    rng = np.random.default_rng(1)
    table = {"ordinal": lambda: sim.simulate_ordinal(rng, n_subjects=4), "egocentric": lambda: sim.simulate_reach(rng, n_subjects=4),
             "realism": lambda: sim.simulate_realism(rng, n_subjects=4)}[study]()
    table["study"] = "mystudy"
    write_dataset(tmp_path / "data", {"mystudy": table}, simulated=True)
    common = ["--data", str(tmp_path / "data"), "--results", str(tmp_path / "res"), "--out", str(tmp_path / "f.png")]
    missing = subprocess.run([sys.executable, str(ANALYSIS / f"{script}.py"), *common], capture_output=True, text=True)
    assert missing.returncode == 2 and "Traceback" not in missing.stderr
    assert f"no sessions found for study '{study}'" in missing.stderr
    assert _script(script).main([*common, "--study", "mystudy"]) == 0


def test_results_name_no_machine_path_and_cite_the_paper_by_reference(built):
    """results/summary.md named the paper by an absolute path of the machine it was built on."""
    import re

    md = (built / "results" / "summary.md").read_text()
    assert "Gaze-Contingent Ocular Parallax Rendering for Virtual Reality" in md and "Konrad" in md
    for path in sorted((built / "results").glob("*.json")) + [built / "results" / "summary.md"]:
        text = path.read_text()
        assert str(built) not in text and "/work/" not in text, path.name
        absolute = re.findall(r"(?:^|[\s(`'\"\[])(/[A-Za-z0-9_.-]+/[^\s)`'\"]*)", text, flags=re.M)
        assert not absolute, f"{path.name}: absolute paths {absolute[:3]}"


def _run_script(name: str, *args: str):
    import subprocess

    return subprocess.run([sys.executable, str(ANALYSIS / f"{name}.py"), *args], capture_output=True, text=True)


def test_a_user_study_beside_the_papers_leaves_every_paper_row_and_figure_unchanged(built, tmp_path):
    """Issue 18: a user's stereo ordinal study analysed beside the paper's data used to overwrite
    results/ordinal.json and land in the paper's rows. Now its outputs carry its own name and the
    paper's summary is byte-for-byte the same."""
    import shutil

    tree = tmp_path / "tree"
    shutil.copytree(built, tree)
    data, res, fig = tree / "data", tree / "results", tree / "figures"
    before_md = (res / "summary.md").read_bytes()
    before_json = (res / "summary.json").read_bytes()
    paper_files = {p.name: p.read_bytes() for p in [*res.glob("*"), *fig.glob("*")]}
    rng = np.random.default_rng(7)
    user = sim.simulate_ordinal(rng, n_subjects=3)
    user["study"] = "stereo_ordinal_blocked"
    write_dataset(data, {"stereo_ordinal_blocked": user}, simulated=True, protocol_sha256={"stereo_ordinal_blocked": "ab" * 32})
    common = ["--data", str(data), "--results", str(res)]
    assert _script("fig_ordinal_depth").main(common + ["--study", "stereo_ordinal_blocked",
                                                       "--out", str(fig / "stereo_ordinal_blocked_depth.png")]) == 0
    assert _script("results_table").main(["--results", str(res), "--out", str(res / "summary.md")]) == 0
    assert (res / "summary.md").read_bytes() == before_md
    assert (res / "summary.json").read_bytes() == before_json
    for name, content in paper_files.items():
        target = res / name if (res / name).exists() else fig / name
        assert target.read_bytes() == content or name.endswith(".pdf"), f"{name} changed"
    payload = json.loads((res / "stereo_ordinal_blocked.json").read_text())
    assert payload["study"] == "stereo_ordinal_blocked" and payload["protocol_sha256"] == ["ab" * 32]
    assert (fig / "stereo_ordinal_blocked_depth.png").exists()
    own = (res / "stereo_ordinal_blocked_summary.md").read_text()
    assert "stereo_ordinal_blocked rm-ANOVA: mode" in own and "not one of the paper's protocols" in own


def test_a_paper_named_study_run_from_another_protocol_does_not_fill_the_paper_rows(built, tmp_path):
    """Identified by protocol hash, not by name: data/ordinal run from a user's own protocol."""
    import shutil

    tree = tmp_path / "tree"
    shutil.copytree(built / "data", tree / "data", ignore=shutil.ignore_patterns("ordinal"))
    rng = np.random.default_rng(3)
    write_dataset(tree / "data", {"ordinal": sim.simulate_ordinal(rng, n_subjects=4)}, simulated=True,
                  protocol_sha256={"ordinal": "cd" * 32})
    res = tree / "results"
    assert _script("fig_ordinal_depth").main(["--data", str(tree / "data"), "--results", str(res),
                                              "--out", str(tree / "o.png")]) == 0
    assert _script("results_table").main(["--results", str(res), "--out", str(res / "summary.md")]) == 0
    rows = json.loads((res / "summary.json").read_text())["paper_comparison"]
    assert {r["psyop"] for r in rows if r["study"] == "ordinal"} == {"study not run"}
    assert (res / "ordinal_summary.md").exists()


def test_supp_psychometric_and_thresholds_take_a_user_two_interval_study(built, tmp_path):
    """supp_psychometric_functions.py refused any name but the paper's; the thresholds figure read
    back_D whatever the study's factor was. A contrast study labels its axes from its own factors."""
    rng = np.random.default_rng(5)
    det = sim.simulate_detection(rng, n_subjects=2).rename(columns={"back_D": "size_deg"})
    det["study"] = "contrast_study"
    data, res = tmp_path / "data", tmp_path / "results"
    write_dataset(data, {"contrast_study": det}, simulated=True)
    common = ["--data", str(data), "--results", str(res), "--study", "contrast_study"]
    assert _script("fit_psychometric").main(common + ["--condition-column", "size_deg", "--n-jobs", "1",
                                                      "--n-bootstrap", "50"]) == 0
    assert (res / "contrast_study_fits.csv").exists()
    assert _script("supp_psychometric_functions").main(common + ["--out", str(tmp_path / "supp.png")]) == 0
    assert _script("fig_detection_thresholds").main(common + ["--out", str(tmp_path / "thr.png")]) == 0
    payload = json.loads((res / "contrast_study_thresholds.json").read_text())
    assert payload["condition_column"] == "size_deg" and payload["study"] == "contrast_study"
    assert any("size (deg)" in k for k in payload["summary"])


@pytest.mark.parametrize("case", ["missing_fits", "fits_without_condition", "wrong_kind", "no_condition"])
def test_bad_analysis_input_is_one_line_and_exit_2(built, tmp_path, case):
    data, res = str(built / "data"), str(tmp_path / "res")
    if case == "missing_fits":
        result = _run_script("fig_detection_thresholds", "--data", data, "--fits", str(tmp_path / "none.csv"),
                             "--results", res, "--out", str(tmp_path / "x.png"))
        expected = "no fit cache here"
    elif case == "fits_without_condition":
        fits = pd.read_csv(built / "results" / "detection_fits.csv").drop(columns=["back_D", "condition_column"])
        fits.to_csv(tmp_path / "f.csv", index=False)
        result = _run_script("fig_detection_thresholds", "--data", data, "--fits", str(tmp_path / "f.csv"),
                             "--results", res, "--out", str(tmp_path / "x.png"))
        expected = "no column 'back_D'"
    elif case == "wrong_kind":
        result = _run_script("supp_psychometric_functions", "--data", data, "--study", "ordinal",
                             "--results", res, "--out", str(tmp_path / "x.png"))
        expected = "analyses two-interval"
    else:
        result = _run_script("fig_ordinal_depth", "--data", data, "--study", "nosuch", "--results", res,
                             "--out", str(tmp_path / "x.png"))
        expected = "no sessions found for study 'nosuch'"
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert expected in result.stderr
