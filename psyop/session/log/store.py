"""A session on disk: create or resume, append trials durably, finalise, recover."""

from __future__ import annotations

import datetime as dt
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from psyop.errors import UserError
from psyop.session.log.layout import SessionPaths, write_json_atomic
from psyop.session.log.schema import FRAME_SCHEMA
from psyop.session.log.stream import DurableStreamWriter, read_stream_tolerant

#: session.json keys that must match when a session is resumed.
_IDENTITY_KEYS = ("protocol_sha256", "seed", "study", "participant", "session", "simulated")


class SessionStore:
    """The durable log of one session.

    ``open`` creates the session directory (first run) or checks that a resume uses the
    same protocol and seed, and starts a new stream segment for this run.
    """

    def __init__(self, paths: SessionPaths, trial_schema: pa.Schema, *, fsync: bool = True) -> None:
        self.paths = paths
        self.trial_schema = trial_schema
        self._fsync = fsync
        self._trials: DurableStreamWriter | None = None
        self._frames: DurableStreamWriter | None = None
        self.run_index = 0
        self.metadata: dict[str, Any] = {}

    # -- lifecycle -------------------------------------------------------------------
    def open(self, metadata: Mapping[str, Any]) -> set[int]:
        """Create or resume; return the set of trial numbers already completed."""
        meta_path = self.paths.metadata
        completed: set[int] = set()
        if meta_path.exists():
            existing = json.loads(meta_path.read_text())
            for key in _IDENTITY_KEYS:
                if key in metadata and existing.get(key) != metadata[key]:
                    raise UserError(
                        f"cannot resume: {key} differs from the existing session "
                        f"({existing.get(key)!r} there, {metadata[key]!r} now); use another --session",
                        str(meta_path),
                    )
            if existing.get("status") == "complete":
                raise UserError("session is already complete; use another --session", str(meta_path))
            completed = set(completed_trials(self.paths))
            self.metadata = existing
            self.metadata.setdefault("runs", [])
        else:
            self.metadata = dict(metadata)
            self.metadata["runs"] = []
            self.metadata["status"] = "running"
        self.paths.log_dir.mkdir(parents=True, exist_ok=True)
        self.run_index = len(self.paths.segments("trials"))
        self.metadata["runs"].append(
            {"run": self.run_index, "started": _now(), "host": metadata.get("host"),
             "resumed_after_trials": len(completed),
             "clock_sync": metadata.get("clock_sync")}
        )
        self.metadata["status"] = "running"
        write_json_atomic(meta_path, self.metadata)
        self._trials = DurableStreamWriter(self.paths.trial_segment(self.run_index), self.trial_schema, fsync=self._fsync)
        self._frames = DurableStreamWriter(self.paths.frame_segment(self.run_index), FRAME_SCHEMA, fsync=self._fsync)
        return completed

    def append_trial(self, row: Mapping[str, Any], frames: pa.Table | None) -> None:
        """Make one finished trial durable: its frames first, then its trial row.

        A crash between the two leaves frames without a trial; finalisation drops them.
        """
        assert self._trials is not None and self._frames is not None, "open() first"
        if frames is not None and frames.num_rows:
            self._frames.append(frames)
        record = {name: [row.get(name)] for name in self.trial_schema.names}
        self._trials.append(pa.Table.from_pydict(record, schema=self.trial_schema))

    def update_metadata(self, **fields: Any) -> None:
        self.metadata.update(fields)
        write_json_atomic(self.paths.metadata, self.metadata)

    def close(self) -> None:
        for writer in (self._trials, self._frames):
            if writer is not None:
                writer.close()

    def finalise(self, *, status: str, summary: Mapping[str, Any] | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Close the streams and write parquet + session.json (see :func:`finalise_session`)."""
        self.close()
        if self.metadata.get("runs"):
            self.metadata["runs"][-1]["ended"] = _now()
            self.metadata["runs"][-1]["status"] = status
        write_json_atomic(self.paths.metadata, self.metadata)
        return finalise_session(self.paths, status=status, summary=summary, expected_trials=self.metadata.get("n_trials_scheduled"))


def completed_trials(paths: SessionPaths) -> list[int]:
    """Trial numbers durably recorded in any segment (torn tails ignored)."""
    trials, _ = recover_tables(paths)
    return [] if trials is None else [int(t) for t in trials["trial"].tolist()]


def recover_tables(paths: SessionPaths) -> tuple[pd.DataFrame | None, pd.DataFrame]:
    """Read all segments: (trials or None, frames); duplicates keep the first record.

    Frames whose trial has no trial record (crash between the two appends, or a
    discarded trial) are dropped.
    """
    trial_tables = [t for t, _ in (read_stream_tolerant(p) for p in paths.segments("trials")) if t is not None]
    frame_tables = [t for t, _ in (read_stream_tolerant(p) for p in paths.segments("frames")) if t is not None]
    frames = (
        pa.concat_tables(frame_tables, promote_options="permissive").to_pandas()
        if frame_tables else FRAME_SCHEMA.empty_table().to_pandas()
    )
    if not trial_tables:  # no segment even holds a schema yet (killed while opening)
        return None, frames.iloc[0:0]
    trials = pa.concat_tables(trial_tables, promote_options="permissive").to_pandas()
    trials = trials.drop_duplicates(subset="trial", keep="first").sort_values("trial", kind="stable")
    trials = trials.reset_index(drop=True)
    frames = frames[frames["trial"].isin(set(trials["trial"].tolist()))]
    frames = frames.sort_values(["trial", "frame"], kind="stable").reset_index(drop=True)
    return trials, frames


def finalise_session(
    paths: SessionPaths,
    *,
    status: str,
    summary: Mapping[str, Any] | None = None,
    expected_trials: int | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Write trials.parquet / frames.parquet atomically from the streams; update session.json.

    ``status`` is 'complete' only when every scheduled trial is recorded; otherwise the
    session stays resumable ('incomplete').
    """
    if not paths.metadata.exists():
        raise UserError("no session.json here: not a psyop session directory", str(paths.directory))
    trials, frames = recover_tables(paths)
    if trials is None:
        trials = pd.DataFrame({"trial": pd.Series([], dtype="int64")})
    meta = json.loads(paths.metadata.read_text())
    expected = expected_trials if expected_trials is not None else meta.get("n_trials_scheduled")
    if status == "complete" and expected is not None and len(trials) < int(expected):
        status = "incomplete"
    _write_parquet_atomic(trials, paths.trials_parquet)
    _write_parquet_atomic(frames, paths.frames_parquet)
    meta["status"] = status
    meta["n_trials_recorded"] = int(len(trials))
    meta["finalised"] = _now()
    if summary:
        meta["summary"] = dict(summary)
    write_json_atomic(paths.metadata, meta)
    return trials, frames


def find_sessions(root: Path) -> Sequence[SessionPaths]:
    """Every session directory under ``root`` (a data root or a session directory)."""
    root = Path(root)
    found: list[SessionPaths] = []
    for meta in sorted(root.rglob("session.json")):
        ses_dir = meta.parent
        try:
            session = int(ses_dir.name.removeprefix("ses-"))
        except ValueError:
            continue
        participant = ses_dir.parent.name.removeprefix("sub-")
        study = ses_dir.parent.parent.name
        found.append(SessionPaths(ses_dir.parent.parent.parent, study, participant, session))
    return found


def _write_parquet_atomic(frame: pd.DataFrame, path: Path) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    table = pa.Table.from_pandas(frame, preserve_index=False)
    pq.write_table(table, tmp)
    with open(tmp, "rb") as handle:
        os.fsync(handle.fileno())
    os.replace(tmp, path)


def _now() -> str:
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")
