"""Head and hand pose: typed samples, a source protocol, hold-last-valid, and the simulation.

Head pose is logged with every frame (``head_*`` columns of frames.parquet); the hand
pose samples that determine an egocentric reach are logged with the trial (``hand_sample_*``
list columns of trials.parquet), so a reach can be recomputed from the log and replayed
(:mod:`psyop.session.pose_replay`).

The paper tracked the hand with an HTC Vive Tracker at 120 Hz (1.9 mm RMSE accuracy,
1.5 mm precision) and took the reach as the mean of the last 10 samples (protocol
``response.average_last_samples``). The simulated observer decides where the hand ends
(along the direction of the target); the simulated tracker measures that endpoint with one
accuracy error per reach and a precision error per sample.
Positions are in head space at the start of the session (metres); orientations are unit
quaternions (w, x, y, z).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from psyop.optics.rotation import quaternion_from_yaw_pitch_roll as quaternion_from_yaw_pitch_roll
from psyop.session.rows import TrialRow
from psyop.session.gaze.simulated import seed_for

#: Direction from the eyes' mid-point to the reach target: straight ahead, a little low.
REACH_DIRECTION = np.array([0.0, -0.15, -1.0]) / np.linalg.norm([0.0, -0.15, -1.0])
IDENTITY_WXYZ: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
ORIGIN_M: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True)
class PoseSample:
    """One tracked pose on the session clock: position (m) and unit quaternion (w, x, y, z)."""

    timestamp_s: float
    position_m: tuple[float, float, float]
    orientation_wxyz: tuple[float, float, float, float] = IDENTITY_WXYZ
    valid: bool = True

    def usable(self) -> bool:
        """Valid, finite, and the quaternion has unit norm (within 1e-6)."""
        w, x, y, z = self.orientation_wxyz
        return (self.valid and all(math.isfinite(v) for v in self.position_m)
                and abs(w * w + x * x + y * y + z * z - 1.0) < 1e-6)  # false for NaN too


@dataclass(frozen=True, slots=True)
class ConditionedPose:
    """A pose after hold-last-valid: what the session uses and logs."""

    sample_t_s: float
    position_m: tuple[float, float, float]
    orientation_wxyz: tuple[float, float, float, float]
    valid: bool  # the sample itself was usable
    held: bool  # the last usable pose was used instead (or the origin, before any)


class PoseConditioner:
    """Hold the last valid pose on an invalid, missing or non-finite sample (like gaze).

    Before any valid sample ``initial_m`` with identity orientation is used (flagged held):
    the origin for the head (its reference pose), NaN for the hand (a reach with no valid
    hand sample at all is unknown, not zero).
    """

    def __init__(self, initial_m: tuple[float, float, float] = ORIGIN_M) -> None:
        self._last = ConditionedPose(math.nan, initial_m, IDENTITY_WXYZ, False, True)

    def condition(self, sample: PoseSample | None) -> ConditionedPose:
        if sample is not None and sample.usable():
            self._last = ConditionedPose(sample.timestamp_s, sample.position_m, sample.orientation_wxyz, True, False)
            return self._last
        t = sample.timestamp_s if sample is not None else math.nan
        return ConditionedPose(t, self._last.position_m, self._last.orientation_wxyz, False, True)


class PoseSource(Protocol):
    """Head and hand poses for a session (simulated, replayed, or a live tracker).

    ``head(now_s)``: the newest head pose at ``now_s`` (None before the first).
    ``hand(row, end_s, n, endpoint_m)``: the ``n`` hand samples up to ``end_s`` that
    determine trial ``row``'s reach, oldest first; ``endpoint_m`` is where a simulated
    observer holds its hand (None when the source must know it itself). Empty when the
    source has no hand data for the trial. ``n_reused_hand_trials``: trials whose hand samples
    repeat another trial's (a replay by condition; 0 for live and simulated sources).
    """

    n_reused_hand_trials: int

    def head(self, now_s: float) -> PoseSample | None: ...

    def hand(self, row: TrialRow, end_s: float, n: int, endpoint_m: Sequence[float] | None) -> list[PoseSample]: ...

    def close(self) -> None: ...


def reach_from_positions(positions_m: np.ndarray, last_n: int) -> tuple[float, np.ndarray]:
    """Distance from the eyes' mid-point (head-space origin) to the mean of the last ``last_n`` positions."""
    mean = np.asarray(positions_m, dtype=np.float64)[-last_n:].mean(axis=0)
    return float(np.linalg.norm(mean)), mean


