"""Load a study's trial logs: every ``data/<study>/sub-<ID>/ses-<N>/trials.parquet``."""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from psyop import datacontract as dc
from psyop.errors import UserError
from psyop.finalised import record_finalised, verify_session


class LowGazeWarning(UserWarning):
    """The loaded trials include trials marked low-gaze (trials.parquet ``gaze_ok`` false)."""


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
    if not path.exists():
        return False
    try:
        description = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise UserError(f"not valid JSON: {exc.msg}", f"{path}:{exc.lineno}:{exc.colno}") from exc
    return bool(description.get(dc.SIMULATED_KEY, False))


def session_files(data_root: Path, study: str) -> list[Path]:
    """Sorted paths of every session log of ``study``."""
    return dc.trials_files(data_root, study)


def load_trials(data_root: Path, study: str, include_practice: bool = False) -> pd.DataFrame:
    """Concatenate every session's trials of ``study`` into one tidy table.

    ``participant`` is returned as str and ``session`` as int so that groupings are
    stable across sessions written by different versions. The result's ``attrs``
    carry ``simulated`` (bool) and ``n_sessions``.
    """
    return load_dataset(data_root, study, include_practice).trials


def load_dataset(data_root: Path, study: str, include_practice: bool = False,
                 include_timeouts: bool = False, drop_low_gaze: bool = False) -> Dataset:
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
    ``drop_low_gaze`` leaves them out (``trials.attrs["n_low_gaze_dropped"]``).
    """
    files = session_files(data_root, study)
    if not files:
        raise UserError(
            f"no sessions found for study {study!r} (expected {study}/sub-<ID>/ses-<N>/trials.parquet)",
            str(Path(data_root)),
        )
    for f in files:  # before anything is read: a damaged or edited session is refused by name
        verify_session(f.parent)
    frames = [pd.read_parquet(f) for f in files]
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
    low = dc.low_gaze_mask(trials)
    n_low = int(low.sum())
    if n_low:
        what = "left out (drop_low_gaze)" if drop_low_gaze else "kept in the analysis (drop_low_gaze=True leaves them out)"
        warnings.warn(LowGazeWarning(
            f"{study}: {n_low} of {len(trials)} trials had less valid gaze than the protocol's "
            f"trial.min_valid_gaze_share (gaze_ok false); {what}"), stacklevel=2)
    if drop_low_gaze:
        trials = trials[~low].reset_index(drop=True)
    simulated = is_simulated(data_root)
    trials.attrs["n_low_gaze"] = n_low
    trials.attrs["n_low_gaze_dropped"] = n_low if drop_low_gaze else 0
    trials.attrs["n_timeout_dropped"] = n_timeout
    trials.attrs["n_practice_dropped"] = n_practice
    trials.attrs["simulated"] = simulated
    trials.attrs["n_sessions"] = len(files)
    return Dataset(study=study, trials=trials, simulated=simulated, n_sessions=len(files))


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
    root = Path(data_root)
    root.mkdir(parents=True, exist_ok=True)
    written = []
    for study, table in tables.items():
        for (participant, session), part in table.groupby(["participant", "session"], sort=True):
            path = dc.session_dir(root, study, participant, session) / dc.TRIALS_FILE
            path.parent.mkdir(parents=True, exist_ok=True)
            part.reset_index(drop=True).to_parquet(path, index=False)
            meta = {"study": study, "participant": str(participant), "session": int(session),
                    dc.SIMULATED_KEY: bool(simulated), "status": "complete", "written_by": "write_dataset"}
            if protocol_sha256 and study in protocol_sha256:
                meta["protocol_sha256"] = protocol_sha256[study]
            record_finalised(meta, path.parent, [path])
            (path.parent / dc.SESSION_METADATA_FILE).write_text(json.dumps(meta, indent=2) + "\n")
            written.append(path)
    (root / dc.DATASET_DESCRIPTION_FILE).write_text(
        json.dumps(dc.dataset_description(simulated=simulated, studies=sorted(tables)), indent=2) + "\n")
    return written
