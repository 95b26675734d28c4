"""session.json as a typed record: the one record every reader of a session uses.

:func:`read_record_file` (a session.json path: the analysis, quality, export, inventory, the command line)
and :func:`read_record` (a session's paths: a run) read the file through psyop.session_json, the one
parser (a damaged, oversized or unreadable file is a located UserError), into a :class:`SessionRecord`:
the fields its readers use, typed (a field an older psyop did not write, or of the wrong type, reads as
None), beside the raw mapping (``raw``), which the log merges and writes back unchanged.
What the analysis reads of the protocol (its factors, the response's column fields, ``study.reported``, a
rating's scale) is the record's typed ``study_design`` (psyop.session.log.recorded_design, written by the runner
through the same model); :func:`design_of_record` gives it, falling back, for a session recorded before psyop wrote
it, to the protocol text the session ran parsed as plain YAML (:func:`recorded_protocol_document`). The runner
reads the record once before the backends are built and hands it to :mod:`psyop.run.resume`; the store reads
session.json again under the session lock, by design (another process may have written it in between).
"""

from __future__ import annotations

from pathlib import Path
from collections.abc import Mapping
from typing import Any, Protocol, TypeVar

from pydantic import BaseModel, ConfigDict, Field, StrictInt, ValidationError, ValidationInfo, field_validator

from psyop.session.rows import JsonMapping, JsonObject
from psyop.session.log.recorded_design import (RecordedDesign, RecordedFactor, RecordedReported, RecordedScale,
                                               unit_of)
from psyop.errors import UserError
from psyop.session_json import MAX_SESSION_JSON_BYTES, read_session_json

__all__ = ["MAX_METADATA_BYTES", "RecordedResponse", "RecordedRig", "SessionFiles", "SessionRecord", "SimTrackerFaults",
           "design_of_record", "legacy_design", "read_metadata", "read_record", "read_record_file", "record_of",
           "recorded_protocol_document"]


_Model = TypeVar("_Model", bound=BaseModel)


class SessionFiles(Protocol):
    """A session's paths as the readers here take them (psyop.session.log.layout.SessionPaths, which
    imports the inventory, which reads the record: so named by what is used, not imported)."""

    @property
    def metadata(self) -> Path:
        """The session's session.json."""
        ...


