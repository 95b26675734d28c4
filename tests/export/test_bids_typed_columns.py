"""The typed response columns (issue 29 item 5: ``response_value``, ``outcome``) are in the data
contract's measured-column list with their Arrow types and units (dataset_description.json), and a BIDS
export of a reach session describes them in its events sidecar (the reach in metres) and still passes
the official validator."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from psyop import datacontract as dc
from psyop.cli import main as cli_main
from psyop.session.log.schema import TRIAL_LOG_FIELDS
from tests.export.bids_validator import validate

REPO = Path(__file__).resolve().parents[2]


def test_every_measured_column_has_the_type_the_trial_log_writes():
    logged = {f.name: str(f.type) for f in TRIAL_LOG_FIELDS}
    assert {dc.RESPONSE_VALUE, dc.OUTCOME} <= set(dc.MEASURED_COLUMNS) <= set(dc.DESCRIBED_COLUMNS)
    for column in dc.MEASURED:
        assert logged[column.name] == column.type, column.name
    described = {c["name"]: c for c in dc.dataset_description(simulated=True, studies=["s"])["measuredColumns"]}
    assert described[dc.RESPONSE_VALUE]["valueType"] == "double" and "m for a reach" in described[dc.RESPONSE_VALUE]["unitText"]
    assert described[dc.OUTCOME]["valueType"] == "string" and "unitText" not in described[dc.OUTCOME]
    assert described[dc.REACH_M]["unitText"] == "m" and described["trial_start_s"]["unitText"] == "s"


@pytest.fixture(scope="module")
def reach_export(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    data = tmp_path_factory.mktemp("typed") / "data"
    assert cli_main(["simulate", "--data", str(data), "--protocols", str(REPO / "protocols" / "egocentric.yaml"),
                     "--participants", "1", "--jobs", "1"]) == 0
    out = data.parent / "bids"
    assert cli_main(["export", str(data), "--bids", str(out)]) == 0
    return data, out


def test_the_reach_export_describes_the_typed_columns(reach_export):
    data, out = reach_export
    description = json.loads((data / dc.DATASET_DESCRIPTION_FILE).read_text())
    assert {dc.RESPONSE_VALUE, dc.OUTCOME} <= set(description["variableMeasured"])
    assert [c["name"] for c in description["measuredColumns"]] == list(dc.MEASURED_COLUMNS)
    (sidecar_path,) = out.glob("sub-*/ses-*/beh/*_events.json")
    sidecar = json.loads(sidecar_path.read_text())
    assert sidecar[dc.RESPONSE_VALUE]["Units"] == "m"
    assert set(sidecar[dc.OUTCOME]["Levels"]) == set(dc.OUTCOMES)


def test_the_reach_export_with_the_typed_columns_passes_the_bids_validator(reach_export):
    _, out = reach_export
    code, issues = validate(out)
    errors = [c for (severity, c) in issues if severity == "error"]
    assert code == 0 and not errors, errors
