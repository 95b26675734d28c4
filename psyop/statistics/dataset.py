"""Load a study's trial logs: every ``data/<study>/sub-<ID>/ses-<N>/trials.parquet``."""

from __future__ import annotations

import functools
import json
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from psyop import datacontract as dc
from psyop.atomic import write_atomic
from psyop.errors import UserError
from psyop.finalised import record_finalised, verify_session
from psyop.input_files import MAX_LOG_TABLE_BYTES, InputFile
from psyop.quality.cache import QualityCache
from psyop.quality.included import include as include_quality
from psyop.statistics.protocol_versions import unit_trials_files


class LowGazeWarning(UserWarning):
    """The loaded trials include trials marked low-gaze (trials.parquet ``gaze_ok`` false)."""


class LateGazeWarning(LowGazeWarning):
    """The loaded trials include trials marked late-gaze (trials.parquet ``gaze_age_ok`` false: more of the
    intervals' frames than the protocol allows were rendered from gaze older than ``trial.max_gaze_age_ms``).
    A LowGazeWarning, so what silences low-gaze warnings silences these too."""


@dataclass(frozen=True)
class Dataset:
    """All trials of one study and whether the data came from simulated sessions."""

    study: str
    trials: pd.DataFrame
    simulated: bool
    n_sessions: int


def is_simulated(data_root: Path) -> bool:
    """Read ``simulated`` from ``data_root/dataset_description.json``.

    A missing file or key counts as *not* simulated only when the file exists and says
    so; an absent description is treated as simulated=False but never silently: callers
    show "simulated" in figures only when this returns True.
    """
    path = Path(data_root) / dc.DATASET_DESCRIPTION_FILE
    if not os.path.lexists(path):
        return False
    raw = _DESCRIPTION.read_bytes(path)  # a regular file within its limit (never a FIFO or /dev/zero)
    try:
        description = json.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise UserError(f"not UTF-8 text ({exc.reason})", str(path)) from exc
    except json.JSONDecodeError as exc:
        raise UserError(f"not valid JSON: {exc.msg}", f"{path}:{exc.lineno}:{exc.colno}") from exc
    if not isinstance(description, dict):
        raise UserError("not a JSON object", str(path))
    return bool(description.get(dc.SIMULATED_KEY, False))


_DESCRIPTION = InputFile(what="dataset_description.json", give="it must be a regular JSON file",
                         max_bytes=1 << 20, typical="a dataset description is a few hundred bytes",
                         not_found="no file {path}")
_TRIALS = InputFile(what="trials.parquet", give="a session's trials.parquet must be a regular file",
                    max_bytes=MAX_LOG_TABLE_BYTES, typical="a session's trials.parquet is a few MB",
                    not_found="no file {path}")


def _read_trials(files: list[Path]) -> tuple[list[pd.DataFrame], list[bool | None]]:
    """Each session's trials (regular files within the size limit, each read once: a file or
    session folder reached twice through a link is a UserError naming both) and what its own
    ``psyop.simulated`` schema metadata says (None: not recorded)."""
    import pyarrow.parquet as pq

    seen: dict[tuple[int, int], Path] = {}
    tables, flags = [], []
    for path in files:
        _TRIALS.check(path)
        for item in (path, path.parent):
            info = os.stat(item)
            key = (info.st_dev, info.st_ino)
            if key in seen:
                raise UserError(f"{item} is the same as {seen[key]} (one is a link to the other): its trials would "
                                "be loaded twice; remove the link", str(item))
            seen[key] = item
        try:
            table = pq.read_table(path)
        except Exception as exc:  # noqa: BLE001 - any unreadable table is the user's data
            raise UserError(f"trials.parquet cannot be read ({type(exc).__name__}: {str(exc)[:120]}); run "
                            f"`psyop recover {path.parent}` to rebuild it from the session's log", str(path)) from None
        value = (table.schema.metadata or {}).get(dc.SIMULATED_METADATA_KEY.encode())
        flags.append(None if value is None else json.loads(value) is True)
        tables.append(dc.with_typed_response(table.to_pandas()))  # sessions logged before the typed columns
    return tables, flags


def session_files(data_root: Path, study: str) -> list[Path]:
    """Sorted paths of every session log of ``study``; of one protocol version for ``study@<hash12>``
    (psyop.statistics.protocol_versions)."""
    return unit_trials_files(data_root, study)


def load_trials(data_root: Path, study: str, include_practice: bool = False) -> pd.DataFrame:
    """Concatenate every session's trials of ``study`` into one tidy table.

    ``participant`` is returned as str and ``session`` as int so that groupings are
    stable across sessions written by different versions. The result's ``attrs``
    carry ``simulated`` (bool) and ``n_sessions``.
    """
    return load_dataset(data_root, study, include_practice).trials


