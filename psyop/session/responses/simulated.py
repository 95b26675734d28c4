"""Simulated observers (protocol ``observer:`` section; docs/architecture.md).

Each is deterministic given (session seed, participant, trial_seed): the answer to a
trial does not depend on which trials ran before it in this process, so a resumed
session answers exactly as an uninterrupted one. Between-subject variation is drawn
once per participant from (seed, participant).
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from typing import Any

import numpy as np

from psyop.session.rows import JsonMapping, TrialRow
from psyop.errors import UserError
from psyop.session.gaze.keyed import KeyedGenerator, keyed_rng, keyed_uniform
from psyop.session.gaze.simulated import seed_for
from psyop.session.reach import HAND_HEIGHT_M
from psyop.protocol.base import format_level
from psyop.protocol.kinds import KINDS, kind_named
from psyop.protocol.kinds.base import ObserverBase, ResponseKindSpec, observer_kind_name
from psyop.session.responses.base import Response, score


def _phi(z: float) -> float:
    """Standard normal CDF (math.erf; avoids importing scipy in every session process)."""
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


def _get(params: JsonMapping, key: str, default: Any = None, *, required: bool = False) -> Any:  # Any: a JSON parameter
    if key in params and params[key] is not None:
        return params[key]
    if required:
        raise UserError(f"observer: missing parameter {key!r}", "protocol observer")
    return default


class SimulatedObserver(ABC):
    """Base: per-trial and per-participant random streams; each kind implements :meth:`collect`
    (the :class:`~psyop.session.responses.base.ResponseSource` seam)."""

    needs_images = False

    def __init__(self, params: JsonMapping, *, seed: int, participant: str) -> None:
        self.params = dict(params)
        self.seed = int(seed)
        self.participant = participant
        self._participant_rng = keyed_rng(seed_for("participant", participant), self.seed)
        self._participant_key = seed_for(participant)  # the trial streams' second key, once
        self._trial_generator = KeyedGenerator()  # re-seeded per trial (each collect draws from it at once)

    def trial_rng(self, row: TrialRow) -> np.random.Generator:
        """The trial's stream (``keyed_rng`` of the session, participant and trial seed), in a generator re-seeded
        in place: draw from it at once; the next trial's call starts its own stream in the same object."""
        return self._trial_generator.at(*self.trial_keys(row))

    def trial_keys(self, row: TrialRow) -> tuple[int, int, int, int]:
        """The keys of the trial's stream (:meth:`trial_rng`): session seed, participant, trial seed, 11."""
        return self.seed, self._participant_key, int(row["trial_seed"]), 11

    @abstractmethod
    def collect(self, row: TrialRow, now_s: float) -> Response:
        """The simulated answer to ``row`` (at once: a simulated observer never waits)."""

    def decision(self, row: TrialRow) -> tuple[float, float] | None:
        """``(u, p)``: the trial's uniform draw and the probability it is compared with (the answer is the
        probable one when ``u < p``), or None for an observer whose answer is not one such draw (reach).

        ``u`` is exact on every machine (integers from the keyed stream, times 2**-53); ``p`` goes through
        libm (``math.erf``) and numpy's normal draws, whose last bits may differ between CPUs and libm builds.
        An answer can therefore differ between machines only where ``|u - p|`` is within those bits, about
        1e-16: tests/session/test_observer_margins.py measures the margins of the shipped studies."""
        return None

    def timed_out(self) -> None:
        return None

    def close(self) -> None:
        return None


