"""session.json ``study_design``: what the analysis reads of the protocol a session ran, typed.

The runner writes it (:func:`design_of` of the validated protocol, dumped by :class:`RecordedDesign`) and the
readers take it back through the same model (psyop.session.log.record.SessionRecord ``study_design``), so
writer and reader cannot drift: each design factor (name, levels, numbers or words, description, unit), the
response's column fields (the ``*_factor`` fields that name a schedule column), ``study.reported`` and a rating's
scale. A session recorded before psyop wrote it has none (None); its readers fall back to the recorded protocol
text (psyop.session.log.record.design_of_record).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictFloat, StrictInt, StrictStr

if TYPE_CHECKING:
    from psyop.protocol.model import Protocol

__all__ = ["FACTOR_UNIT_SUFFIXES", "RecordedDesign", "RecordedFactor", "RecordedReported", "RecordedScale",
           "design_of", "unit_of"]

#: Units by factor-name suffix (docs/protocols.md: a numeric factor says its unit in its name).
FACTOR_UNIT_SUFFIXES: tuple[tuple[str, str], ...] = (
    ("_deg", "deg"), ("_arcmin", "arcmin"), ("_mm", "mm"), ("_m", "m"), ("_D", "D"), ("_ms", "ms"), ("_s", "s"),
    ("_hz", "Hz"), ("_px", "px"), ("_fraction", "fraction"), ("_log10", "log10"))

#: a level as recorded: a number or a word (JSON keeps an integral level as an integer)
LevelValue = StrictInt | StrictFloat | StrictStr


def unit_of(name: str) -> str | None:
    """The unit a factor's name ends in, or None.

    Examples
    --------
    >>> unit_of("back_D"), unit_of("contrast"), unit_of("eccentricity_deg")
    ('D', None, 'deg')
    """
    for suffix, unit in FACTOR_UNIT_SUFFIXES:
        if name.endswith(suffix) and len(name) > len(suffix):
            return unit
    return None


class RecordedFactor(BaseModel):
    """One design factor: its column name, every level it can take (none for an adaptive one), whether the levels
    are numbers (else words), its description and the unit its name ends in."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    name: StrictStr
    #: None: not known (an older session's protocol text whose levels no longer validate)
    levels: tuple[LevelValue, ...] | None
    numeric: StrictBool | None
    description: StrictStr | None = None
    unit: StrictStr | None = None


class RecordedReported(BaseModel):
    """One ``study.reported`` threshold: its condition (factor -> level), the threshold (in the level factor's unit)
    and its source."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    condition: dict[str, LevelValue] = Field(min_length=1)
    threshold: StrictInt | StrictFloat
    source: StrictStr | None = None


class RecordedScale(BaseModel):
    """A rating's scale: its points and, if the protocol gives them, one label per point (lowest first)."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    points: StrictInt
    labels: tuple[StrictStr, ...] | None = None


class RecordedDesign(BaseModel):
    """session.json ``study_design``: the factors in the protocol's order, the response's column fields
    (``separation_factor``, ``rendering_factor``, ... -> the column), ``study.reported`` and a rating's scale."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    factors: tuple[RecordedFactor, ...] = ()
    column_fields: dict[str, StrictStr] = Field(default_factory=dict)
    reported: tuple[RecordedReported, ...] = ()
    scale: RecordedScale | None = None


def design_of(protocol: Protocol) -> RecordedDesign:
    """The :class:`RecordedDesign` of a validated protocol (what the runner writes to session.json)."""
    from psyop.protocol.kinds.rating import RatingResponse

    factors = tuple(RecordedFactor(name=name, levels=tuple(factor.all_levels()),
                                   numeric=not any(isinstance(v, str) for v in factor.all_levels()),
                                   description=factor.description, unit=unit_of(name))
                    for name, factor in protocol.design.factors.items())
    response = protocol.response.model_dump(mode="json")
    columns = {k: v for k, v in response.items() if k.endswith("_factor") and isinstance(v, str)}
    reported = tuple(RecordedReported(condition=dict(r.condition), threshold=r.threshold, source=r.source)
                     for r in protocol.study.reported)
    scale = RecordedScale(points=int(protocol.response.scale.points), labels=None if protocol.response.scale.labels
                          is None else tuple(protocol.response.scale.labels)) \
        if isinstance(protocol.response, RatingResponse) else None
    return RecordedDesign(factors=factors, column_fields=columns, reported=reported, scale=scale)
