"""Durations that used to be asserted in tests (tests assert behaviour; time is measured here).

- RealClock.sleep_until overshoot (was tests/session/test_clock.py: < 5 ms);
- 100 000 degenerate camera cases (was tests/optics/test_optics_stability.py: < 10 s);
- a Pupil client's sample age on the loopback fake (was tests/devices/test_pupil.py: median < 20 ms).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np


def _overshoot_ms(n: int) -> np.ndarray:
    from psyop.session.clock import RealClock

    clock = RealClock()
    out = np.empty(n)
    for k in range(n):
        target = clock.now_s() + 0.002
        clock.sleep_until(target)
        out[k] = (clock.now_s() - target) * 1e3
    return out


def _camera_cases_s(n: int) -> float:
    from psyop.optics.camera import eye_camera_arrays
    from psyop.optics.display import VIVE_PRO

    rng = np.random.default_rng(0)
    fix = rng.normal(0, 1, (n, 3)) + np.array([0.0, 0.0, -1.0])
    near, far = np.full(n, 0.05), np.full(n, 100.0)
    start = time.perf_counter()
    eye_camera_arrays(VIVE_PRO, "right", fix, 0.064, 0.0076916, "ocular", near, far)
    return time.perf_counter() - start


def _pupil_age_ms(seconds: float) -> np.ndarray:
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "devices"))
    from pupil_server import FakePupilCapture

    from psyop.session.clock import RealClock
    from psyop.devices.gaze.pupil import PupilClient

    server = FakePupilCapture()
    clock = RealClock()
    client = PupilClient("127.0.0.1", server.port, clock=clock.now_s)
    ages = []
    try:
        client.start()
        end = clock.now_s() + seconds
        while clock.now_s() < end:
            sample = client.latest(clock.now_s())
            if sample is not None:
                ages.append((clock.now_s() - sample.timestamp_s) * 1e3)
            clock.sleep_until(clock.now_s() + 1 / 90)
    finally:
        client.close()
        server.stop()
    return np.array(ages)


def run(out_dir: Path, quick: bool) -> str:
    over = _overshoot_ms(200 if quick else 2000)
    cases = 100_000
    cam_s = _camera_cases_s(cases)
    try:
        ages = _pupil_age_ms(1.0 if quick else 5.0)
        age_line = f"| Pupil loopback fake: gaze sample age at use | median {np.median(ages):.2f} ms, p99 {np.percentile(ages, 99):.2f} ms ({len(ages)} frames) |"
    except Exception as exc:  # noqa: BLE001 - the fake needs zmq; report instead of failing the whole bench
        age_line = f"| Pupil loopback fake: gaze sample age at use | not measured ({exc}) |"
    lines = [
        "## Durations moved out of the test suite",
        "",
        "Tests assert behaviour only (a loaded CI machine makes them slower, not red); these are the durations.",
        "",
        "| what | measured |",
        "|---|---|",
        f"| RealClock.sleep_until(now + 2 ms) overshoot | median {np.median(over):.3f} ms, p99 {np.percentile(over, 99):.3f} ms, max {over.max():.3f} ms |",
        f"| {cases} camera solves (eye_camera_arrays, one batch) | {cam_s:.3f} s ({cam_s / cases * 1e6:.2f} us each) |",
        age_line,
    ]
    return "\n".join(lines)
