"""LSL gaze in vs the Pupil Network API path, and the raw gaze stream's cost per sample.

1. Gaze-in to frame latency: a sender pushes 200 Hz gaze on loopback, once as Pupil Capture does
   (ZMQ PUB, msgpack, the ``tests/devices/pupil_server.py`` stand-in) and once as Pupil Capture's
   LSL relay does (a real pylsl outlet, 22 channels); psyop's source for each (``PupilClient``,
   ``LslGazeSource``) is polled at 90 Hz like the frame loop, and each poll records the age of the
   newest sample on the session clock (``now - sample.timestamp_s``: transport, parsing, clock
   sync and waiting for the poll). The two run one after the other in one process; the claim is
   the ratio of medians (LSL / Pupil).
2. Raw-stream cost per sample: what recording every sample adds (building a ``RawGazeSample``
   and buffering it, converting a trial's samples to the Arrow table, the durable fdatasync'ed
   append once per trial), per sample, against the existing Pupil path's own per-sample work
   (``PupilClient._handle``: msgpack decode, mapping, the sample) measured side by side.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

import msgpack
import numpy as np

from benchmarks.timing import median_s
from psyop.session.clock import RealClock
from psyop.session.gaze.sample import EyeSample, RawBuffer, RawGazeSample
from psyop.session.log.raw_gaze import raw_gaze_table
from psyop.session.log.schema import GAZE_SCHEMA
from psyop.session.log.stream import DurableStreamWriter

_TESTS = Path(__file__).resolve().parents[1] / "tests" / "devices"


def _ages_ms(source, clock: RealClock, duration_s: float) -> np.ndarray:  # type: ignore[no-untyped-def]
    ages, period = [], 1.0 / 90.0
    next_t = clock.now_s() + 0.3  # let the first samples arrive
    end = next_t + duration_s
    while clock.now_s() < end:
        clock.sleep_until(next_t)
        next_t += period
        sample = source.latest(clock.now_s())
        if sample is not None and sample.valid:
            ages.append((clock.now_s() - sample.timestamp_s) * 1e3)
    return np.array(ages)


def _pupil_ages(duration_s: float) -> np.ndarray:
    sys.path.insert(0, str(_TESTS))
    from pupil_server import FakePupilCapture

    from psyop.devices.gaze.pupil import PupilClient

    server = FakePupilCapture(rate_hz=200.0)
    clock = RealClock()
    client = PupilClient("127.0.0.1", server.port, clock=clock.now_s, n_sync=10)
    try:
        client.start()
        return _ages_ms(client, clock, duration_s)
    finally:
        client.close()
        server.stop()


def _lsl_ages(duration_s: float) -> np.ndarray:
    sys.path.insert(0, str(_TESTS))
    from lsl_outlets import PupilRelayOutlet

    from psyop.devices.gaze.lsl import LslGazeSource

    name = f"psyop_bench_{time.monotonic_ns()}"
    outlet = PupilRelayOutlet(name, rate_hz=200.0)
    clock = RealClock()
    source = LslGazeSource(name, clock=clock.now_s)
    try:
        source.start()
        return _ages_ms(source, clock, duration_s)
    finally:
        source.close()
        outlet.close()


def _pupil_handle_us(n: int) -> float:
    """The existing path's per-message work, without sockets (PupilClient._handle on one message)."""
    from psyop.devices.gaze.pupil import PupilClient
    from psyop.session.gaze.sync import ClockSync

    clock = RealClock()
    client = PupilClient("127.0.0.1", 1, clock=clock.now_s)
    client.sync = ClockSync(0.0, 0.0, 0.0, 1e-4, 10)
    payload = {"topic": "gaze.3d.01.", "timestamp": 0.0, "confidence": 0.95, "gaze_point_3d": [100.0, -50.0, 800.0],
               "norm_pos": [0.5, 0.5], "eye_centers_3d": {0: [30.0, 10.0, -20.0], 1: [-30.0, 10.0, -20.0]},
               "gaze_normals_3d": {0: [0.0, 0.0, 1.0], 1: [0.0, 0.0, 1.0]},
               "base_data": [{"id": 0, "diameter": 40.0, "diameter_3d": 3.0}, {"id": 1, "diameter": 41.0, "diameter_3d": 3.1}]}
    parts = [b"gaze.3d.01.", msgpack.packb(payload, use_bin_type=True)]

    def batch() -> None:
        for _ in range(n):
            payload_t = clock.now_s()
            parts[1] = msgpack.packb({**payload, "timestamp": payload_t}, use_bin_type=True)
            client._handle(parts)

    def pack_only() -> None:
        for _ in range(n):
            msgpack.packb({**payload, "timestamp": clock.now_s()}, use_bin_type=True)

    cost = median_s(batch, 5) - median_s(pack_only, 5)  # the packing stands in for the sender: not ours
    client._raw.drain()
    client._ctx.term()
    return cost / n * 1e6


