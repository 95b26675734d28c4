"""The NC calibration example end to end (issue 18): the shipped protocol validates and passes the audit,
simulated sessions are analysed by analysis/nc_calibration.py (outputs named after the study, each
participant's PSS with its interval holding the simulated participant's own NC), `psyop studies` builds it by
its response kind, and bad input is one line with exit 2. Coverage over 200 participants is
benchmarks/bench_nc_calibration.py."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from psyop.cli import main

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "protocols" / "examples" / "nc_calibration.yaml"


def _script(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(REPO / "analysis" / "nc_calibration.py"), *args], cwd=REPO,
                          capture_output=True, text=True)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("nc") / "data"
    assert main(["simulate", "--protocols", str(EXAMPLE), "--participants", "3", "--data", str(root), "--jobs", "1"]) == 0
    return root


def test_the_example_validates_and_passes_the_audit() -> None:
    from psyop.audit.run import AuditSettings, run_audit
    from psyop.protocol import load_protocol
    from psyop.rendering.renderer import create_headless_context

    assert main(["validate", str(EXAMPLE)]) == 0
    ctx = create_headless_context()
    try:
        report = run_audit(load_protocol(EXAMPLE), AuditSettings(scale=0.125, gazes=2, samples_per_axis=8), ctx=ctx,
                           base_dir=EXAMPLE.parent)
    finally:
        ctx.release()
    assert report.passed, "\n".join(report.failures)
    assert {r.frame.mode for r in report.records} == {"conventional", "ocular", "reversed"}


def test_the_analysis_recovers_each_simulated_participants_nc(simulated: Path, tmp_path: Path) -> None:
    from benchmarks.bench_nc_calibration import true_nc_mm

    results, figure = tmp_path / "results", tmp_path / "figures" / "nc_calibration_pss.png"
    done = _script("--data", str(simulated), "--results", str(results), "--out", str(figure))
    assert done.returncode == 0, done.stderr
    assert figure.is_file() and figure.with_suffix(".pdf").is_file()
    fits = pd.read_csv(results / "nc_calibration_pss.csv", dtype={"participant": str})
    payload = json.loads((results / "nc_calibration.json").read_text())
    assert payload["study"] == "nc_calibration" and payload["response_kind"] == "with_against"
    truth = true_nc_mm(simulated, "nc_calibration")
    assert sorted(truth) == sorted(fits["participant"]) == ["S01", "S02", "S03"]
    assert len(set(round(v, 6) for v in truth.values())) == 3  # three participants, three own NCs
    for _, fit in fits.iterrows():
        assert fit["status"] == "ok"
        assert fit["pss_ci_low_mm"] <= truth[fit["participant"]] <= fit["pss_ci_high_mm"], fit.to_dict()
        assert payload["calibrated_rendering_nc"][fit["participant"]] == f"display.rendering_nc: {{mm: {fit['pss_mm']:.2f}}}"
    # the calibrated line is a valid protocol: a later protocol renders with the participant's PSS
    from psyop.protocol import parse_protocol

    detection = (REPO / "protocols" / "detection.yaml").read_text()
    line = payload["calibrated_rendering_nc"]["S01"]
    parse_protocol(detection.replace("  ipd: tracker ", f"  {line.replace('display.', '')}\n  ipd: tracker "),
                   "calibrated.yaml", REPO / "protocols")


def test_psyop_studies_builds_it_by_its_kind(simulated: Path, capsys) -> None:
    assert main(["studies", str(simulated)]) == 0
    assert "nc_calibration (with/against (NC calibration)): nc_calibration_pss.png" in capsys.readouterr().out


def test_bad_input_is_one_line_with_exit_2(simulated: Path, tmp_path: Path) -> None:
    done = _script("--data", str(tmp_path / "absent"), "--results", str(tmp_path / "r"))
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1 and "no sessions found" in done.stderr
    done = _script("--data", str(simulated), "--study", "nc_calibration", "--level-column", "nope",
                   "--results", str(tmp_path / "r"), "--out", str(tmp_path / "f.png"))
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1 and "'nope'" in done.stderr
    # a study of another kind
    from psyop.statistics.dataset import write_dataset

    other = tmp_path / "other"
    write_dataset(other, {"prefs": pd.DataFrame({"participant": ["1"], "session": [1], "pair": ["a|b"], "mode_a": ["a"],
                                                 "mode_b": ["b"]})}, simulated=True)
    done = _script("--data", str(other), "--study", "prefs", "--results", str(tmp_path / "r"))
    assert done.returncode == 2 and "nc_calibration.py analyses with_against studies" in done.stderr
