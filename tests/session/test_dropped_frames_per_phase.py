"""Dropped frames per phase (issue 43 item 6): each phase counts the display periods inside its own nominal
span without a new frame, not the periods before its first frame. Constructed frame timelines on a 90 Hz slot
grid: a display that stalls in a blank and comes back in the next interval, and one that stalls over a whole
blank; the slow real-clock runs are tests/session/test_timing_real_clock.py (timing_helpers.check_session)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from psyop.protocol.timing import TimingSection
from psyop.session.phases import PhaseSpec
from psyop.session.timing import SessionTiming, TrialTiming, frames_summary

PERIOD_S = 1.0 / 90.0
START_S = 12.5
#: 45, 180, 45 and 180 slots of 1/90 s
PHASES = [PhaseSpec("cross", 0.5, "cross", "cross"), PhaseSpec("interval1", 2.0, "stimulus", "none"),
          PhaseSpec("blank", 0.5, "blank", "none"), PhaseSpec("interval2", 2.0, "stimulus", "none")]
BOUNDS = np.array([0, 45, 225, 270, 450])  # slot of each phase's start, and of the response phase's


def _timeline(stalled: range | set[int], start_s: float | None = None) -> TrialTiming:
    """Frames on every slot from the trial's start to 20 slots into the response phase except ``stalled``
    (the display showed nothing new there: the next frame counts them as missed)."""
    timing = TrialTiming(start_s=start_s)
    missed = 0
    for slot in range(BOUNDS[-1] + 20):
        if slot in stalled:
            missed += 1
            continue
        phase = int(np.searchsorted(BOUNDS, slot, side="right")) - 1
        timing.add(phase if phase < len(PHASES) else -1, START_S + slot * PERIOD_S, PERIOD_S, missed)
        missed = 0
    return timing


def _frames(timing: TrialTiming) -> pd.DataFrame:
    names = [PHASES[i].name if i >= 0 else "response" for i in timing.phase_index]
    return pd.DataFrame({"trial": 0, "frame": range(len(names)), "phase": names,
                         "display_time_s": timing.display_time_s, "display_period_s": timing.period_s,
                         "display_missed_frames": timing.missed})


@pytest.mark.parametrize("start_s", [None, START_S])
def test_a_stall_from_a_blank_into_an_interval_counts_in_each(start_s) -> None:
    # slots 260..282 show nothing: 10 in the blank (260..269), 13 in interval2 (270..282), whose first frame is
    # the one after the stall (the old count: blank 0, interval2 23)
    timing = _timeline(range(260, 283), start_s)
    columns = timing.columns(PHASES, TimingSection(max_dropped_frames=12, on_violation="flag"))
    assert columns["blank_dropped_frames"] == 10 and columns["interval2_dropped_frames"] == 13
    assert columns["cross_dropped_frames"] == columns["interval1_dropped_frames"] == 0
    assert columns["interval2_frames"] == 180 - 13 and columns["timing_ok"] is False
    assert timing.stimulus_dropped(PHASES) == 13
    session = SessionTiming(PERIOD_S)
    session.add(timing, PHASES)
    by_kind = session.summary()["dropped_frames_by_kind"]
    assert by_kind == {"blank": 10, "cross": 0, "response": 0, "stimulus": 13}
    summary = frames_summary(_frames(timing), PHASES, PERIOD_S, {0: START_S} if start_s is not None else None)
    assert summary["dropped_frames_by_kind"] == by_kind and summary["dropped_frames"] == 23


def test_a_blank_the_display_stalled_through_counts_its_whole_span() -> None:
    timing = _timeline(range(220, 275))  # from 5 slots before the blank to 5 into interval2
    columns = timing.columns(PHASES, None)
    assert columns["blank_frames"] == 0 and columns["blank_onset_s"] is None
    assert (columns["interval1_dropped_frames"], columns["blank_dropped_frames"],
            columns["interval2_dropped_frames"]) == (5, 45, 5)


def test_every_skipped_period_counts_in_one_phase() -> None:
    """Per-phase counts add up to the periods each phase spanned without a new frame, for stalls anywhere."""
    rng = np.random.default_rng(43)
    for _ in range(200):
        stalled: set[int] = set()
        for onset in rng.integers(1, BOUNDS[-1] + 10, rng.integers(1, 5)):
            stalled.update(range(int(onset), int(onset) + int(rng.integers(1, 60))))
        stalled = {s for s in stalled if s < BOUNDS[-1] + 19}
        timing = _timeline(stalled, START_S)
        columns = timing.columns(PHASES, None)
        for i, phase in enumerate(PHASES):
            want = sum(BOUNDS[i] <= s < BOUNDS[i + 1] for s in stalled)
            assert columns[f"{phase.name}_dropped_frames"] == want
        session = SessionTiming(PERIOD_S)
        session.add(timing, PHASES)
        assert session.summary()["dropped_frames"] == len(stalled) == sum(timing.missed)