class Psychometric2AFC(SimulatedObserver):
    """p(correct) = 0.5 + (0.5 - lapse) * Phi((x - threshold) / width) (psignifit's 2AFC form,
    as psyop.statistics.simulate uses).

    At x = threshold this is 0.75 without lapse: ``threshold_D`` is the 75 % point. The
    threshold may depend on a row column: ``threshold_slope`` x its value (a factor of numbers), or
    ``threshold_offset_D[level]`` (any factor, e.g. a mode effect), and varies between participants with sd
    ``between_subject_sd_D``.
    """

    kind = kind_named("two_interval")

    def __init__(self, params: JsonMapping, *, seed: int, participant: str) -> None:
        super().__init__(params, seed=seed, participant=participant)
        self.level_column = str(_get(params, "level_column", "level_D"))
        self.threshold_D = float(_get(params, "threshold_D", required=True))
        self.width_D = float(_get(params, "width_D", required=True))
        self.lapse = float(_get(params, "lapse", 0.0))
        self.slope = float(_get(params, "threshold_slope", 0.0))
        self.offset_column = _get(params, "threshold_offset_column")
        #: the threshold's offset per level of the offset column (None: ``threshold_slope`` x its value)
        self.offsets_D = None if _get(params, "threshold_offset_D") is None else \
            {str(k): float(v) for k, v in dict(_get(params, "threshold_offset_D")).items()}
        sd = float(_get(params, "between_subject_sd_D", 0.0))
        self.participant_shift_D = float(self._participant_rng.normal(0.0, sd)) if sd > 0 else 0.0
        if self.width_D <= 0 or not 0 <= self.lapse < 0.5:
            raise UserError("observer: width_D must be > 0 and lapse in [0, 0.5)", "protocol observer")

    def threshold_for(self, row: TrialRow) -> float:
        if self.offset_column and self.offsets_D is not None:
            level = format_level(row[self.offset_column])
            if level not in self.offsets_D:
                raise UserError(f"observer: threshold_offset_D has no offset for {self.offset_column} = {level}",
                                "protocol observer")
            return self.threshold_D + self.participant_shift_D + self.offsets_D[level]
        offset = float(row[self.offset_column]) if self.offset_column else 0.0
        return self.threshold_D + self.participant_shift_D + self.slope * offset

    def p_correct(self, row: TrialRow) -> float:
        x = float(row[self.level_column])
        return 0.5 + (0.5 - self.lapse) * _phi((x - self.threshold_for(row)) / self.width_D)

    def decision(self, row: TrialRow) -> tuple[float, float]:
        # the trial stream's one uniform (trial_rng(row).uniform(), without re-seeding a Generator)
        return keyed_uniform(*self.trial_keys(row)), self.p_correct(row)

    def collect(self, row: TrialRow, now_s: float) -> Response:
        u, p = self.decision(row)
        correct = bool(u < p)
        right = int(row["correct_interval"])
        answer = right if correct else 3 - right
        return score(self.kind, row, str(answer))


class OrdinalAccuracy(SimulatedObserver):
    """p(correct) looked up by (mode, separation_D).

    ``p_correct`` is a mapping ``{mode: {separation_D: p}}`` (keys may be strings) or a
    list of ``{mode, separation_D, p}`` records.
    """

    kind = kind_named("left_right_nearer")

    def __init__(self, params: JsonMapping, *, seed: int, participant: str) -> None:
        super().__init__(params, seed=seed, participant=participant)
        table = _get(params, "p_correct", required=True)
        self.table: dict[tuple[str, float], float] = {}
        if isinstance(table, Mapping):
            for mode, by_sep in table.items():
                for sep, p in dict(by_sep).items():
                    self.table[(str(mode), round(float(sep), 6))] = float(p)
        else:
            for record in table:
                record = dict(record)
                self.table[(str(record["mode"]), round(float(record["separation_D"]), 6))] = float(record["p"])
        sd = float(_get(params, "between_subject_sd", 0.0))
        self.participant_shift = float(self._participant_rng.normal(0.0, sd)) if sd > 0 else 0.0
        # the response's separation factor (the session plan passes its name)
        self.separation_column = str(_get(params, "separation_column", "separation_D"))

    def p_correct(self, row: TrialRow) -> float:
        key = (str(row["mode"]), round(float(row[self.separation_column]), 6))
        if key not in self.table:
            raise UserError(f"observer: no p_correct for mode={key[0]!r}, separation_D={key[1]}", "protocol observer")
        return float(np.clip(self.table[key] + self.participant_shift, 0.0, 1.0))

    def decision(self, row: TrialRow) -> tuple[float, float]:
        return float(self.trial_rng(row).uniform()), self.p_correct(row)

    def collect(self, row: TrialRow, now_s: float) -> Response:
        u, p = self.decision(row)
        correct = bool(u < p)
        near = str(row["near_side"])
        other = "left" if near == "right" else "right"
        return score(self.kind, row, near if correct else other)


class PairwisePreference(SimulatedObserver):
    """Bradley-Terry: p(choose a) = s_a / (s_a + s_b) with a positive strength per mode."""

    kind = kind_named("pairwise_preference")

    def __init__(self, params: JsonMapping, *, seed: int, participant: str) -> None:
        super().__init__(params, seed=seed, participant=participant)
        strengths = _get(params, "strengths", None) or _get(params, "strength", required=True)
        self.strengths = {str(k): float(v) for k, v in dict(strengths).items()}
        if any(not (v > 0 and math.isfinite(v)) for v in self.strengths.values()):
            raise UserError("observer: Bradley-Terry strengths must be positive", "protocol observer")

    def p_a(self, row: TrialRow) -> float:
        a, b = str(row["mode_a"]), str(row["mode_b"])
        for mode in (a, b):
            if mode not in self.strengths:
                raise UserError(f"observer: no strength for mode {mode!r}", "protocol observer")
        return self.strengths[a] / (self.strengths[a] + self.strengths[b])

    def decision(self, row: TrialRow) -> tuple[float, float]:
        return float(self.trial_rng(row).uniform()), self.p_a(row)

    def collect(self, row: TrialRow, now_s: float) -> Response:
        u, p = self.decision(row)
        return score(self.kind, row, "a" if u < p else "b")


