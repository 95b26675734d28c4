"""``psyop studies DATA``: every study in a data root, its response kind and the analysis that
``make figures`` runs for it; ``--make-rules FILE`` writes those as make rules (figures.mk includes them).

Studies are found in ``DATA/<study>/`` by their sessions, and their analysis chosen by their
response kind (psyop.statistics.studies), never by name:

- two-interval: the psychometric fits (results/<study>_fits.csv), the thresholds figure
  (figures/<study>_thresholds.png: thresholds by condition with an rm-ANOVA; with the linear fit
  of analysis/fig_discrimination_thresholds.py for sessions of the paper's discrimination protocol,
  identified by its hash) and every psychometric function (figures/supp_psychometric_<study>.png);
- adaptive two-interval runs (staircase, QUEST+) also: figures/<study>_tracks.png (analysis/adaptive_tracks.py);
- left/right nearer: figures/<study>_depth.png; reach: figures/<study>_reach.png;
  pairwise preference: figures/<study>_preferences.png; with/against (NC calibration):
  figures/<study>_pss.png.

A study whose sessions ran more than one protocol version (distinct ``protocol_sha256``) is analysed
per version: each is the study ``<study>@<hash12>`` (psyop.statistics.protocol_versions), with its own
outputs (results/<study>@<hash12>_<what>.json, figures/<study>@<hash12>_<what>.png) from its sessions
only, unless ``--pool-protocols`` (``make figures POOL=1``) pools them on purpose.
"""

from __future__ import annotations

import argparse
import hashlib
import os
from pathlib import Path
from typing import TYPE_CHECKING


if TYPE_CHECKING:
    from psyop.protocol.kinds.base import AnalysisTarget as Target
    from psyop.protocol.kinds.base import ResponseKindSpec
    from psyop.statistics.studies import StudyFacts

#: Sessions of this shipped protocol (by hash) get the linear-fit thresholds figure.
LINEAR_FIT_PROTOCOLS = ("discrimination.yaml",)
def kind_name(kind: ResponseKindSpec) -> str:
    """How ``psyop studies`` and make's progress lines name a response kind (its label)."""
    return kind.label


def make_escaped(path: Path) -> str:
    r"""``path`` as one word in a make prerequisite list (spaces, ``#``, ``:`` and ``$`` escaped).

    Examples
    --------
    >>> make_escaped(Path("my data/sub-1/ses-1/trials.parquet"))
    'my\\ data/sub-1/ses-1/trials.parquet'
    """
    text = path.as_posix().replace("$", "$$")
    for character in " #:":
        text = text.replace(character, "\\" + character)
    return text


def targets_for(study: str, kind: ResponseKindSpec, linear_fit: bool, trials: str = "", adaptive: bool = False,
                level_factor: str | None = None) -> list[Target]:
    """The analysis of one study, as its response kind declares it (psyop.protocol.kinds); ``trials`` is its
    sessions' trials.parquet files as make prerequisites (:func:`make_escaped`, so a data root may hold spaces);
    ``adaptive`` (a study whose levels a staircase or QUEST+ placed) adds what the kind draws of it.

    Examples
    --------
    >>> from psyop.protocol.kinds import kind_named
    >>> [t.output for t in targets_for("mine", kind_named("left_right_nearer"), False)]
    ['mine_depth.png']
    """
    from psyop.protocol.kinds.base import StudyInputs

    return kind.targets(StudyInputs(study, trials, linear_fit, adaptive, level_factor))


def analysis_units(data: Path, pool_protocols: bool) -> list[tuple[StudyFacts, list[Path]]]:
    """Each study of ``data`` with its sessions, or, for a study whose sessions ran several protocol
    versions and ``pool_protocols`` is off, each version apart (``<study>@<hash12>``,
    psyop.statistics.protocol_versions). A session without a recorded hash in such a study could
    belong to either version: a UserError naming it (pool on purpose, or give it its session.json)."""
    from psyop.errors import UserError
    from psyop.statistics.dataset import session_files
    from psyop.statistics.protocol_versions import session_hash, unit_name
    from psyop.statistics.studies import study_facts, studies_in

    units = []
    for facts in studies_in(data):
        if len(facts.protocol_sha256) < 2 or pool_protocols:
            units.append((facts, session_files(data, facts.name)))
            continue
        unknown = [f for f in session_files(data, facts.name) if session_hash(f) is None]
        if unknown:
            raise UserError(f"study {facts.name!r} ran {len(facts.protocol_sha256)} protocol versions and this session "
                            "records none (no session.json or no protocol_sha256), so it cannot be analysed with its "
                            "version; pool the versions on purpose (`make figures POOL=1`)", str(unknown[0]))
        for sha in facts.protocol_sha256:
            name = unit_name(facts.name, sha)
            units.append((study_facts(data, name), session_files(data, name)))
    return units


