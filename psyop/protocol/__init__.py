"""YAML study protocols -> validated pydantic models, with errors at file:line:column.

Public API: :func:`load_protocol`, :func:`parse_protocol`, :class:`Protocol` and the section
models. ``docs/protocols.md`` explains how to write a protocol.
"""

from psyop.protocol.conditions import condition_label, expand_conditions
from psyop.protocol.design import AdaptiveLevel, Design, Factor, Randomisation, SteppedLevels
from psyop.protocol.display import DisplaySpec, resolve_display_profile, resolve_eye_model
from psyop.protocol.loader import load_protocol, parse_protocol
from psyop.protocol.model import Protocol, StudyInfo
from psyop.protocol.observer import Observer, OrdinalAccuracy, PairwisePreference, Psychometric2afc, Reach
from psyop.protocol.response import (IntervalSpec, LeftRightNearerResponse, ModeFromFactor, PairwisePreferenceResponse,
                                     ReachResponse, Response, TwoIntervalResponse)
from psyop.protocol.scene import (RENDERING_MODES, Aperture, CirclePath, Depth, Disc, FactorRef, FixationTarget,
                                  GridPlanes, ImageSurface, PinkNoiseSurface, Primitive, Quad, ReachTarget, Room,
                                  SinusoidalBorder, SolidSurface, TargetField, WhiteNoiseSurface)
from psyop.protocol.trial import Blank, DriftRecalibration, Interval, ResponsePhase, TrialSpec

__all__ = [
    "RENDERING_MODES", "AdaptiveLevel", "Aperture", "Blank", "CirclePath", "Depth", "Design", "Disc", "DisplaySpec",
    "DriftRecalibration", "Factor", "FactorRef", "FixationTarget", "GridPlanes", "ImageSurface", "Interval",
    "IntervalSpec", "LeftRightNearerResponse", "ModeFromFactor", "Observer", "OrdinalAccuracy", "PairwisePreference",
    "PairwisePreferenceResponse", "PinkNoiseSurface", "Primitive", "Protocol", "Psychometric2afc", "Quad",
    "Randomisation", "Reach", "ReachResponse", "ReachTarget", "Response", "ResponsePhase", "Room",
    "SinusoidalBorder", "SolidSurface", "SteppedLevels", "StudyInfo", "TargetField", "TrialSpec",
    "TwoIntervalResponse", "WhiteNoiseSurface", "condition_label", "expand_conditions", "load_protocol",
    "parse_protocol", "resolve_display_profile", "resolve_eye_model",
]
