"""The simulated observers' shared machinery (protocol ``observer:`` section; docs/architecture.md,
"Simulated observers").

Each observer's behaviour is declared by its response kind (psyop.protocol.kinds: an ``ObserverBase`` with
``declared = True``); this module gives it its seeded draws and builds its :class:`Response`. Each answer is
deterministic given (session seed, participant, trial_seed): it does not depend on which trials ran before it in
this process, so a resumed session answers exactly as an uninterrupted one. Between-subject variation is drawn once
per participant from (seed, participant). The confidence model (:meth:`SimulatedObserver.confidence`) applies to
any observer that answers by one draw against a probability.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod

import numpy as np

from psyop.session.rows import JsonMapping, TrialRow
from psyop.errors import UserError
from psyop.session.gaze.keyed import KeyedGenerator, keyed_rng, keyed_uniform
from psyop.session.gaze.simulated import seed_for
from psyop.protocol.kinds import KINDS
from psyop.protocol.kinds.base import ObserverBase, ResponseKindSpec, observer_kind_name
from psyop.protocol.kinds.confidence import ObserverConfidence, simulated_confidence
from psyop.session.responses.base import Response, score


class SimulatedObserver(ABC):
    """Base: per-trial and per-participant random streams and the confidence hook; :class:`DeclaredObserver`
    (and the image observer, psyop.session.responses.image_observer) implement :meth:`collect`
    (the :class:`~psyop.session.responses.base.ResponseSource` seam)."""

    needs_images = False

    def __init__(self, params: JsonMapping, *, seed: int, participant: str) -> None:
        self.params = dict(params)
        self.seed = int(seed)
        self.participant = participant
        self._participant_rng = keyed_rng(seed_for("participant", participant), self.seed)
        self._participant_key = seed_for(participant)  # the trial streams' second key, once
        self._trial_generator = KeyedGenerator()  # re-seeded per trial (each collect draws from it at once)
        raw = self.params.get("confidence")  # the observer's confidence model (None: it rates no confidence)
        self.confidence_model = None if raw is None else ObserverConfidence.model_validate(raw)

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

    def confidence(self, row: TrialRow, points: int) -> int | None:
        """The confidence (1..``points``) in the answer to ``row``: the ``confidence`` model's ``criteria``,
        ``meta_noise_sd`` and ``evidence_weight`` (psyop.protocol.kinds.confidence states it) applied to the draw the
        answer came from (:meth:`decision`) and the trial's own meta-noise draw (key 12 beside the answer's 11);
        None: no confidence model, or an answer that is not one such draw (reach)."""
        decision = self.decision(row)
        if self.confidence_model is None or decision is None:
            return None
        u, p = decision
        seed, participant, trial_seed, _ = self.trial_keys(row)
        meta_u = keyed_uniform(seed, participant, trial_seed, 12)
        return simulated_confidence(self.confidence_model, u, p, int(row.get("n_alternatives", 2)), meta_u, points)

    def timed_out(self) -> None:
        return None

    def close(self) -> None:
        return None


class DeclaredObserver(SimulatedObserver):
    """An observer a response kind declares (psyop.protocol.kinds, e.g. two_interval's ``psychometric_2afc``): its
    model (:meth:`~psyop.protocol.kinds.base.ObserverBase.for_session` of the plan's parameters) answers each trial
    from the participant's draws (drawn once from the participant stream, :attr:`participant_state`) and the
    trial's one keyed uniform, or, where the model :attr:`~psyop.protocol.kinds.base.ObserverBase.draws_stream`,
    from the trial's keyed generator (:meth:`trial_rng`)."""

    def __init__(self, params: JsonMapping, *, seed: int, participant: str, name: str) -> None:
        super().__init__(params, seed=seed, participant=participant)
        self.kind, model = declared_observer(name)
        self.model = model.for_session(params)
        #: what the model drew for this participant (e.g. ``participant_shift_D``, ``own_nc_mm``, ``arm_reach_m``)
        self.participant_state = self.model.participant_draws(self._participant_rng)

    def decision(self, row: TrialRow) -> tuple[float, float] | None:
        p = None if self.model.draws_stream else self.model.probability(row, self.participant_state)
        return None if p is None else (keyed_uniform(*self.trial_keys(row)), p)

    def collect(self, row: TrialRow, now_s: float) -> Response:
        if self.model.draws_stream:
            drawn = self.model.answer_drawn(row, self.participant_state, self.trial_rng(row))
            r, extras = score(self.kind, row, drawn.answer, reach_m=drawn.reach_m), drawn.extras
        else:
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
    name = str(params.get("kind") or params.get("type") or params.get("model"))
    try:
        declared_observer(name)
    except KeyError:
        known = sorted(observer_kind_name(m) for k in KINDS.values() for m in k.observer_models if m.declared)
        raise UserError(f"observer: unknown kind {name!r}; expected one of {known}", "protocol observer") from None
    return DeclaredObserver(params, seed=seed, participant=participant, name=name)
