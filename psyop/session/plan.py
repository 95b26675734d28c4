"""The session plan: a validated Protocol (plus the session's choices) compiled into one frozen,
typed value that the session runs.

Everything the session takes from a protocol is decided here, once: the phases (what each
shows, in which rendering mode, for how long, what gaze does), the response kind and its
parameters (timeout, prompt, question, whether the display is off), the simulated observer,
the display profile, and the eye rig (eye model + ipd + which eyes). The loop, the renderers and
the response sources see only this plan, never the protocol model (the stimulus builder gets
the protocol's scene through ``plan.protocol``).

:func:`compile_plan` reads every field of the protocol that the session needs; the fields it
does not read belong to other compilers (the schedule compiler's design and response columns,
the stimulus builder's scene) -- ``PLAN_FIELDS`` lists which, and a test walks the protocol
schema to check that every field is claimed by one of them or refused at validation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from collections.abc import Mapping
from typing import Any

from psyop.adaptive.session import AdaptivePlan, adaptive_plan
from psyop.datacontract import TIMEOUT_RESPONSE
from psyop.errors import UserError
from psyop.optics.display import DisplayProfile
from psyop.optics.ranges import DEFAULT_IPD_M, IPD_M
from psyop.optics.rig import EyeRig
from psyop.protocol.factor_fields import factor_fields, resolve_factor_fields
from psyop.protocol.model import Protocol
from psyop.protocol.observer import Observer
from psyop.protocol.kinds import kind_of
from psyop.protocol.kinds.adjustment import AdjustmentResponse, AdjustmentSpec
from psyop.protocol.kinds.base import INPUT_SOURCES, Inputs, KindResponse, ResponseKindSpec
from psyop.protocol.kinds.left_right_nearer import LeftRightNearerResponse
from psyop.protocol.kinds.reach import ReachResponse
from psyop.protocol.scene import FactorRef, FixationTarget
from psyop.protocol.trial import Blank, DriftRecalibration, Interval, ResponsePhase
from psyop.schedule.rows import mode_column
from psyop.session.latency import GazeLatency
from psyop.session.phases import PhaseSpec, mode_for
from psyop.stimulus.placement import centre_angles_deg

#: ipd used when the protocol says ``ipd: tracker`` and the tracker reports none (recorded as such).

__all__ = ["DEFAULT_IPD_M", "TIMEOUT_RESPONSE", "FixationPath", "ResponsePlan", "SessionPlan",
           "compile_phases", "compile_plan", "fixation_path", "fixation_path_of", "FixationPoint", "fixation_point",
           "fixation_point_of",
           "session_response_kind"]


def session_response_kind(response: KindResponse) -> ResponseKindSpec:
    """The kind (psyop.protocol.kinds) of the protocol's response: what the response sources and the log read."""
    return kind_of(response)


@dataclass(frozen=True)
class FixationPath:
    """The circling fixation target of the threshold studies (drives pursuit gaze).

    When the target's centre, ``path.eccentricity_deg`` or ``path.speed_deg_s`` is ``{factor: NAME}``,
    ``target`` holds the protocol's fixation target and the numbers here are NaN: :meth:`for_values`
    gives the path of one trial (interval), resolved by the rule the stimulus builder draws it with
    (psyop.protocol.factor_fields)."""

    eccentricity_deg: float = 16.0
    speed_deg_s: float = 90.0
    distance_m: float = 1.0
    #: Fick (azimuth, elevation) the target circles around (docs/optics.md, "Angles")
    centre_deg: tuple[float, float] = (0.0, 0.0)
    #: the scene item's id: the schedule's ``<id>_start_deg`` / ``<id>_direction`` columns
    id: str = "fixation"
    #: the protocol's fixation target when a field of its centre or path is a factor's level, else None
    target: FixationTarget | None = None

    def for_values(self, values: Mapping[str, Any]) -> "FixationPath":  # Any: a trial row's factor values
        """This path with the trial's (interval's) factor levels filled in (itself when it has no factor).

        Examples
        --------
        >>> from psyop.protocol.scene import FixationTarget
        >>> item = FixationTarget(id="fixation", kind="fixation_target", size_deg=0.5, depth={"D": 1},
        ...                       path={"kind": "circle", "eccentricity_deg": {"factor": "radius_deg"},
        ...                             "speed_deg_s": {"factor": "speed_deg_s"}})
        >>> path = fixation_path_of(item)
        >>> p = path.for_values({"radius_deg": 8.0, "speed_deg_s": 45.0})
        >>> p.eccentricity_deg, p.speed_deg_s, p.target is None
        (8.0, 45.0, True)
        """
        if self.target is None:
            return self
        try:
            item = resolve_factor_fields(self.target, values)
        except ValueError as error:
            raise UserError(f"fixation target '{self.id}': {error}") from None
        assert item.path is not None
        return FixationPath(float(item.path.eccentricity_deg), float(item.path.speed_deg_s), self.distance_m,
                            centre_angles_deg(item.centre_deg), self.id)

    def as_dict(self) -> dict[str, Any]:  # Any: session.json values
        """What session.json records: the numbers, or ``{factor: NAME}`` for each field a factor sets."""
        out: dict[str, Any] = {"eccentricity_deg": self.eccentricity_deg, "speed_deg_s": self.speed_deg_s,  # Any: JSON
                               "distance_m": self.distance_m, "centre_deg": list(self.centre_deg), "id": self.id}
        if self.target is not None:
            out["centre_deg"] = self.target.model_dump(mode="json")["centre_deg"]
            out.update({key: self.target.path.model_dump(mode="json")[key]  # type: ignore[union-attr]  # target set: path set
                        for key in ("eccentricity_deg", "speed_deg_s")})
        return out


