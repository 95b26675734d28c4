"""The sessions a read-only command is given: one session directory, or every session under a data root."""

from __future__ import annotations

from pathlib import Path

from psyop import datacontract as dc
from psyop.errors import UserError


def session_dirs(path: Path) -> list[Path]:
    """``[path]`` when ``path`` is a session directory (it holds trials.parquet), else every session
    directory below it, sorted; a one-line UserError naming ``path`` when it does not exist or holds none."""
    if not path.exists():
        raise UserError("no such session directory or data root", str(path))
    if (path / dc.TRIALS_FILE).is_file():
        return [path]
    sessions = sorted(p.parent for p in path.rglob(dc.TRIALS_FILE))
    if not sessions:
        raise UserError("no sessions here (expected <study>/sub-<ID>/ses-<N>/trials.parquet)", str(path))
    return sessions
