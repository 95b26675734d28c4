"""A confidence rating after a kind's one choice: ``response: {kind: two_interval, ..., confidence: {points: 4,
labels: [...], question: ...}}``, and the simulated observer's confidence model (``observer: {...,
confidence: {criteria: [...], meta_noise_sd: ...}}``).

Every kind whose answer is one discrete choice (:attr:`~psyop.protocol.kinds.base.ResponseKindSpec.takes_confidence`)
accepts the section; the others refuse it at its line with the reason (a rating already is a rating; an
adjustment's answer is a value and a reach's a hand position, not one of a few choices). After the choice the same
response source asks the confidence on a k-point scale: keys 1..k (top row or keypad), response-box buttons 1..k;
the OpenXR controllers move a highlighted point along the scale with either stick and confirm it with either select
button (:data:`SCALE_CONTROLLER`, psyop.session.scale_picker). The trial log gets ``confidence`` (1..k; null when not
answered), ``confidence_time_s``, ``confidence_outcome`` (``answered``, ``timeout``, or ``not_asked`` after a
timed-out choice; psyop.session.confidence) and, answered with the controllers, ``confidence_path`` (the
highlighted points, JSON ``[[t_s, point], ...]``). The question and the labels are drawn on the response's text
panel as a rating scale is (:func:`confidence_text`).

The simulated confidence model (:class:`ObserverConfidence`) is stated on the probit scale of the probability of
the answer given: with p the trial's probability of the observer's probable answer (p correct for two_interval,
left_right_nearer, n_afc; p of 'yes', 'a' or 'against' for the others) and n the number of answers, the answer
given had probability q = p when it is the probable one, else (1 - p) / (n - 1); the observer's confidence variable
is c = ``evidence_weight`` * Phi^-1(q) + m, m ~ N(0, ``meta_noise_sd``) drawn per trial from its own keyed stream,
and the rating is 1 + the number of ``criteria`` below c. Correct answers are the probable ones wherever
p > 1 / n, so confidence rises with accuracy; ``evidence_weight: 0`` gives a confidence independent of correctness.
"""

from __future__ import annotations

from statistics import NormalDist
from typing import Protocol

import numpy as np
from pydantic import Field

from psyop.protocol.base import Integer, Number, StrictModel
from psyop.records import Loc

#: the fewest and most points a confidence scale may have (its keys are the digits 1..k)
MIN_POINTS, MAX_POINTS = 2, 9

#: the schedule column holding the confidence scale's number of points (the observer and the analysis read it)
POINTS_COLUMN = "confidence_points"
#: the trial-log columns of a confidence rating: the point (1..k; null when not given), the time from the scale's
#: onset to the answer (s), and how it ended: ``answered``, ``timeout`` (the scale timed out) or ``not_asked`` (the
#: choice timed out, so no confidence was asked)
CONFIDENCE, CONFIDENCE_TIME_S, CONFIDENCE_OUTCOME = "confidence", "confidence_time_s", "confidence_outcome"
#: the trial-log column of the points a controller highlighted on the confidence scale (psyop.session.scale_picker)
CONFIDENCE_PATH = "confidence_path"

#: the raw input names a scale (rating, confidence) reads from the OpenXR controllers once the kind's map has named
#: them: a stick's sideways deflection (psyop.devices.xr.tracking reports it as ``thumbstick_x``) moves the
#: highlighted point, either select button confirms it (psyop.session.scale_picker)
SCALE_AXIS, SCALE_CONFIRM = "scale_axis", "confirm"
SCALE_CONTROLLER: dict[str, str] = {"thumbstick_x": SCALE_AXIS, "left": SCALE_CONFIRM, "right": SCALE_CONFIRM}
#: what a participant answering a scale with the controllers reads under its question
STICK_HELP = "Move with a stick, answer with a trigger."

#: why a kind whose answer is not one discrete choice refuses a confidence rating
_REFUSAL_REASONS = {
    "rating": "its answer already is a rating on a scale",
    "adjustment": "its answer is an adjusted value, not one of a few choices",
    "reach": "its answer is a hand position, not one of a few choices",
}


