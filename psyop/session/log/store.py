"""A session on disk: create or resume, append trials durably, finalise, recover."""

from __future__ import annotations

import datetime as dt
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from psyop.session.rows import JsonMapping, JsonObject, TrialRecord, TrialRow
from psyop.datacontract import (EVENTS_FILE, MIN_VALID_GAZE_SHARE, QUESTIONNAIRES_FILE, VALIDATION_FILE,
                                low_gaze_mask)
from psyop.errors import UserError
from psyop.finalised import record_finalised
from psyop.session.lock import SessionLock
from psyop.atomic import io_error, write_atomic
from psyop.session.log.layout import SessionPaths, check_inside_root, stale_temp_files, write_json_atomic
from psyop.session.log.record import MAX_METADATA_BYTES as MAX_METADATA_BYTES, read_metadata, record_of
from psyop.session.latency import GazeLatency, late_gaze_report
from psyop.session.log.schema import FRAME_SCHEMA, GAZE_SCHEMA
from psyop.session.signals import interrupts_deferred
from psyop.session.log.validation_log import ValidationLog, ValidationRecorder, recorded_validations
from psyop.session.log.screens_log import ScreenLog, recorded_screen_table
from psyop.session.log.stream import DurableStreamWriter, is_legacy_ipc, read_segment, read_stream_tolerant

#: session.json keys that must match when a session is resumed (also written into the log).
_IDENTITY_KEYS = ("protocol_sha256", "seed", "study", "participant", "session", "simulated", "clock")
#: options recorded per run (a resume may change them, e.g. another tracker host).
_RUN_OPTION_KEYS = ("clock", "tracker", "responses", "display_mode", "pose", "render", "protocol_file_sha256")


class SessionComplete(UserError):
    """A run was asked to resume a complete session (`psyop simulate` counts it as done)."""


class SessionLog(Protocol):
    """What a session records into (psyop.session.loop and runner): :class:`SessionStore`, or a
    log that keeps only what its caller reads (psyop.power.memory_log). ``keeps_samples`` false: the
    loop builds no frame or raw gaze tables and passes None for them."""

    keeps_samples: bool
    run_index: int

    def open(self, metadata: JsonObject) -> set[int]: ...
    def append_trial(self, row: TrialRow, frames: pa.Table | None, gaze: pa.Table | None = None) -> None: ...
    def append_gaze(self, gaze: pa.Table, key: int = -1) -> None: ...
    def update_metadata(self, **fields: Any) -> None: ...  # Any: session.json fields, JSON values
    def update_run(self, **fields: Any) -> None: ...  # Any: this run's fields in session.json's runs, JSON values
    def close(self) -> None: ...
    def finalise(self, *, status: str, summary: JsonMapping | None = None) -> object: ...  # the runner reads nothing back
    def validation_recorder(self) -> ValidationRecorder | None: ...  # None: no samples kept, nothing reads them


