"""One protocol version of a study as an analysis unit: ``<study>@<short hash>``.

A study folder (``data/<study>/``) whose sessions ran more than one protocol version (distinct
``protocol_sha256`` in their session.json) is analysed per version unless pooled on purpose
(``--pool-protocols``, ``make figures POOL=1``). Each version is named ``<study>@<hash12>`` (the
first 12 hex digits of its protocol's SHA-256): the name every analysis script takes as ``--study``
and that names its outputs (``results/<study>@<hash12>_<what>.json``). ``@`` cannot occur in a
study name (:data:`psyop.datacontract.STUDY_PATTERN`), so a unit never collides with a study.

- :func:`split_unit`: (study folder, hash prefix or None).
- :func:`unit_name`: the unit of one version.
- :func:`session_hash`: the protocol hash a session's session.json records (None: not recorded).
- :func:`unit_trials_files`: the trial logs of a study or of one of its versions.
"""

from __future__ import annotations

import re
from pathlib import Path

from psyop import datacontract as dc
from psyop.errors import UserError
from psyop.session.log.record import read_record_file

SEPARATOR = "@"
#: hex digits of the protocol hash in a unit's name
SHORT_HASH_DIGITS = 12
_PREFIX = re.compile(r"[0-9a-f]{6,64}")


def split_unit(name: str) -> tuple[str, str | None]:
    """(study folder, protocol-hash prefix) of ``study`` or ``study@<hash prefix>``.

    Examples
    --------
    >>> split_unit("realism"), split_unit("realism@0123456789ab")
    (('realism', None), ('realism', '0123456789ab'))
    """
    study, sep, prefix = name.partition(SEPARATOR)
    if not sep:
        return name, None
    if not _PREFIX.fullmatch(prefix):
        raise UserError(f"{name!r}: after {SEPARATOR!r} comes the protocol hash (6 to 64 lower-case hex digits, "
                        f"e.g. {study}@0123456789ab); `python -m psyop studies DATA` names each version", name)
    return study, prefix


def unit_name(study: str, sha256: str) -> str:
    """``study@<first 12 hex digits>``.

    Examples
    --------
    >>> unit_name("realism", "ab" * 32)
    'realism@abababababab'
    """
    return f"{study}{SEPARATOR}{sha256[:SHORT_HASH_DIGITS]}"


def session_hash(trials_file: Path) -> str | None:
    """The ``protocol_sha256`` of the session.json beside ``trials_file`` (None when not recorded)."""
    record = read_record_file(trials_file.parent / dc.SESSION_METADATA_FILE)
    return (record.protocol_sha256 or None) if record is not None else None


def unit_trials_files(data_root: Path, name: str) -> list[Path]:
    """The sorted trial logs of study ``name``, or of the one protocol version ``study@<prefix>`` names.

    A prefix that matches no session's hash, or the hashes of two versions, is a UserError naming
    the study's versions."""
    study, prefix = split_unit(name)
    files = dc.trials_files(data_root, study)
    if prefix is None:
        return files
    hashes = {f: session_hash(f) for f in files}
    matching = sorted({h for h in hashes.values() if h and h.startswith(prefix)})
    if len(matching) != 1:
        versions = ", ".join(sorted({unit_name(study, h) for h in hashes.values() if h})) or "none recorded"
        what = "no session of" if not matching else f"{len(matching)} protocol versions of"
        raise UserError(f"{what} study {study!r} ran a protocol whose sha256 starts {prefix!r} (its versions: "
                        f"{versions})", str(Path(data_root) / study))
    return [f for f, h in hashes.items() if h == matching[0]]


__all__ = ["SEPARATOR", "SHORT_HASH_DIGITS", "session_hash", "split_unit", "unit_name", "unit_trials_files"]
