"""The included data of a study: its protocol's ``quality:`` rules applied to its sessions at analysis time
(psyop.quality.rules). Nothing recorded is read for a study without the section, and nothing is changed."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from psyop import datacontract as dc
from psyop.protocol.model import Protocol
from psyop.protocol.quality import QualitySection
from psyop.quality.cache import QualityCache
from psyop.quality.latency import latency_sentence
from psyop.quality.validation import validation_sentence
from psyop.session.log.record import read_record_file
from psyop.quality.rules import (
    apply_rules,
    included_mask,
    methods_sentence,
    unmeasured_sentence,
)


@dataclass(frozen=True)
class StudyQuality:
    """A study's per-trial measures (every session), events, exclusions and the methods sentence."""

    measures: pd.DataFrame
    events: pd.DataFrame
    exclusions: pd.DataFrame
    sentence: str


def _first_recorded_protocol(session_dirs: list[Path]) -> Protocol | None:
    """The protocol the first of ``session_dirs`` that recorded one ran (None: none did; a session.json
    without its protocol text, as in hand-made test tables)."""
    from psyop.quality.session import recorded_protocol

    for directory in session_dirs:
        meta_path = Path(directory) / dc.SESSION_METADATA_FILE
        record = read_record_file(meta_path)
        if record is not None and record.protocol_text is not None:
            return recorded_protocol(record, meta_path)
    return None


def quality_rules(session_dirs: list[Path]) -> QualitySection | None:
    """The ``quality:`` section of the protocol the first of ``session_dirs`` that recorded one has (None: no
    rules)."""
    protocol = _first_recorded_protocol(session_dirs)
    return None if protocol is None else protocol.quality


def validation_bounded(session_dirs: list[Path]) -> bool:
    """Whether that protocol states ``gaze_validation.require`` (its validations can fail)."""
    protocol = _first_recorded_protocol(session_dirs)
    validation = None if protocol is None else protocol.gaze_validation
    return validation is not None and validation.require is not None


def study_quality(session_dirs: list[Path], rules: QualitySection | None,
                  cache: QualityCache | None = None) -> StudyQuality:
    """Measure every session (through ``cache`` when given: :mod:`psyop.quality.cache`), apply ``rules`` and
    state the counts."""
    from psyop.quality.session import PlanCache, measure_session

    plans: PlanCache = {}  # one compiled plan per recorded protocol, shared by the sessions that ran it
    tables = [measure_session(d, plans, cache) for d in session_dirs]
    measures = pd.concat([t[0] for t in tables], ignore_index=True) if tables else pd.DataFrame()
    events = pd.concat([t[1] for t in tables], ignore_index=True) if tables else pd.DataFrame()
    exclusions = apply_rules(measures, rules)
    n_people = measures["participant"].nunique() if not measures.empty else 0
    sentence = methods_sentence(exclusions, n_people, len(measures)) if rules is not None else \
        "No quality: section in the protocol: no gaze-based exclusions."
    validations = validation_sentence(session_dirs, validation_bounded(session_dirs))
    latency = latency_sentence(session_dirs)  # the gaze-to-photon age (psyop.quality.latency)
    extra = " ".join(part for part in (unmeasured_sentence(measures, rules), validations, latency) if part)
    return StudyQuality(measures, events, exclusions, sentence + (" " + extra if extra else ""))


def include(trials: pd.DataFrame, session_dirs: list[Path], cache: QualityCache | None = None) -> pd.DataFrame:
    """``trials`` without what the study's ``quality:`` rules exclude; ``attrs["quality"]`` states the counts
    and ``attrs["n_quality_excluded"]`` how many trials went. Without the section: ``trials`` as given.
    ``cache``: as :func:`study_quality`'s."""
    rules = quality_rules(session_dirs)
    if rules is None:
        trials.attrs["quality"], trials.attrs["n_quality_excluded"] = "no quality: rules (nothing excluded)", 0
        return trials
    quality = study_quality(session_dirs, rules, cache)
    keep = included_mask(trials, quality.exclusions)
    kept = trials[keep].reset_index(drop=True)
    kept.attrs.update(trials.attrs)
    kept.attrs["quality"], kept.attrs["n_quality_excluded"] = quality.sentence, int((~keep).sum())
    return kept