def load_dataset(data_root: Path, study: str, include_practice: bool = False,
                 include_timeouts: bool = False, drop_low_gaze: bool = False, drop_late_gaze: bool = False) -> Dataset:
    """Like :func:`load_trials` but returns a :class:`Dataset` with the simulated flag.

    Practice trials (a true ``practice`` column) are left out unless ``include_practice``;
    how many were left out is in ``trials.attrs["n_practice_dropped"]``. Every session's finalised
    files are checked against the SHA-256 its session.json recorded (:mod:`psyop.finalised`) before
    any is read: a damaged or edited session is a :class:`UserError` naming it. Timed-out trials
    (response ``timeout``, psyop.datacontract) are left out unless ``include_timeouts``;
    how many in ``trials.attrs["n_timeout_dropped"]``. Low-gaze trials (``gaze_ok`` false:
    less valid gaze than the protocol's ``trial.min_valid_gaze_share``; see
    :func:`psyop.datacontract.low_gaze_mask`) are kept and counted in
    ``trials.attrs["n_low_gaze"]``, with a :class:`LowGazeWarning` naming the count;
    ``drop_low_gaze`` leaves them out (``trials.attrs["n_low_gaze_dropped"]``); ``quality:`` rules too (attrs["quality"]).
    Late-gaze trials (``gaze_age_ok`` false: gaze older than the protocol's ``trial.max_gaze_age_ms`` on more
    of their interval frames than it allows; :func:`psyop.datacontract.late_gaze_mask`) are counted alike:
    ``attrs["n_late_gaze"]``, a :class:`LateGazeWarning`, ``drop_late_gaze`` (``attrs["n_late_gaze_dropped"]``).
    """
    files = session_files(data_root, study)
    if not files:
        raise UserError(
            f"no sessions found for study {study!r} (expected {study}/sub-<ID>/ses-<N>/trials.parquet)",
            str(Path(data_root)),
        )
    for f in files:  # before anything is read: only regular files within the limit (a FIFO never blocks) ...
        _TRIALS.check(f)
    for f in files:  # ... then a damaged or edited session is refused by name
        verify_session(f.parent)
    frames, file_flags = _read_trials(files)
    trials = pd.concat(frames, ignore_index=True)
    if "participant" in trials:
        trials["participant"] = trials["participant"].astype(str)
    if "session" in trials:
        trials["session"] = trials["session"].astype(int)
    n_practice = 0
    if not include_practice and "practice" in trials:
        is_practice = trials["practice"].fillna(False).astype(bool)
        n_practice = int(is_practice.sum())
        trials = trials[~is_practice].reset_index(drop=True)
    n_timeout = 0
    if not include_timeouts:
        trials = dc.drop_timeouts(trials)
        n_timeout = trials.attrs["n_timeout_dropped"]
    trials, n_low, n_late = _gaze_flags(trials, study, drop_low_gaze, drop_late_gaze)
    # the protocol's quality: rules, each session's measures kept in the data root's quality cache (docs/quality.md)
    trials = include_quality(trials, [f.parent for f in files], QualityCache.beside(data_root))
    # simulated only when the description says so and no session's own trials.parquet says real
    # (a real session whose session.json was deleted still carries its flag in its finalised table)
    simulated = is_simulated(data_root) and False not in file_flags
    trials.attrs["n_low_gaze"] = n_low
    trials.attrs["n_low_gaze_dropped"] = n_low if drop_low_gaze else 0
    trials.attrs["n_late_gaze"] = n_late
    trials.attrs["n_late_gaze_dropped"] = n_late if drop_late_gaze else 0
    trials.attrs["n_timeout_dropped"] = n_timeout
    trials.attrs["n_practice_dropped"] = n_practice
    trials.attrs["simulated"] = simulated
    trials.attrs["n_sessions"] = len(files)
    return Dataset(study=study, trials=trials, simulated=simulated, n_sessions=len(files))


def _gaze_flags(trials: pd.DataFrame, study: str, drop_low_gaze: bool, drop_late_gaze: bool
                ) -> tuple[pd.DataFrame, int, int]:
    """``trials`` less the low-gaze and late-gaze trials asked to be dropped, and how many of each there were (each
    count warned about: :class:`LowGazeWarning`, :class:`LateGazeWarning`)."""
    low = dc.low_gaze_mask(trials)
    n_low = int(low.sum())
    if n_low:
        what = "left out (drop_low_gaze)" if drop_low_gaze else "kept in the analysis (drop_low_gaze=True leaves them out)"
        warnings.warn(LowGazeWarning(
            f"{study}: {n_low} of {len(trials)} trials had less valid gaze than the protocol's "
            f"trial.min_valid_gaze_share (gaze_ok false); {what}"), stacklevel=3)
    late = dc.late_gaze_mask(trials)
    n_late = int(late.sum())
    if n_late:
        what = "left out (drop_late_gaze)" if drop_late_gaze else \
            "kept in the analysis (drop_late_gaze=True leaves them out)"
        warnings.warn(LateGazeWarning(
            f"{study}: {n_late} of {len(trials)} trials had more frames with gaze older than the protocol's "
            f"trial.max_gaze_age_ms than trial.max_gaze_age_over_share allows (gaze_age_ok false); {what}"),
            stacklevel=3)
    drop = (low if drop_low_gaze else pd.Series(False, index=trials.index)) | \
        (late if drop_late_gaze else pd.Series(False, index=trials.index))
    if drop.any():
        trials = trials[~drop].reset_index(drop=True)
    return trials, n_low, n_late