class SessionStore:
    """The durable log of one session.

    ``open`` takes the session's exclusive lock (:mod:`psyop.session.lock`), creates the
    session directory (first run) or checks that a resume uses the same protocol, seed and
    clock, and starts a new pair of checksummed segments for this run. The lock is held
    until :meth:`finalise` (or :meth:`close`, or the process's death).
    """

    keeps_samples = True  # every trial's frames and raw gaze samples are logged with it

    def validation_recorder(self) -> ValidationLog:
        """This run's gaze validation attempts, durable in the session folder (log/validation-NNN.psylog)."""
        return ValidationLog(self.paths, self.run_index)

    def screen_recorder(self) -> ScreenLog:
        """This run's screens and questionnaire answers, durable in the session folder (log/events-NNN.psylog,
        log/questionnaires-NNN.psylog; psyop.session.screens)."""
        return ScreenLog(self.paths, self.run_index, fsync=self._fsync)

    def __init__(self, paths: SessionPaths, trial_schema: pa.Schema, *, fsync: bool = True) -> None:
        self.paths = paths
        self.trial_schema = trial_schema
        self._fsync = fsync
        self._trials: DurableStreamWriter | None = None
        self._frames: DurableStreamWriter | None = None
        self._gaze: DurableStreamWriter | None = None
        self.run_index = 0
        self.metadata: JsonObject = {}
        self.lock = SessionLock(paths.lock_file)

    # -- lifecycle -------------------------------------------------------------------
    def open(self, metadata: JsonObject) -> set[int]:
        """Create or resume; return the set of trial numbers already completed."""
        self.lock.acquire("run")
        try:
            return self._open_locked(metadata)
        except BaseException:
            self.close()
            raise

    def _open_locked(self, metadata: JsonObject) -> set[int]:
        meta_path = self.paths.metadata
        completed: set[int] = set()
        existing = read_metadata(self.paths)
        if existing is None and self.paths.segments("trials"):
            # session.json lost: the identity written into the log decides
            existing = {k: v for k, v in log_identity(self.paths).items() if k in metadata}
            existing["status"] = "incomplete"
        if existing is not None:
            for key in _IDENTITY_KEYS:
                if key in metadata and key in existing and existing.get(key) != metadata[key]:
                    raise UserError(
                        f"cannot resume: {key} differs from the existing session "
                        f"({existing.get(key)!r} there, {metadata[key]!r} now); use another --session",
                        str(meta_path),
                    )
            record = record_of(existing, self.paths)  # the typed fields a resume decides by
            if record.status == "complete":
                raise SessionComplete("session is already complete; use another --session", str(meta_path))
            completed = set(completed_trials(self.paths))
            self.metadata = {**metadata, **existing}
            self.metadata["runs"] = list(record.runs)
        else:
            self.metadata = dict(metadata)
            self.metadata["runs"] = []
        self.metadata["status"] = "running"
        try:
            self.paths.log_dir.mkdir(parents=True, exist_ok=True)
            self.run_index = self.paths.next_run_index()
            self.metadata["runs"].append(
                {"run": self.run_index, "started": _now(), "host": metadata.get("host"),
                 "resumed_after_trials": len(completed),
                 "clock_sync": metadata.get("clock_sync"),
                 **{key: metadata.get(key) for key in _RUN_OPTION_KEYS if key in metadata}}
            )
            write_json_atomic(meta_path, self.metadata)
            identity = {f"psyop.{key}": json.dumps(metadata.get(key))
                        for key in (*_IDENTITY_KEYS, "n_trials_scheduled") if key in metadata}
            self._trials = DurableStreamWriter(self.paths.trial_segment(self.run_index),
                                               self.trial_schema.with_metadata(identity), fsync=self._fsync)
            self._frames = DurableStreamWriter(self.paths.frame_segment(self.run_index), FRAME_SCHEMA, fsync=self._fsync)
            self._gaze = DurableStreamWriter(self.paths.gaze_segment(self.run_index), GAZE_SCHEMA, fsync=self._fsync)
        except OSError as exc:
            raise io_error(exc, exc.filename or self.paths.directory,
                           "cannot start the session; nothing recorded is lost: free space (or fix the disk), then "
                           "rerun the same command") from exc
        return completed

    def append_trial(self, row: TrialRow, frames: pa.Table | None, gaze: pa.Table | None = None) -> None:
        """Make one finished trial durable: its raw gaze samples and frames first, then its trial row.

        A crash between them leaves frames without a trial; finalisation drops them (raw gaze
        samples are kept: they are the tracker's recording, whether or not a trial used them).
        A write error (disk full) stops the session cleanly: every earlier trial is
        durable, session.json says 'incomplete' where it still can, and the error (exit
        code 2) says how to resume.
        """
        assert self._trials is not None and self._frames is not None, "open() first"
        trial = int(row["trial"]) if row.get("trial") is not None else -1
        record = {name: [row.get(name)] for name in self.trial_schema.names}
        table = pa.Table.from_pydict(record, schema=self._trials.schema)
        try:
            if gaze is not None and gaze.num_rows and self._gaze is not None:
                self._gaze.append(gaze, key=trial)
            if frames is not None and frames.num_rows:
                self._frames.append(frames, key=trial)
            self._trials.append(table, key=trial)
        except OSError as exc:
            self._stop_after_write_error(trial, exc)

    def append_gaze(self, gaze: pa.Table, key: int = -1) -> None:
        """Make raw gaze samples durable outside a trial record (those that arrived after the
        run's last recorded trial: a discarded trial's, or after the last trial). ``key``: the
        trial they arrived during (-1: none)."""
        if self._gaze is None or self._gaze.closed or not gaze.num_rows:
            return
        try:
            self._gaze.append(gaze, key=key)
        except OSError as exc:
            self._stop_after_write_error(key, exc)

    def _stop_after_write_error(self, trial: int, exc: OSError) -> None:
        reason = exc.strerror or str(exc)
        self.metadata["status"] = "incomplete"
        self.metadata["stopped"] = f"write error while recording trial {trial}: {reason}"
        try:
            write_json_atomic(self.paths.metadata, self.metadata)
        except OSError:
            pass  # session.json still says 'running': equally resumable
        self.close()
        raise UserError(
            f"cannot record trial {trial} ({reason}); every earlier trial is safely in the log. "
            "Free space (or fix the disk), then rerun the same command to resume the session",
            str(self.paths.directory),
        ) from exc

    def update_metadata(self, **fields: Any) -> None:  # Any: session.json fields, JSON values
        """Add ``fields`` to session.json. A write error (disk full) closes the store and is a
        UserError: every recorded trial is in the log, and rerunning the command resumes."""
        self.metadata.update(fields)
        try:
            write_json_atomic(self.paths.metadata, self.metadata)
        except OSError as exc:
            self.close()
            raise io_error(exc, self.paths.metadata,
                           "every recorded trial is safely in the log; free space (or fix the disk), then rerun "
                           "the same command to resume the session") from exc

    def update_run(self, **fields: Any) -> None:  # Any: this run's session.json fields, JSON values
        """Add ``fields`` to this run's entry of session.json's ``runs`` (e.g. the display it used); a
        write error as :meth:`update_metadata`."""
        runs = self.metadata.get("runs") or []
        if runs:
            runs[-1].update(fields)
            self.update_metadata()

    def close(self) -> None:
        try:
            for writer in (self._trials, self._frames, self._gaze):
                if writer is not None:
                    try:
                        writer.close()
                    except OSError:
                        pass  # the end record is optional: readers treat the tail as torn
        finally:
            self.lock.release()

    def finalise(self, *, status: str, summary: JsonMapping | None = None) -> tuple[pd.DataFrame, pd.DataFrame]:
        """Close the streams and write parquet + session.json (see :func:`finalise_session`).

        A write error (the end record of a segment, session.json) is a UserError: the log
        holds every recorded trial, and `psyop recover` (or rerunning) finishes the session."""
        fix = ("every recorded trial is safely in the log; free space (or fix the disk), then run "
               f"`psyop recover {self.paths.directory}` (or rerun the same command to resume)")
        try:
            for writer in (self._trials, self._frames, self._gaze):
                if writer is not None:
                    try:
                        writer.close()
                    except OSError as exc:
                        raise io_error(exc, writer.path, fix) from exc
            if self.metadata.get("runs"):
                self.metadata["runs"][-1]["ended"] = _now()
                self.metadata["runs"][-1]["status"] = status
            try:
                write_json_atomic(self.paths.metadata, self.metadata)
            except OSError as exc:
                raise io_error(exc, self.paths.metadata, fix) from exc
            return finalise_session(self.paths, status=status, summary=summary,
                                    expected_trials=expected_trial_count(self.metadata), lock=self.lock)
        finally:
            self.lock.release()


