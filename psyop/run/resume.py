"""Which seed a session uses, and which option combinations a run or a resume may use.

Called by the runner before anything is written:

- :func:`check_options` refuses combinations that would record wrong numbers: a live
  device (a backend the registry marks ``real_time``: a serial button box or keyboard
  timestamps presses in real time, so on the virtual clock its response times would be
  meaningless, presses 0.25 s apart logged as 24-28 s response times) on the virtual clock.
- :func:`resolve_seed` decides the seed: an existing session's (session.json, or the
  seed written into the checksummed log when session.json was lost) wins over the
  default; an explicit ``--seed`` that differs from it is refused (exit code 2) rather
  than mixing two schedules in one session.

Resuming with another protocol, seed or clock is refused by the store
(:class:`psyop.session.log.store.SessionStore`), which compares them with session.json
or, without it, with the identity written into the log. Each run's clock, tracker,
responses and display are recorded in session.json's ``runs``.

- :func:`accept_protocol_change` is the one documented override (``psyop run
  --allow-protocol-change``): a protocol file edited only in its comments or layout (another
  SHA-256, the same validated protocol, hence the same schedule, plan and scene) may resume
  the session; any change to a value is still refused, naming the sections that differ.
"""

from __future__ import annotations

from pathlib import Path

from psyop.errors import UserError
from psyop.protocol.model import Protocol
from psyop.run.backends import OPTION, Category, is_real_time, lookup
from psyop.session.lock import SessionLock
from psyop.session.log.layout import SessionPaths
from psyop.session.log.record import SessionRecord
from psyop.session.log.store import log_identity

def check_options(*, clock: str, responses: str, tracker: str, pose: str = "sim", display: str = "headless") -> None:
    """Refuse a live device on the virtual clock, and a headset source without the headset display (exit code 2,
    naming the option).

    Which backends are live is the registry's ``real_time`` (:mod:`psyop.run.backends`);
    an unknown backend name is refused here too, before anything is written."""
    chosen: dict[Category, str] = {"display": display, "tracker": tracker, "pose": pose, "responses": responses}
    for category, spec in chosen.items():
        lookup(category, spec)
        if category != "display" and spec.partition(":")[0] == "openxr" and display.partition(":")[0] != "openxr":
            raise UserError(f"{OPTION[category]} openxr reads the headset's runtime: use it with --display openxr",
                            OPTION[category])
        if clock == "virtual" and is_real_time(category, spec):
            name = spec.partition(":")[0]
            what = ("a live device whose presses are timed in real time; on --clock virtual its response times "
                    "would be wrong" if category == "responses" else "a live device")
            raise UserError(f"{OPTION[category]} {name} is {what}: use --clock real with it", "--clock")


def check_free(paths: SessionPaths) -> None:
    """Refuse a session another process is writing (naming it), as the store would, before reading it."""
    SessionLock(paths.lock_file).check_free()


def recorded_seed(paths: SessionPaths, record: SessionRecord | None) -> int | None:
    """The seed of an existing session: session.json's (``record``), else the one in its log, else None."""
    if record is not None and record.seed is not None:
        return record.seed
    if record is None and paths.segments("trials"):
        seed = log_identity(paths).get("seed")
        if seed is not None:
            return _as_seed(seed, str(paths.log_dir))
    return None


def resolve_seed(paths: SessionPaths, record: SessionRecord | None, requested: int | None, default: int) -> int:
    """The seed this run must use (see the module docstring); ``record``: the session's session.json as read
    (after :func:`check_free`: a session another process is writing is refused first, naming it)."""
    recorded = recorded_seed(paths, record)
    if recorded is None:
        return default if requested is None else requested
    if requested is not None and requested != recorded:
        raise UserError(
            f"cannot resume: seed differs from the existing session ({recorded} there, {requested} now); "
            "drop --seed to resume it, or use another --session", str(paths.directory))
    return recorded


def _as_seed(value: object, location: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise UserError(f"the recorded seed {value!r} is not an integer", location)
    return value


def accept_protocol_change(paths: SessionPaths, record: SessionRecord | None, protocol: Protocol) -> str:
    """The protocol hash the session keeps when ``protocol`` resumes it under
    ``--allow-protocol-change`` (see the module docstring).

    No existing session, or the same file: ``protocol``'s own hash. Otherwise the recorded
    protocol text (session.json ``protocol_text``) is validated again and must equal
    ``protocol`` field by field; then the session keeps its recorded hash (each run records its
    file's hash in ``runs``). Anything else is a UserError naming the difference.
    """
    from psyop.protocol.loader import parse_protocol

    if record is None:
        if paths.segments("trials"):
            raise UserError("--allow-protocol-change needs session.json's copy of the protocol to compare with; "
                            "it is lost, so only the identical protocol file can resume this session",
                            str(paths.directory))
        return protocol.source_sha256
    recorded_sha = record.protocol_sha256
    if recorded_sha == protocol.source_sha256:
        return protocol.source_sha256
    text = record.protocol_text
    if not text:
        raise UserError("--allow-protocol-change: session.json holds no protocol_text to compare with",
                        str(paths.metadata))
    base_dir = Path(protocol.source_name).parent if protocol.source_name else None
    recorded = parse_protocol(text, f"{paths.metadata} (protocol_text)", base_dir=base_dir)
    before, now = recorded.model_dump(mode="json"), protocol.model_dump(mode="json")
    changed = [key for key in sorted(set(before) | set(now)) if before.get(key) != now.get(key)]
    if changed:
        raise UserError(
            f"cannot resume: the protocol's values changed, not only its comments (sections {changed} differ "
            "from the session's protocol); --allow-protocol-change only accepts edits to comments and layout: "
            "undo the change, or use another --session", str(paths.metadata))
    return str(recorded_sha)
