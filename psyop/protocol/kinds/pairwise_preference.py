"""``pairwise_preference``: which of two intervals looked more realistic. The pair factor's levels are
written ``first|second``; columns ``mode_a``, ``mode_b`` (in shown order) and ``pair``."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, ClassVar, Literal

import numpy as np
from pydantic import Field

from psyop.errors import UserError
from psyop.protocol.base import Number
from psyop.protocol.image_observer import ImageObserver, unread_fields
from psyop.protocol.kinds.base import (AnalysisTarget, Checks, Counterbalance, KindResponse, ObserverBase,
                                       ResponseKindSpec, ScheduleInput, Scored, StudyInputs, figure_target)
from psyop.protocol.scene import RENDERING_MODES, RenderingMode
from psyop.records import Loc, TrialRow


class PairwisePreferenceResponse(KindResponse):
    """Which of two intervals (modes ``a`` then ``b``) looked more realistic. The pair factor's
    levels are written ``first|second``; ``order`` counterbalances which is shown first."""

    kind: Literal["pairwise_preference"]
    intervals_needed: ClassVar[int] = 2
    question: str = "Which stimulus gave a stronger impression of realistic depth?"
    pair_factor: str = "pair"
    order: Counterbalance = "balanced"

    @property
    def counterbalance(self) -> Counterbalance:
        """How the pair order (which mode is shown first) is assigned."""
        return self.order

    def factors_read(self) -> set[str]:
        """The pair factor."""
        return {self.pair_factor}


class PairwisePreference(ObserverBase):
    """Bradley-Terry: p(a preferred over b) = s_a / (s_a + s_b)."""

    kind: Literal["pairwise_preference"]
    strength: dict[RenderingMode, Annotated[Number, Field(gt=0)]] = Field(min_length=2)
    declared: ClassVar[bool] = True

    def probability(self, row: TrialRow, participant: Mapping[str, float]) -> float:
        """p(the trial's mode ``a`` is chosen)."""
        a, b = str(row["mode_a"]), str(row["mode_b"])
        strengths: dict[str, float] = {str(mode): float(s) for mode, s in self.strength.items()}
        for mode in (a, b):
            if mode not in strengths:
                raise UserError(f"observer: no strength for mode {mode!r}", "protocol observer")
        return strengths[a] / (strengths[a] + strengths[b])

    def answer(self, row: TrialRow, participant: Mapping[str, float], u: float) -> str:
        """``a`` when ``u < p``, else ``b``."""
        return "a" if u < self.probability(row, participant) else "b"


class PairwisePreferenceKind(ResponseKindSpec):
    name = "pairwise_preference"
    former_names = ("preference",)
    label = "pairwise preference"
    takes_confidence = True  # one discrete choice: a confidence rating may follow
    model = PairwisePreferenceResponse
    observer_models = (PairwisePreference, ImageObserver)
    keys = {"1": "a", "2": "b", "a": "a", "b": "b", "left": "a", "right": "b"}
    buttons = {"1": "a", "2": "b", "A": "a", "B": "b", "L": "a", "R": "b"}
    controller = {"left": "a", "right": "b"}
    answer_labels = {"a": "first", "b": "second"}
    fields = {"PairwisePreferenceResponse": {"kind": "plan", "question": "plan", "pair_factor": "kinds",
                                             "order": "kinds"},
              "PairwisePreference": {"kind": "kinds", "strength": "kinds"},
              "ImageObserver": {k: "image_observer" for k in ImageObserver.model_fields if k != "eye"}}

    def columns(self, response: KindResponse, schedule: ScheduleInput) -> dict[str, np.ndarray]:
        """The two modes in shown order (``binary`` True: the pair's second mode first)."""
        assert isinstance(response, PairwisePreferenceResponse)
        out: dict[str, np.ndarray] = {}
        pairs = schedule.columns[response.pair_factor]
        first = np.array([p.split("|")[0] for p in pairs], dtype=object)
        second = np.array([p.split("|")[1] for p in pairs], dtype=object)
        out["mode_a"] = np.where(schedule.binary, second, first)
        out["mode_b"] = np.where(schedule.binary, first, second)
        if response.pair_factor != "pair":
            out["pair"] = pairs
        out["mode_interval1"] = out["mode_a"]
        out["mode_interval2"] = out["mode_b"]
        return out

    def check(self, response: KindResponse, checks: Checks, path: Loc) -> None:
        """Every pair level is two different rendering modes written ``a|b``."""
        assert isinstance(response, PairwisePreferenceResponse)
        if checks.factor_exists(response.pair_factor, path + ("pair_factor",), numeric=False):
            for level in checks.factors[response.pair_factor].all_levels():
                parts = str(level).split("|")
                if len(parts) != 2 or parts[0] == parts[1] or not set(parts) <= set(RENDERING_MODES):
                    checks.add(("design", "factors", response.pair_factor, "levels"),
                               f"pair level '{level}' must be two different modes written 'a|b' with modes from "
                               f"{', '.join(RENDERING_MODES)}")

    def check_design(self, response: KindResponse, checks: Checks) -> None:
        """``a|b`` and ``b|a`` are one comparison (``order`` already counterbalances which is shown first)."""
        assert isinstance(response, PairwisePreferenceResponse)
        if response.pair_factor not in checks.factors:
            return
        seen: dict[frozenset[str], str] = {}
        factor = checks.factors[response.pair_factor]
        for index, level in enumerate(factor.all_levels()):
            parts = frozenset(str(level).split("|"))
            if parts in seen:
                path: Loc = ("design", "factors", response.pair_factor, "levels")
                if isinstance(factor.levels, list):
                    path += (index,)
                checks.add(path, f"pair '{level}' is '{seen[parts]}' written in the other order: both are one "
                                 f"comparison (response.order: {response.order} already sets which is shown first); "
                                 f"remove '{level}'")
            seen.setdefault(parts, str(level))

    def check_observer(self, observer: ObserverBase, response: KindResponse, checks: Checks, path: Loc) -> None:
        if isinstance(observer, ImageObserver):  # prefers from the frames: nothing of the schedule to check
            for name in unread_fields(observer, self.name):
                checks.add(path + (name,), f"the image observer's preference rule does not read {name}; remove it")
            return
        assert isinstance(observer, PairwisePreference) and isinstance(response, PairwisePreferenceResponse)
        if response.pair_factor in checks.factors:
            modes = {m for level in checks.factors[response.pair_factor].all_levels() for m in str(level).split("|")}
            for mode in sorted(modes - set(observer.strength)):
                checks.add(path + ("strength",), f"no strength for mode '{mode}'; add '{mode}: 1.0' under strength")

    def score(self, row: TrialRow, answer: str) -> Scored:
        return Scored(chosen_mode=str(row["mode_a"] if answer == "a" else row["mode_b"]))

    def targets(self, study: StudyInputs) -> list[AnalysisTarget]:
        return [figure_target(study, "preferences", "analysis/fig_realism.py")]


KIND = PairwisePreferenceKind()
