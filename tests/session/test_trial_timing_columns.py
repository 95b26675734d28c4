"""TrialTiming.columns (psyop.session.timing) in one pass over the frames, held to a plain definition
(one list scan per phase and one skipped slot at a time, kept here as ``_columns_by_scan``) for random trials: phases with no frame, one
frame, late frames counted in later phases, the response phase's frames (-1), repeated phase names, the
sampled regime (measured False), with and without a timing rule. Same keys, same order, same values."""

from __future__ import annotations

import random

import pytest

from psyop.protocol.timing import TimingSection
from psyop.session.phases import PhaseSpec
from psyop.session.timing import TIMING_OK, TrialTiming, phase_labels

PHASES = [PhaseSpec("cross", 1.0, "cross", "cross"), PhaseSpec("stimulus", 2.0, "stimulus", "pursuit"),
          PhaseSpec("blank", 0.5, "blank", "none"), PhaseSpec("stimulus", 2.0, "stimulus", "pursuit"),
          PhaseSpec("dark", 0.3, "off", "none"), PhaseSpec("blank", 0.25, "blank", "none")]


def _skipped_in(timing: TrialTiming, phases, i: int) -> int:
    """Skipped slots (before a frame m periods late: its display time less 1..m periods) inside phase i's
    nominal span (the trial's start: the first frame's asked slot), one slot at a time."""
    if not any(timing.missed):
        return 0
    start = timing.display_time_s[0] - timing.missed[0] * timing.period_s[0]
    begin = start + sum(p.duration_s for p in phases[:i])
    end = begin + phases[i].duration_s
    return sum(begin - 1e-9 <= d - k * p < end - 1e-9
               for d, p, m in zip(timing.display_time_s, timing.period_s, timing.missed) for k in range(1, m + 1))


def _columns_by_scan(timing: TrialTiming, phases, rule, measured=True) -> dict:
    out: dict = {}
    stimulus_dropped = 0
    for i, (phase, label) in enumerate(zip(phases, phase_labels(phases))):
        if label is None:
            continue
        rows = [r for r, p in enumerate(timing.phase_index) if p == i]
        dropped = _skipped_in(timing, phases, i)
        if rows and measured:
            last = rows[-1]
            onset, offset = timing.display_time_s[rows[0]], timing.display_time_s[last]
            until = (timing.display_time_s[last + 1] if last + 1 < len(timing.display_time_s)
                     else offset + timing.period_s[last])
            out.update({f"{label}_onset_s": onset, f"{label}_offset_s": offset, f"{label}_duration_s": until - onset})
        else:
            out.update({f"{label}_onset_s": None, f"{label}_offset_s": None, f"{label}_duration_s": None})
        out.update({f"{label}_frames": len(rows), f"{label}_dropped_frames": dropped})
        stimulus_dropped += dropped if phase.show == "stimulus" else 0
    out[TIMING_OK] = None if rule is None else not rule.violated(stimulus_dropped)
    return out


def _random_trial(rng: random.Random) -> TrialTiming:
    timing = TrialTiming()
    t = rng.uniform(0, 100)
    phase = 0
    for _ in range(rng.randint(0, 40)):
        phase = min(phase + rng.choice([0, 0, 0, 1, 2]), len(PHASES))  # phases in order, some skipped
        index = -1 if phase == len(PHASES) else phase
        period = rng.choice([1 / 90, 1 / 72, 1 / 120])
        missed = rng.choice([0, 0, 0, 0, 1, 3])
        t += period * (1 + missed)
        timing.add(index, t, period, missed)
    return timing


@pytest.mark.parametrize("measured", [True, False])
@pytest.mark.parametrize("rule", [None, TimingSection(max_dropped_frames=2, on_violation="flag")])
def test_columns_equal_the_scan_definition(measured, rule):
    rng = random.Random(20261203)
    for _ in range(2000):
        timing = _random_trial(rng)
        got = timing.columns(PHASES, rule, measured=measured)
        want = _columns_by_scan(timing, PHASES, rule, measured=measured)
        assert list(got) == list(want)
        assert got == want
        assert [type(v) for v in got.values()] == [type(v) for v in want.values()]


def test_a_trial_without_frames():
    got = TrialTiming().columns(PHASES, None)
    assert got == _columns_by_scan(TrialTiming(), PHASES, None)
    assert got["stimulus_frames"] == 0 and got["stimulus_2_onset_s"] is None
