"""The session -> data/ contract: where sessions are written, what dataset_description.json
says, and the names of the trial-log columns the analysis reads.

Both sides import this module: the session's log layout (psyop.session.log.layout) writes by it
and the statistics loader (psyop.statistics.dataset) reads by it, so a renamed file or column
changes in one place. docs/architecture.md ("session -> data/") describes the same contract.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from psyop.protocol.trial import MIN_VALID_GAZE_SHARE
from psyop.records import JsonObject

# ---- layout: data/<study>/sub-<ID>/ses-<N>/ (psyop's own; no standard claimed) ----------------------------------
DATASET_DESCRIPTION_FILE = "dataset_description.json"
SESSION_METADATA_FILE = "session.json"
TRIALS_FILE = "trials.parquet"
#: schema metadata key of a finalised trials.parquet and of the log's trial segments: JSON true/false
SIMULATED_METADATA_KEY = "psyop.simulated"
FRAMES_FILE = "frames.parquet"
#: the raw gaze stream: every sample the tracker delivered (psyop.session.log.schema.GAZE_SCHEMA)
GAZE_FILE = "gaze.parquet"
#: the gaze validations of a session whose protocol has gaze_validation: (psyop.session.log.validation_log)
VALIDATION_FILE = "validation.parquet"
#: the screens around the trials of a session whose protocol has session: (psyop.session.log.screens_log)
EVENTS_FILE = "events.parquet"
#: the questionnaire answers of such a session, one row per item answered (psyop.session.log.screens_log)
QUESTIONNAIRES_FILE = "questionnaires.parquet"
LOG_DIR = "log"
#: Participant IDs are BIDS labels (psyop export --bids): letters and digits only.
PARTICIPANT_PATTERN = re.compile(r"[A-Za-z0-9]{1,64}")  # use with fullmatch: "ab\n" is refused
STUDY_PATTERN = re.compile(r"[A-Za-z0-9_-]{1,64}")  # use with fullmatch


def session_dir(data_root: Path, study: str, participant: str, session: int) -> Path:
    """``data_root/<study>/sub-<participant>/ses-<session>``."""
    return Path(data_root) / study / f"sub-{participant}" / f"ses-{int(session)}"


def trials_files(data_root: Path, study: str) -> list[Path]:
    """Every session's trial log of ``study``, sorted."""
    return sorted((Path(data_root) / study).glob(f"sub-*/ses-*/{TRIALS_FILE}"))


def session_metadata_files(data_root: Path) -> list[Path]:
    """Every session.json under ``data_root`` (all studies), sorted."""
    return sorted(Path(data_root).glob(f"*/sub-*/ses-*/{SESSION_METADATA_FILE}"))


# ---- trial-log columns -----------------------------------------------------------------------------
#: Schedule columns every trial has (psyop.schedule.compile_schedule).
SCHEDULE_COLUMNS: tuple[str, ...] = ("trial", "block", "condition", "trial_seed")
PRACTICE = "practice"
#: Who: added by the session to every row.
IDENTITY_COLUMNS: tuple[str, ...] = ("study", "participant", "session")
RESPONSE = "response"
CORRECT = "correct"
REACH_M = "reach_m"
CHOSEN_MODE = "chosen_mode"

#: ``response`` of a trial whose response phase timed out (protocol ``timeout_s``); its
#: ``correct``, ``reach_m`` and ``chosen_mode`` are null.
TIMEOUT_RESPONSE = "timeout"

#: The typed form of ``response``: ``response_value`` is the response as a number where it is one
#: (the interval chosen, 1 or 2; a reach in metres), else null; ``outcome`` is what happened to the
#: trial's response phase (:data:`OUTCOMES`).
RESPONSE_VALUE = "response_value"
OUTCOME = "outcome"
OUTCOMES: tuple[str, ...] = ("answered", TIMEOUT_RESPONSE)
#: When a trial ran, on the session clock (s).
TRIAL_START_S = "trial_start_s"
TRIAL_END_S = "trial_end_s"

# ---- gaze columns (the frame log's gaze and the raw stream, psyop.session.log.schema) -------------------
#: the time of the gaze sample (the raw stream's own sample; the frame log's: the sample a frame was rendered with)
GAZE_SAMPLE_T_S = "gaze_sample_t_s"
#: whether the sample holds a gaze direction
GAZE_VALID = "gaze_valid"
#: the tracker's confidence in the sample (null: it reports none)
GAZE_CONFIDENCE = "gaze_confidence"
#: the fixation point in head space (m): x right, y up, -z forward
FIXATION_X_M = "fixation_x_m"
FIXATION_Y_M = "fixation_y_m"
FIXATION_Z_M = "fixation_z_m"
FIXATION_COLUMNS: tuple[str, str, str] = (FIXATION_X_M, FIXATION_Y_M, FIXATION_Z_M)

