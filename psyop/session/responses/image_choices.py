"""The image observer (``observer: {kind: image}``) answering ``n_afc`` (``alternatives: intervals``),
``yes_no`` and ``pairwise_preference`` trials from the frames the session's renderer draws for each interval
(psyop.session.image_observer.frames): for n-AFC and yes/no each interval's internal response is its
relative-motion energy (psyop.session.image_observer.response), as for ``two_interval``, and the decision rules
are stated in psyop.session.image_observer.decisions: n-AFC picks the interval with the largest noisy response;
yes/no says yes when the noisy response exceeds ``criterion_sd`` noise sds. A preference trial's rule is
psyop.session.image_observer.preference: the interval whose frames carry more depth evidence from the eye's own
movements (a stated hypothesis about preference, not a fit). Each answer is decided against the trial's one keyed
uniform draw (psyop.session.responses.simulated): the same session seed gives the same answers. Every answer
carries the values its decision used (:func:`observer_extras`), logged in the trial's ``observer_responses``."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Mapping
from typing import Any, ClassVar, TypeVar

import numpy as np

from psyop.datacontract import OBSERVER_RESPONSES
from psyop.protocol.kinds import kind_named
from psyop.session.gaze.keyed import keyed_uniform
from psyop.session.image_observer.decisions import p_largest, p_yes
from psyop.session.image_observer.frames import FrameSource
from psyop.session.image_observer.preference import interval_depth_arcmin, p_first_preferred
from psyop.session.image_observer.response import interval_response
from psyop.session.image_observer.stages import model_of, stages_of
from psyop.session.plan import SessionPlan
from psyop.session.responses.base import Response, score
from psyop.session.responses.simulated import SimulatedObserver
from psyop.session.rows import JsonMapping, TrialRow

T = TypeVar("T")


def observer_extras(response: Response, rule: str, values: Mapping[str, object], u: float, p: float) -> Response:
    """``response`` with the decision's values as its ``observer_responses`` trial-log column (JSON): the observer
    (``image``), its ``rule``, ``values`` (each interval's internal response or evidence and the noise), the
    trial's uniform draw ``u`` and the probability ``p`` it was compared with (the probable answer when u < p)."""
    record = {"observer": "image", "rule": rule, **values, "u": u, "p": p}
    return dataclasses.replace(response, extras=response.extras + ((OBSERVER_RESPONSES, json.dumps(record)),))


class RenderedSource(SimulatedObserver):
    """An image-observer response source: its model, the eye and motion stages, the frames it renders of each
    interval (the plan must have :attr:`intervals` of them; None: any number), and one trial's values computed once
    (:meth:`per_trial`)."""

    #: how many interval phases the kind's plan must have (None: any), and what the observer does, for the refusal
    intervals: ClassVar[int | None] = None
    does: ClassVar[str] = "answers"

    def __init__(self, params: JsonMapping, *, seed: int, participant: str, plan: SessionPlan) -> None:
        super().__init__(params, seed=seed, participant=participant)
        self.model = model_of(params)
        self.eye, self.motion = stages_of(self.model)
        self.frames = FrameSource(plan, scale=float(self.model.render_scale),
                                  frames_per_interval=self.model.frames_per_interval)
        count = len(self.frames.interval_phases())
        if self.intervals is not None and count != self.intervals:
            raise ValueError(f"the image observer {self.does}; this plan has {count} interval(s)")
        self._last: tuple[int, Any] | None = None  # Any: (trial seed, that trial's values of the subclass's rule)

    def per_trial(self, row: TrialRow, compute: Callable[[], T]) -> T:
        """``compute()`` for trial ``row``, computed once per trial (keyed by its ``trial_seed``)."""
        key = int(row["trial_seed"])
        if self._last is None or self._last[0] != key:
            self._last = key, compute()
        return self._last[1]

    def close(self) -> None:
        self.frames.close()


class ImageIntervalSource(RenderedSource):
    """The image observer's internal response to each interval of a trial (computed once per trial)."""

    def responses(self, row: TrialRow) -> tuple[float, ...]:
        """Each interval's internal response to trial ``row`` (contrast^2 deg^2)."""
        return self.per_trial(row, lambda: tuple(interval_response(f, self.eye, self.motion)
                                                 for f in self.frames.intervals(row)))


class ImageNafcSource(ImageIntervalSource):
    """n-AFC over intervals: the interval with the largest noisy response (decisions.p_largest)."""

    kind = kind_named("n_afc")

    def choices(self, row: TrialRow) -> np.ndarray:
        """Each interval's probability of being answered."""
        return p_largest(self.responses(row), float(self.model.noise_sd_c2deg2), float(self.model.lapse))

    def decision(self, row: TrialRow) -> tuple[float, float]:
        return keyed_uniform(*self.trial_keys(row)), float(self.choices(row)[int(row["correct_interval"]) - 1])

    def collect(self, row: TrialRow, now_s: float) -> Response:
        """The right interval when ``u < p(right)``; else the wrong one whose share of the rest covers ``u``."""
        u, _ = self.decision(row)
        p = self.choices(row)
        right = int(row["correct_interval"])
        order = [right] + [k for k in range(1, len(p) + 1) if k != right]
        cumulative = np.cumsum([p[k - 1] for k in order])
        chosen = order[min(int(np.searchsorted(cumulative, u, side="right")), len(order) - 1)]
        values = {"responses_c2deg2": list(self.responses(row)), "noise_sd_c2deg2": float(self.model.noise_sd_c2deg2),
                  "p_intervals": [float(x) for x in p]}
        return observer_extras(score(self.kind, row, str(chosen)), "largest noisy response", values, u,
                               float(p[right - 1]))


class ImageYesNoSource(ImageIntervalSource):
    """Yes/no: yes when the one interval's noisy response exceeds ``criterion_sd`` noise sds (decisions.p_yes)."""

    kind = kind_named("yes_no")

    def p_yes(self, row: TrialRow) -> float:
        (response,) = self.responses(row)
        return p_yes(response, float(self.model.noise_sd_c2deg2), float(self.model.criterion_sd),
                     float(self.model.lapse))

    def decision(self, row: TrialRow) -> tuple[float, float]:
        yes = self.p_yes(row)
        return keyed_uniform(*self.trial_keys(row)), (yes if bool(row["signal"]) else 1.0 - yes)

    def collect(self, row: TrialRow, now_s: float) -> Response:
        u, p = self.decision(row)
        right = "yes" if bool(row["signal"]) else "no"
        values = {"responses_c2deg2": list(self.responses(row)), "noise_sd_c2deg2": float(self.model.noise_sd_c2deg2),
                  "criterion_sd": float(self.model.criterion_sd)}
        return observer_extras(score(self.kind, row, right if u < p else ("no" if right == "yes" else "yes")),
                               "noisy response above the criterion", values, u, p)


class ImagePreferenceSource(RenderedSource):
    """Pairwise preference: the interval whose frames carry more depth evidence (image_observer.preference)."""

    kind = kind_named("pairwise_preference")
    intervals, does = 2, "prefers one of two intervals"

    def evidence_arcmin(self, row: TrialRow) -> tuple[float, ...]:
        """Each interval's depth evidence (arcmin) in trial ``row``, in shown order (a, b)."""
        return self.per_trial(row, lambda: tuple(
            interval_depth_arcmin(f, self.eye, self.motion.scale_deg, self.motion.window_deg)
            for f in self.frames.intervals(row)))

    def decision(self, row: TrialRow) -> tuple[float, float]:
        """``(u, p)``: the trial's uniform draw and p(the first interval, ``a``, is preferred)."""
        first, second = self.evidence_arcmin(row)
        p = p_first_preferred(first, second, float(self.model.shift_noise_arcmin), float(self.model.lapse))
        return keyed_uniform(*self.trial_keys(row)), p

    def collect(self, row: TrialRow, now_s: float) -> Response:
        u, p = self.decision(row)
        first, second = self.evidence_arcmin(row)
        values = {"evidence_arcmin": [first, second], "noise_arcmin": float(self.model.shift_noise_arcmin),
                  "modes": [str(row["mode_a"]), str(row["mode_b"])]}
        return observer_extras(score(self.kind, row, "a" if u < p else "b"), "more depth evidence", values, u, p)