class ConfidenceScale(StrictModel):
    """``response: confidence:``: the scale asked after the choice: ``points`` (k, 2 to 9; answered 1..k), one label
    per point (lowest first) or none, and the ``question`` shown above it."""

    points: Integer
    labels: list[str] | None = None
    question: str = "How sure are you?"


class ObserverConfidence(StrictModel):
    """``observer: confidence:``: how a simulated observer rates its confidence (the module docstring states the
    model): ``criteria`` (k - 1 increasing cut points on the probit scale of q), ``meta_noise_sd`` (the per-trial
    noise of the confidence variable) and ``evidence_weight`` (0: confidence independent of the evidence)."""

    criteria: list[Number]
    meta_noise_sd: Number = Field(default=0.5, ge=0)
    evidence_weight: Number = Field(default=1.0, ge=0)


class _Kind(Protocol):
    """The part of a response kind (psyop.protocol.kinds.base.ResponseKindSpec, which imports this module) read here."""

    @property
    def name(self) -> str: ...

    @property
    def takes_confidence(self) -> bool: ...


class _WithScale(Protocol):
    """A ``response:`` section (psyop.protocol.kinds.base.KindResponse)."""

    @property
    def confidence(self) -> ConfidenceScale | None: ...


class _WithModel(Protocol):
    """An ``observer:`` section (psyop.protocol.kinds.base.ObserverBase)."""

    @property
    def confidence(self) -> ObserverConfidence | None: ...


class _Checks(Protocol):
    """The part of the protocol checker (psyop.protocol.kinds.base.Checks) used here."""

    def add(self, path: tuple[str | int | float, ...], message: str) -> None: ...


def confidence_keys(points: int) -> dict[str, str]:
    """The keyboard keys of a ``points``-point scale: the digits 1..k and the keypad's, each to its point."""
    return {str(j): str(j) for j in range(1, points + 1)} | {f"kp_{j}": str(j) for j in range(1, points + 1)}


def confidence_point(raw: str, points: int) -> int | None:
    """The point a raw input names on a ``points``-point scale: a digit key (``3``, keypad ``kp_3``) or box button
    1..k; None for any other input.

    Examples
    --------
    >>> confidence_point("kp_3", 4), confidence_point("4", 4), confidence_point("5", 4), confidence_point("left", 4)
    (3, 4, None, None)
    """
    digit = raw.lower().removeprefix("kp_")
    return int(digit) if len(digit) == 1 and digit.isdigit() and 1 <= int(digit) <= points else None


def scale_lines(points: int, labels: list[str] | None, ends: tuple[str, str], highlighted: int | None = None) -> str:
    """A k-point scale as drawn under its question: each point's digit and label, lowest first, or without labels
    the digits' range (``ends`` names the lowest and the highest). With ``highlighted`` (a controller picks the
    point) that point is marked: its line between ``>`` and ``<``, or, without labels, a row of the digits with it in
    brackets.

    Examples
    --------
    >>> print(scale_lines(3, None, ("low", "high"), highlighted=2))
    1 (low) to 3 (high)
    1  [2]  3
    >>> print(scale_lines(2, ["no", "yes"], ("low", "high"), highlighted=1))
    >  1  no  <
       2  yes
    """
    if labels is None:
        lines = f"1 ({ends[0]}) to {points} ({ends[1]})"
        if highlighted is None:
            return lines
        return lines + "\n" + "  ".join(f"[{j}]" if j == highlighted else str(j) for j in range(1, points + 1))
    if highlighted is None:
        return "\n".join(f"{point}  {label}" for point, label in enumerate(labels, start=1))
    return "\n".join((f">  {point}  {label}  <" if point == highlighted else f"   {point}  {label}")
                     for point, label in enumerate(labels, start=1))


def confidence_text(scale: ConfidenceScale, highlighted: int | None = None) -> str:
    """What the participant reads after the choice: the question, an empty line, then each point's key and label
    (lowest first), or the keys' range without labels (as a rating's scale is drawn); ``highlighted``: that point
    marked (the controllers answer)."""
    lines = scale_lines(int(scale.points), scale.labels, ("least sure", "most sure"), highlighted)
    return f"{scale.question.strip()}\n\n{lines}"