class SimTrackerFaults(BaseModel):
    """session.json ``sim_tracker_faults``: the simulated tracker's command-line fault rates (Hz)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    dropout_rate_hz: float = Field(ge=0, allow_inf_nan=False)
    nan_burst_rate_hz: float = Field(ge=0, allow_inf_nan=False)


class RecordedRig(BaseModel):
    """session.json ``rig``: the eyes the session rendered for and the interpupillary distance it used."""

    model_config = ConfigDict(frozen=True, extra="ignore")

    eyes: tuple[str, ...] = Field(min_length=1)
    ipd_m: float = Field(strict=True, allow_inf_nan=False)


class RecordedResponse(BaseModel):
    """session.json ``response``: the fields of the response kind its readers use (each None when not a string)."""

    model_config = ConfigDict(frozen=True, extra="ignore")

    kind: str | None = None
    #: the level factor of a kind with one (two_interval, n_afc, yes_no, ...)
    level_factor: str | None = None
    #: the question the participant answered
    question: str | None = None

    @field_validator("kind", "level_factor", "question", mode="before")
    @classmethod
    def _text_or_none(cls, value: object) -> str | None:
        return value if isinstance(value, str) else None


class RecordedDisplayOutput(BaseModel):
    """session.json ``display_output``: whether the stimuli went through a display calibration, and which file
    (psyop.session.achieved writes it; docs/calibration.md)."""

    model_config = ConfigDict(frozen=True, extra="ignore")

    calibrated: bool = Field(strict=True)
    calibration_file: str | None = None
    calibration_sha256: str | None = None


def _model_or_none(model: type[_Model], value: object) -> _Model | None:
    """``value`` as ``model`` when it is an object that validates, else None (not recorded, or not usable)."""
    try:
        return model.model_validate(value) if isinstance(value, dict) else None
    except ValidationError:
        return None


class SessionRecord(BaseModel):
    """The typed fields of an existing session's session.json (docs/data.md lists them all)."""

    model_config = ConfigDict(frozen=True, extra="ignore")

    seed: StrictInt | None = None
    #: keys block_order; a value that is not an integer is not used (the participant ID decides)
    participant_index: int | None = None
    protocol_sha256: str | None = None
    #: the protocol text the session ran (``--allow-protocol-change`` compares with it); not a string: none
    protocol_text: str | None = None
    #: where the protocol was run from (a mesh's files resolve beside it); not a string: none
    protocol_file: str | None = None
    study: str | None = None
    #: the participant ID (a number recorded as one is read as its text)
    participant: str | None = None
    session: int | None = None
    #: whether every source of the session was simulated (psyop.datacontract.SIMULATED_KEY); not a bool: none
    simulated: bool | None = None
    #: the simulated observer's kind that answered (``psychometric_2afc``, ``image``, ...); None: a person answered,
    #: or a session before psyop recorded it
    observer: str | None = None
    #: the response kind's name as the session recorded it (an older spelling is one of the kind's former names)
    response_kind: str | None = None
    response: RecordedResponse | None = None
    #: the plan's timed phases (psyop.session.timing reads each)
    phases: list[JsonObject] = Field(default_factory=list)  # Any: each phase's JSON fields
    #: the gaze-latency rule the session ran under (psyop.session.latency.GazeLatency.of_record reads it)
    gaze_latency: JsonObject | None = None  # Any: the rule's JSON fields
    #: the eyes and ipd the session rendered with; None: not recorded (or unusable)
    rig: RecordedRig | None = None
    #: calibrated or pixel values (psyop.session.achieved); None: not recorded (a session before psyop recorded it)
    display_output: RecordedDisplayOutput | None = None
    #: the finalised files' SHA-256 and size by file name (psyop.finalised.FINALISED_KEY; it verifies them)
    finalised_files: dict[str, JsonObject] = Field(default_factory=dict)  # Any: each file's JSON fields
    status: str | None = None
    runs: list[JsonObject] = Field(default_factory=list)  # Any: each run's JSON fields (store.py writes them)
    #: the session's clock (``virtual`` or ``real``); not a string: none
    clock: str | None = None
    #: the ``--tracker`` option (``sim``, ``replay:PATH``, ...); not a string: none
    tracker: str | None = None
    #: ``--tracker sim``'s fault rates; None: another tracker, or not recorded (a session before psyop
    #: recorded them, or a value that is not two rates)
    sim_tracker_faults: SimTrackerFaults | None = None
    #: the attempts the protocol's timing rule discarded in earlier runs (psyop.session.loop writes them)
    timing_reruns: list[JsonObject] = Field(default_factory=list)
    #: what the analysis reads of the protocol, typed (psyop.session.log.recorded_design); None: not recorded (a
    #: session before psyop recorded it: :func:`design_of_record` falls back to the protocol text), or unusable
    study_design: RecordedDesign | None = None
    #: the whole file as read (the store merges and writes it back as it was)
    raw: Mapping[str, Any] = Field(default_factory=dict, exclude=True)  # Any: JSON values of every field

    @field_validator("timing_reruns", mode="before")
    @classmethod
    def _reruns_or_none(cls, value: object) -> list[object]:
        return [r for r in value if isinstance(r, dict)] if isinstance(value, list) else []

    @field_validator("participant_index", mode="before")
    @classmethod
    def _index_or_none(cls, value: object) -> int | None:
        return value if isinstance(value, int) else None

    @field_validator("protocol_sha256", mode="before")
    @classmethod
    def _sha_as_text(cls, value: object) -> str | None:
        return None if value is None else str(value)

    @field_validator("sim_tracker_faults", mode="before")
    @classmethod
    def _faults_or_none(cls, value: object) -> SimTrackerFaults | None:
        try:
            return SimTrackerFaults.model_validate(value) if isinstance(value, dict) else None
        except ValidationError:
            return None

    @field_validator("rig", "response", mode="before")
    @classmethod
    def _part_or_none(cls, value: object, info: ValidationInfo) -> BaseModel | None:
        return _model_or_none(RecordedRig if info.field_name == "rig" else RecordedResponse, value)

    @field_validator("display_output", mode="before")
    @classmethod
    def _output_or_none(cls, value: object) -> BaseModel | None:
        return _model_or_none(RecordedDisplayOutput, value)

    @field_validator("study_design", mode="before")
    @classmethod
    def _design_or_none(cls, value: object) -> RecordedDesign | None:
        return _model_or_none(RecordedDesign, value)

    @field_validator("participant", mode="before")
    @classmethod
    def _id_as_text(cls, value: object) -> str | None:
        return value if isinstance(value, str) else str(value) if isinstance(value, int) and \
            not isinstance(value, bool) else None

    @field_validator("session", mode="before")
    @classmethod
    def _session_or_none(cls, value: object) -> int | None:
        return value if isinstance(value, int) and not isinstance(value, bool) else None

    @field_validator("simulated", mode="before")
    @classmethod
    def _bool_or_none(cls, value: object) -> bool | None:
        return value if isinstance(value, bool) else None

    @field_validator("finalised_files", mode="before")
    @classmethod
    def _files_or_empty(cls, value: object) -> dict[object, object]:
        return {k: v for k, v in value.items() if isinstance(v, dict)} if isinstance(value, dict) else {}

    @field_validator("gaze_latency", mode="before")
    @classmethod
    def _object_or_none(cls, value: object) -> object:
        return value if isinstance(value, dict) else None

    @field_validator("response_kind", mode="before")
    @classmethod
    def _kind_as_text(cls, value: object) -> str | None:
        return None if value is None else str(value)  # a kind psyop does not know is refused where it is used

    @field_validator("protocol_text", "protocol_file", "study", "status", "clock", "tracker", mode="before")
    @classmethod
    def _text_or_none(cls, value: object) -> str | None:
        return value if isinstance(value, str) else None

    @field_validator("runs", "phases", mode="before")
    @classmethod
    def _runs_or_empty(cls, value: object) -> list[object]:
        return [r for r in value if isinstance(r, dict)] if isinstance(value, list) else []


