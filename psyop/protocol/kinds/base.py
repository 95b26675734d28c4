"""What a response kind is: one object that owns everything a protocol's ``response:`` section means.

A kind (:class:`ResponseKindSpec`, one module per kind in this package, found by
:mod:`psyop.protocol.kinds`) owns

- its protocol model (:attr:`~ResponseKindSpec.model`, the ``response:`` section) and the simulated observer
  models it accepts (:attr:`~ResponseKindSpec.observer_models`, the ``observer:`` section);
- the checks that need the whole protocol (:meth:`~ResponseKindSpec.check`, :meth:`~ResponseKindSpec.check_design`,
  :meth:`~ResponseKindSpec.check_observer`);
- the schedule columns it adds (:meth:`~ResponseKindSpec.columns`);
- how raw input becomes an answer: a key (:attr:`~ResponseKindSpec.keys`), a response-box button
  (:attr:`~ResponseKindSpec.buttons`), an OpenXR controller's select button (:attr:`~ResponseKindSpec.controller`);
  devices emit only the raw, time-stamped input, as PsychoPy's ``BaseResponse(t, value)`` does;
- how an answer is scored (:meth:`~ResponseKindSpec.score`);
- its analysis in ``make figures`` (:meth:`~ResponseKindSpec.targets`) and its name in ``psyop studies``.

Its one spelling, :attr:`~ResponseKindSpec.name`, is the protocol's ``kind:``, session.json's ``response_kind``
and what the analysis reads. This module is imported by the protocol layer, so it imports nothing above it:
the checker is the structural :class:`Checks`, the analysis targets are data (:class:`AnalysisTarget`).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Literal, Protocol

import numpy as np
from pydantic import Field

from psyop.protocol.base import Number, StrictModel
from psyop.protocol.kinds.confidence import ConfidenceScale, ObserverConfidence
from psyop.protocol.design import Design, Factor
from psyop.protocol.display import DisplaySpec
from psyop.protocol.scene import Primitive, RenderingMode
from psyop.protocol.simulated_eye import SimulatedEye
from psyop.records import Loc, TrialRow


#: How an order or side is assigned. ``balanced``: within each condition, as evenly as possible
#: (an odd count gets its extra trial on a seeded random side). ``random``: a fair coin per trial.
Counterbalance = Literal["balanced", "random"]


class ModeFromFactor(StrictModel):
    """The rendering mode is the trial's level of a factor whose levels are mode names."""

    factor: str


def mode_factor_of(mode: RenderingMode | ModeFromFactor) -> set[str]:
    """The factor a mode is read from ({} for a fixed mode)."""
    return {mode.factor} if isinstance(mode, ModeFromFactor) else set()


class IntervalSpec(StrictModel):
    """One stimulus of a trial: its rendering mode and factor overrides (``set: {level_D: 0}`` shows the
    reference with the level at 0)."""

    mode: RenderingMode | ModeFromFactor
    set: dict[str, Number] = Field(default_factory=dict)


class KindResponse(StrictModel):
    """What every kind's ``response:`` model has: its ``kind`` and ``question``, how many interval phases a
    trial needs, how its counterbalanced choice is drawn, and which factors it reads."""

    kind: str
    question: str
    #: a confidence rating asked after the choice (psyop.protocol.kinds.confidence; only where the kind takes one)
    confidence: ConfidenceScale | None = None
    intervals_needed: ClassVar[int] = 1

    @property
    def counterbalance(self) -> Counterbalance:
        """How the schedule's counterbalanced 0/1 choice is drawn (kinds without one: balanced and unused)."""
        return "balanced"

    def interval_specs(self) -> tuple[IntervalSpec, ...]:
        """The per-interval specs (none for most kinds)."""
        return ()

    def factors_read(self) -> set[str]:
        """The design factors this response reads (a factor nothing reads is refused at validation)."""
        return set()

    def intervals(self) -> int:
        """How many interval phases a trial of this response has (the class's ``intervals_needed``)."""
        return self.intervals_needed

    def level(self) -> str | None:
        """The factor whose level a psychometric function is fitted over (None: the kind has none)."""
        return None

    def identical_conditions(self) -> list[dict[str, str | float]]:
        """The conditions whose intervals are meant to render identically (a control; ``psyop audit`` reports them
        as intended), each as factor -> level (none for a kind without the declaration)."""
        return []

    def scene_variables(self) -> dict[str, tuple[float, float]]:
        """Per-trial variables the scene may read as ``{factor: NAME}`` though no design factor (an adjustment's
        adjusted value), each with the range it can take (validation checks the scene at both ends)."""
        return {}


