"""``observer: {kind: image}``: a simulated participant that answers from the frames the session renders
(psyop.session.responses.image_observer implements it; docs/protocols.md, "The image observer").

Its parameters state the model of the participant (psyop.session.image_observer): the eye's optics (pupil,
accommodation error), how acuity and sensitivity fall with eccentricity, the relative-motion stage, one internal
noise and a lapse rate, and the resolution and frame count it renders each interval at. Every default is a
stated value; ``noise_sd_c2deg2`` is calibrated once (benchmarks/bench_image_observer.py) so that on the paper's
detection stimulus the observer's 75 % point is the paper's 0.36 D.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from psyop.protocol.base import Number
from psyop.protocol.kinds.base import ObserverBase

#: ``noise_sd_c2deg2`` calibrated at the other defaults: ``python -m benchmarks --only image_observer`` (part of
#: ``make bench``; benchmarks/bench_image_observer.py) prints it: with it the observer's mean p(correct) on the
#: detection stimulus (protocols/detection.yaml, back 1, 2, 3 D) is 0.75 at 0.36 D
CALIBRATED_NOISE_SD_C2DEG2 = 1.832e-6


#: the fields each response kind's decision rule reads (the others are refused where set: :func:`unread_fields`)
FIELDS_READ: dict[str, frozenset[str]] = {
    "two_interval": frozenset({"kind", "eye", "pupil_mm", "defocus_D", "mar0_arcmin", "e2_deg", "motion_scale_deg",
                               "motion_window_deg", "pursued_deg", "luminance_weight", "noise_sd_c2deg2", "lapse",
                               "render_scale", "frames_per_interval"}),
    "n_afc": frozenset({"kind", "eye", "pupil_mm", "defocus_D", "mar0_arcmin", "e2_deg", "motion_scale_deg",
                        "motion_window_deg", "pursued_deg", "luminance_weight", "noise_sd_c2deg2", "lapse",
                        "render_scale", "frames_per_interval"}),
    "yes_no": frozenset({"kind", "eye", "pupil_mm", "defocus_D", "mar0_arcmin", "e2_deg", "motion_scale_deg",
                         "motion_window_deg", "pursued_deg", "luminance_weight", "noise_sd_c2deg2", "criterion_sd",
                         "lapse", "render_scale", "frames_per_interval"}),
    "left_right_nearer": frozenset({"kind", "eye", "pupil_mm", "defocus_D", "mar0_arcmin", "e2_deg",
                                    "motion_scale_deg", "shift_noise_arcmin", "border_strip_deg", "lapse",
                                    "render_scale", "frames_per_interval"}),
    "pairwise_preference": frozenset({"kind", "eye", "pupil_mm", "defocus_D", "mar0_arcmin", "e2_deg",
                                      "motion_scale_deg", "motion_window_deg", "shift_noise_arcmin", "lapse",
                                      "render_scale", "frames_per_interval"}),
}


class ImageObserver(ObserverBase):
    """Answers from each interval's rendered frames, by the rule of the response kind
    (psyop.session.responses.image_observer): a two-interval trial from the energy of the relative motion each
    interval shows (psyop.session.image_observer.response), the larger after Gaussian internal noise of sd
    ``noise_sd_c2deg2`` on each; a left/right-nearer trial from the direction of the two half fields' relative
    shift at each gaze shift (psyop.session.image_observer.ordinal), with noise ``shift_noise_arcmin``; an n-AFC
    trial (over intervals) by the largest noisy energy; a yes/no trial by the noisy energy against
    ``criterion_sd`` (psyop.session.image_observer.decisions); a pairwise-preference trial by the interval whose
    frames carry more depth evidence from the eye's own movements (the spread of the local image shifts along each
    gaze shift, noise ``shift_noise_arcmin``: psyop.session.image_observer.preference; a hypothesis about
    preference, not a fit). It lapses (guesses) at rate ``lapse``."""

    kind: Literal["image"]
    #: pupil diameter (mm): diffraction, and with ``defocus_D`` the defocus blur
    pupil_mm: Number = Field(default=4.0, ge=1.0, le=9.0)
    #: the eye's accommodation error with respect to the display's image distance (D)
    defocus_D: Number = Field(default=0.0, ge=0.0, le=10.0)
    #: the foveal minimum angle of resolution (arcmin)
    mar0_arcmin: Number = Field(default=1.0, gt=0.0, le=10.0)
    #: the eccentricity at which the minimum angle of resolution has doubled (deg)
    e2_deg: Number = Field(default=2.5, gt=0.0, le=30.0)
    #: the spatial scale of the relative-motion stage (sd, deg)
    motion_scale_deg: Number = Field(default=0.25, gt=0.0, le=5.0)
    #: the window a local translation is fitted over (sd, deg; the two-interval, n-AFC, yes/no and preference rules)
    motion_window_deg: Number = Field(default=1.0, gt=0.0, le=10.0)
    #: around the gaze, what pursuit holds on the fovea (deg): not counted as motion
    pursued_deg: Number = Field(default=2.0, ge=0.0, le=20.0)
    #: the luminance channel's weight beside the two chromatic channels (weight 1)
    luminance_weight: Number = Field(default=0.0, ge=0.0, le=100.0)
    #: the internal noise (sd) on each interval's response (contrast^2 deg^2)
    noise_sd_c2deg2: Number = Field(default=CALIBRATED_NOISE_SD_C2DEG2, gt=0.0)
    #: the share of trials answered by a guess
    lapse: Number = Field(default=0.0, ge=0.0, lt=0.5)
    #: left_right_nearer and pairwise_preference only: the sd of the observer's estimate of a relative shift along
    #: each gaze shift (arcmin; stated, not calibrated: a differential-displacement threshold of about 1 arcmin)
    shift_noise_arcmin: Number = Field(default=1.0, gt=0.0, le=60.0)
    #: left_right_nearer only: the strip about the view's vertical midline left out of both half fields (deg each
    #: side; the border between the two surfaces runs in it)
    border_strip_deg: Number = Field(default=2.0, ge=0.0, le=20.0)
    #: yes_no only: "yes" when the interval's noisy response exceeds this many noise sds (the false-alarm rate to a
    #: stimulus without relative motion is Phi(-criterion_sd): 0.16 at the default)
    criterion_sd: Number = Field(default=1.0, ge=-5.0, le=5.0)
    #: the rendered frames' resolution, a fraction of the display's
    render_scale: Number = Field(default=0.25, ge=0.05, le=1.0)
    #: frames rendered per interval, evenly spaced through it
    frames_per_interval: int = Field(default=8, ge=2, le=64)


def unread_fields(observer: ImageObserver, kind: str) -> list[str]:
    """The fields set in the protocol that the decision rule of response kind ``kind`` does not read."""
    return sorted(set(observer.model_fields_set) - FIELDS_READ[kind])
