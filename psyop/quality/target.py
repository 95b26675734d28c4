"""What the participant was asked to look at, rebuilt from a trial row and the phase timing:
phase k of a trial starts at ``trial_start_s`` plus the durations of the phases before it (exact on the
virtual clock, within about a frame per phase on a real one), and its target is the loop's own
:func:`psyop.session.loop.fixation_plan`. :func:`psyop.quality.measures.trial_measures` measures the gaze
against these phases, and :func:`target_path_deg` gives the same target at any time (the sample figure)."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import pandas as pd

from psyop.session.gaze.plan import CirclingTarget, FixationPlan
from psyop.session.loop import LoopConfig, fixation_plan, pursuit_fields
from psyop.session.phases import PhaseSpec
from psyop.session.plan import SessionPlan
from psyop.session.rows import TrialRow


@dataclass(frozen=True)
class TrialPhase:
    """One phase of one trial: ``[start_s, end_s)`` on the session clock and where gaze was asked to go."""

    phase: PhaseSpec
    start_s: float
    end_s: float
    fixation: FixationPlan


def loop_config(plan: SessionPlan) -> LoopConfig:
    """The loop's fixation and pursuit settings of ``plan`` (as the session loop built them)."""
    return LoopConfig(**pursuit_fields(plan.fixation), fixate_point=plan.fixation_point)


def trial_phases(plan: SessionPlan, row: TrialRow, config: LoopConfig) -> Iterator[TrialPhase]:
    """The phases of trial ``row`` (its ``trial_start_s`` and the plan's phase durations), in order."""
    t0 = float(row["trial_start_s"])
    for phase in plan.phases:
        end = t0 + phase.duration_s
        yield TrialPhase(phase, t0, end, fixation_plan(config, phase, row, t0))
        t0 = end


def target_positions_deg(target: Callable[[float], tuple[float, float]], t_rel_s: np.ndarray) -> np.ndarray:
    """The pursuit target's Fick (az, el) in degrees at ``t_rel_s`` (s from the phase start); shape (n, 2)."""
    if isinstance(target, CirclingTarget):
        return target.positions(t_rel_s)
    return np.array([target(float(x)) for x in t_rel_s]).reshape(-1, 2)


def target_path_deg(plan: SessionPlan, trials: pd.DataFrame, t_s: np.ndarray) -> np.ndarray:
    """The target's Fick (az, el) in degrees at each of ``t_s`` (s, session clock), shape (n, 2), as
    :func:`psyop.quality.measures.trial_measures` measures against it: the cross's centre in a cross phase, the static target's in a fixate phase,
    the pursuit target's path in a pursuit phase; NaN in any other phase (free viewing, display off) and
    outside the trials of ``trials`` (columns ``trial_start_s``, ``trial_end_s`` and the trial row's)."""
    t_s = np.asarray(t_s, dtype=np.float64)
    out = np.full((len(t_s), 2), np.nan)
    config = loop_config(plan)
    for row in trials.to_dict("records"):
        trial_end_s = float(row["trial_end_s"])
        for p in trial_phases(plan, row, config):
            sel = (t_s >= p.start_s) & (t_s < min(p.end_s, trial_end_s))
            if not sel.any():
                continue
            if p.phase.gaze in ("cross", "fixate"):
                out[sel] = p.fixation.centre_deg
            elif p.phase.gaze == "pursuit" and p.fixation.target is not None:
                out[sel] = target_positions_deg(p.fixation.target, t_s[sel] - p.start_s)
    return out
