"""The optional ``gaze_validation:`` section: a multi-point check of the tracker's accuracy in the headset.

Single-point drift correction (``drift_recalibration``) is not a calibration check. A validation shows
each of ``points_deg`` in turn (Fick azimuth, elevation from the midpoint between the eyes, where the
tracker's gaze is referenced) at ``distance_m``, lets the eye settle for ``settle_s``, records the gaze
for ``dwell_s`` and reports accuracy (mean and max angular error) and precision (RMS sample-to-sample, SD)
per point and over all points, at the times ``when`` says. ``require`` makes trials wait for a validation
whose errors are small enough: it is run again up to ``max_attempts`` times, then the session stops
(psyop.session.validation). docs/protocols.md "Gaze validation", docs/quality.md.
"""

from __future__ import annotations

import math
from typing import Literal

from pydantic import Field, field_validator

from psyop.optics.angles import fick_direction
from psyop.optics.display import DisplayProfile
from psyop.optics.nodal import eye_centre_x_m
from psyop.protocol.base import Integer, Number, StrictModel

#: the default point set: 9 points, a 3 x 3 grid over +-15 deg (centre first)
NINE_POINTS_DEG: tuple[tuple[float, float], ...] = (
    (0.0, 0.0), (-15.0, 15.0), (0.0, 15.0), (15.0, 15.0), (-15.0, 0.0), (15.0, 0.0), (-15.0, -15.0),
    (0.0, -15.0), (15.0, -15.0))

#: the largest eccentricity of a point (per angle): inside every headset's field of view
MAX_POINT_DEG = 40.0

#: the quality measures a validation gives each trial (psyop.quality.validation; QUALITY_MEASURES)
VALIDATION_MEASURES: tuple[str, ...] = (
    "validation_mean_error_deg", "validation_max_error_deg", "validation_precision_rms_s2s_deg",
    "validation_precision_sd_deg")

When = Literal["start", "between_blocks", "end"]


class ValidationRequirement(StrictModel):
    """Trials go on only after a validation whose mean error over the points (and, when given, every
    point's mean error) is at most the bound; one that fails is run again, ``max_attempts`` in all, then
    the session stops (exit 3, finalised incomplete, resumable)."""

    max_mean_error_deg: Number = Field(gt=0, le=20, description="largest mean error over all points, deg")
    max_point_error_deg: Number | None = Field(default=None, gt=0, le=30,
                                               description="largest mean error of any one point, deg")
    max_attempts: Integer = Field(default=3, ge=1, le=20, description="validations run before the session stops")


class GazeValidation(StrictModel):
    """``gaze_validation:``: the points, how each is shown, when it runs and what it must reach."""

    when: list[When] = Field(min_length=1, description="start, between_blocks and/or end of the session")
    points_deg: list[tuple[Number, Number]] = Field(
        default_factory=lambda: list(NINE_POINTS_DEG), min_length=1, max_length=64,
        description="[azimuth, elevation] Fick angles of each target from the midpoint between the eyes, deg")
    distance_m: Number = Field(default=1.0, ge=0.25, le=20, description="the targets' distance, m")
    target_size_deg: Number = Field(default=0.5, gt=0, le=5, description="the target disc's diameter, deg")
    settle_s: Number = Field(default=0.5, ge=0, le=5, description="time on each target before gaze is recorded")
    dwell_s: Number = Field(default=1.0, ge=0.1, le=10, description="time gaze is recorded on each target")
    require: ValidationRequirement | None = None

    @field_validator("when")
    @classmethod
    def _once_each(cls, value: list[str]) -> list[str]:
        if len(set(value)) != len(value):
            raise ValueError("name each of start, between_blocks, end at most once")
        return value

    @field_validator("points_deg")
    @classmethod
    def _points(cls, value: list[tuple[float, float]]) -> list[tuple[float, float]]:
        for az, el in value:
            if abs(az) > MAX_POINT_DEG or abs(el) > MAX_POINT_DEG:
                raise ValueError(f"point [{az:g}, {el:g}] is outside +-{MAX_POINT_DEG:g} deg; move it inward")
        if len({(float(a), float(e)) for a, e in value}) != len(value):
            raise ValueError("a point is listed twice; list each once")
        return value

    @property
    def point_s(self) -> float:
        """How long one point is shown."""
        return float(self.settle_s) + float(self.dwell_s)

    def expected_s(self) -> float:
        """Length of one validation (one attempt)."""
        return len(self.points_deg) * self.point_s


def validation_issues(validation: GazeValidation | None, blocked: bool,
                      rule_measures: list[tuple[tuple[str | int, ...], str]]) -> list[tuple[tuple[str | int, ...], str]]:
    """Cross-section problems (key path, message): ``between_blocks`` in a design without blocks (it would
    never run), and a ``quality:`` rule on a validation measure without a ``gaze_validation:`` section (it
    could never judge). ``rule_measures``: each rule's key path and measure."""
    issues: list[tuple[tuple[str | int, ...], str]] = []
    if validation is not None and "between_blocks" in validation.when and not blocked:
        index = validation.when.index("between_blocks")
        issues.append((("gaze_validation", "when", index),
                       "between_blocks needs blocks (design: randomisation: kind: blocked, by: [...]); "
                       "drop it or block the design"))
    if validation is None:
        for path, measure in rule_measures:
            if measure in VALIDATION_MEASURES:
                issues.append((path, f"{measure} needs a gaze_validation: section (nothing measures it); "
                                     "add one or drop the rule"))
    return issues


def points_off_display(validation: GazeValidation, display: DisplayProfile, eyes: tuple[str, ...],
                       ipd_m: float) -> list[tuple[int, str]]:
    """(point index, message) for every point whose target disc is not wholly inside the display's frustum of
    each eye that sees it (from the eye's centre of rotation, ``ipd_m`` apart; the point at ``distance_m``
    from their midpoint): a point the participant is never shown measures nothing.

    Examples
    --------
    >>> narrow = DisplayProfile("narrow", 400, 400, 90.0, -0.27, 0.27, -0.27, 0.27)  # about +-15 deg
    >>> v = GazeValidation(when=["start"], points_deg=[(0, 0), (10, 0), (20, 0)])
    >>> [i for i, _ in points_off_display(v, narrow, ("left", "right"), 0.063)]
    [2]
    """
    radius_deg = float(validation.target_size_deg) / 2
    out: list[tuple[int, str]] = []
    for index, (az_deg, el_deg) in enumerate(validation.points_deg):
        target_m = fick_direction(float(az_deg), float(el_deg)) * float(validation.distance_m)
        for eye in eyes:
            x_m = target_m[0] - eye_centre_x_m(eye, ipd_m)
            forward_m = -float(target_m[2])
            left, right, bottom, top = display.frustum_tangents(eye)
            if forward_m <= 0:
                inside = False
            else:
                h_deg = math.degrees(math.atan2(x_m, forward_m))
                v_deg = math.degrees(math.atan2(float(target_m[1]), math.hypot(x_m, forward_m)))
                inside = (math.degrees(math.atan(left)) <= h_deg - radius_deg and
                          h_deg + radius_deg <= math.degrees(math.atan(right)) and
                          math.degrees(math.atan(bottom)) <= v_deg - radius_deg and
                          v_deg + radius_deg <= math.degrees(math.atan(top)))
            if not inside:
                out.append((index, f"point [{az_deg:g}, {el_deg:g}] at {float(validation.distance_m):g} m is not "
                                   f"inside the {eye} eye's field of view of display '{display.name}' "
                                   f"(ipd {ipd_m * 1000:g} mm): the participant would never see it; move it inward"))
                break
    return out
