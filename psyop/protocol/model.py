"""The top-level protocol model: one YAML file, one study."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, PrivateAttr

from psyop.protocol.base import Number, StrictModel
from psyop.protocol.design import Design
from psyop.protocol.display import DisplaySpec
from psyop.protocol.observer import Observer
from psyop.protocol.quality import QualitySection
from psyop.protocol.response import Response
from psyop.protocol.scene import Primitive
from psyop.protocol.session_screens import SessionScreens
from psyop.protocol.timing import TimingSection
from psyop.protocol.trial import TrialSpec
from psyop.protocol.validation import GazeValidation


class ReportedThreshold(StrictModel):
    """A threshold the literature reports for one condition of this design (``study: reported:``): the two-interval
    analysis states it beside the threshold it measures there (``condition``: factor -> level; ``threshold`` in the
    level factor's unit)."""

    condition: dict[str, Number | str] = Field(min_length=1)
    threshold: Number
    source: str | None = None


class StudyInfo(StrictModel):
    """Who and what: ``name`` is the study's folder under data/."""

    # a folder name: bounded like every name psyop makes a folder of (psyop.datacontract.STUDY_PATTERN)
    name: str = Field(pattern=r"^[a-z][a-z0-9_]*$", max_length=64,
                      description="lower_snake_case, at most 64 characters; data/<name>/ holds its sessions")
    title: str = Field(min_length=1)
    citation: str | None = None
    description: str | None = None
    reported: list[ReportedThreshold] = Field(default_factory=list)


class Protocol(StrictModel):
    """A complete study: display, scene, trial phases, design, response and (optionally) the
    simulated observer used for headless sessions."""

    psyop_protocol: Literal[1] = Field(description="protocol format version")
    study: StudyInfo
    display: DisplaySpec = Field(default_factory=DisplaySpec)
    eyes: Literal["right", "left", "stereo"] = Field(description="monocular right/left, or both eyes (stereo)")
    scene: list[Primitive] = Field(min_length=1)
    trial: TrialSpec
    design: Design
    response: Response
    observer: Observer | None = None
    quality: QualitySection | None = None  # gaze-based exclusions at analysis time (psyop.protocol.quality)
    timing: TimingSection | None = None  # dropped-frame rule of a trial's intervals (psyop.protocol.timing)
    gaze_validation: GazeValidation | None = None  # multi-point gaze checks in the headset (psyop.protocol.validation)
    #: instructions, breaks, questionnaires, end screen around the trials (psyop.protocol.session_screens)
    session: SessionScreens | None = None

    _source_text: str = PrivateAttr(default="")
    _source_name: str = PrivateAttr(default="")

    @property
    def source_text(self) -> str:
        """The YAML text this protocol was read from (record it with every session)."""
        return self._source_text

    @property
    def source_name(self) -> str:
        return self._source_name

    @property
    def source_sha256(self) -> str:
        import hashlib

        return hashlib.sha256(self._source_text.encode("utf-8")).hexdigest()

    def primitive(self, primitive_id: str):
        """The scene primitive with this id (KeyError if none)."""
        for item in self.scene:
            if item.id == primitive_id:
                return item
        raise KeyError(primitive_id)
