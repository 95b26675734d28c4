"""Where a session's files live: ``data/<study>/sub-<ID>/ses-<N>/`` (Psych-DS spirit)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from psyop import datacontract as dc
from psyop.errors import UserError

_ID_PATTERN = dc.PARTICIPANT_PATTERN


@dataclass(frozen=True)
class SessionPaths:
    """All paths of one session directory."""

    data_root: Path
    study: str
    participant: str
    session: int

    @property
    def directory(self) -> Path:
        return dc.session_dir(self.data_root, self.study, self.participant, self.session)

    @property
    def metadata(self) -> Path:
        return self.directory / dc.SESSION_METADATA_FILE

    @property
    def log_dir(self) -> Path:
        return self.directory / dc.LOG_DIR

    @property
    def trials_parquet(self) -> Path:
        return self.directory / dc.TRIALS_FILE

    @property
    def frames_parquet(self) -> Path:
        return self.directory / dc.FRAMES_FILE

    def trial_segment(self, index: int) -> Path:
        return self.log_dir / f"trials-{index:03d}.arrows"

    def frame_segment(self, index: int) -> Path:
        return self.log_dir / f"frames-{index:03d}.arrows"

    def segments(self, kind: str) -> list[Path]:
        """Existing stream segments of ``kind`` ('trials' or 'frames'), in write order."""
        if not self.log_dir.is_dir():
            return []
        return sorted(self.log_dir.glob(f"{kind}-[0-9][0-9][0-9].arrows"))


def session_paths(data_root: Path, study: str, participant: str, session: int) -> SessionPaths:
    """Validate the identifiers (Psych-DS keys are alphanumeric) and build the paths."""
    if not _ID_PATTERN.match(participant):
        raise UserError(f"participant ID {participant!r} must be letters and digits only", "--participant")
    if session < 1:
        raise UserError(f"session number must be 1 or more, got {session}", "--session")
    if not dc.STUDY_PATTERN.match(study):
        raise UserError(f"study name {study!r} must be letters, digits, '-' or '_'", "protocol")
    return SessionPaths(Path(data_root), study, participant, session)


def write_json_atomic(path: Path, content: dict[str, Any]) -> None:
    """Write JSON to ``path`` via a temporary file + rename, fsynced: never half-written."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "w") as handle:
        json.dump(content, handle, indent=2, sort_keys=True, default=str)
        handle.write("\n")
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)


def write_dataset_description(data_root: Path, *, simulated: bool, studies: list[str] | None = None) -> Path:
    """Write ``data_root/dataset_description.json``.

    ``simulated`` is true only when every session in the dataset is simulated: a real
    session added to a simulated dataset turns the flag false (and is listed).
    """
    data_root = Path(data_root)
    path = data_root / dc.DATASET_DESCRIPTION_FILE
    sessions = dc.session_metadata_files(data_root)
    n_sim = n_real = 0
    found_studies: set[str] = set(studies or [])
    for meta_path in sessions:
        try:
            meta = json.loads(meta_path.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        found_studies.add(str(meta.get("study", meta_path.parents[2].name)))
        if meta.get(dc.SIMULATED_KEY):
            n_sim += 1
        else:
            n_real += 1
    if not sessions:
        all_simulated = simulated
    else:
        all_simulated = n_real == 0
    description = dc.dataset_description(simulated=all_simulated, studies=sorted(found_studies),
                                         n_simulated=n_sim, n_real=n_real)
    write_json_atomic(path, description)
    return path