@dataclass(frozen=True)
class FixationPoint:
    """A static fixation target (a ``fixation_target`` without ``path``): the observer fixates it in every
    phase that shows the scene (gaze ``'fixate'``), as it pursues a moving one.

    ``centre_deg`` is its Fick (azimuth, elevation); when its centre is ``{factor: NAME}``, ``target``
    holds the protocol's item and :meth:`centre_for` resolves each trial's (interval's) centre by the rule
    the stimulus builder draws it with."""

    centre_deg: tuple[float, float]
    id: str
    target: FixationTarget | None = None

    def centre_for(self, values: Mapping[str, Any]) -> tuple[float, float]:  # Any: a trial row's factor values
        """The target's centre in a trial (interval) whose factor levels are ``values``.

        Examples
        --------
        >>> from psyop.protocol.scene import FixationTarget
        >>> item = FixationTarget(id="dot", kind="fixation_target", size_deg=0.5, depth={"D": 1},
        ...                       centre_deg=[{"factor": "x_deg"}, 0])
        >>> fixation_point_of(item).centre_for({"x_deg": 5.0})
        (5.0, 0.0)
        """
        if self.target is None:
            return self.centre_deg
        try:
            item = resolve_factor_fields(self.target, values)
        except ValueError as error:
            raise UserError(f"fixation target '{self.id}': {error}") from None
        return centre_angles_deg(item.centre_deg)

    def as_dict(self) -> dict[str, Any]:  # Any: session.json values
        """What session.json records: the centre, or ``{factor: NAME}`` where a factor sets it."""
        centre: Any = list(self.centre_deg) if self.target is None else \
            self.target.model_dump(mode="json")["centre_deg"]  # Any: numbers or {factor: NAME}
        return {"centre_deg": centre, "id": self.id}