def log_identity(paths: SessionPaths) -> JsonObject:
    """Seed, protocol hash etc. written into the trial segments' schema (first readable one)."""
    for segment in paths.segments("trials"):
        if is_legacy_ipc(segment):
            continue
        schema = read_segment(segment).schema
        if schema is None or not schema.metadata:
            continue
        identity: JsonObject = {}
        for raw_key, raw_value in schema.metadata.items():
            key = raw_key.decode(errors="replace")
            if key.startswith("psyop."):
                try:
                    identity[key.removeprefix("psyop.")] = json.loads(raw_value)
                except ValueError:
                    continue
        if identity:
            return identity
    return {}


def completed_trials(paths: SessionPaths) -> list[int]:
    """Trial numbers durably recorded in any segment (torn tails and damaged records ignored)."""
    trials, _ = recover_tables(paths)
    return [] if trials is None else [int(t) for t in trials["trial"].tolist()]


@dataclass(frozen=True)
class Salvage:
    """Everything intact in a session's log, and an exact account of what is not."""

    trials: pd.DataFrame | None
    frames: pd.DataFrame
    report: JsonObject
    gaze: pd.DataFrame | None = None  # the raw gaze stream, every intact sample (GAZE_SCHEMA)

    @property
    def lost_trials(self) -> list[int]:
        return list(self.report["lost_trials"])