# ---- frame-log timing columns (psyop.session.timing measures them) ---------------------------------------
#: when the frame's rendering began, on the session clock (s)
RENDER_START_S = "render_start_s"
#: when the frame was shown (a headset's predicted photon time, a window's flip), on the session clock (s)
DISPLAY_TIME_S = "display_time_s"
#: the display periods that passed without a new frame before this one
DISPLAY_MISSED_FRAMES = "display_missed_frames"


@dataclass(frozen=True)
class MeasuredColumn:
    """A measured trial column as dataset_description.json describes it: its trials.parquet type
    (the Arrow type name, psyop.session.log.schema.TRIAL_LOG_FIELDS), unit (None: none) and meaning."""

    name: str
    type: str
    unit: str | None
    description: str


#: What the session measured per trial (``correct``: 2AFC and left/right; ``reach_m``: reach;
#: ``chosen_mode``: preference; ``response_value`` / ``outcome``: the typed ``response``).
MEASURED: tuple[MeasuredColumn, ...] = (
    MeasuredColumn(RESPONSE, "string", None, "the response as logged: '1'/'2' (interval chosen), a reach in metres, "
                   f"'left'/'right', a mode name, 'with'/'against', or {TIMEOUT_RESPONSE!r}"),
    MeasuredColumn(CORRECT, "bool", None, "the response was correct (2AFC, left/right); null: no correct answer or "
                   "timed out"),
    MeasuredColumn(REACH_M, "double", "m", "the reach: the hand's distance from the eyes' mid-point along the "
                   "horizontal eye-to-target direction (reach studies)"),
    MeasuredColumn(CHOSEN_MODE, "string", None, "the rendering mode chosen (preference studies)"),
    MeasuredColumn("trial_start_s", "double", "s", "trial start on the session clock"),
    MeasuredColumn("trial_end_s", "double", "s", "end of the trial's response phase on the session clock"),
    MeasuredColumn(RESPONSE_VALUE, "double", "m for a reach; none for the interval chosen (1 or 2)",
                   "the response as a number where it is one (the interval chosen, 1 or 2; a reach in metres); null "
                   "otherwise (left/right, a mode name, a timeout)"),
    MeasuredColumn(OUTCOME, "string", None, f"what happened to the response phase: one of {', '.join(OUTCOMES)}"),
)
MEASURED_COLUMNS: tuple[str, ...] = tuple(c.name for c in MEASURED)
#: Every column dataset_description.json lists as measured (schedule + identity + measured).
DESCRIBED_COLUMNS: tuple[str, ...] = SCHEDULE_COLUMNS + IDENTITY_COLUMNS + MEASURED_COLUMNS


def typed_response(response: object) -> dict[str, object]:
    """``{"response_value": float | None, "outcome": "answered" | "timeout"}`` of one logged response.

    Examples
    --------
    >>> typed_response("2"), typed_response("timeout")["outcome"], typed_response("left")["response_value"]
    ({'response_value': 2.0, 'outcome': 'answered'}, 'timeout', None)
    """
    text = "" if response is None else str(response)
    if text == TIMEOUT_RESPONSE:
        return {RESPONSE_VALUE: None, OUTCOME: TIMEOUT_RESPONSE}
    try:
        value = float(text)
    except ValueError:
        value = None
    return {RESPONSE_VALUE: value if value is not None and math.isfinite(value) else None, OUTCOME: "answered"}


def with_typed_response(trials: pd.DataFrame) -> pd.DataFrame:
    """``trials`` with ``response_value`` and ``outcome`` derived from ``response`` where a session
    logged before those columns existed lacks them (older sessions read as new ones)."""
    if RESPONSE not in trials or (RESPONSE_VALUE in trials and OUTCOME in trials):
        return trials
    typed = [typed_response(r) for r in trials[RESPONSE]]
    out = trials.copy()
    out[RESPONSE_VALUE] = pd.Series([t[RESPONSE_VALUE] for t in typed], index=trials.index, dtype="float64")
    out[OUTCOME] = pd.Series([t[OUTCOME] for t in typed], index=trials.index, dtype="object")
    return out