@dataclass(frozen=True)
class ResponsePlan:
    """What the participant answers and how the response phase runs.

    ``timeout_s`` None: wait for the answer; else a trial without an answer by then is logged
    with response :data:`TIMEOUT_RESPONSE` and ``correct`` null. ``question``: what the study
    asks (printed at the session start); ``prompt``: the response phase's own line (printed on the
    experimenter's console at each response phase of a live session). The participant reads the
    prompt, else the question, in the headset during the response phase (:attr:`participant_text`).
    Both are recorded in session.json. ``phase``: what the display shows while
    waiting (blank, off for blind reaching, or interval 1's stimulus for an adjustment, whose
    ``adjustment`` says what is adjusted: psyop.protocol.kinds.adjustment)."""

    kind: ResponseKindSpec
    question: str
    #: the raw inputs that answer this protocol's response (the kind's maps for its section)
    inputs: Inputs
    prompt: str | None = None
    timeout_s: float | None = None
    display_off: bool = False
    average_last_samples: int = 10
    level_factor: str | None = None  # the factor a psychometric function is fitted over (two_interval, yes_no)
    phase: PhaseSpec = field(default_factory=lambda: PhaseSpec("response", 0.0, "blank", "none"))
    adjustment: AdjustmentSpec | None = None
    #: the kind's lines under the prompt (ResponseKindSpec.response_text: a rating's scale); None: the prompt alone
    response_text: str | None = None
    #: the lines a default prompt adds under the question: which inputs of the session's response source give each
    #: answer (ResponseKindSpec.answer_keys_text); None: no source that names inputs (simulated, nobody, unknown)
    answer_keys: str | None = None

    @property
    def _default_prompt(self) -> bool:
        return not (self.prompt is not None and self.prompt.strip())

    @property
    def keeps_lines(self) -> bool:
        """Whether :attr:`participant_text` is drawn with its line breaks kept (each line wrapped on its own):
        when the kind or the source's keys add lines; a prompt alone is wrapped as one paragraph, as ever."""
        return self.response_text is not None or (self._default_prompt and self.answer_keys is not None)

    @property
    def participant_text(self) -> str | None:
        """What the participant reads in the headset during the response phase: the ``prompt``, else the
        ``question`` followed by :attr:`answer_keys` (the default prompt names the keys); then the kind's
        :attr:`response_text`, each part after an empty line; None when the display is off (docs/protocols.md,
        "Trial phases")."""
        if self.display_off or self.phase.show in ("off", "stimulus"):  # an adjustment shows what it adjusts
            return None
        head = self.question if self._default_prompt else self.prompt
        keys = self.answer_keys if self._default_prompt else None
        parts = [text.strip() for text in (head, keys, self.response_text) if text is not None and text.strip()]
        return "\n\n".join(parts) if parts else None

    def as_dict(self) -> dict[str, Any]:  # Any: session.json values
        return {"kind": self.kind.name, "question": self.question,
                "prompt": self.prompt, "timeout_s": self.timeout_s, "display_off": self.display_off,
                "average_last_samples": self.average_last_samples, "level_factor": self.level_factor} | \
            ({} if self.adjustment is None else {"adjustment": self.adjustment.as_dict()}) | \
            ({} if self.response_text is None else {"response_text": self.response_text}) | \
            ({} if self.answer_keys is None else {"answer_keys": self.answer_keys})


@dataclass(frozen=True)
class SessionPlan:
    """Everything a session runs, typed and frozen (see the module docstring)."""

    study: str
    protocol: Protocol
    phases: tuple[PhaseSpec, ...]
    response: ResponsePlan
    observer: Observer | None
    display: DisplayProfile
    rig: EyeRig
    fixation: FixationPath | None
    adaptive: AdaptivePlan | None = None  # the adaptive level factor's procedure (psyop.adaptive.session)
    #: the static fixation target the observer fixates (None: a moving one, or none: free viewing)
    fixation_point: FixationPoint | None = None
    #: protocol ``trial.min_valid_gaze_share``: a trial below it is logged with ``gaze_ok`` false
    min_valid_gaze_share: float = 0.5
    #: protocol ``display.added_latency_ms`` and ``trial.max_gaze_age_ms`` / ``max_gaze_age_over_share``
    #: (psyop.session.latency): the gaze latency each trial adds and the bound its frames are judged by
    latency: GazeLatency = GazeLatency()

    @property
    def kind(self) -> ResponseKindSpec:
        return self.response.kind

    @property
    def eyes(self) -> tuple[str, ...]:
        return self.rig.eyes

    def mode_for(self, phase: PhaseSpec, row: dict[str, Any]) -> str:  # Any: a trial row's columns
        """The rendering mode of ``phase`` in trial ``row`` (:func:`psyop.session.phases.mode_for`)."""
        return mode_for(phase, row)

    def observer_params(self) -> dict[str, Any] | None:  # Any: the observer's JSON parameters
        """The simulated observer's parameters, with the schedule columns it reads."""
        if self.observer is None:
            return None
        params = self.observer.model_dump()
        if isinstance(self.protocol.response, LeftRightNearerResponse):
            params["separation_column"] = self.protocol.response.separation_factor
        if self.observer.kind == "nc_nulling":  # it answers from the NC the camera renders (the rig's rule)
            params["rendering_nc"] = None if self.rig.rendering_nc is None else self.rig.rendering_nc.as_dict()
            params["eye_model_nc_m"] = self.rig.nc_m
        return params

    def metadata(self) -> dict[str, Any]:  # Any: session.json values
        """The plan as session.json records it."""
        return {
            "response_kind": self.kind.name,
            "response": self.response.as_dict(),
            # ends_after_s is the protocol's min_duration_s (in protocol_text): left out, session.json as before
            "phases": [{k: v for k, v in dict(p.__dict__, primitives=None if p.primitives is None else
                                              list(p.primitives)).items() if k != "ends_after_s"}
                       for p in self.phases],
            "eye_model": {"name": self.rig.eye_model.name, "nc_m": self.rig.nc_m},
            "ipd_m": self.rig.ipd_m,
            "rig": self.rig.as_dict(),
            "display": {k: (v if not isinstance(v, float) or math.isfinite(v) else "inf")
                        for k, v in self.display.__dict__.items()},
            "fixation_path": None if self.fixation is None else self.fixation.as_dict(),
            "adaptive": None if self.adaptive is None else {"factor": self.adaptive.factor,
                                                            "procedure": type(self.adaptive.spec).__name__},
            "min_valid_gaze_share": self.min_valid_gaze_share,
            "gaze_latency": self.latency.as_dict(),
        } | ({} if self.fixation_point is None else {"fixation_point": self.fixation_point.as_dict()})


