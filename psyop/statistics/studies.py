"""What the analysis needs to know of a study in ``data/``: its response kind, the protocol(s) its
sessions ran (by hash), and the factors' names, descriptions and units (for columns and axis labels).

Read from each session's ``session.json`` (``response_kind``, ``protocol_sha256`` and the
``protocol_text`` it ran, written by psyop.run.runner). The protocol text is read as plain
YAML, not re-validated: an old session stays analysable when validation grows stricter. A study
written without session.json (psyop.statistics.dataset.write_dataset without hashes) has its kind
read from its trial columns and no protocol hash.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import pyarrow.parquet as pq
import yaml

from psyop import datacontract as dc
from psyop.errors import UserError
from psyop.protocol.kinds import KINDS, kind_named
from psyop.protocol.kinds.base import ResponseKindSpec
from psyop.statistics.protocol_versions import session_hash, split_unit, unit_trials_files

#: Units by factor-name suffix (docs/protocols.md: a numeric factor says its unit in its name).
UNIT_SUFFIXES: tuple[tuple[str, str], ...] = (("_deg", "deg"), ("_arcmin", "arcmin"), ("_mm", "mm"), ("_m", "m"),
                                              ("_D", "D"), ("_ms", "ms"), ("_s", "s"), ("_hz", "Hz"), ("_px", "px"),
                                              ("_fraction", "fraction"))

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


def unit_of(name: str) -> str | None:
    """The unit a factor's name ends in, or None.

    Examples
    --------
    >>> unit_of("back_D"), unit_of("contrast"), unit_of("eccentricity_deg")
    ('D', None, 'deg')
    """
    for suffix, unit in UNIT_SUFFIXES:
        if name.endswith(suffix) and len(name) > len(suffix):
            return unit
    return None


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


def _protocol_factors(text: str) -> tuple[dict[str, FactorFacts], str | None, dict[str, str]]:
    try:
        document = yaml.safe_load(text) or {}
    except (yaml.YAMLError, ValueError, TypeError, AttributeError, KeyError):  # a bad explicit tag fails outside YAMLError
        return {}, None, {}
    design = document.get("design") if isinstance(document, dict) else None
    factors_in = design.get("factors") if isinstance(design, dict) else None
    factors = {}
    for name, spec in (factors_in or {}).items():
        description = spec.get("description") if isinstance(spec, dict) else None
        factors[str(name)] = FactorFacts(str(name), description if isinstance(description, str) else None,
                                         unit_of(str(name)))
    response = document.get("response") if isinstance(document, dict) else None
    level = response.get("level_factor", "level_D") if isinstance(response, dict) and \
        response.get("kind") == "two_interval" else None
    fields = {str(k): v for k, v in response.items() if isinstance(v, str)} if isinstance(response, dict) else {}
    return factors, level, fields


def _reported(text: str | None) -> tuple[dict[str, object], ...]:
    """The protocol text's ``study.reported`` entries (validated when the session ran), as plain mappings."""
    try:
        document = yaml.safe_load(text or "") or {}
    except (yaml.YAMLError, ValueError, TypeError, AttributeError, KeyError):
        return ()
    study = document.get("study") if isinstance(document, dict) else None
    entries = study.get("reported") if isinstance(study, dict) else None
    return tuple(dict(e) for e in entries if isinstance(e, dict) and isinstance(e.get("condition"), dict)) \
        if isinstance(entries, list) else ()


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
    kind: ResponseKindSpec | None = None
    text: str | None = None
    recorded_level: str | None = None
    for trials in files:
        meta_path = trials.parent / dc.SESSION_METADATA_FILE
        if not meta_path.exists():
            continue
        try:
            meta = json.loads(meta_path.read_text())
        except (OSError, ValueError) as exc:
            raise UserError(f"unreadable session metadata ({exc})", str(meta_path)) from exc
        sha = meta.get("protocol_sha256")
        if isinstance(sha, str) and sha and sha not in hashes:
            hashes.append(sha)
        kind = kind or _recorded_kind(meta.get("response_kind"), meta_path)
        text = text or meta.get("protocol_text")
        response = meta.get("response")
        if isinstance(response, dict) and isinstance(response.get("level_factor"), str):
            recorded_level = recorded_level or response["level_factor"]
    kind = kind or _kind_from_columns(files[0])
    factors, level, fields = _protocol_factors(text) if text else ({}, None, {})
    level = recorded_level or level  # the session plan's record (every kind with a level), else the protocol's
    if kind.name == "two_interval" and level is None:
        level = "level_D"
    folder = split_unit(study)[0]
    everything = tuple(sorted(hashes)) if folder == study else \
        tuple(sorted({h for f in dc.trials_files(data_root, folder) if (h := session_hash(f))}))
    return StudyFacts(study, kind, tuple(sorted(hashes)), factors, level, fields, _reported(text), everything)


def studies_in(data_root: Path) -> list[StudyFacts]:
    """Every study folder of ``data_root`` that holds at least one trial log, by name."""
    root = Path(data_root)
    if not root.is_dir():
        return []
    return [study_facts(root, p.name) for p in sorted(root.iterdir())
            if p.is_dir() and dc.STUDY_PATTERN.fullmatch(p.name) and dc.trials_files(root, p.name)]
