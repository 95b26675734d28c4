"""Where a session's files live: ``data/<study>/sub-<ID>/ses-<N>/`` (Psych-DS spirit)."""

from __future__ import annotations

import json
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

from psyop.session.rows import JsonObject
from psyop import datacontract as dc
from psyop.atomic import TEMP_SUFFIX, exclusive_temp, stale_temp_files, write_atomic  # noqa: F401 - re-exported
from psyop.errors import UserError

_ID_PATTERN = dc.PARTICIPANT_PATTERN
_STUDY_PATTERN = dc.STUDY_PATTERN
MAX_SESSION = 9999
#: new segments are checksummed record logs; ``.arrows`` ones are legacy Arrow IPC streams
SEGMENT_SUFFIX = ".psylog"
_SEGMENT_NAME = re.compile(r"(trials|frames|gaze|validation|events|questionnaires)-([0-9]{3})\.(psylog|arrows)")


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

    @property
    def gaze_parquet(self) -> Path:
        return self.directory / dc.GAZE_FILE

    @property
    def lock_file(self) -> Path:
        return self.directory / ".lock"

    def trial_segment(self, index: int) -> Path:
        return self.log_dir / f"trials-{index:03d}{SEGMENT_SUFFIX}"

    def frame_segment(self, index: int) -> Path:
        return self.log_dir / f"frames-{index:03d}{SEGMENT_SUFFIX}"

    def gaze_segment(self, index: int) -> Path:
        return self.log_dir / f"gaze-{index:03d}{SEGMENT_SUFFIX}"

    def segments(self, kind: str) -> list[Path]:
        """Existing stream segments of ``kind`` ('trials', 'frames', 'gaze', 'validation', 'events' or
        'questionnaires'), in write order."""
        if not self.log_dir.is_dir():
            return []
        found = []
        for path in self.log_dir.iterdir():
            match = _SEGMENT_NAME.fullmatch(path.name)
            if match and match.group(1) == kind:
                if not stat.S_ISREG(os.stat(path).st_mode):  # a FIFO would block, /dev/zero never ends
                    raise UserError("a log segment is not a regular file (a FIFO, a device or a folder); restore "
                                    "the segment or move it away", str(path))
                found.append((int(match.group(2)), path))
        return [p for _, p in sorted(found)]

    def next_run_index(self) -> int:
        """One more than the highest segment index of either kind (0 for a new session)."""
        indices = [int(_SEGMENT_NAME.fullmatch(p.name).group(2))  # type: ignore[union-attr]  # segments() lists matching names only
                   for kind in ("trials", "frames", "gaze") for p in self.segments(kind)]
        return max(indices, default=-1) + 1


def session_paths(data_root: Path, study: str, participant: str, session: int) -> SessionPaths:
    """Validate the identifiers (Psych-DS keys are alphanumeric) and build the paths."""
    if not _ID_PATTERN.fullmatch(participant):
        raise UserError(f"participant ID {_short(participant)} must be 1 to 64 letters and digits only", "--participant")
    if not 1 <= session <= MAX_SESSION:
        raise UserError(f"session number must be 1 or more and at most {MAX_SESSION}, got {str(session)[:20]}"
                        + (f"... ({len(str(session))} digits)" if len(str(session)) > 20 else ""), "--session")
    if not _STUDY_PATTERN.fullmatch(study):
        raise UserError(f"study name {_short(study)} must be 1 to 64 letters, digits, '-' or '_'", "protocol")
    root = Path(data_root)
    if root.exists() and not root.is_dir():
        raise UserError("the data root is not a directory; point --data at a directory", str(root))
    paths = SessionPaths(root, study, participant, session)
    check_inside_root(paths)
    return paths


def check_inside_root(paths: SessionPaths) -> None:
    """Every write stays inside the data root: a study, participant, session or log folder that is
    a symlink to somewhere else (``data/detection/sub-L1 -> /elsewhere``) is refused, not followed."""
    real_root = paths.data_root.resolve()
    for folder in (paths.data_root / paths.study, paths.directory.parent, paths.directory, paths.log_dir):
        if folder.is_symlink() and not folder.resolve().is_relative_to(real_root):
            raise UserError(f"{folder} is a link to {folder.resolve()}, outside the data root {real_root}; psyop "
                            "writes only inside the data root: move the folder into it (or use the folder that holds it as "
                            "the data root, --data)", str(folder))


def _short(text: str, limit: int = 40) -> str:
    """``text`` quoted, shortened to ``limit`` characters (a 5000-character name is not echoed)."""
    return repr(text) if len(text) <= limit else f"{text[:limit]!r}... ({len(text)} characters)"


def write_json_atomic(path: Path, content: JsonObject) -> None:
    """Write JSON to ``path`` atomically (:func:`psyop.atomic.write_atomic`): never half-written."""
    write_atomic(path, json.dumps(content, indent=2, sort_keys=True, default=str) + "\n")


def write_dataset_description(data_root: Path, *, simulated: bool, studies: list[str] | None = None) -> Path:
    """Write ``data_root/dataset_description.json``.

    ``simulated`` is true only when every session in the dataset is simulated: a real
    session added to a simulated dataset turns the flag false (and is listed).
    """
    from psyop.session.inventory import session_record

    data_root = Path(data_root)
    path = data_root / dc.DATASET_DESCRIPTION_FILE
    sessions = sorted(p for p in data_root.glob("*/sub-*/ses-*") if p.is_dir())
    n_sim = n_real = 0
    found_studies: set[str] = set(studies or [])
    for directory in sessions:
        try:  # session.json, else the finalised trials.parquet or the log's header (psyop.session.inventory)
            record = session_record(directory, data_root)
        except UserError:  # a hostile or damaged file (`psyop sessions` names it): never called simulated
            n_real += 1
            continue
        if record is None:
            continue
        found_studies.add(directory.parents[1].name)
        if record.simulated is True:
            n_sim += 1
        else:
            n_real += 1
    if n_sim + n_real == 0:
        all_simulated = simulated
    else:
        all_simulated = n_real == 0
    description = dc.dataset_description(simulated=all_simulated, studies=sorted(found_studies),
                                         n_simulated=n_sim, n_real=n_real)
    write_json_atomic(path, description)
    return path