def check_confidence(kind: _Kind, response: _WithScale, observer: _WithModel | None, checks: _Checks,
                     path: Loc) -> None:
    """``response.confidence`` only on a kind that takes one, with 2 to 9 points and one label per point; the
    observer's ``confidence`` model only with a confidence scale, with one criterion fewer than points, increasing;
    a simulated observer of a protocol with a confidence scale states its confidence model."""
    scale = response.confidence
    observer_model = observer.confidence if observer is not None else None
    if scale is None:
        if observer_model is not None:
            checks.add(("observer", "confidence"), "the observer has a confidence model but the response asks no "
                                                   "confidence; add response: confidence: or remove this")
        return
    where = path + ("confidence",)
    if not kind.takes_confidence:
        reason = _REFUSAL_REASONS.get(kind.name, "its answer is not one discrete choice")
        article = "an" if kind.name[0] in "aeiou" else "a"
        checks.add(where, f"{article} {kind.name} response takes no confidence rating: {reason}; remove confidence")
        return
    points = int(scale.points)
    if not MIN_POINTS <= points <= MAX_POINTS:
        checks.add(where + ("points",), f"a confidence scale has {MIN_POINTS} to {MAX_POINTS} points (keys 1 to "
                                        f"{MAX_POINTS}), not {points}")
        return
    if scale.labels is not None and len(scale.labels) != points:
        checks.add(where + ("labels",), f"{len(scale.labels)} label(s) for a {points}-point confidence scale: give "
                                        f"one label per point, least sure first, or leave labels out")
    if observer is not None:
        _check_observer_model(observer_model, points, checks)


def _check_observer_model(model: ObserverConfidence | None, points: int, checks: _Checks) -> None:
    if model is None:
        checks.add(("observer",), f"the response asks a {points}-point confidence rating but the observer states no "
                                  f"confidence model; add confidence: {{criteria: [{points - 1} increasing numbers]}} "
                                  f"under observer")
        return
    criteria = [float(c) for c in model.criteria]
    if len(criteria) != points - 1:
        checks.add(("observer", "confidence", "criteria"), f"{len(criteria)} criteria for a {points}-point confidence "
                                                           f"scale: give {points - 1} (one between each two points)")
    elif any(b <= a for a, b in zip(criteria, criteria[1:])):
        checks.add(("observer", "confidence", "criteria"), "the confidence criteria must increase strictly, lowest "
                                                           "first")


def confidence_columns(scale: ConfidenceScale | None, n: int) -> dict[str, np.ndarray]:
    """The schedule columns of a confidence scale: its points, and the log columns the session fills in (null,
    NaN and '' until then; the path only when the controllers answer); none without a scale."""
    if scale is None:
        return {}
    return {POINTS_COLUMN: np.full(n, int(scale.points), dtype=np.int64), CONFIDENCE: np.full(n, np.nan),
            CONFIDENCE_TIME_S: np.full(n, np.nan), CONFIDENCE_OUTCOME: np.full(n, "", dtype=object),
            CONFIDENCE_PATH: np.full(n, "", dtype=object)}


def simulated_confidence(model: ObserverConfidence, u: float, p: float, n_answers: int, meta_u: float,
                         points: int) -> int:
    """The simulated rating (the module docstring states the model): ``u`` and ``p`` the choice's uniform draw and
    the probability of its probable answer (the answer given is the probable one when ``u < p``), ``n_answers`` the
    choice's number of answers, ``meta_u`` the trial's uniform draw for the meta noise.

    Examples
    --------
    >>> model = ObserverConfidence(criteria=[0.0, 0.5, 1.0], meta_noise_sd=0.0)
    >>> simulated_confidence(model, 0.1, 0.95, 2, 0.5, 4), simulated_confidence(model, 0.99, 0.95, 2, 0.5, 4)
    (4, 1)
    """
    def probit(x: float) -> float:
        return NormalDist().inv_cdf(min(max(x, 2.0 ** -53), 1.0 - 2.0 ** -53))

    q = p if u < p else (1.0 - p) / max(n_answers - 1, 1)
    weight = float(model.evidence_weight)
    evidence = weight * probit(q) if weight > 0 else 0.0
    c = evidence + float(model.meta_noise_sd) * probit(meta_u)
    return min(1 + sum(c > float(k) for k in model.criteria), points)