def drop_timeouts(trials: pd.DataFrame) -> pd.DataFrame:
    """The answered trials: rows whose response is :data:`TIMEOUT_RESPONSE` are left out and
    counted in ``attrs["n_timeout_dropped"]`` (documented in docs/protocols.md)."""
    if RESPONSE not in trials:
        out = trials.copy()
        out.attrs["n_timeout_dropped"] = 0
        return out
    timed_out = trials[RESPONSE].astype(str).eq(TIMEOUT_RESPONSE)
    out = trials[~timed_out].reset_index(drop=True)
    out.attrs.update(trials.attrs)
    out.attrs["n_timeout_dropped"] = int(timed_out.sum())
    return out


#: Per trial: the share of rendered frames with valid gaze, and whether it reached the
#: protocol's ``trial.min_valid_gaze_share`` (null: no frame of the trial measured gaze).
GAZE_VALID_FRACTION = "gaze_valid_fraction"
GAZE_OK = "gaze_ok"


def low_gaze_mask(trials: pd.DataFrame, legacy_threshold: float = MIN_VALID_GAZE_SHARE) -> pd.Series:
    """True for the trials marked low-gaze: ``gaze_ok`` false. Rows without a ``gaze_ok``
    value (sessions logged before the column existed) are judged by ``gaze_valid_fraction <
    legacy_threshold`` (the default threshold); rows with neither are not marked."""
    ok = trials[GAZE_OK] if GAZE_OK in trials else pd.Series(pd.NA, index=trials.index, dtype="object")
    marked = ok.map(lambda value: not pd.isna(value) and not bool(value))
    share = pd.to_numeric(trials[GAZE_VALID_FRACTION], errors="coerce") if GAZE_VALID_FRACTION in trials \
        else pd.Series(np.nan, index=trials.index)
    legacy = ok.isna() & (share < legacy_threshold)
    return (marked.astype(bool) | legacy).rename(None)


#: Per trial, in sessions whose protocol's observer is ``kind: image`` (psyop.session.log.schema.trial_schema):
#: the values the image observer's decision used, as JSON (its rule, each interval's internal response or
#: evidence, the noise, the trial's uniform draw ``u`` and the probability ``p`` it was compared with:
#: psyop.session.responses.image_choices.observer_extras); null where a person answered.
OBSERVER_RESPONSES = "observer_responses"


#: Per trial: whether the intervals' frames stayed within the protocol's ``trial.max_gaze_age_ms`` on all but
#: ``trial.max_gaze_age_over_share`` of them (null: no bound, or no interval frame with valid gaze;
#: psyop.session.latency).
GAZE_AGE_OK = "gaze_age_ok"


def late_gaze_mask(trials: pd.DataFrame) -> pd.Series:
    """True for the trials marked late-gaze: ``gaze_age_ok`` false (a session before the column: none)."""
    if GAZE_AGE_OK not in trials:
        return pd.Series(False, index=trials.index)
    return trials[GAZE_AGE_OK].map(lambda value: not pd.isna(value) and not bool(value)).astype(bool).rename(None)


# ---- dataset_description.json -------------------------------------------------------------------------
SIMULATED_KEY = "simulated"


def dataset_description(*, simulated: bool, studies: list[str], n_simulated: int = 0, n_real: int = 0) -> JsonObject:
    """The content of ``dataset_description.json``; ``simulated`` is what figures and the loader read.

    It names no data standard (no ``schemaVersion``): the layout is psyop's own and no standard's
    validator accepts it; ``psyop export --bids`` writes the validated form (psyop.export)."""
    return {
        "@context": "https://schema.org/",
        "@type": "Dataset",
        "name": "psyop sessions",
        "description": (
            "Trial and frame logs of gaze-contingent VR psychophysics sessions recorded by psyop. "
            f"Layout: <study>/sub-<ID>/ses-<N>/{{{TRIALS_FILE.split('.')[0]},{FRAMES_FILE.split('.')[0]},"
            f"{GAZE_FILE.split('.')[0]}}}.parquet "
            f"with {SESSION_METADATA_FILE} metadata (psyop's own layout; it claims no data standard: "
            "`psyop export --bids DIR` writes a BIDS dataset that the BIDS validator accepts)."
        ),
        SIMULATED_KEY: bool(simulated),
        "n_sessions_simulated": int(n_simulated),
        "n_sessions_real": int(n_real),
        "studies": sorted(studies),
        "variableMeasured": list(DESCRIBED_COLUMNS),
        # the measured columns' types and units (schema.org PropertyValue; unitText only where there is a unit)
        "measuredColumns": [{"@type": "PropertyValue", "name": c.name, "valueType": c.type, "description": c.description,
                             **({"unitText": c.unit} if c.unit else {})} for c in MEASURED],
    }