def normal_cdf(z: float) -> float:
    """The standard normal CDF (``math.erf``; a simulated observer's psychometric functions, without scipy)."""
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


@dataclass(frozen=True)
class DrawnAnswer:
    """An answer drawn from a trial's keyed generator (:meth:`ObserverBase.answer_drawn`): the answer, the reach
    distance it reports (None: no reach) and its trial-log values beside it."""

    answer: str
    reach_m: float | None = None
    extras: Mapping[str, float | str] = field(default_factory=dict)


class ObserverBase(StrictModel):
    """What every simulated observer has: ``eye``, the simulated eye and tracker (psyop.protocol.simulated_eye).

    A kind's own observer (:attr:`declared` True) answers through :meth:`participant_draws` and :meth:`answer`
    (or :meth:`answer_drawn`), which the session's simulated-observer source (psyop.session.responses.simulated)
    calls with seeded draws; an observer that is not declared has its own source (the image observer,
    psyop.session.responses.image_observer)."""

    kind: str
    eye: SimulatedEye | None = None
    #: how it rates its confidence after a choice (psyop.protocol.kinds.confidence; only with a confidence scale)
    confidence: ObserverConfidence | None = None
    #: this model answers through :meth:`answer` (False: a response source of its own implements it)
    declared: ClassVar[bool] = False
    #: the answer needs more than the trial's one uniform draw: :meth:`answer_drawn` answers from the trial's
    #: keyed generator instead of :meth:`answer` and :meth:`extras`
    draws_stream: ClassVar[bool] = False

    @classmethod
    def for_session(cls, params: Mapping[str, object]) -> "ObserverBase":
        """The model from the session plan's observer parameters (psyop.session.plan.SessionPlan.observer_params:
        this section's fields and what the plan adds, the schedule columns and rig values it reads); the default
        validates the model's own fields and ignores the rest."""
        return cls.model_validate({k: v for k, v in params.items() if k in cls.model_fields})

    def participant_draws(self, rng: np.random.Generator) -> dict[str, float]:
        """What varies between simulated participants, drawn once per participant from ``rng``."""
        return {}

    def answer_drawn(self, row: TrialRow, participant: Mapping[str, float], rng: np.random.Generator) -> DrawnAnswer:
        """The answer to trial ``row`` of an observer that :attr:`draws_stream`, from the participant's draws and
        ``rng``, the trial's keyed generator freshly seeded (its first uniform is :meth:`answer`'s ``u``)."""
        raise NotImplementedError(f"{type(self).__name__} answers from the trial's one uniform draw (answer)")

    def answer(self, row: TrialRow, participant: Mapping[str, float], u: float) -> str:
        """The answer (a value of the kind's key map) to trial ``row``, from the participant's draws and ``u``,
        the trial's one uniform draw in [0, 1) (exact on every machine)."""
        raise NotImplementedError(f"{type(self).__name__} answers in psyop.session.responses.simulated")

    def probability(self, row: TrialRow, participant: Mapping[str, float]) -> float | None:
        """For a binary answer: p of the answer given when ``u < p`` (the margin tests read it); else None."""
        return None

    def extras(self, row: TrialRow, participant: Mapping[str, float], u: float) -> dict[str, float | str]:
        """Trial-log values beside the answer (an adjustment's path), from the same draws as :meth:`answer`."""
        return {}


class ProtocolParts(Protocol):
    """The parts of a protocol (psyop.protocol.model.Protocol) a kind reads beside its own section."""

    @property
    def display(self) -> DisplaySpec: ...

    @property
    def design(self) -> Design: ...

    @property
    def scene(self) -> Sequence[Primitive]: ...


class Checks(Protocol):
    """The part of the protocol checker (psyop.protocol.semantics) a kind's checks use."""

    @property
    def p(self) -> ProtocolParts: ...

    @property
    def factors(self) -> Mapping[str, Factor]: ...

    def add(self, path: tuple[str | int | float, ...], message: str) -> None: ...

    def factor_exists(self, name: str, path: Loc, *, numeric: bool | None = None) -> bool: ...

    def mode_factor(self, name: str, path: Loc) -> None: ...


@dataclass(frozen=True)
class ScheduleInput:
    """What a kind's schedule columns are drawn from: the protocol, the design columns so far (one entry per
    trial, practice first), the counterbalanced 0/1 choice per trial (:data:`Counterbalance`), the trials'
    condition indices, and the kind's own seeded stream (independent of every other stream of the schedule)."""

    protocol: ProtocolParts
    columns: Mapping[str, np.ndarray]
    binary: np.ndarray
    condition: np.ndarray
    practice: np.ndarray
    rng: np.random.Generator

    @property
    def n(self) -> int:
        return int(self.binary.size)


