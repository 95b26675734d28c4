"""Which sessions a data root holds, per study: how many, simulated or real, complete or not.

``make figures`` prints this before it draws anything, and refuses a study whose sessions
mix simulated and real participants (the figures would pool them) unless asked to (MIX=1).
Reads each session's session.json (the ``simulated`` and ``status`` fields written by
psyop.session.runner) and checks its finalised files against the SHA-256 recorded there
(psyop.finalised); stdlib only, so it is quick to import.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from psyop.errors import UserError
from psyop.finalised import verify_session


@dataclass(frozen=True)
class StudySessions:
    study: str
    n_simulated: int
    n_real: int
    n_incomplete: int
    participants: tuple[str, ...]

    @property
    def mixed(self) -> bool:
        return self.n_simulated > 0 and self.n_real > 0

    def describe(self) -> str:
        kinds = [f"{n} {label}" for n, label in ((self.n_simulated, "simulated"), (self.n_real, "real")) if n]
        extra = f", {self.n_incomplete} incomplete" if self.n_incomplete else ""
        return f"{self.study}: {self.n_simulated + self.n_real} sessions ({', '.join(kinds)}{extra})"


def inventory(data_root: Path, *, verify: bool = True) -> dict[str, StudySessions]:
    """Every session under ``data_root/<study>/sub-*/ses-*/session.json``, grouped by study.

    With ``verify`` (the default) each session's finalised files must match the SHA-256 its
    session.json recorded (:func:`psyop.finalised.verify_session`): a damaged or edited session is
    a :class:`UserError` naming it."""
    studies: dict[str, StudySessions] = {}
    for study_dir in sorted(p for p in Path(data_root).iterdir() if p.is_dir()) if Path(data_root).is_dir() else []:
        simulated = real = incomplete = 0
        participants = []
        for meta_path in sorted(study_dir.glob("sub-*/ses-*/session.json")):
            try:
                meta = json.loads(meta_path.read_text())
            except (OSError, ValueError) as exc:
                raise UserError(f"unreadable session metadata ({exc}); run `psyop recover {data_root}`", str(meta_path)) from exc
            if verify:
                verify_session(meta_path.parent)
            if meta.get("simulated") is True:
                simulated += 1
            else:
                real += 1
            if meta.get("status") != "complete":
                incomplete += 1
            participants.append(meta_path.parent.parent.name.removeprefix("sub-"))
        if simulated or real:
            studies[study_dir.name] = StudySessions(study_dir.name, simulated, real, incomplete, tuple(participants))
    return studies


def check_not_mixed(studies: dict[str, StudySessions], data_root: Path) -> None:
    """UserError when a study pools simulated and real sessions."""
    mixed = [s for s in studies.values() if s.mixed]
    if mixed:
        names = "; ".join(s.describe() for s in mixed)
        raise UserError(f"simulated and real sessions mixed in one study ({names}): its figures would pool them. "
                        f"Move the simulated sessions out of {data_root}/ (they are marked \"simulated\": true in "
                        "session.json), or pool them on purpose with `make figures MIX=1` (psyop sessions --allow-mixed)",
                        str(data_root))