class Reach(SimulatedObserver):
    """Horizontal reach = intercept_m + slope * target_m + a participant's own deviations + N(0, noise_sd_m).

    ``target_m = target_fraction * arm_reach_m`` (the target's horizontal distance). Parameters:
    ``by_condition: {enabled: {slope, intercept_m, noise_sd_m}, disabled: {...}}`` (or the three
    keys at top level for every condition), ``arm_reach_m`` (mean) and ``arm_reach_sd_m`` between
    people; ``slope_sd`` and ``intercept_sd_m``: each participant's line deviates from the
    condition's by one draw of each (shared by the conditions); ``max_reach_fraction``: the hand
    ends at most this fraction of the arm reach from the eyes (3-D), a physical bound.
    The hand ends at :data:`psyop.session.reach.HAND_HEIGHT_M` below the eyes, straight ahead;
    ``reach_m`` is its horizontal distance (psyop.session.reach).
    """

    kind = kind_named("reach")

    def __init__(self, params: JsonMapping, *, seed: int, participant: str) -> None:
        super().__init__(params, seed=seed, participant=participant)
        arm_mean = float(_get(params, "arm_reach_m", 0.7))
        arm_sd = float(_get(params, "arm_reach_sd_m", 0.0))
        self.arm_reach_m = arm_mean + (float(self._participant_rng.normal(0.0, arm_sd)) if arm_sd > 0 else 0.0)
        slope_sd = float(_get(params, "slope_sd", 0.0))
        intercept_sd = float(_get(params, "intercept_sd_m", 0.0))
        self.slope_offset = float(self._participant_rng.normal(0.0, slope_sd)) if slope_sd > 0 else 0.0
        self.intercept_offset_m = float(self._participant_rng.normal(0.0, intercept_sd)) if intercept_sd > 0 else 0.0
        self.max_reach_m = float(_get(params, "max_reach_fraction", 1.0)) * self.arm_reach_m
        self.conditions = {str(k): dict(v) for k, v in dict(_get(params, "by_condition", None) or _get(params, "conditions", {}) or {}).items()}

    def _condition(self, rendering: str) -> JsonMapping:
        cond = self.conditions.get(rendering, self.params)
        for key in ("slope", "intercept_m", "noise_sd_m"):
            if key not in cond:
                raise UserError(f"observer: reach condition {rendering!r} lacks {key!r}", "protocol observer")
        return cond

    def collect(self, row: TrialRow, now_s: float) -> Response:
        """Where the hand really ends (the observer's motor output, ``reach_m`` = its horizontal
        distance). A hand tracker (the session's pose source) then measures it with its own error."""
        cond = self._condition(str(row.get("rendering", "")))
        target_m = float(row["target_fraction"]) * self.arm_reach_m
        rng = self.trial_rng(row)
        reach = (float(cond["intercept_m"]) + self.intercept_offset_m + (float(cond["slope"]) + self.slope_offset) * target_m
                 + float(rng.normal(0.0, float(cond["noise_sd_m"]))))
        horizontal_max = math.sqrt(max(self.max_reach_m ** 2 - HAND_HEIGHT_M ** 2, 0.0))
        reach = min(max(reach, 0.0), horizontal_max)  # the hand cannot end behind the eyes or beyond the arm
        endpoint = np.array([0.0, HAND_HEIGHT_M, -reach])
        r = score(self.kind, row, f"{reach:.6f}", reach_m=reach)
        extras = (("arm_reach_m", self.arm_reach_m), ("target_m", target_m),
                  ("hand_x_m", float(endpoint[0])), ("hand_y_m", float(endpoint[1])), ("hand_z_m", float(endpoint[2])))
        return Response(r.response, r.correct, r.reach_m, r.chosen_mode, r.response_time_s, extras)


#: The sign of the NC each rendering mode renders (psyop.optics.camera: the centre of projection's lateral
#: offset from the centre of rotation is +N ocular, 0 conventional, mirrored reversed).
MODE_NC_SIGN: dict[str, float] = {"ocular": 1.0, "conventional": 0.0, "reversed": -1.0}