@dataclass(frozen=True)
class Scored:
    """An answer as the kind scores it: whether it was correct (None: no correct answer), the rendering mode
    chosen (preference kinds), and its number (``response_value``; None where the answer is no number)."""

    correct: bool | None = None
    chosen_mode: str | None = None


@dataclass(frozen=True)
class Inputs:
    """The raw inputs that answer one protocol's response, each mapped to an answer: keyboard key names (lower
    case), response-box buttons (the character after ``B``), OpenXR controller select buttons (``left`` /
    ``right``). An empty map: that device cannot answer it."""

    keys: Mapping[str, str]
    buttons: Mapping[str, str]
    controller: Mapping[str, str]


#: the response sources whose inputs a default prompt names (psyop run --responses), and how each names one input
InputSource = Literal["keyboard", "serial", "openxr"]
INPUT_SOURCES: tuple[InputSource, ...] = ("keyboard", "serial", "openxr")
#: keyboard key names (psyop.devices.responses.keyboard) as a participant reads them; a letter is written upper case
KEY_NAMES: Mapping[str, str] = {"left": "left arrow", "right": "right arrow", "up": "up arrow", "down": "down arrow",
                                "space": "space bar", "enter": "Enter", "kp_enter": "keypad Enter",
                                "kp_add": "keypad +", "kp_subtract": "keypad -"}


def input_name(source: InputSource, raw: str) -> str:
    """How a prompt names raw input ``raw`` of ``source``: a key (``left arrow``, ``Y``, ``keypad 1``), a response-box
    button (``button L``), a controller's select button (``left trigger``: the trigger on the Vive, Index and Touch
    controllers, select on the Khronos simple controller).

    Examples
    --------
    >>> input_name("keyboard", "left"), input_name("keyboard", "y"), input_name("serial", "1"), input_name("openxr", "right")
    ('left arrow', 'Y', 'button 1', 'right trigger')
    """
    if source == "serial":
        return f"button {raw}"
    if source == "openxr":
        return f"{raw} trigger"
    if raw in KEY_NAMES:
        return KEY_NAMES[raw]
    if raw.startswith("kp_"):
        return f"keypad {raw.removeprefix('kp_')}"
    return raw.upper() if len(raw) == 1 else raw


def inputs_text(inputs: Inputs, source: InputSource, labels: Mapping[str, str] | None = None) -> str | None:
    """One line per answer naming the inputs of ``source`` that give it, answers in the map's order, e.g.
    ``left: left arrow / L`` (an answer written as ``labels`` names it, else as itself); a keypad key is left out
    where its top-row twin is named. None: ``source`` cannot answer (an empty map).

    Examples
    --------
    >>> print(inputs_text(Inputs({"y": "yes", "n": "no", "kp_1": "yes", "1": "yes"}, {}, {}), "keyboard"))
    yes: Y / 1
    no: N
    """
    raw_map = {"keyboard": inputs.keys, "serial": inputs.buttons, "openxr": inputs.controller}[source]
    by_answer: dict[str, list[str]] = {}
    for raw, answer in raw_map.items():
        if source == "keyboard" and raw.startswith("kp_") and raw.removeprefix("kp_") in raw_map:
            continue
        by_answer.setdefault(answer, []).append(input_name(source, raw))
    names_of = labels or {}
    return "\n".join(f"{names_of.get(answer, answer)}: {' / '.join(names)}"
                     for answer, names in by_answer.items()) or None


@dataclass(frozen=True)
class AnalysisTarget:
    """One output of a study's analysis in ``make figures``: the file (relative to $(FIGDIR) or $(RESULTS)),
    the script and its extra make prerequisites and arguments."""

    output: str
    script: str
    prerequisites: str
    arguments: str
    kind: str = "figure"  # figure (in $(FIGDIR)) or fits (in $(RESULTS))


@dataclass(frozen=True)
class StudyInputs:
    """What a kind's analysis targets are built from: the study (or protocol version) name, its sessions'
    trials.parquet files as make prerequisites, whether it is a linear-fit (discrimination) study, and
    whether an adaptive procedure placed its levels, and its level factor (None: unknown, or a kind without one)."""

    study: str
    trials: str = ""
    linear_fit: bool = False
    adaptive: bool = False
    level_factor: str | None = None

    @property
    def common_arguments(self) -> str:
        return f'--study {self.study} --data "$(DATA)" --results "$(RESULTS)"'