def salvage(paths: SessionPaths) -> Salvage:
    """Read all segments: intact records are kept (duplicates keep the first), damage reported.

    Frames whose trial has no trial record (crash between the two appends, or a
    discarded trial) are dropped. The report lists every damaged stretch (segment,
    offset, trial if its header survived), ``lost_trials`` (damaged and not recorded
    intact elsewhere, or missing below the last recorded trial: resume re-runs them),
    ``frames_lost_for_trials`` (trial row intact, its frame record damaged) and torn tails.
    """
    damaged: list[JsonObject] = []
    torn: list[str] = []
    damaged_keys: dict[str, set[int]] = {"trials": set(), "frames": set(), "gaze": set()}

    def read_kind(kind: str) -> list[pa.Table]:
        tables: list[pa.Table] = []
        hint: pa.Schema | None = None
        for segment in paths.segments(kind):
            if is_legacy_ipc(segment):
                table, was_torn = read_stream_tolerant(segment)
                if was_torn:
                    torn.append(segment.name)
            else:
                read = read_segment(segment, schema_hint=hint)
                hint = read.schema or hint
                table = read.table
                for d in read.damage:
                    if d.reason == "truncated" and d.offset + d.length == segment.stat().st_size:
                        torn.append(segment.name)
                        continue
                    damaged.append({"segment": segment.name, **d.as_dict()})
                    if d.key is not None and d.key >= 0:
                        damaged_keys[kind].add(d.key)
            if table is not None:
                tables.append(table)
        return tables

    trial_tables = read_kind("trials")
    frame_tables = read_kind("frames")
    gaze_tables = read_kind("gaze")
    gaze = (pa.concat_tables(gaze_tables, promote_options="permissive").to_pandas()
            if gaze_tables else GAZE_SCHEMA.empty_table().to_pandas())
    frames = (
        pa.concat_tables(frame_tables, promote_options="permissive").to_pandas()
        if frame_tables else FRAME_SCHEMA.empty_table().to_pandas()
    )
    report: TrialRecord = {"damaged_records": damaged, "torn_segments": sorted(set(torn))}
    if not trial_tables:  # no segment even holds a schema yet (killed while opening)
        report.update(lost_trials=sorted(damaged_keys["trials"]), frames_lost_for_trials=[])
        return Salvage(None, frames.iloc[0:0], report, gaze)
    trials = pa.concat_tables([t.replace_schema_metadata(None) for t in trial_tables],
                              promote_options="permissive").to_pandas()
    trials = trials.drop_duplicates(subset="trial", keep="first").sort_values("trial", kind="stable")
    trials = trials.reset_index(drop=True)
    recorded = {int(t) for t in trials["trial"].tolist()}
    gaps = set(range(max(recorded) + 1)) - recorded if recorded else set()
    report["lost_trials"] = sorted((damaged_keys["trials"] - recorded) | gaps)
    report["frames_lost_for_trials"] = sorted(damaged_keys["frames"] & recorded)
    frames = frames[frames["trial"].isin(recorded)]
    frames = frames.sort_values(["trial", "frame"], kind="stable").reset_index(drop=True)
    return Salvage(trials, frames, report, gaze)


