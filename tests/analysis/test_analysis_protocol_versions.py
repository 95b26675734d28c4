"""Two protocol versions in one study: refused unless pooled on purpose, and the pooling is stated."""

from __future__ import annotations

import importlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from psyop.errors import UserError
from psyop.statistics import simulate as sim
from psyop.statistics.dataset import write_dataset

ANALYSIS = Path(__file__).resolve().parents[2] / "analysis"


def _realism():
    if str(ANALYSIS) not in sys.path:
        sys.path.insert(0, str(ANALYSIS))
    return importlib.import_module("fig_realism")


@pytest.fixture()
def two_versions(tmp_path):
    data = tmp_path / "data"
    table = sim.simulate_realism(np.random.default_rng(3), n_subjects=4)
    write_dataset(data, {"realism": table}, simulated=True, protocol_sha256={"realism": "a" * 64})
    first = sorted(data.glob("realism/sub-*/ses-*/session.json"))[0]
    meta = json.loads(first.read_text())
    meta["protocol_sha256"] = "b" * 64  # this participant's session ran the second version
    first.write_text(json.dumps(meta))
    return data, tmp_path / "results"


def test_sessions_of_two_protocol_versions_are_refused_naming_both_hashes(two_versions):
    data, results = two_versions
    with pytest.raises(UserError, match=r"2 protocol versions \(sha256 aaaaaaaaaaaa, bbbbbbbbbbbb\).*--pool-protocols"):
        _realism().main(["--data", str(data), "--results", str(results), "--out", str(results / "r.png")])
    assert not list(results.glob("*.json")), "a refused analysis writes no results"


def test_pooled_on_purpose_the_results_say_they_are_pooled(two_versions):
    data, results = two_versions
    assert _realism().main(["--data", str(data), "--results", str(results), "--out", str(results / "r.png"),
                            "--pool-protocols"]) == 0
    (payload,) = [json.loads(p.read_text()) for p in results.glob("realism.json")]
    assert payload["protocols_pooled"] is True
    assert sorted(payload["protocol_sha256"]) == ["a" * 64, "b" * 64]


def test_one_protocol_version_is_not_pooled(tmp_path):
    data = tmp_path / "data"
    write_dataset(data, {"realism": sim.simulate_realism(np.random.default_rng(3), n_subjects=4)}, simulated=True,
                  protocol_sha256={"realism": "a" * 64})
    assert _realism().main(["--data", str(data), "--results", str(tmp_path / "res"),
                            "--out", str(tmp_path / "r.png")]) == 0
    (payload,) = [json.loads(p.read_text()) for p in (tmp_path / "res").glob("realism.json")]
    assert payload["protocols_pooled"] is False


def test_make_figures_pool_1_pools_through_the_environment(two_versions, monkeypatch):
    """figures.mk exports PSYOP_POOL_PROTOCOLS=1 for POOL=1; the scripts take it as --pool-protocols."""
    data, results = two_versions
    monkeypatch.setenv("PSYOP_POOL_PROTOCOLS", "1")
    assert _realism().main(["--data", str(data), "--results", str(results), "--out", str(results / "r.png")]) == 0
    assert json.loads((results / "realism.json").read_text())["protocols_pooled"] is True
    mk = (ANALYSIS.parent / "figures.mk").read_text()
    assert "ifeq ($(POOL),1)\nexport PSYOP_POOL_PROTOCOLS := 1" in mk