def _duration_s(phase: Interval | Blank | DriftRecalibration) -> float:
    """A fixed phase's duration; a participant-paced one runs for its minimum, else expected, time
    (a simulated participant ends it then; a live one with an answer input after its minimum: PhaseSpec.ends_after_s,
    psyop.session.loop)."""
    if isinstance(phase, DriftRecalibration):
        return float(phase.expected_s)
    if phase.duration_s is not None:
        return float(phase.duration_s)
    if isinstance(phase, Interval) and phase.min_duration_s:
        return float(phase.min_duration_s)
    return float(phase.expected_s or 0.0)


def fixation_path(protocol: Protocol) -> FixationPath | None:
    """The circling fixation target, if the scene has one."""
    for item in protocol.scene:
        if isinstance(item, FixationTarget) and item.path is not None:
            return fixation_path_of(item)
    return None


def fixation_point(protocol: Protocol) -> FixationPoint | None:
    """The static fixation target (no ``path``), if the scene has one and no moving one."""
    if fixation_path(protocol) is not None:
        return None
    for item in protocol.scene:
        if isinstance(item, FixationTarget):
            return fixation_point_of(item)
    return None


def fixation_point_of(item: FixationTarget) -> FixationPoint:
    """The point of a static fixation target; NaN centre and ``target`` set when its centre is ``{factor: NAME}``."""
    if any(path[0] == "centre_deg" for path, _ in factor_fields(item)):
        return FixationPoint((math.nan, math.nan), item.id, target=item)
    return FixationPoint(centre_angles_deg(item.centre_deg), item.id)


def fixation_path_of(item: FixationTarget) -> FixationPath:
    """The path of a circling fixation target (``item.path`` is set); NaN numbers and ``target`` set when
    a field of its centre or path is ``{factor: NAME}`` (:meth:`FixationPath.for_values`)."""
    assert item.path is not None
    if any(True for _ in factor_fields(item)):
        return FixationPath(math.nan, math.nan, centre_deg=(math.nan, math.nan), id=item.id, target=item)
    # no field is {factor: NAME} (checked above), so both are numbers
    return FixationPath(float(item.path.eccentricity_deg), float(item.path.speed_deg_s),  # type: ignore[arg-type]
                        centre_deg=centre_angles_deg(item.centre_deg), id=item.id)


def compile_phases(protocol: Protocol, gaze: str) -> tuple[tuple[PhaseSpec, ...], ResponsePhase | None]:
    """The timed phases before the (first) response phase, and that response phase."""
    out: list[PhaseSpec] = []
    n_interval = 0
    for phase in protocol.trial.phases:
        if isinstance(phase, DriftRecalibration):
            out.append(PhaseSpec(f"recalibration{'' if not out else len(out)}", _duration_s(phase), "cross", "cross",
                                 target_size_deg=float(phase.target_size_deg)))
        elif isinstance(phase, Interval):
            n_interval += 1
            primitives = None if phase.show == "all" else tuple(phase.show)
            out.append(PhaseSpec(f"interval{n_interval}", _duration_s(phase), "stimulus", gaze,
                                 mode_column=mode_column(n_interval), primitives=primitives, interval=n_interval,
                                 ends_after_s=None if phase.min_duration_s is None else float(phase.min_duration_s)))
        elif isinstance(phase, Blank):
            if phase.display_off:
                out.append(PhaseSpec("display_off", _duration_s(phase), "off", "none", mode=phase.mode))
            else:
                out.append(PhaseSpec("blank", _duration_s(phase), "blank", gaze, mode=phase.mode,
                                     primitives=tuple(phase.show), interval=max(1, n_interval)))
        elif isinstance(phase, ResponsePhase):
            return tuple(out), phase
    return tuple(out), None


