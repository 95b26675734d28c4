"""session.json as a typed record, read once per run and passed on.

:func:`read_record` reads the file (through :func:`psyop.session.log.store.read_metadata`, which refuses a
damaged or oversized one with a located UserError) into a :class:`SessionRecord`: the fields a run
decides by (seed, participant index, protocol hash and text, status, runs), typed, beside the raw mapping
(``raw``), which the log merges and writes back unchanged. The runner reads it once before the backends
are built and hands it to :mod:`psyop.session.resume`; the store reads session.json again under the
session lock, by design (another process may have written it in between).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, StrictInt, ValidationError, field_validator

from psyop.session.rows import JsonObject
from psyop.errors import UserError
from psyop.session.log.layout import SessionPaths

__all__ = ["SessionRecord", "read_record"]


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
    #: the whole file as read (the store merges and writes it back as it was)
    raw: Mapping[str, Any] = Field(default_factory=dict, exclude=True)  # Any: JSON values of every field

    @field_validator("participant_index", mode="before")
    @classmethod
    def _index_or_none(cls, value: object) -> int | None:
        return value if isinstance(value, int) else None

    @field_validator("protocol_sha256", mode="before")
    @classmethod
    def _sha_as_text(cls, value: object) -> str | None:
        return None if value is None else str(value)

    @field_validator("protocol_text", "status", mode="before")
    @classmethod
    def _text_or_none(cls, value: object) -> str | None:
        return value if isinstance(value, str) else None

    @field_validator("runs", mode="before")
    @classmethod
    def _runs_or_empty(cls, value: object) -> list[object]:
        return [r for r in value if isinstance(r, dict)] if isinstance(value, list) else []


def read_record(paths: SessionPaths) -> SessionRecord | None:
    """The session's session.json as a :class:`SessionRecord`; None if there is none.

    A recorded seed that is not an integer is a UserError naming session.json."""
    from psyop.session.log.store import read_metadata

    meta = read_metadata(paths)
    if meta is None:
        return None
    try:
        return SessionRecord.model_validate({**meta, "raw": meta})
    except ValidationError as exc:
        raise UserError(f"the recorded seed {meta.get('seed')!r} is not an integer", str(paths.metadata)) from exc
