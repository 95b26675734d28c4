"""The session's questionnaire answers (questionnaires.parquet, the protocol's ``session: questionnaires``) are in the
BIDS export as phenotype files, one per questionnaire and administration, and the official validator accepts the
dataset (issue 40 item 3: "answers in their own table and in the BIDS export")."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from psyop.cli import main as cli_main

from tests.export.bids_validator import validate

REPO = Path(__file__).resolve().parents[2]


def test_questionnaire_answers_become_phenotype_files_that_validate(tmp_path: Path) -> None:
    data, out = tmp_path / "data", tmp_path / "bids"
    assert cli_main(["simulate", "--data", str(data), "--protocols", str(REPO / "protocols" / "examples" /
                                                                       "full_session.yaml"),
                     "--participants", "1", "--jobs", "1"]) == 0
    assert cli_main(["export", str(data), "--bids", str(out)]) == 0
    answers = pd.read_parquet(next(data.glob("*/sub-*/ses-1/questionnaires.parquet")))
    for when in ("start", "end"):
        table = pd.read_csv(out / "phenotype" / f"ssq_{when}.tsv", sep="\t")
        given = answers[(answers["questionnaire"] == "ssq") & (answers["when"] == when)].sort_values("item")
        assert len(table) == 1 and table["participant_id"].iloc[0] == f"sub-{given['participant'].iloc[0]}"
        assert [int(table[f"item{i + 1:02d}"].iloc[0]) for i in range(16)] == given["answer"].astype(int).tolist()
        sidecar = json.loads((out / "phenotype" / f"ssq_{when}.json").read_text())
        assert sidecar["item01"]["Description"].startswith("General discomfort")
        assert "Simulator Sickness Questionnaire" in sidecar["MeasurementToolMetadata"]["Description"]
    code, issues = validate(out)
    errors = {key: n for key, n in issues.items() if key[0] == "error"}
    assert code == 0 and not errors, f"validator exit {code}: {dict(issues)}"
