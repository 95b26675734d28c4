"""The image observer (protocol ``observer: {kind: image}``, psyop.protocol.image_observer): a simulated
participant that answers from the frames the session's renderer draws for each interval
(psyop.session.image_observer.frames), not from the schedule, by the decision rule of the response kind
(:func:`image_observer_source` picks it).

``two_interval`` (:class:`ImageObserverSource`): each interval's internal response is the relative-motion energy
its eye sees (psyop.session.image_observer.response, through the eye of psyop.session.image_observer.eye). With
Gaussian internal noise of sd ``noise_sd_c2deg2`` on each response it picks the larger, so it answers correctly
with probability ``lapse / 2 + (1 - lapse) Phi((R_correct - R_other) / (noise_sd_c2deg2 sqrt 2))``. Two intervals
with the same frames have the same response: it answers at chance wherever the stimulus carries no cue.

``left_right_nearer`` (:class:`ImageOrdinalSource`): the side whose shift against each gaze shift says nearer
(psyop.session.image_observer.ordinal), with noise ``shift_noise_arcmin`` on each pair of frames' evidence;
``border_strip_deg`` about the midline is left out of both half fields. Frames that do not change with the gaze
(conventional rendering) carry no evidence: a coin toss.

``n_afc``, ``yes_no`` and ``pairwise_preference`` (the interval whose frames carry more depth evidence from the
eye's own movements: psyop.session.image_observer.preference) are answered by psyop.session.responses.image_choices.

Each answer is decided against the trial's one keyed uniform draw (as every simulated observer,
psyop.session.responses.simulated): the same session seed gives the same answers, resumed or not. Each answer
carries the values its decision used (image_choices.observer_extras: each interval's response or evidence, the
noise, ``u`` and ``p``), which the session logs in the trial's ``observer_responses`` column.
"""

from __future__ import annotations

import math

from psyop.protocol.kinds import kind_named
from psyop.session.gaze.keyed import keyed_uniform
from psyop.session.image_observer.ordinal import interval_evidence_arcmin, p_left
from psyop.session.image_observer.response import interval_response
from psyop.session.plan import SessionPlan
from psyop.session.responses.base import Response, score
from psyop.session.responses.image_choices import RenderedSource, observer_extras
from psyop.session.responses.simulated import SimulatedObserver
from psyop.session.rows import JsonMapping, TrialRow


def p_correct(responses: tuple[float, ...], correct_interval: int, noise_sd: float, lapse: float) -> float:
    """p(correct) of the noisy comparison of two interval responses (see the module docstring)."""
    right, other = responses[correct_interval - 1], responses[2 - correct_interval]
    z = (right - other) / (noise_sd * math.sqrt(2.0))
    return 0.5 * lapse + (1.0 - lapse) * 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


class ImageObserverSource(RenderedSource):
    """The image observer as the session's response source (see the module docstring)."""

    kind = kind_named("two_interval")
    intervals, does = 2, "answers two-interval trials"

    def responses(self, row: TrialRow) -> tuple[float, ...]:
        """Each interval's internal response to trial ``row`` (contrast^2 deg^2)."""
        return self.per_trial(row, lambda: tuple(interval_response(f, self.eye, self.motion)
                                                 for f in self.frames.intervals(row)))

    def decision(self, row: TrialRow) -> tuple[float, float]:
        p = p_correct(self.responses(row), int(row["correct_interval"]), float(self.model.noise_sd_c2deg2),
                      float(self.model.lapse))
        return keyed_uniform(*self.trial_keys(row)), p

    def collect(self, row: TrialRow, now_s: float) -> Response:
        u, p = self.decision(row)
        right = int(row["correct_interval"])
        values = {"responses_c2deg2": list(self.responses(row)), "noise_sd_c2deg2": float(self.model.noise_sd_c2deg2)}
        return observer_extras(score(self.kind, row, str(right if u < p else 3 - right)), "larger noisy response",
                               values, u, p)


class ImageOrdinalSource(RenderedSource):
    """The image observer answering a left/right-nearer trial (see the module docstring)."""

    kind = kind_named("left_right_nearer")
    intervals, does = 1, "answers a left/right-nearer trial from one interval"

    def evidence_arcmin(self, row: TrialRow) -> list[float]:
        """Each pair of successive frames' evidence (arcmin) that the left side is nearer in trial ``row``."""
        return self.per_trial(row, lambda: interval_evidence_arcmin(
            next(iter(self.frames.intervals(row))), self.eye, self.motion.scale_deg, float(self.model.border_strip_deg)))

    def decision(self, row: TrialRow) -> tuple[float, float]:
        """``(u, p)``: the trial's uniform draw and p(the near side is answered)."""
        left = p_left(self.evidence_arcmin(row), float(self.model.shift_noise_arcmin), float(self.model.lapse))
        return keyed_uniform(*self.trial_keys(row)), (left if str(row["near_side"]) == "left" else 1.0 - left)

    def collect(self, row: TrialRow, now_s: float) -> Response:
        u, p = self.decision(row)
        near = str(row["near_side"])
        values = {"evidence_arcmin": self.evidence_arcmin(row), "noise_arcmin": float(self.model.shift_noise_arcmin)}
        return observer_extras(score(self.kind, row, near if u < p else ("right" if near == "left" else "left")),
                               "side the shifts say nearer", values, u, p)


def image_observer_source(params: JsonMapping, *, seed: int, participant: str,
                          plan: SessionPlan) -> SimulatedObserver:
    """The image observer for the plan's response kind (``two_interval``, ``left_right_nearer``; ``n_afc``,
    ``yes_no`` or ``pairwise_preference``: psyop.session.responses.image_choices)."""
    if plan.kind.name == "left_right_nearer":
        return ImageOrdinalSource(params, seed=seed, participant=participant, plan=plan)
    if plan.kind.name == "pairwise_preference":
        from psyop.session.responses.image_choices import ImagePreferenceSource

        return ImagePreferenceSource(params, seed=seed, participant=participant, plan=plan)
    if plan.kind.name in ("n_afc", "yes_no"):
        from psyop.session.responses.image_choices import ImageNafcSource, ImageYesNoSource

        source = ImageNafcSource if plan.kind.name == "n_afc" else ImageYesNoSource
        return source(params, seed=seed, participant=participant, plan=plan)
    return ImageObserverSource(params, seed=seed, participant=participant, plan=plan)
