"""`make figures` is incremental: a new session of one study rebuilds only that study's
fits, its figures and the summary (checked with make's dry run on a scratch tree)."""

from __future__ import annotations

import hashlib
import json
import os
import subprocess
from pathlib import Path

import sys

import pytest

REPO = Path(__file__).resolve().parents[1]
STUDIES = {"detection": "2afc_interval", "discrimination": "2afc_interval", "ordinal": "near_side",
           "egocentric": "reach", "realism": "preference"}
OUTPUTS = [  # in build order: each is written after the ones before it
    "results/detection_fits.csv", "results/discrimination_fits.csv",
    "figures/fig03_parallax_vs_eccentricity.png", "figures/supp_linearity.png",
    "figures/detection_thresholds.png", "figures/discrimination_thresholds.png",
    "figures/supp_psychometric_detection.png", "figures/supp_psychometric_discrimination.png",
    "figures/ordinal_depth.png", "figures/egocentric_reach.png", "figures/realism_preferences.png",
    *(f"figures/{study}_gaze_quality.png" for study in STUDIES),  # analysis/gaze_quality.py (issue 27)
    "results/summary.md",
]
# the study rules are written before anything is built (psyop studies --make-rules)
STUDIES_MK = "results/.studies.mk"


def _sha(study: str) -> str:
    return hashlib.sha256((REPO / "protocols" / f"{study}.yaml").read_bytes()).hexdigest()


def dry_run(tmp: Path, data: str = "data") -> str:
    cmd = ["make", "--no-print-directory", "-n", "-C", str(REPO), "figures-build",
           f"DATA={tmp / data}", f"RESULTS={tmp / 'results'}", f"FIGDIR={tmp / 'figures'}"]
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def _build_tree(tmp_path: Path, data: str = "data") -> Path:
    newest_source = max(p.stat().st_mtime for p in [*REPO.glob("psyop/**/*.py"), *REPO.glob("analysis/*.py"),
                                                     *REPO.glob("protocols/*.yaml")])  # make's prerequisites
    t = newest_source + 10
    for study, kind in STUDIES.items():
        f = tmp_path / data / study / "sub-S01" / "ses-1" / "trials.parquet"
        f.parent.mkdir(parents=True)
        f.write_bytes(b"")
        (f.parent / "session.json").write_text(json.dumps({"response_kind": kind, "protocol_sha256": _sha(study)}))
        os.utime(f, (t, t))
    subprocess.run([sys.executable, "-m", "psyop", "studies", str(tmp_path / data), "--protocols",
                    str(REPO / "protocols"), "--make-rules", str(tmp_path / STUDIES_MK)], check=True, cwd=REPO,
                   capture_output=True)
    for i, rel in enumerate(OUTPUTS, start=1):
        f = tmp_path / rel
        f.parent.mkdir(parents=True, exist_ok=True)
        f.write_bytes(b"")
        os.utime(f, (t + i, t + i))
    return tmp_path


@pytest.fixture()
def built_tree(tmp_path: Path) -> Path:
    return _build_tree(tmp_path)


def test_a_data_root_with_spaces(tmp_path: Path) -> None:
    """`make figures DATA='/path/with a space/data'` was `psyop: error: unrecognized arguments`:
    every recipe quotes the path and the sessions are escaped prerequisites."""
    import shlex

    tree = _build_tree(tmp_path, "with a space/data")
    assert "analysis/" not in dry_run(tree, "with a space/data")
    new = tree / "with a space" / "data" / "detection" / "sub-S02" / "ses-1" / "trials.parquet"
    new.parent.mkdir(parents=True)
    new.write_bytes(b"")
    later = (tree / "results" / "summary.md").stat().st_mtime + 10
    os.utime(new, (later, later))
    commands = [shlex.split(line) for line in dry_run(tree, "with a space/data").splitlines() if "analysis/" in line]
    assert len(commands) == 5  # fits, thresholds, psychometric functions, gaze quality, summary
    for words in commands:
        assert words[words.index("--data") + 1] == str(tree / "with a space" / "data")


