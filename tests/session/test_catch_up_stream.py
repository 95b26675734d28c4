"""CatchUpStream (the simulated eye's catch-up saccades found on demand) gives exactly the saccades of
catch_up_schedule, whatever times it is asked in whatever order (issue 30: a replication computes only the
part of a pursuit its samples read, and no number changes)."""

from __future__ import annotations

import numpy as np
import pytest

from psyop.optics.angles import offset_direction, offset_direction_in, offset_frame
from psyop.session.gaze.plan import circling_target
from psyop.session.gaze.pursuit import CatchUpStream, PursuitParams, catch_up_schedule
from psyop.session.gaze.keyed import keyed_rng


@pytest.mark.parametrize("gain, threshold_deg, speed", [(0.9, 1.5, 90.0), (0.8, 1.0, -120.0), (0.95, 0.5, 45.0)])
def test_stream_equals_schedule_at_every_time_asked(gain: float, threshold_deg: float, speed: float) -> None:
    params = PursuitParams(gain, 0.02, threshold_deg, 500.0, 8.0)
    target = circling_target(16.0, speed, 37.0, (2.0, -3.0))
    for seed in range(4):
        stream = CatchUpStream(target.positions, params, keyed_rng(seed, 9))
        # a search left at a time asked resumes at the next (the dense steps), later times extend the stream
        for until in (0.0, 0.0004, 0.0011, *np.arange(0.01, 0.8, 0.037), 0.31, 0.2, 1.7, 1.7, 4.05, 2.5, 7.3):
            horizon = max(until, 0.5) + 0.5  # as SimulatedTracker.catch_ups asked catch_up_schedule before
            whole = [s for s in catch_up_schedule(target.positions, params, float(horizon), keyed_rng(seed, 9))
                     if s.onset_s <= until]
            assert stream.through(until) == whole  # dataclass equality: every float the same


def test_stream_of_a_target_without_catch_ups_is_empty() -> None:
    target = circling_target(16.0, 90.0)
    assert CatchUpStream(target.positions, PursuitParams(1.0, 0.02, 1.5, 500.0, 8.0), keyed_rng(1)).through(5.0) == []


@pytest.mark.cross_cpu
def test_target_positions_equal_offset_direction_bit_for_bit() -> None:
    target = circling_target(12.0, -75.0, 200.0, (4.0, 1.5))
    t = np.arange(3000) * 0.0005
    frame = offset_frame(4.0, 1.5, 12.0)
    polar = 200.0 + -75.0 * t
    assert np.array_equal(offset_direction_in(frame, polar), offset_direction(4.0, 1.5, 12.0, polar))
    whole = target.positions(t)
    assert all(np.array_equal(target.positions(t[a:b]), whole[a:b]) for a, b in ((0, 1), (17, 530), (2999, 3000)))


def test_sample_at_noise_rows_equal_the_window_tables() -> None:
    from psyop.session.gaze.simulated import SimulatedTracker

    tracker, again = SimulatedTracker(7), SimulatedTracker(7)
    ticks = [5, 3, 200, 255, 256, 1000, 999, 1024, 40, 4000]  # in and out of order, within and across windows
    for tick in ticks:
        assert tracker._noise_row(tick) == tuple(again._noise(tick).tolist())