#: the largest session.json read (psyop.session_json, the one parser)
MAX_METADATA_BYTES = MAX_SESSION_JSON_BYTES


def read_metadata(paths: SessionFiles) -> JsonObject | None:
    """session.json as a dict, None if absent; a damaged file is a located UserError.

    It must be a regular file of at most :data:`MAX_METADATA_BYTES` (never a FIFO or device)."""
    return read_session_json(paths.metadata)


def read_record(paths: SessionFiles) -> SessionRecord | None:
    """The session's session.json as a :class:`SessionRecord`; None if there is none.

    A recorded seed that is not an integer is a UserError naming session.json."""
    meta = read_metadata(paths)
    if meta is None:
        return None
    return record_of(meta, paths)


def read_record_file(path: Path) -> SessionRecord | None:
    """The session.json at ``path`` as a :class:`SessionRecord`; None if there is none. An unreadable or
    damaged file, or a seed that is not an integer, is a one-line UserError naming the file."""
    meta = read_session_json(path)
    return None if meta is None else record_of(meta, path)


def recorded_protocol_document(record: SessionRecord) -> JsonObject:
    """The protocol text ``record`` ran, as the plain YAML mapping it is ({} when none is recorded or it is
    not a mapping). Not validated again: an old session stays readable when validation grows stricter; what
    a session's plan recorded (``response``, ``phases``, ``rig``) is read from the record itself."""
    import yaml

    try:
        document = yaml.safe_load(record.protocol_text or "")
    except (yaml.YAMLError, ValueError, TypeError, AttributeError, KeyError):  # a bad explicit tag fails outside YAMLError
        return {}
    return document if isinstance(document, dict) else {}


def design_of_record(record: SessionRecord) -> RecordedDesign:
    """What the analysis reads of the protocol ``record`` ran: its typed ``study_design``; for a session recorded
    before psyop wrote it, :func:`legacy_design` (the recorded protocol text, parsed as plain YAML)."""
    return record.study_design if record.study_design is not None else legacy_design(record)


def legacy_design(record: SessionRecord) -> RecordedDesign:
    """The :class:`RecordedDesign` of a session recorded before session.json held ``study_design``, read from the
    protocol text it ran (:func:`recorded_protocol_document`, not re-validated: an old session stays analysable when
    validation grows stricter). What the text does not give, or gives in a form that no longer reads, is left out:
    a factor whose levels do not validate has ``levels`` and ``numeric`` None; a ``reported`` entry or a scale that
    does not validate is dropped."""
    document = recorded_protocol_document(record)
    design = document.get("design")
    factors_in = design.get("factors") if isinstance(design, dict) else None
    factors = tuple(_legacy_factor(str(name), spec)
                    for name, spec in (factors_in if isinstance(factors_in, dict) else {}).items())
    response = document.get("response")
    response = response if isinstance(response, dict) else {}
    columns = {str(k): v for k, v in response.items() if str(k).endswith("_factor") and isinstance(v, str)}
    study = document.get("study")
    entries = study.get("reported") if isinstance(study, dict) else None
    reported = tuple(r for e in (entries if isinstance(entries, list) else [])
                     if (r := _model_or_none(RecordedReported, e)) is not None)
    scale = _model_or_none(RecordedScale, response.get("scale"))
    return RecordedDesign(factors=factors, column_fields=columns, reported=reported, scale=scale)


def _legacy_factor(name: str, spec: object) -> RecordedFactor:
    """A recorded protocol text's factor: its levels as the protocol's Factor reads them (None when they no longer
    validate), its description (a string, else None) and the unit its name ends in."""
    from psyop.protocol.design import Factor

    description = spec.get("description") if isinstance(spec, dict) else None
    try:
        levels = tuple(Factor.model_validate(spec).all_levels()) if isinstance(spec, dict) else None
    except ValidationError:
        levels = None
    return RecordedFactor(name=name, levels=levels, numeric=None if levels is None else
                          not any(isinstance(v, str) for v in levels),
                          description=description if isinstance(description, str) else None, unit=unit_of(name))


def record_of(meta: JsonMapping, paths: SessionFiles | Path) -> SessionRecord:
    """``meta`` (session.json as read, or rebuilt from the log) as a :class:`SessionRecord`; ``paths``: the
    session's paths, or the session.json file it came from (a finalised session's, a replication's).

    A recorded seed that is not an integer is a UserError naming session.json."""
    try:
        return SessionRecord.model_validate({**meta, "raw": meta})
    except ValidationError as exc:
        where = paths if isinstance(paths, Path) else paths.metadata
        raise UserError(f"the recorded seed {meta.get('seed')!r} is not an integer", str(where)) from exc
