"""A finalised session's gaze-quality result (per-trial measures and events) kept on disk, keyed on
everything it is computed from, so that a study analysed again does not rebuild and measure its streams again.

The key is the SHA-256 of: every file of the session directory (relative path and content), the source
of every module of the installed psyop package (the measures, the simulated tracker the streams are rebuilt
with, the protocol parser and the plan compiler all live there), the versions of the libraries the result
passes through (pymovements, polars, numpy, pandas, pyarrow, scipy) and Python's. Any change to any of them
is another key: a stale entry is never read, only left behind (delete the folder freely). An entry is the
two tables exactly as :func:`psyop.quality.session.measure_session` returned them, in parquet (float64
round-trips bit for bit), written atomically; an entry that cannot be read is measured again, and a folder
that cannot be written (read-only data) is measured without a cache. docs/quality.md, "The quality cache".
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import sys
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from psyop.atomic import write_atomic

#: the cache's folder under a data root
CACHE_FOLDER = Path(".psyop-cache") / "gaze-quality"
#: the libraries whose versions are part of the key
KEYED_LIBRARIES = ("pymovements", "polars", "numpy", "pandas", "pyarrow", "scipy")
_CHUNK = 1 << 20


def _file_digest(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as handle:
        while block := handle.read(_CHUNK):
            digest.update(block)
    return digest.hexdigest()


def _tree_digest(root: Path, pattern: str) -> str:
    """SHA-256 of the relative path and content of every file under ``root`` matching ``pattern``, in order."""
    digest = hashlib.sha256()
    for path in sorted(p for p in root.rglob(pattern) if p.is_file()):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + _file_digest(path).encode() + b"\n")
    return digest.hexdigest()


def code_fingerprint() -> str:
    """SHA-256 of psyop's source (every ``.py`` of the package) and the keyed libraries' and Python's versions."""
    import psyop

    digest = hashlib.sha256(_tree_digest(Path(psyop.__file__).resolve().parent, "*.py").encode())
    for name in KEYED_LIBRARIES:
        try:
            version = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            version = "absent"
        digest.update(f"{name}={version}\n".encode())
    digest.update(sys.version.encode())
    return digest.hexdigest()


@dataclass(frozen=True)
class QualityCache:
    """Gaze-quality results under ``folder``, for the code whose :func:`code_fingerprint` is ``code_key``."""

    folder: Path
    code_key: str

    @staticmethod
    def beside(data_root: Path) -> QualityCache:
        """The cache of the sessions under ``data_root`` (:data:`CACHE_FOLDER` there), for this psyop."""
        return QualityCache(Path(data_root) / CACHE_FOLDER, code_fingerprint())

    def key(self, session_dir: Path) -> str:
        """The key of the session in ``session_dir``: its files' paths and contents and :attr:`code_key`."""
        return hashlib.sha256(f"{self.code_key}\n{_tree_digest(Path(session_dir), '*')}".encode()).hexdigest()

    def _paths(self, key: str) -> tuple[Path, Path]:
        return self.folder / f"{key}.measures.parquet", self.folder / f"{key}.events.parquet"

    def get(self, key: str) -> tuple[pd.DataFrame, pd.DataFrame] | None:
        """The (measures, events) stored under ``key``; None when there are none or they cannot be read."""
        measures_path, events_path = self._paths(key)
        if not (measures_path.is_file() and events_path.is_file()):
            return None
        try:
            return pd.read_parquet(measures_path), pd.read_parquet(events_path)
        except (OSError, ValueError):  # a damaged entry is measured again (and rewritten)
            return None

    def put(self, key: str, measures: pd.DataFrame, events: pd.DataFrame) -> bool:
        """Store (measures, events) under ``key``, each file atomically; False when the folder cannot be
        written (the result stands; it is only not kept)."""
        measures_path, events_path = self._paths(key)
        try:
            write_atomic(events_path, lambda handle: events.to_parquet(handle, index=False))
            write_atomic(measures_path, lambda handle: measures.to_parquet(handle, index=False))
        except OSError:
            return False
        return True