class ResponseKindSpec(ABC):
    """One response kind (see the module docstring). Subclasses set the class attributes and implement
    :meth:`columns`; the other methods have the defaults of a kind without them."""

    #: the one spelling: the protocol's ``kind:``, session.json's ``response_kind``, the analysis's kind
    name: ClassVar[str]
    #: session.json spellings of this kind written before it had one (read, never written)
    former_names: ClassVar[tuple[str, ...]] = ()
    #: how ``psyop studies`` and make's progress lines name it
    label: ClassVar[str]
    model: ClassVar[type[KindResponse]]
    observer_models: ClassVar[tuple[type[ObserverBase], ...]] = ()
    #: keyboard key name (lower case) -> answer
    keys: ClassVar[Mapping[str, str]] = {}
    #: serial response-box button (the character after ``B``) -> answer; empty: a box cannot answer it
    buttons: ClassVar[Mapping[str, str]] = {}
    #: OpenXR controller select button ('left' / 'right' hand) -> answer
    controller: ClassVar[Mapping[str, str]] = {}
    #: how a default prompt names an answer (e.g. '1' -> 'first interval'); an answer not listed: as itself
    answer_labels: ClassVar[Mapping[str, str]] = {}
    #: the answer is a hand position read when the participant confirms (keys map to 'confirm')
    needs_hand_pose: ClassVar[bool] = False
    #: the answer is one discrete choice, which a confidence rating may follow (psyop.protocol.kinds.confidence)
    takes_confidence: ClassVar[bool] = False
    #: who reads each field of this kind's models (model name -> field -> user of psyop.protocol.fields:
    #: ``kinds`` for this module, ``plan``, ``observer``, ...); a test checks each user's source names it
    fields: ClassVar[Mapping[str, Mapping[str, str]]] = {}

    def __repr__(self) -> str:
        return f"<response kind {self.name}>"

    @abstractmethod
    def columns(self, response: KindResponse, schedule: ScheduleInput) -> dict[str, np.ndarray]:
        """The schedule columns of this kind (psyop.schedule.compile adds them to every trial)."""

    def check(self, response: KindResponse, checks: Checks, path: Loc) -> None:
        """Checks of the ``response:`` section against the design (psyop.protocol.semantics)."""
        return None

    def check_design(self, response: KindResponse, checks: Checks) -> None:
        """Checks of the design's factors that only this kind needs."""
        return None

    def check_observer(self, observer: ObserverBase, response: KindResponse, checks: Checks, path: Loc) -> None:
        """Checks of the ``observer:`` section (its kind is one of :attr:`observer_models`)."""
        return None

    def inputs(self, response: KindResponse) -> Inputs:
        """The inputs that answer ``response`` (the class maps; a kind whose answers depend on its section, e.g.
        a scale's points, narrows them)."""
        return Inputs(self.keys, self.buttons, self.controller)

    def score(self, row: TrialRow, answer: str) -> Scored:
        """``answer`` (one of the values of :attr:`keys`) scored against the trial ``row``."""
        return Scored()

    def response_text(self, response: KindResponse) -> str | None:
        """Lines the participant reads under the prompt on the response panel (e.g. a rating scale's points and
        labels), each kept on its own line; None: the prompt alone (psyop.session.plan.ResponsePlan)."""
        return None

    def answer_keys_text(self, response: KindResponse, source: InputSource) -> str | None:
        """The lines a default prompt (no ``prompt:`` given) adds under the question: which inputs of ``source``
        give each answer (:func:`inputs_text` of :meth:`inputs`); None: nothing to add."""
        return inputs_text(self.inputs(response), source, self.answer_labels)

    @abstractmethod
    def targets(self, study: StudyInputs) -> list[AnalysisTarget]:
        """The study's analysis in ``make figures``."""

    def observer_kinds(self) -> tuple[str, ...]:
        """The ``observer: kind:`` names this response accepts."""
        return tuple(observer_kind_name(m) for m in self.observer_models)


def observer_kind_name(model: type[ObserverBase]) -> str:
    """The one value of an observer model's ``kind: Literal[...]`` field (what ``observer: kind:`` names)."""
    annotation = model.model_fields["kind"].annotation
    values: tuple[object, ...] = tuple(getattr(annotation, "__args__", ()))
    name = values[0] if len(values) == 1 else None
    if not isinstance(name, str):
        raise TypeError(f"{model.__name__}.kind must be a Literal of one name")
    return name


def figure_target(study: StudyInputs, suffix: str, script: str) -> AnalysisTarget:
    """A study's one figure ``<study>_<suffix>.png`` drawn by ``script`` from its trials."""
    return AnalysisTarget(f"{study.study}_{suffix}.png", script, f"{study.trials} $(DRAW_SRC)",
                          study.common_arguments)