@dataclass(frozen=True)
class SimulatedPoseConfig:
    """Seated head sway and a slow drift (a few mm, a fraction of a degree); Vive Tracker hand.

    ``hand_dropout_p`` / ``head_dropout_p``: probability that a sample is invalid (tests).
    """

    sway_amplitude_m: float = 0.004
    drift_m_per_min: float = 0.003
    rotation_amplitude_deg: float = 0.5
    hand_rate_hz: float = 120.0
    hand_precision_m: float = 0.0015  # Vive Tracker precision, RMSE (paper sec. 4.3)
    hand_accuracy_m: float = 0.0019  # Vive Tracker accuracy, RMSE: one error per reach (sec. 4.3)
    head_dropout_p: float = 0.0
    hand_dropout_p: float = 0.0


class SimulatedPose:
    """Stateless in time (a function of seed and time, or seed and trial): resumed sessions see
    the same poses as uninterrupted ones.

    Head: three incommensurate sinusoids per axis (0.05-0.4 Hz, breathing and postural sway)
    plus a linear drift, and small yaw/pitch/roll oscillations. Hand: the observer's true
    endpoint tracked at 120 Hz with the tracker's accuracy (one error per reach) and precision
    (per sample), drawn from (seed, trial_seed).
    """

    n_reused_hand_trials = 0

    def __init__(self, seed: int, config: SimulatedPoseConfig | None = None) -> None:
        self.seed = int(seed)
        self.config = config or SimulatedPoseConfig()
        rng = np.random.default_rng(seed_for(self.seed, "head"))
        self._freq_hz = rng.uniform(0.05, 0.4, (6, 3))
        self._phase = rng.uniform(0.0, 2 * math.pi, (6, 3))
        self._drift_dir = rng.normal(size=3)
        self._drift_dir /= np.linalg.norm(self._drift_dir)
        self._freq_list, self._phase_list = self._freq_hz.tolist(), self._phase.tolist()
        self._drift_list = self._drift_dir.tolist()

    def head(self, now_s: float) -> PoseSample:
        # plain floats: a few microseconds per frame (numpy on 18 numbers costs ~20x more)
        c = self.config
        waves = [[math.sin(2 * math.pi * f * now_s + ph) for f, ph in zip(fs, phs, strict=True)]
                 for fs, phs in zip(self._freq_list, self._phase_list, strict=True)]  # 6 x 3
        drift = c.drift_m_per_min * now_s / 60.0
        position = tuple(c.sway_amplitude_m / 3.0 * (waves[0][i] + waves[1][i] + waves[2][i]) + self._drift_list[i] * drift
                         for i in range(3))
        scale = math.radians(c.rotation_amplitude_deg) / 3.0
        angles = [scale * (waves[3][i] + waves[4][i] + waves[5][i]) for i in range(3)]
        valid = True
        if c.head_dropout_p > 0:
            u = np.random.default_rng(seed_for(self.seed, "head-dropout", int(round(now_s * 1e6)))).uniform()
            valid = bool(u >= c.head_dropout_p)
        return PoseSample(float(now_s), position, quaternion_from_yaw_pitch_roll(*angles), valid)  # type: ignore[arg-type]  # position: 3 floats, built with range(3)

    def hand(self, row: TrialRow, end_s: float, n: int, endpoint_m: Sequence[float] | None) -> list[PoseSample]:
        if endpoint_m is None:
            return []
        c = self.config
        rng = np.random.default_rng(seed_for(self.seed, "hand", int(row.get("trial_seed", row.get("trial", 0))) & 0xFFFFFFFF))
        bias = rng.normal(0.0, c.hand_accuracy_m / math.sqrt(3.0), 3)
        positions = np.asarray(endpoint_m, dtype=np.float64) + bias + rng.normal(0.0, c.hand_precision_m / math.sqrt(3.0), (n, 3))
        valid = rng.uniform(size=n) >= c.hand_dropout_p
        times = end_s - (n - 1 - np.arange(n)) / c.hand_rate_hz
        return [PoseSample(float(t), (float(p[0]), float(p[1]), float(p[2])), IDENTITY_WXYZ, bool(v))
                for t, p, v in zip(times, positions, valid, strict=True)]

    def close(self) -> None:
        return None
