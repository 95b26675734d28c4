"""What the analysis needs to know of a study in ``data/``: its response kind, the protocol(s) its
sessions ran (by hash), and the factors' names, descriptions and units (for columns and axis labels).

Read from each session's ``session.json`` as its typed record (psyop.session.log.record: ``response_kind``,
``protocol_sha256``, the plan's ``response.level_factor``, and ``study_design``: the factors' descriptions and
units, the response's column fields, ``study.reported``). A session recorded before psyop wrote ``study_design``
has it read from the protocol text it ran, once per study, by ``design_of_record`` (the one fallback). A study
written without session.json
(psyop.statistics.dataset.write_dataset without hashes) has its kind read from its trial columns and no
protocol hash.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pyarrow.parquet as pq

from psyop import datacontract as dc
from psyop.errors import UserError
from psyop.protocol.kinds import KINDS, kind_named
from psyop.protocol.kinds.base import ResponseKindSpec
from psyop.session.log.record import SessionRecord, design_of_record, read_record_file
from psyop.session.log.recorded_design import FACTOR_UNIT_SUFFIXES, RecordedDesign, unit_of
from psyop.statistics.protocol_versions import session_hash, split_unit, unit_trials_files

#: Units by factor-name suffix (docs/protocols.md: a numeric factor says its unit in its name).
UNIT_SUFFIXES = FACTOR_UNIT_SUFFIXES

#: Labels of the paper's factors when a study's sessions record no protocol description.
PLAIN_NAMES = {"back_D": "back surface distance", "offset_D": "relative offset", "level_D": "level",
               "separation_D": "separation of the two surfaces", "target_fraction": "target distance"}


@dataclass(frozen=True)
class FactorFacts:
    """A design factor: its column name, description (or None) and unit (or None)."""

    name: str
    description: str | None = None
    unit: str | None = None

    @property
    def text(self) -> str:
        """The description, else a plain name (the paper's factors) or the name without its unit suffix."""
        return self.description or PLAIN_NAMES.get(self.name) or _strip_unit(self.name).replace("_", " ")

    @property
    def label(self) -> str:
        """An axis label: the description (else the name without its unit suffix) and the unit.

        Examples
        --------
        >>> FactorFacts("back_D", None, "D").label
        'back surface distance (D)'
        >>> FactorFacts("contrast").label
        'contrast'
        >>> FactorFacts("size_deg", "target size", "deg").label
        'target size (deg)'
        """
        return f"{self.text} ({self.unit})" if self.unit else self.text


@dataclass(frozen=True)
class StudyFacts:
    """One study of a data root.

    ``kind``: the response kind; ``protocol_sha256``: the distinct protocol hashes of its sessions
    (empty when no session.json records one); ``factors``: the design's factors by name;
    ``level_factor``: the 2AFC level factor (None for other kinds)."""

    name: str
    kind: ResponseKindSpec
    protocol_sha256: tuple[str, ...] = ()
    factors: dict[str, FactorFacts] = field(default_factory=dict)
    level_factor: str | None = None
    response_fields: dict[str, str] = field(default_factory=dict)
    #: the protocol's ``study.reported``: thresholds the literature reports, each {condition, threshold, source}
    reported: tuple[dict[str, object], ...] = ()
    #: the protocol hashes of every session in the study's folder (more than ``protocol_sha256`` when
    #: this is one version of it, ``study@<hash12>``: psyop.statistics.protocol_versions)
    folder_protocol_sha256: tuple[str, ...] = ()
    #: the simulated observers' kinds that answered its sessions (session.json ``observer``), sorted; empty: people
    #: answered, or the sessions did not record it
    observers: tuple[str, ...] = ()

    @property
    def folder(self) -> str:
        """The study folder (``data/<folder>``): the name without its ``@<hash12>``."""
        return split_unit(self.name)[0]

    def response_column(self, key: str, default: str) -> str:
        """The column a response field names (``separation_factor``, ``rendering_factor``, ...), else ``default``."""
        return self.response_fields.get(key, default)

    def factor(self, name: str) -> FactorFacts:
        """The named factor's facts (a bare name with its suffix's unit when the protocol is unknown)."""
        return self.factors.get(name) or FactorFacts(name, None, unit_of(name))

    def condition_columns(self) -> list[str]:
        """The 2AFC study's factors other than its level factor, in the protocol's order."""
        return [n for n in self.factors if n != self.level_factor]


def _strip_unit(name: str) -> str:
    for suffix, _ in UNIT_SUFFIXES:
        if name.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return name


#: Sessions whose session.json records no ``response_kind`` (psyop.statistics.dataset.write_dataset without one,
#: for tests and demos) are told by the columns only the paper's kinds have; every session psyop runs records it.
_KIND_COLUMNS: tuple[tuple[frozenset[str], str], ...] = (
    (frozenset({"correct_interval"}), "two_interval"), (frozenset({"near_side"}), "left_right_nearer"),
    (frozenset({"mode_a", "mode_b"}), "pairwise_preference"), (frozenset({"target_fraction"}), "reach"),
    (frozenset({"rendered_nc_mm"}), "with_against"),
    # tables without the schedule's columns (psyop.statistics.simulate): a 2AFC level, or a mode, and correct
    (frozenset({"correct", "level_D"}), "two_interval"), (frozenset({"correct", "mode"}), "left_right_nearer"))


def _kind_from_columns(path: Path) -> ResponseKindSpec:
    """The kind of a trial log whose session.json records none (:data:`_KIND_COLUMNS`)."""
    try:
        columns = set(pq.read_schema(path).names)
    except Exception as exc:  # any unreadable parquet is bad input here (re-raised as UserError)
        raise UserError(f"unreadable trial log ({exc})", str(path)) from exc
    for needed, name in _KIND_COLUMNS:
        if needed <= columns:
            return kind_named(name)
    raise UserError("its session.json records no response_kind and its columns are none of the paper's kinds; "
                    f"record the kind (response_kind: one of {', '.join(KINDS)}) in its session.json", str(path))


def _recorded_kind(value: object, meta_path: Path) -> ResponseKindSpec | None:
    """session.json's ``response_kind`` (None: not recorded); a UserError naming the file for a kind psyop
    does not know."""
    if value is None:
        return None
    try:
        return kind_named(str(value))
    except KeyError:
        raise UserError(f"response_kind {value!r} is not one psyop analyses ({', '.join(KINDS)})",
                        str(meta_path)) from None


def _design_facts(design: RecordedDesign) -> tuple[dict[str, FactorFacts], dict[str, str],
                                                  tuple[dict[str, object], ...]]:
    """The factors (name, description, unit), the response's column fields and the ``study.reported`` entries (each
    {condition, threshold, source}) of a session's recorded design."""
    factors = {f.name: FactorFacts(f.name, f.description, f.unit) for f in design.factors}
    return factors, dict(design.column_fields), tuple(r.model_dump() for r in design.reported)


def study_facts(data_root: Path, study: str) -> StudyFacts:
    """The :class:`StudyFacts` of ``data_root/<study>``; a UserError naming the folder when it has no sessions.

    Examples
    --------
    >>> import tempfile, pandas as pd
    >>> from psyop.statistics.dataset import write_dataset
    >>> root = Path(tempfile.mkdtemp())
    >>> _ = write_dataset(root, {"s": pd.DataFrame({"participant": ["1"], "session": [1], "pair": ["a|b"],
    ...                                              "mode_a": ["a"], "mode_b": ["b"]})}, simulated=True)
    >>> study_facts(root, "s").kind
    <response kind pairwise_preference>
    """
    files = unit_trials_files(data_root, study)
    if not files:
        raise UserError(f"no sessions found for study {study!r} (expected {study}/sub-<ID>/ses-<N>/trials.parquet)",
                        str(Path(data_root)))
    hashes: list[str] = []
    observers: set[str] = set()
    kind: ResponseKindSpec | None = None
    ran: SessionRecord | None = None  # the first session that recorded its design (or, before that, its protocol text)
    recorded_level: str | None = None
    for trials in files:
        meta_path = trials.parent / dc.SESSION_METADATA_FILE
        record = read_record_file(meta_path)
        if record is None:
            continue
        if record.protocol_sha256 and record.protocol_sha256 not in hashes:
            hashes.append(record.protocol_sha256)
        if record.observer:
            observers.add(record.observer)
        kind = kind or _recorded_kind(record.response_kind, meta_path)
        ran = ran or (record if record.study_design is not None or record.protocol_text else None)
        recorded_level = recorded_level or (record.response.level_factor if record.response else None)
    kind = kind or _kind_from_columns(files[0])
    factors, fields, reported = _design_facts(design_of_record(ran) if ran is not None else RecordedDesign())
    # the session plan's record (every kind with a level), else the two_interval protocol's response.level_factor
    level = recorded_level or (fields.get("level_factor", "level_D") if kind.name == "two_interval" else None)
    folder = split_unit(study)[0]
    everything = tuple(sorted(hashes)) if folder == study else \
        tuple(sorted({h for f in dc.trials_files(data_root, folder) if (h := session_hash(f))}))
    return StudyFacts(study, kind, tuple(sorted(hashes)), factors, level, fields, reported, everything,
                      tuple(sorted(observers)))


def studies_in(data_root: Path) -> list[StudyFacts]:
    """Every study folder of ``data_root`` that holds at least one trial log, by name."""
    root = Path(data_root)
    if not root.is_dir():
        return []
    return [study_facts(root, p.name) for p in sorted(root.iterdir())
            if p.is_dir() and dc.STUDY_PATTERN.fullmatch(p.name) and dc.trials_files(root, p.name)]