def _response_phase(protocol: Protocol, display_off: bool) -> PhaseSpec:
    """What the response phase shows: nothing (display off), a blank with the prompt, or, for an adjustment,
    interval 1's stimulus (its mode and ``show:``), which the session draws with the adjusted value."""
    if isinstance(protocol.response, AdjustmentResponse) and not display_off:
        show = protocol.trial.intervals[0].show if protocol.trial.intervals else "all"
        return PhaseSpec("response", 0.0, "stimulus", "none", mode_column=mode_column(1),
                         primitives=None if show == "all" else tuple(show), interval=1)
    return PhaseSpec("response", 0.0, "off" if display_off else "blank", "none")


def compile_plan(protocol: Protocol, *, tracker_ipd_m: float | None = None, responses: str | None = None) -> SessionPlan:
    """The plan of a session of ``protocol``. ``tracker_ipd_m``: the ipd the tracker measured
    (used when the protocol says ``ipd: tracker``; None: :data:`DEFAULT_IPD_M`, recorded as
    the default). ``responses``: the session's response source as ``psyop run --responses`` names it
    (``keyboard``, ``serial:DEVICE``, ``openxr``, ...): a default prompt names that source's inputs
    (:func:`answer_keys`); None (the default): no source known, the default prompt is the question alone."""
    from psyop.protocol.display import FixedIpd, rendering_nc_rule, resolve_display_profile, resolve_eye_model

    spec = protocol.display
    if isinstance(spec.ipd, FixedIpd):
        ipd_m, source = spec.ipd.mm / 1000.0, "protocol"
    elif tracker_ipd_m is not None:
        if not IPD_M.contains(tracker_ipd_m):
            raise UserError(f"the tracker reports an ipd of {tracker_ipd_m!r} m, outside {IPD_M.describe()}; recalibrate "
                            "the headset's ipd or fix it in the protocol (display.ipd: {mm: ...})", "--tracker")
        ipd_m, source = float(tracker_ipd_m), "tracker"
    else:
        ipd_m, source = DEFAULT_IPD_M, "default (ipd: tracker, none reported)"
    rig = EyeRig.for_protocol_eyes(protocol.eyes, resolve_eye_model(spec), ipd_m, source, rendering_nc_rule(spec))
    path, point = fixation_path(protocol), fixation_point(protocol)
    phases, response_phase = compile_phases(protocol, "pursuit" if path is not None else
                                            "fixate" if point is not None else "free")
    r = protocol.response
    display_off = bool(response_phase.display_off) if response_phase is not None else False
    response = ResponsePlan(
        kind=kind_of(r),
        inputs=kind_of(r).inputs(r),
        question=r.question,
        prompt=response_phase.prompt if response_phase is not None else None,
        timeout_s=float(response_phase.timeout_s) if response_phase is not None and response_phase.timeout_s else None,
        display_off=display_off,
        average_last_samples=int(r.average_last_samples) if isinstance(r, ReachResponse) else 10,
        level_factor=r.level(),
        response_text=kind_of(r).response_text(r),
        answer_keys=answer_keys(r, responses),
        phase=_response_phase(protocol, display_off),
        adjustment=AdjustmentSpec.of(r) if isinstance(r, AdjustmentResponse) else None,
    )
    return SessionPlan(study=protocol.study.name, protocol=protocol, phases=phases, response=response,
                       observer=protocol.observer, display=resolve_display_profile(spec), rig=rig, fixation=path, fixation_point=point,
                       adaptive=adaptive_plan(protocol),
                       min_valid_gaze_share=float(protocol.trial.min_valid_gaze_share),
                       latency=gaze_latency(protocol))


def answer_keys(response: KindResponse, responses: str | None) -> str | None:
    """The lines a default prompt adds for the response source ``responses`` (``psyop run --responses``; its name
    before any ``:``): the kind's inputs of a keyboard, a serial response box or OpenXR controllers; None for any
    other source (simulated, nobody) and for None."""
    source = None if responses is None else responses.partition(":")[0]
    for known in INPUT_SOURCES:
        if source == known:
            return kind_of(response).answer_keys_text(response, known)
    return None


def gaze_latency(protocol: Protocol) -> GazeLatency:
    """The protocol's gaze-latency rules: ``display.added_latency_ms`` (ms, or ``{factor: NAME}``) and
    ``trial.max_gaze_age_ms`` with ``trial.max_gaze_age_over_share`` (psyop.session.latency)."""
    added = protocol.display.added_latency_ms
    bound = protocol.trial.max_gaze_age_ms
    return GazeLatency(added_ms=float(added) if isinstance(added, (int, float)) else 0.0,
                       added_factor=added.factor if isinstance(added, FactorRef) else None,
                       max_age_s=None if bound is None else float(bound) / 1000.0,
                       max_over_share=float(protocol.trial.max_gaze_age_over_share))
