"""Trial structure: an ordered list of timed phases.

A phase with ``duration_s`` lasts exactly that long. A participant-paced phase (drift
recalibration, response, a self-ended view) has no fixed duration; its ``expected_s`` is only
used to estimate the session length (``psyop show``).
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import Field, model_validator

from psyop.protocol.base import Number, StrictModel
from psyop.protocol.scene import RenderingMode


class DriftRecalibration(StrictModel):
    """Single-point re-calibration: the participant fixates a centred cross; the measured gaze
    offset corrects tracker drift for the rest of the trial."""

    kind: Literal["drift_recalibration"]
    target_size_deg: Number = Field(default=1.0, gt=0, le=10)
    expected_s: Number = Field(default=1.0, gt=0, le=600)


class Interval(StrictModel):
    """The stimulus is shown (the n-th interval phase is interval n of the response).

    ``duration_s``: fixed length. Or ``min_duration_s`` + ``expected_s``: the participant ends it
    (e.g. egocentric: at least 5 s, then the participant blanks the display)."""

    kind: Literal["interval"]
    duration_s: Number | None = Field(default=None, gt=0, le=600)
    min_duration_s: Number | None = Field(default=None, ge=0, le=600)
    expected_s: Number | None = Field(default=None, gt=0, le=3600)
    show: Literal["all"] | list[str] = "all"

    @model_validator(mode="after")
    def _timing(self) -> "Interval":
        if self.duration_s is None and self.expected_s is None:
            raise ValueError("give duration_s (fixed) or expected_s (participant-paced, with optional min_duration_s)")
        if self.duration_s is not None and self.min_duration_s is not None:
            raise ValueError("min_duration_s only applies to participant-paced intervals; drop it or duration_s")
        if self.min_duration_s is not None and self.expected_s is not None and self.expected_s < self.min_duration_s:
            raise ValueError("expected_s must be at least min_duration_s")
        return self


class Blank(StrictModel):
    """Between intervals: nothing (``show: []``) or some primitives (e.g. a grid) in ``mode``.
    ``display_off: true`` turns the headset image off (blind reaching)."""

    kind: Literal["blank"]
    duration_s: Number | None = Field(default=None, gt=0, le=600)
    expected_s: Number | None = Field(default=None, gt=0, le=3600)
    show: list[str] = Field(default_factory=list)
    mode: RenderingMode = "conventional"
    display_off: bool = False

    @model_validator(mode="after")
    def _timing(self) -> "Blank":
        if self.duration_s is None and self.expected_s is None:
            raise ValueError("give duration_s (fixed) or expected_s (ends with the response)")
        return self


class ResponsePhase(StrictModel):
    """The participant answers (keyboard, controller, reach); ``timeout_s`` none = wait."""

    kind: Literal["response"]
    expected_s: Number = Field(default=1.5, gt=0, le=3600)
    timeout_s: Number | None = Field(default=None, gt=0, le=3600)
    prompt: str | None = None
    display_off: bool = Field(default=False, description="headset image off while answering (blind reaching)")


Phase = Annotated[Union[DriftRecalibration, Interval, Blank, ResponsePhase], Field(discriminator="kind")]


#: default of ``trial.min_valid_gaze_share``
MIN_VALID_GAZE_SHARE = 0.5
#: default of ``trial.max_gaze_age_over_share``
MAX_GAZE_AGE_OVER_SHARE = 0.05


class TrialSpec(StrictModel):
    """The phases of every trial, in order. ``min_valid_gaze_share``: a trial whose rendered
    frames had a smaller share of valid gaze is marked (trials.parquet ``gaze_ok`` false),
    counted and warned about (docs/protocols.md, "Gaze quality"). ``max_gaze_age_ms``: a trial whose
    intervals had more than ``max_gaze_age_over_share`` of their frames (with valid gaze) rendered from
    gaze older than it (the latency ``display.added_latency_ms`` adds not counted) is marked
    (``gaze_age_ok`` false) and counted alike (docs/latency.md)."""

    phases: list[Phase] = Field(min_length=1)
    min_valid_gaze_share: Number = Field(
        default=MIN_VALID_GAZE_SHARE, ge=0, le=1,
        description="trials with a smaller share of frames with valid gaze are marked gaze_ok: false")
    max_gaze_age_ms: Number | None = Field(
        default=None, gt=0, le=1000,
        description="bound on the gaze-to-photon age of the intervals' frames, ms (the latency the protocol adds "
                    "not counted): trials with more than max_gaze_age_over_share of frames over it are marked "
                    "gaze_age_ok: false")
    max_gaze_age_over_share: Number = Field(
        default=MAX_GAZE_AGE_OVER_SHARE, ge=0, le=1,
        description="the share of the intervals' frames that may exceed max_gaze_age_ms")

    @property
    def intervals(self) -> list[Interval]:
        return [p for p in self.phases if isinstance(p, Interval)]

    def expected_duration_s(self) -> float:
        """Expected length of one trial: fixed durations plus participant-paced estimates."""
        total = 0.0
        for phase in self.phases:
            fixed = getattr(phase, "duration_s", None)
            expected = fixed if fixed is not None else phase.expected_s
            assert expected is not None  # Interval._timing: duration_s or expected_s is given
            total += float(expected)
        return total