def test_results_with_spaces_is_refused_with_one_line(tmp_path: Path) -> None:
    done = subprocess.run(["make", "--no-print-directory", "-n", "-C", str(REPO), "figures-build",
                           f"RESULTS={tmp_path / 'my results'}"], capture_output=True, text=True)
    assert done.returncode == 2 and "may not contain spaces" in done.stderr, done.stderr


def test_up_to_date_tree_rebuilds_nothing(built_tree: Path) -> None:
    assert "analysis/" not in dry_run(built_tree)


def test_new_detection_session_rebuilds_only_detection_and_summary(built_tree: Path) -> None:
    new = built_tree / "data" / "detection" / "sub-S02" / "ses-1" / "trials.parquet"
    new.parent.mkdir(parents=True)
    new.write_bytes(b"")
    later = (built_tree / "results" / "summary.md").stat().st_mtime + 10
    os.utime(new, (later, later))
    commands = [line for line in dry_run(built_tree).splitlines() if "analysis/" in line]
    scripts = " ".join(commands)
    assert "fit_psychometric.py\" --study detection" in scripts
    assert "fig_detection_thresholds.py" in scripts
    assert "supp_psychometric_functions.py\" --study detection" in scripts
    assert "results_table.py" in scripts
    for other in ["--study discrimination", "fig_discrimination", "fig_ordinal", "fig_egocentric", "fig_realism",
                  "fig03_parallax", "supp_linearity"]:
        assert other not in scripts, f"{other} rebuilt for a detection session"
    assert "gaze_quality.py\" --study detection" in scripts
    assert len(commands) == 5
    assert "fig_detection_thresholds.py\" --study detection" in scripts  # by kind, outputs named after the study


def test_a_user_study_gets_its_own_rules_and_never_a_paper_figure(built_tree: Path) -> None:
    """A study found in data/ is built by its response kind, under its own name; the paper's figures
    are not rebuilt for it (the summary is: it lists which results are the paper's)."""
    f = built_tree / "data" / "stereo_blocks" / "sub-P1" / "ses-1" / "trials.parquet"
    f.parent.mkdir(parents=True)
    f.write_bytes(b"")
    (f.parent / "session.json").write_text(json.dumps({"response_kind": "near_side", "protocol_sha256": "ab" * 32}))
    later = (built_tree / "results" / "summary.md").stat().st_mtime + 10
    os.utime(f, (later, later))
    out = dry_run(built_tree)
    commands = " ".join(line for line in out.splitlines() if "analysis/" in line)
    assert "fig_ordinal_depth.py\" --study stereo_blocks" in commands
    assert "stereo_blocks_depth.png" in commands
    assert "[psyop] study stereo_blocks (left/right nearer): stereo_blocks_depth.png" in out
    for paper in ("--study ordinal ", "--study detection", "fig_realism", "fig_egocentric"):
        assert paper not in commands


def test_a_session_json_with_an_unknown_response_kind_is_one_line_naming_it(tmp_path) -> None:
    """The analysis dispatches on the kind session.json records (psyop.protocol.kinds); a kind it does not
    know is refused naming the file."""
    import json

    import pytest

    from psyop.errors import UserError
    from psyop.statistics.studies import study_facts

    session = tmp_path / "data" / "mine" / "sub-S01" / "ses-1"
    session.mkdir(parents=True)
    import pandas as pd

    pd.DataFrame({"participant": ["S01"], "mode_a": ["a"], "mode_b": ["b"]}).to_parquet(session / "trials.parquet")
    (session / "session.json").write_text(json.dumps({"response_kind": "magnitude_estimate"}))
    with pytest.raises(UserError) as info:
        study_facts(tmp_path / "data", "mine")
    assert "magnitude_estimate" in info.value.message and "session.json" in str(info.value)