def recover_tables(paths: SessionPaths) -> tuple[pd.DataFrame | None, pd.DataFrame]:
    """(trials or None, frames) salvaged from every segment (see :func:`salvage`)."""
    found = salvage(paths)
    return found.trials, found.frames


def low_gaze_report(trials: pd.DataFrame, threshold: float = MIN_VALID_GAZE_SHARE) -> JsonObject:
    """Trials marked low-gaze (``gaze_ok`` false; older logs: ``gaze_valid_fraction`` below
    ``threshold``), as session.json's ``integrity`` records them. ``threshold``: the protocol's
    ``trial.min_valid_gaze_share`` (recorded in session.json)."""
    if not len(trials):
        return {"low_gaze_trials": [], "min_valid_gaze_share": threshold}
    low = trials.loc[low_gaze_mask(trials, threshold), "trial"]
    return {"low_gaze_trials": [int(t) for t in low.tolist()], "min_valid_gaze_share": threshold}


def expected_trial_count(meta: JsonObject) -> int | None:
    """The trials a complete session records: the scheduled ones less those its adaptive stop
    rule left out (session.json ``adaptive_stop.n_trials_not_run``, psyop.adaptive.session)."""
    scheduled = meta.get("n_trials_scheduled")
    if scheduled is None:
        return None
    stop = meta.get("adaptive_stop") or {}
    return int(scheduled) - int(stop.get("n_trials_not_run", 0))


