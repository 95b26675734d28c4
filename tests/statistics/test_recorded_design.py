"""session.json ``study_design``: the runner records what the analysis reads of the protocol (factors, the response's
column fields, ``study.reported``, a rating's scale) typed, and the analysis reads it from there; a session recorded
before psyop wrote it falls back to its protocol text (psyop.session.log.record.design_of_record), with the same
results."""

from __future__ import annotations

import importlib
import json
import re
import sys
from pathlib import Path

import pandas as pd
import pytest

import unshipped_protocols
from psyop.protocol import load_protocol
from psyop.session.log import record as record_module
from psyop.session.log.record import SessionRecord, design_of_record, legacy_design, read_record_file
from psyop.session.log.recorded_design import RecordedDesign, RecordedFactor, design_of
from psyop.statistics.studies import study_facts

ROOT = Path(__file__).resolve().parents[2]
PROTOCOLS = sorted((ROOT / "protocols").glob("*.yaml")) + sorted((ROOT / "protocols" / "examples").glob("*.yaml"))
RATING = ROOT / "protocols" / "examples" / "rating.yaml"
RATING_STUDY = "rating_realism"
#: an unshipped two_interval protocol: a word factor with a description, and a reported threshold at one of its levels
DESCRIBED = ("    mode:\n      levels: [ocular, reversed]\n",
             "    mode:\n      description: the test interval's rendering\n      levels: [ocular, reversed]\n")


def _refuse_protocol_text(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make any reading of the recorded protocol text fail (a session recorded by this psyop must not need it)."""
    def refuse(record: SessionRecord) -> dict:
        raise AssertionError("the analysis read the recorded protocol text of a session that records its design")
    monkeypatch.setattr(record_module, "recorded_protocol_document", refuse)


def _simulate(protocol: Path, data: Path, participants: int) -> None:
    from psyop.cli import main

    assert main(["simulate", "--data", str(data), "--protocols", str(protocol), "--participants",
                 str(participants)]) == 0


def _as_older_psyop(data: Path, study: str) -> None:
    """Each session.json of ``study`` as psyop wrote it before ``study_design``: the same file without that key."""
    for path in (data / study).glob("sub-*/ses-*/session.json"):
        meta = json.loads(path.read_text())
        del meta["study_design"]
        path.write_text(json.dumps(meta, indent=2, sort_keys=True))


@pytest.mark.parametrize("protocol", PROTOCOLS, ids=lambda p: p.stem)
def test_the_recorded_design_is_the_protocols_and_the_fallback_reads_the_same(protocol: Path) -> None:
    """Every shipped protocol: the recorded design's factors are the validated protocol's (levels, numbers or words,
    description, unit), and reading the protocol's text as an older session's (legacy_design) gives the same
    factors, ``reported`` and scale; a column field the text leaves out is the response model's default."""
    parsed = load_protocol(protocol)
    design = RecordedDesign.model_validate(json.loads(json.dumps(design_of(parsed).model_dump(mode="json"))))
    assert [f.name for f in design.factors] == list(parsed.design.factors)
    for factor in design.factors:
        assert list(factor.levels or ()) == parsed.design.factors[factor.name].all_levels()
        assert factor.numeric == all(not isinstance(v, str) for v in factor.levels or ())
        assert factor.description == parsed.design.factors[factor.name].description
    legacy = legacy_design(SessionRecord(protocol_text=protocol.read_text()))
    assert (legacy.factors, legacy.reported, legacy.scale) == (design.factors, design.reported, design.scale)
    assert legacy.column_fields.items() <= design.column_fields.items()
    defaults = {k: f.default for k, f in type(parsed.response).model_fields.items()}
    assert all(defaults[k] == v for k, v in design.column_fields.items() if k not in legacy.column_fields)


def test_an_unusable_design_reads_as_none_and_falls_back() -> None:
    text = "design:\n  factors:\n    size_deg: {levels: [1, 2], description: target size}\n    odd: {levels: 3}\n"
    record = SessionRecord.model_validate({"study_design": {"factors": "not a list"}, "protocol_text": text})
    assert record.study_design is None
    assert design_of_record(record).factors == (
        RecordedFactor(name="size_deg", levels=(1, 2), numeric=True, description="target size", unit="deg"),
        RecordedFactor(name="odd", levels=None, numeric=None, description=None, unit=None))
    assert design_of_record(SessionRecord()) == RecordedDesign()


def test_a_new_sessions_study_facts_need_no_protocol_text(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An unshipped protocol (a word factor with a description, a reported threshold): its sessions' study facts come
    from session.json ``study_design`` with the protocol text unreadable, and equal the facts an older session
    (no ``study_design``: its protocol text) gives."""
    text = unshipped_protocols.word_factor(repetitions=2).replace(*DESCRIBED)
    text = text.replace("study:\n", "study:\n  reported:\n    - {condition: {mode: ocular}, threshold: 0.4, "
                                    "source: assumed}\n", 1)
    protocol = tmp_path / "words.yaml"
    protocol.write_text(text)
    data = tmp_path / "data"
    _simulate(protocol, data, 1)
    with monkeypatch.context() as patched:
        _refuse_protocol_text(patched)
        new = study_facts(data, "words")
    assert new.factor("mode").description == "the test interval's rendering" and new.factor("mode").unit is None
    assert new.reported == ({"condition": {"mode": "ocular"}, "threshold": 0.4, "source": "assumed"},)
    assert new.level_factor == "level_D" and new.response_column("level_factor", "") == "level_D"
    _as_older_psyop(data, "words")
    record = read_record_file(next((data / "words").glob("sub-*/ses-1/session.json")))
    assert record is not None and record.study_design is None
    assert study_facts(data, "words") == new


def _rating_results(monkeypatch: pytest.MonkeyPatch, data: Path, results: Path) -> tuple[pd.DataFrame, dict]:
    monkeypatch.syspath_prepend(str(ROOT / "analysis"))
    try:
        assert importlib.import_module("rating").main(["--study", RATING_STUDY, "--data", str(data), "--results",
                                                        str(results), "--out", str(results / "fig.png")]) == 0
    finally:
        sys.modules.pop("rating", None)
    summary = json.loads((results / f"{RATING_STUDY}.json").read_text())
    return pd.read_csv(results / f"{RATING_STUDY}_rating.csv"), summary


def test_a_new_rating_session_is_analysed_without_its_protocol_text(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """analysis/rating.py reads the scale's labels from ``study_design`` (the protocol text unreadable), and the same
    sessions as an older psyop wrote them (their protocol text) give the same results."""
    protocol = tmp_path / "rating.yaml"
    protocol.write_text(re.sub(r"(?m)^(\s*repetitions:)\s*\d+", r"\g<1> 3", RATING.read_text()))
    data = tmp_path / "data"
    _simulate(protocol, data, 2)
    with monkeypatch.context() as patched:
        _refuse_protocol_text(patched)
        means, summary = _rating_results(patched, data, tmp_path / "new")
        assert study_facts(data, RATING_STUDY).factor("mode").description == "rendering mode"
    assert summary["points"] == 7 and summary["labels"] == list(load_protocol(protocol).response.scale.labels)
    _as_older_psyop(data, RATING_STUDY)
    old_means, old_summary = _rating_results(monkeypatch, data, tmp_path / "old")
    pd.testing.assert_frame_equal(old_means, means, check_exact=False, rtol=1e-12, atol=1e-12)
    assert old_summary == summary