def load_gaze(data_root: Path, study: str) -> pd.DataFrame:
    """Every session's raw gaze stream of ``study`` (``gaze.parquet``, every sample the tracker
    delivered; columns: :data:`psyop.session.log.schema.GAZE_SCHEMA`) in one table, with
    ``participant`` (str) and ``session`` (int) added. Sessions finalised before the raw stream
    existed have no gaze.parquet: they are counted in ``attrs["n_sessions_without_gaze"]``, never
    silently missing. Each session's finalised files are verified first, as for :func:`load_dataset`.
    Join to the trials on (participant, session, run, trial).

    Examples
    --------
    >>> import tempfile
    >>> root = Path(tempfile.mkdtemp())
    >>> ses = dc.session_dir(root, "demo", "P1", 1)
    >>> ses.mkdir(parents=True)
    >>> pd.DataFrame({"trial": [0]}).to_parquet(ses / dc.TRIALS_FILE)
    >>> pd.DataFrame({"run": [0, 0], "trial": [0, 0], "gaze_sample_t_s": [0.1, 0.2]}).to_parquet(ses / dc.GAZE_FILE)
    >>> meta = {}
    >>> _ = record_finalised(meta, ses, [ses / dc.TRIALS_FILE, ses / dc.GAZE_FILE])
    >>> _ = (ses / dc.SESSION_METADATA_FILE).write_text(json.dumps(meta))
    >>> gaze = load_gaze(root, "demo")
    >>> len(gaze), gaze["participant"].tolist(), gaze.attrs["n_sessions_without_gaze"]
    (2, ['P1', 'P1'], 0)
    """
    files = session_files(data_root, study)
    if not files:
        raise UserError(f"no sessions found for study {study!r} (expected {study}/sub-<ID>/ses-<N>/trials.parquet)",
                        str(Path(data_root)))
    tables, without = [], 0
    for trials_file in files:
        verify_session(trials_file.parent)  # the SHA-256 session.json recorded (psyop.finalised)
        path = trials_file.parent / dc.GAZE_FILE
        if not path.is_file():
            without += 1
            continue
        table = pd.read_parquet(path)
        table.insert(0, "session", int(trials_file.parent.name.removeprefix("ses-")))
        table.insert(0, "participant", trials_file.parent.parent.name.removeprefix("sub-"))
        tables.append(table)
    gaze = pd.concat(tables, ignore_index=True) if tables else pd.DataFrame({"participant": [], "session": []})
    gaze.attrs["n_sessions"] = len(files)
    gaze.attrs["n_sessions_without_gaze"] = without
    return gaze


def write_dataset(data_root: Path, tables: dict[str, pd.DataFrame], simulated: bool,
                  protocol_sha256: dict[str, str] | None = None) -> list[Path]:
    """Write trial tables in the session-log layout (for tests and demos).

    Each table is split by ``participant`` and ``session`` into
    ``<root>/<study>/sub-<ID>/ses-<N>/trials.parquet`` with a session.json that records its
    SHA-256 (as finalisation does); ``dataset_description.json`` records ``simulated``. With
    ``protocol_sha256`` (study -> hash), the session.json of that study's sessions also names the
    protocol it ran (what psyop.statistics.studies reads to tell the paper's protocols from a
    user's). Returns the written parquet paths.
    """
    import pyarrow as pa
    import pyarrow.parquet as pq

    root = Path(data_root)
    root.mkdir(parents=True, exist_ok=True)
    written = []
    for study, table in tables.items():
        for (participant, session), part in table.groupby(["participant", "session"], sort=True):
            path = dc.session_dir(root, study, participant, session) / dc.TRIALS_FILE
            arrow = pa.Table.from_pandas(part.reset_index(drop=True), preserve_index=False)
            arrow = arrow.replace_schema_metadata({**(arrow.schema.metadata or {}),  # as a finalised session's
                                                   dc.SIMULATED_METADATA_KEY.encode(): json.dumps(simulated).encode()})
            write_atomic(path, functools.partial(pq.write_table, arrow))  # pq.write_table(arrow, handle)
            meta = {"study": study, "participant": str(participant), "session": int(session),
                    dc.SIMULATED_KEY: bool(simulated), "status": "complete", "written_by": "write_dataset"}
            if protocol_sha256 and study in protocol_sha256:
                meta["protocol_sha256"] = protocol_sha256[study]
            record_finalised(meta, path.parent, [path])
            write_atomic(path.parent / dc.SESSION_METADATA_FILE, json.dumps(meta, indent=2) + "\n")
            written.append(path)
    write_atomic(root / dc.DATASET_DESCRIPTION_FILE,
                 json.dumps(dc.dataset_description(simulated=simulated, studies=sorted(tables)), indent=2) + "\n")
    return written