def _raw_costs_us(n: int, fsync: bool) -> dict[str, float]:
    eye = EyeSample((0.03, -0.01, 0.02), (0.0, 0.0, -1.0), 3.0, 40.0)
    buffer = RawBuffer()

    def add() -> None:
        for k in range(n):
            buffer.add(RawGazeSample(float(k), float(k), float(k), True, 0.95, (0.1, 0.05, -0.8), (0.5, 0.5), eye, eye))

    add_s = median_s(add, 5)
    samples = buffer.drain()[:n]
    table_s = median_s(lambda: raw_gaze_table(samples, run=0, trial=0), 5)
    table = raw_gaze_table(samples, run=0, trial=0)
    with tempfile.TemporaryDirectory(prefix="psyop-bench-raw-") as tmp:
        writer = DurableStreamWriter(Path(tmp) / "gaze-000.psylog", GAZE_SCHEMA, fsync=fsync)
        append_s = median_s(lambda: writer.append(table, key=0), 10)
        writer.close()
    return {"add": add_s / n * 1e6, "table": table_s / n * 1e6, "append": append_s / n * 1e6}


def run(out_dir: Path, quick: bool) -> str:
    duration_s = 0.5 if quick else 5.0
    pupil = _pupil_ages(duration_s)
    lsl = _lsl_ages(duration_s)
    n = 200 if quick else 2000
    per_trial = 1000  # a 5 s trial at 200 Hz
    handle_us = _pupil_handle_us(n)
    raw = _raw_costs_us(per_trial, fsync=True)
    raw_total = raw["add"] + raw["table"] + raw["append"]

    def pct(a: np.ndarray, q: float) -> float:
        return float(np.percentile(a, q)) if a.size else float("nan")

    lines = [
        "## LSL gaze in vs the Pupil Network API; the raw gaze stream's cost per sample",
        "",
        f"Sample age at 90 Hz polls of a 200 Hz loopback stream, {duration_s:g} s each, one process "
        f"({pupil.size} Pupil polls, {lsl.size} LSL polls). Age = poll time - sample time on the session clock.",
        "",
        "| path | median ms | p99 ms | max ms |",
        "|---|---|---|---|",
        f"| Pupil (ZMQ + msgpack, PupilClient) | {statistics.median(pupil):.3f} | {pct(pupil, 99):.3f} | {pupil.max():.3f} |",
        f"| LSL (Pupil relay outlet, LslGazeSource) | {statistics.median(lsl):.3f} | {pct(lsl, 99):.3f} | {lsl.max():.3f} |",
        "",
        f"LSL / Pupil median age: **{statistics.median(lsl) / statistics.median(pupil):.2f}**",
        "",
        f"Raw gaze stream, per sample ({per_trial} samples per trial record, fdatasync'ed once per trial):",
        "",
        "| step | us per sample |",
        "|---|---|",
        f"| RawGazeSample + RawBuffer.add | {raw['add']:.2f} |",
        f"| raw_gaze_table (Arrow) | {raw['table']:.2f} |",
        f"| durable append (CRC32 record, fdatasync) | {raw['append']:.2f} |",
        f"| raw stream total | {raw_total:.2f} |",
        f"| Pupil path's own per-message work (PupilClient._handle, incl. its raw add) | {handle_us:.2f} |",
        "",
        f"Raw stream total / Pupil per-message work: **{raw_total / handle_us:.2f}**",
    ]
    return "\n".join(lines)