def make_rules(data: Path, protocols: Path, pool_protocols: bool = False) -> tuple[str, list[str]]:
    """(the make fragment, one line per study, or per protocol version of one, saying what it builds)."""
    from psyop.protocol.kinds.base import AnalysisTarget

    linear = set()
    for name in LINEAR_FIT_PROTOCOLS:
        path = protocols / name
        if path.is_file():
            linear.add(hashlib.sha256(path.read_bytes().decode("utf-8").encode("utf-8")).hexdigest())
    rules = ["# written by `psyop studies --make-rules`: one block per study (per protocol version unless pooled)", ""]
    said = []
    for facts, sessions in analysis_units(data, pool_protocols):
        uses_linear = bool(facts.protocol_sha256) and set(facts.protocol_sha256) <= linear
        prerequisites = " ".join(make_escaped(p) for p in sessions)
        adaptive = _adaptive(sessions)
        targets = targets_for(facts.name, facts.kind, uses_linear, prerequisites, adaptive,
                              facts.level_factor) + [AnalysisTarget(  # the study's gaze quality
            f"{facts.name}_gaze_quality.png", "analysis/gaze_quality.py", f"{prerequisites} $(QUALITY_SRC)",
            f'--study {facts.name} --data "$(DATA)" --results "$(RESULTS)"')]
        figures = [t for t in targets if t.kind == "figure"]
        rules.append("STUDY_FIGURES += " + " ".join(f"$(FIGDIR)/{t.output}" for t in figures))
        for t in targets:
            where = "$(RESULTS)" if t.kind == "fits" else "$(FIGDIR)"
            label = f"fitting psychometric functions: {facts.name}" if t.kind == "fits" else \
                f"{facts.name} ({kind_name(facts.kind)}): $@"
            rules += [f"{where}/{t.output}: {t.script} {t.prerequisites}", f'\t@mkdir -p "{where}"',
                      f"\t@echo \"[psyop] {label}\"", f'\t@"$(ANALYSE)" "$<" {t.arguments} --out "$@"', ""]
        said.append(f"{facts.name} ({kind_name(facts.kind)}{_versions_note(facts, len(sessions))}): "
                    + ", ".join(t.output for t in figures))
    return "\n".join(rules) + "\n", said


def _adaptive(sessions: list[Path]) -> bool:
    """Whether any session logged an adaptive procedure's columns (``adaptive_procedure``: staircase, QUEST+)."""
    import pyarrow.parquet as pq

    for path in sessions:
        try:
            if "adaptive_procedure" in pq.read_schema(path).names:
                return True
        except Exception:  # noqa: BLE001 - an unreadable log is refused by name when its analysis loads it
            continue
    return False


def _versions_note(facts: StudyFacts, n_sessions: int) -> str:
    """'; protocol version 1 of 2, 3 sessions, analysed apart' / '; 2 protocol versions pooled on purpose' / ''."""
    versions = facts.folder_protocol_sha256
    if len(facts.protocol_sha256) > 1:
        return f"; {len(facts.protocol_sha256)} protocol versions pooled on purpose (POOL=1)"
    if len(versions) > 1 and facts.protocol_sha256:
        place = versions.index(facts.protocol_sha256[0]) + 1
        return f"; protocol version {place} of {len(versions)}, {n_sessions} sessions, analysed apart (POOL=1 pools them)"
    return ""


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "studies", help="list the studies of a data root with their response kind and analysis",
        description="Every study in DATA (by its sessions), its response kind and the figures `make figures` "
        "builds for it. --make-rules FILE writes the make rules (figures.mk includes them).")
    parser.add_argument("data", type=Path, nargs="?", default=Path("data"), help="data root (default data/)")
    parser.add_argument("--make-rules", type=Path, default=None, help="write the make rules to this file "
                        "(rewritten only when they change)")
    parser.add_argument("--protocols", type=Path, default=Path("protocols"), help="the paper's protocols")
    parser.add_argument("--pool-protocols", action="store_true", default=os.environ.get("PSYOP_POOL_PROTOCOLS") == "1",
                        help="one analysis per study even when its sessions ran different protocol versions (default: "
                        "one per version, <study>@<hash12>; `make figures POOL=1` sets PSYOP_POOL_PROTOCOLS=1)")
    parser.set_defaults(func=main)


def main(args: argparse.Namespace) -> int:
    text, said = make_rules(args.data, args.protocols, args.pool_protocols)
    for line in said:
        print(f"[psyop] study {line}")
    if not said:
        print(f"[psyop] {args.data}/: no studies")
    if args.make_rules is not None:
        args.make_rules.parent.mkdir(parents=True, exist_ok=True)
        if not args.make_rules.exists() or args.make_rules.read_text() != text:
            args.make_rules.write_text(text)
    return 0
