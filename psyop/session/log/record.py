"""session.json as a typed record, read once per run and passed on.

:func:`read_record` reads the file (through :func:`read_metadata`, which refuses a damaged or oversized
one with a located UserError; psyop.session.log.store re-exports it) into a :class:`SessionRecord`: the fields a run
decides by (seed, participant index, protocol hash and text, status, runs), typed, beside the raw mapping
(``raw``), which the log merges and writes back unchanged. The runner reads it once before the backends
are built and hands it to :mod:`psyop.run.resume`; the store reads session.json again under the
session lock, by design (another process may have written it in between).
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path
from collections.abc import Mapping
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, StrictInt, ValidationError, field_validator

from psyop.session.rows import JsonMapping, JsonObject
from psyop.errors import UserError
from psyop.session.log.layout import SessionPaths

__all__ = ["MAX_METADATA_BYTES", "SessionRecord", "SimTrackerFaults", "read_metadata", "read_record", "record_of"]


class SimTrackerFaults(BaseModel):
    """session.json ``sim_tracker_faults``: the simulated tracker's command-line fault rates (Hz)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    dropout_rate_hz: float = Field(ge=0, allow_inf_nan=False)
    nan_burst_rate_hz: float = Field(ge=0, allow_inf_nan=False)


class SessionRecord(BaseModel):
    """The typed fields of an existing session's session.json (docs/data.md lists them all)."""

    model_config = ConfigDict(frozen=True, extra="ignore")

    seed: StrictInt | None = None
    #: keys block_order; a value that is not an integer is not used (the participant ID decides)
    participant_index: int | None = None
    protocol_sha256: str | None = None
    #: the protocol text the session ran (``--allow-protocol-change`` compares with it); not a string: none
    protocol_text: str | None = None
    status: str | None = None
    runs: list[JsonObject] = Field(default_factory=list)  # Any: each run's JSON fields (store.py writes them)
    #: the ``--tracker`` option (``sim``, ``replay:PATH``, ...); not a string: none
    tracker: str | None = None
    #: ``--tracker sim``'s fault rates; None: another tracker, or not recorded (a session before psyop
    #: recorded them, or a value that is not two rates)
    sim_tracker_faults: SimTrackerFaults | None = None
    #: the attempts the protocol's timing rule discarded in earlier runs (psyop.session.loop writes them)
    timing_reruns: list[JsonObject] = Field(default_factory=list)
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

    @field_validator("protocol_text", "status", "tracker", mode="before")
    @classmethod
    def _text_or_none(cls, value: object) -> str | None:
        return value if isinstance(value, str) else None

    @field_validator("runs", mode="before")
    @classmethod
    def _runs_or_empty(cls, value: object) -> list[object]:
        return [r for r in value if isinstance(r, dict)] if isinstance(value, list) else []


#: session.json holds the protocol text and per-run records: a few hundred kB at most
MAX_METADATA_BYTES = 64 << 20


def read_metadata(paths: SessionPaths) -> JsonObject | None:
    """session.json as a dict, None if absent; a damaged file is a located UserError.

    It must be a regular file of at most :data:`MAX_METADATA_BYTES` (never a FIFO or device)."""
    try:
        info = os.stat(paths.metadata)
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise UserError(f"cannot read session.json: {exc.strerror or exc}", str(paths.metadata)) from exc
    if not stat.S_ISREG(info.st_mode) or info.st_size > MAX_METADATA_BYTES:
        raise UserError(f"session.json is not a regular file of at most {MAX_METADATA_BYTES} bytes; "
                        "restore it, or delete it to rebuild it from the log", str(paths.metadata))
    try:
        text = paths.metadata.read_text()
    except FileNotFoundError:
        return None
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read session.json: {exc}", str(paths.metadata)) from exc
    try:
        meta = json.loads(text)
    except json.JSONDecodeError as exc:
        raise UserError(
            f"session.json is damaged ({exc.msg}); restore it from a backup, or delete it: "
            "`psyop recover` / `psyop run` then rebuild it from the checksummed log",
            f"{paths.metadata}:{exc.lineno}:{exc.colno}") from exc
    if not isinstance(meta, dict):
        raise UserError("session.json is not a JSON object", str(paths.metadata))
    return meta


def read_record(paths: SessionPaths) -> SessionRecord | None:
    """The session's session.json as a :class:`SessionRecord`; None if there is none.

    A recorded seed that is not an integer is a UserError naming session.json."""
    meta = read_metadata(paths)
    if meta is None:
        return None
    return record_of(meta, paths)


def record_of(meta: JsonMapping, paths: SessionPaths | Path) -> SessionRecord:
    """``meta`` (session.json as read, or rebuilt from the log) as a :class:`SessionRecord`; ``paths``: the
    session's paths, or the session.json file it came from (a finalised session's, a replication's).

    A recorded seed that is not an integer is a UserError naming session.json."""
    try:
        return SessionRecord.model_validate({**meta, "raw": meta})
    except ValidationError as exc:
        where = paths.metadata if isinstance(paths, SessionPaths) else paths
        raise UserError(f"the recorded seed {meta.get('seed')!r} is not an integer", str(where)) from exc
