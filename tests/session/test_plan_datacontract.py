"""One data contract (issue 9, item 6): the session writes and the analysis reads data/ through
psyop.datacontract; real run_session output goes through load_dataset and rm_anova."""

from __future__ import annotations

import json
from pathlib import Path

from session_helpers import small_protocol

from psyop import datacontract as dc
from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.log import layout
from psyop.session.log.schema import TRIAL_LOG_FIELDS
from psyop.run.runner import SessionOptions, run_session
from psyop.statistics import dataset
from psyop.statistics.anova import cell_means, rm_anova


def test_session_output_loads_and_goes_through_rm_anova(tmp_path: Path) -> None:
    protocol = load_protocol(small_protocol(tmp_path, "ordinal", repetitions=2))
    root = tmp_path / "data"
    for participant in ("S1", "S2", "S3", "S4"):
        options = SessionOptions(participant=participant, seed=None, data_root=root, progress=False, fsync=False,
                                 render="cameras")
        assert run_session(protocol, compile_schedule, options).status == "complete"
    description = json.loads((root / dc.DATASET_DESCRIPTION_FILE).read_text())
    assert description[dc.SIMULATED_KEY] is True and description["studies"] == ["ordinal"]
    assert set(dc.DESCRIBED_COLUMNS) == set(description["variableMeasured"])
    data = dataset.load_dataset(root, "ordinal")
    assert data.simulated and data.n_sessions == 4
    trials = data.trials
    assert set(dc.DESCRIBED_COLUMNS) <= set(trials.columns)
    assert len(trials) == 4 * len(compile_schedule(protocol, 1))
    result = rm_anova(cell_means(trials, dc.CORRECT, ["mode", "separation_D"]), dc.CORRECT, ["mode", "separation_D"])
    assert result.n_subjects == 4
    assert list(result.table["effect"]) == ["mode", "separation_D", "mode * separation_D"]
    assert result.table["F"].notna().all()


def test_both_sides_use_the_contract() -> None:
    assert layout.dc is dc and dataset.dc is dc
    paths = layout.session_paths(Path("d"), "study", "P1", 2)
    assert paths.directory == dc.session_dir(Path("d"), "study", "P1", 2)
    assert paths.trials_parquet.name == dc.TRIALS_FILE and paths.metadata.name == dc.SESSION_METADATA_FILE
    logged = {f.name for f in TRIAL_LOG_FIELDS}
    assert set(dc.IDENTITY_COLUMNS + dc.MEASURED_COLUMNS) <= logged