def finalise_session(
    paths: SessionPaths,
    *,
    status: str,
    summary: JsonMapping | None = None,
    expected_trials: int | None = None,
    lock: SessionLock | None = None,
    adaptive_stop: JsonMapping | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Write trials.parquet / frames.parquet / gaze.parquet atomically from the streams; update session.json.

    ``status`` is 'complete' only when every scheduled trial is recorded; otherwise the
    session stays resumable ('incomplete'). Takes the session lock unless ``lock`` (held
    by the caller) is given; removes temporary files of an interrupted finalisation.
    session.json's ``integrity`` records what the salvage found. ``adaptive_stop`` (rebuilt by
    psyop.adaptive.recorded_stop) replaces session.json's record of the trials an adaptive stop
    rule left out.
    """
    own_lock = lock is None
    held = SessionLock(paths.lock_file) if lock is None else lock
    held.acquire("finalise")
    try:
        with interrupts_deferred():  # a Ctrl-C (or SIGTERM) here waits: the files are written together
            return _finalise_locked(paths, status=status, summary=summary, expected_trials=expected_trials,
                                    adaptive_stop=adaptive_stop)
    finally:
        if own_lock:
            held.release()


def _finalise_locked(
    paths: SessionPaths, *, status: str, summary: JsonMapping | None, expected_trials: int | None,
    adaptive_stop: JsonMapping | None = None,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    meta = read_metadata(paths)
    if meta is None:
        if not paths.segments("trials"):
            raise UserError("no session.json here: not a psyop session directory", str(paths.directory))
        meta = {**log_identity(paths), "study": paths.study, "participant": paths.participant,
                "session": paths.session, "rebuilt_from_log": _now()}
    found = salvage(paths)
    trials, frames = found.trials, found.frames
    if trials is None:
        trials = pd.DataFrame({"trial": pd.Series([], dtype="int64")})
    if adaptive_stop is not None:
        meta["adaptive_stop"] = dict(adaptive_stop)
    expected = expected_trials if expected_trials is not None else expected_trial_count(meta)
    if status == "complete" and expected is not None and len(trials) < int(expected):
        status = "incomplete"
    if status == "complete" and expected is None and "rebuilt_from_log" in meta:
        status = "incomplete"  # cannot tell: never call a rebuilt session complete without its schedule size
    try:
        for stale in stale_temp_files(paths.directory):
            stale.unlink()
        _write_parquet_atomic(frames, paths.frames_parquet)  # frames and gaze first: trials.parquet never stands alone
        _write_parquet_atomic(found.gaze if found.gaze is not None else GAZE_SCHEMA.empty_table().to_pandas(),
                              paths.gaze_parquet)
        written = [paths.trials_parquet, paths.frames_parquet, paths.gaze_parquet]
        validations = recorded_validations(paths)  # None: the protocol validates no gaze (no file, as before)
        if validations is not None:
            _write_parquet_atomic(validations, paths.directory / VALIDATION_FILE)
            written.append(paths.directory / VALIDATION_FILE)
        for kind, name in (("events", EVENTS_FILE), ("questionnaires", QUESTIONNAIRES_FILE)):
            table = recorded_screen_table(paths, kind)  # None: the protocol has no session: screens (no file)
            if table is not None:
                _write_table_atomic(table, paths.directory / name)
                written.append(paths.directory / name)
        _write_parquet_atomic(trials, paths.trials_parquet, {"simulated": meta.get("simulated")})
        record_finalised(meta, paths.directory, written)
        meta["status"] = status
        meta["n_trials_recorded"] = int(len(trials))
        meta["finalised"] = _now()
        threshold = float(meta.get("min_valid_gaze_share", MIN_VALID_GAZE_SHARE))
        meta["integrity"] = {**found.report, **low_gaze_report(trials, threshold),
                             **late_gaze_report(trials, GazeLatency.of_record(meta.get("gaze_latency")))}
        not_run = {t for c in ((meta.get("adaptive_stop") or {}).get("conditions") or {}).values()
                   for t in c.get("trials_not_run", [])}
        if not_run:  # left out by the adaptive stop rule, not lost
            meta["integrity"]["lost_trials"] = [t for t in meta["integrity"].get("lost_trials", []) if t not in not_run]
        if summary:
            meta["summary"] = dict(summary)
        write_json_atomic(paths.metadata, meta)
    except OSError as exc:
        raise io_error(exc, exc.filename or paths.directory,
                       f"cannot finalise the session; the log is intact: free space (or fix the disk), then run "
                       f"`psyop recover {paths.directory}`") from exc
    return trials, frames


def find_sessions(root: Path) -> Sequence[SessionPaths]:
    """Every session directory under ``root`` (a data root or a session directory): those
    with a session.json, and those whose session.json is lost but whose log remains."""
    root = Path(root)
    found: dict[Path, SessionPaths] = {}
    candidates = [m.parent for m in root.rglob("session.json")]
    candidates += [log.parent for log in root.rglob("log") if log.is_dir() and any(log.glob("trials-*"))]
    for ses_dir in sorted(set(candidates)):
        try:
            session = int(ses_dir.name.removeprefix("ses-"))
        except ValueError:
            continue
        participant = ses_dir.parent.name.removeprefix("sub-")
        study = ses_dir.parent.parent.name
        paths = SessionPaths(ses_dir.parent.parent.parent, study, participant, session)
        check_inside_root(paths)  # `psyop recover DATA/s/sub-L1/ses-1` with sub-L1 -> /elsewhere wrote there
        found[ses_dir] = paths
    return list(found.values())


def _write_table_atomic(table: pa.Table, path: Path) -> None:
    """``table`` as parquet at ``path`` (psyop.atomic.write_atomic), its Arrow types kept (a null answer stays null)."""
    write_atomic(path, lambda handle: pq.write_table(table, handle))


def _write_parquet_atomic(frame: pd.DataFrame, path: Path, identity: JsonMapping | None = None) -> None:
    """``frame`` as parquet at ``path`` (psyop.atomic.write_atomic); ``identity`` (e.g. ``simulated``)
    goes into the file's schema metadata as ``psyop.KEY`` (JSON), readable without session.json."""
    table = pa.Table.from_pandas(frame, preserve_index=False)
    if identity:
        extra = {f"psyop.{key}".encode(): json.dumps(value).encode() for key, value in identity.items()}
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), **extra})
    write_atomic(path, lambda handle: pq.write_table(table, handle))


def _now() -> str:
    return dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")