class NcNulling(SimulatedObserver):
    """An observer with its own NC (protocol ``observer: {kind: nc_nulling}``): p(against) =
    lapse + (1 - 2 lapse) * Phi((r - nc_mm) / width_mm), r the signed NC the trial's interval is rendered
    with, read as the camera reads it: the interval's mode (``mode_interval1``) and the protocol's rendering
    NC rule (``rendering_nc``, the plan passes it with the eye model's NC, psyop.optics.rig.NcRule), never the
    schedule's ``rendered_nc_mm``. Rendered below its own NC the scene lags the eye's parallax: 'with'.
    Each participant's NC is ``nc_mm`` + N(0, ``between_subject_sd_mm``), drawn once (:attr:`own_nc_mm`)."""

    kind = kind_named("with_against")

    def __init__(self, params: JsonMapping, *, seed: int, participant: str) -> None:
        from psyop.optics.rig import NcRule

        super().__init__(params, seed=seed, participant=participant)
        self.width_mm = float(_get(params, "width_mm", required=True))
        self.lapse = float(_get(params, "lapse", 0.0))
        sd = float(_get(params, "between_subject_sd_mm", 0.0))
        shift = float(self._participant_rng.normal(0.0, sd)) if sd > 0 else 0.0
        self.own_nc_mm = float(_get(params, "nc_mm", required=True)) + shift
        rule = _get(params, "rendering_nc", required=True)
        self.rule = NcRule(**dict(rule))
        self.eye_model_nc_m = float(_get(params, "eye_model_nc_m", required=True))
        if self.width_mm <= 0 or not 0 <= self.lapse < 0.5:
            raise UserError("observer: width_mm must be > 0 and lapse in [0, 0.5)", "protocol observer")

    def rendered_nc_mm(self, row: TrialRow) -> float:
        """The signed NC this trial is rendered with (mm): the mode's sign times the camera's NC."""
        mode = str(row["mode_interval1"])
        if mode not in MODE_NC_SIGN:
            raise UserError(f"observer: trial {row.get('trial')} has no rendering mode ({mode!r})", "protocol observer")
        return MODE_NC_SIGN[mode] * self.rule.nc_m_for(self.eye_model_nc_m, row) * 1000.0

    def p_against(self, row: TrialRow) -> float:
        z = (self.rendered_nc_mm(row) - self.own_nc_mm) / self.width_mm
        return self.lapse + (1.0 - 2.0 * self.lapse) * _phi(z)

    def decision(self, row: TrialRow) -> tuple[float, float]:
        return float(self.trial_rng(row).uniform()), self.p_against(row)

    def collect(self, row: TrialRow, now_s: float) -> Response:
        u, p = self.decision(row)
        return score(self.kind, row, "against" if u < p else "with")


OBSERVERS: dict[str, type[SimulatedObserver]] = {
    "psychometric_2afc": Psychometric2AFC,
    "ordinal_accuracy": OrdinalAccuracy,
    "pairwise_preference": PairwisePreference,
    "reach": Reach,
    "nc_nulling": NcNulling,
}


class DeclaredObserver(SimulatedObserver):
    """An observer a response kind declares (psyop.protocol.kinds): its model answers each trial from the
    participant's draws (drawn once from the participant stream) and the trial's one keyed uniform."""

    def __init__(self, params: JsonMapping, *, seed: int, participant: str) -> None:
        super().__init__(params, seed=seed, participant=participant)
        self.kind, model = declared_observer(str(params.get("kind")))
        self.model = model.model_validate({k: v for k, v in params.items() if k in model.model_fields})
        self.participant_state = self.model.participant_draws(self._participant_rng)

    def decision(self, row: TrialRow) -> tuple[float, float] | None:
        p = self.model.probability(row, self.participant_state)
        return None if p is None else (keyed_uniform(*self.trial_keys(row)), p)

    def collect(self, row: TrialRow, now_s: float) -> Response:
        u = keyed_uniform(*self.trial_keys(row))
        r = score(self.kind, row, self.model.answer(row, self.participant_state, u))
        extras = self.model.extras(row, self.participant_state, u)
        return r if not extras else dataclasses.replace(r, extras=tuple(extras.items()))


def declared_observer(name: str) -> tuple[ResponseKindSpec, type[ObserverBase]]:
    """The kind and model of the declared observer ``name`` (a KeyError when no kind declares one)."""
    for kind in KINDS.values():
        for model in kind.observer_models:
            if model.declared and observer_kind_name(model) == name:
                return kind, model
    raise KeyError(name)


def make_observer(params: JsonMapping, *, seed: int, participant: str) -> SimulatedObserver:
    """Build the observer named by ``params['kind']`` (or ``type``/``model``)."""
    name = params.get("kind") or params.get("type") or params.get("model")
    if name in OBSERVERS:
        return OBSERVERS[name](params, seed=seed, participant=participant)
    try:
        declared_observer(str(name))
    except KeyError:
        known = sorted(OBSERVERS) + sorted(observer_kind_name(m) for k in KINDS.values() for m in k.observer_models
                                           if m.declared)
        raise UserError(f"observer: unknown kind {name!r}; expected one of {known}", "protocol observer") from None
    return DeclaredObserver(params, seed=seed, participant=participant)
