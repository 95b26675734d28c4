"""Simulated reaches: horizontal eye-to-target distance, between-subject lines, physical bound."""

from __future__ import annotations

import numpy as np
import pytest

from psyop.session.reach import HAND_HEIGHT_M, horizontal_direction, horizontal_reach_m
from psyop.session.responses.simulated import make_observer

FRACTIONS = (0.5, 0.58, 0.67, 0.75, 0.82, 0.9)


def _observer(participant: str, **extra):
    params = {"kind": "reach", "arm_reach_m": 0.7, "by_condition": {
        "enabled": {"slope": 1.141, "intercept_m": 0.117, "noise_sd_m": 0.03}}, **extra}
    return make_observer(params, seed=4, participant=participant)


def _reaches(observer, n_repeats: int = 20) -> tuple[np.ndarray, np.ndarray]:
    fr = np.repeat(FRACTIONS, n_repeats)
    rows = [{"trial": i, "trial_seed": 77 + i, "rendering": "enabled", "target_fraction": f} for i, f in enumerate(fr)]
    return fr, np.array([observer.collect(r, 0.0).reach_m for r in rows])


def test_reach_is_the_horizontal_distance_along_the_eye_to_target_direction():
    np.testing.assert_allclose(horizontal_direction((0.3, -0.2, -0.4)), [0.6, 0.0, -0.8])
    assert horizontal_reach_m((0.0, -0.15, -0.6)) == pytest.approx(0.6)  # not the 3-D 0.618
    assert horizontal_reach_m((0.1, 0.0, -0.6), (0.0, -0.1, -1.0)) == pytest.approx(0.6)


def test_reaches_never_exceed_the_physical_bound():
    """The old observer's reaches ran to 123 % of arm reach; the hand now ends within max_reach_fraction."""
    for p in ("S01", "S02", "S03"):
        obs = _observer(p, max_reach_fraction=1.0, slope_sd=0.1, intercept_sd_m=0.03)
        _, reach = _reaches(obs)
        assert np.all(np.hypot(reach, HAND_HEIGHT_M) <= 1.0 * obs.participant_state["arm_reach_m"] + 1e-12)
        assert np.all(reach >= 0)


def _slope_sd(**extra) -> float:
    slopes = []
    for p in [f"S{i:02d}" for i in range(24)]:
        fr, reach = _reaches(_observer(p, max_reach_fraction=1.5, **extra), 20)
        slopes.append(np.polyfit(fr * 0.7, reach, 1)[0])
    return float(np.std(slopes, ddof=1))


def test_participants_differ_in_slope_and_intercept():
    """The old observer gave every participant the paper's line; now each has an own line."""
    assert _slope_sd() < 0.05  # estimation noise only (SE ~0.035)
    assert 0.06 < _slope_sd(slope_sd=0.1, intercept_sd_m=0.03) < 0.16
