"""The simulated eye and tracker (``observer: eye:``): how a headless session's gaze behaves.

Every field is optional; an unset field keeps the simulated tracker's default
(:class:`psyop.session.gaze.simulated.SimulatedTrackerConfig`, which states them). ``participants``
overrides some of them for named simulated participants (e.g. one whose tracker loses the pupil), so
that a study can be simulated with participants its ``quality:`` rules must exclude. A real tracker
ignores the section; psyop.session.gaze.simulated reads it (``tracker_config``).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from psyop.protocol.base import Number, StrictModel

Rate = Annotated[Number, Field(ge=0, le=50)]


class EyeOverride(StrictModel):
    """What one simulated participant's eye or tracker does differently."""

    precision_deg: Number | None = Field(default=None, gt=0, le=5)
    pursuit_gain: Number | None = Field(default=None, gt=0, le=1.5)
    pursuit_lag_s: Number | None = Field(default=None, ge=0, le=0.5)
    blink_rate_hz: Rate | None = None
    dropout_rate_hz: Rate | None = None
    dropout_s: Number | None = Field(default=None, gt=0, le=60)
    nan_burst_rate_hz: Rate | None = None
    error_centre_deg: Number | None = Field(default=None, ge=0, le=10,
                                            description="tracker error at the centre: a random offset per target")
    error_per_15deg: Number | None = Field(default=None, ge=0, le=10,
                                           description="tracker error growing with eccentricity, per 15 deg")
    drift_start_deg: Number | None = Field(default=None, ge=0, le=10, description="the session's tracker drift at 0 s")
    drift_deg_per_min: Number | None = Field(default=None, ge=0, le=10, description="how fast that drift grows")


class SimulatedEye(EyeOverride):
    """The simulated eye (pursuit, catch-up saccades on the main sequence, blinks) and its tracker (rate,
    latency, noise, dropouts); docs/protocols.md "Simulated eye"."""

    rate_hz: Number | None = Field(default=None, ge=10, le=2000, description="the tracker's sampling rate")
    latency_s: Number | None = Field(default=None, ge=0, le=0.2)
    catch_up_threshold_deg: Number | None = Field(default=None, gt=0, le=10,
                                                  description="position error that starts a catch-up saccade")
    main_sequence_vmax_deg_s: Number | None = Field(default=None, gt=50, le=1500)
    main_sequence_c_deg: Number | None = Field(default=None, gt=0, le=50)
    blink_s: Number | None = Field(default=None, gt=0, le=2)
    nan_burst_s: Number | None = Field(default=None, gt=0, le=5)
    raw_stream: Literal["requested", "every_sample"] | None = Field(
        default=None, description="every_sample: the raw stream holds every tick at rate_hz, as a real tracker's")
    participants: dict[str, EyeOverride] = Field(default_factory=dict,
                                                 description="per simulated participant ID (e.g. S03): overrides")
