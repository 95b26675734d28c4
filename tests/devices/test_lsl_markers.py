"""`--lsl-markers`: every trial event of a session arrives through a real LSL inlet, on the LSL clock."""

from __future__ import annotations

import json
import threading
from pathlib import Path

import numpy as np
import pandas as pd
import pylsl
import pylsl.util
import pytest
from session_helpers import fast_protocol

from psyop.cli import main as cli_main
from psyop.protocol import load_protocol
from psyop.schedule import compile_schedule
from psyop.session.log.layout import session_paths
from psyop.devices.lsl_markers import CHANNELS, STREAM_NAME
from psyop.session.plan import compile_plan
from psyop.run.runner import SessionOptions, run_session

pytestmark = pytest.mark.timeout(180)


class MarkerRecorder:
    """An LSL inlet on the session's marker stream (found by its source_id), pulling every marker."""

    def __init__(self, source_id: str) -> None:
        self.source_id = source_id
        self.markers: list[tuple[list[str], float]] = []
        self.info: pylsl.StreamInfo | None = None
        self.correction = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        found: list[pylsl.StreamInfo] = []
        while not found and not self._stop.is_set():
            found = pylsl.resolve_byprop("source_id", self.source_id, 1, 0.2)
        if not found:
            return
        inlet = pylsl.StreamInlet(found[0], recover=False)
        self.info = inlet.info(timeout=5.0)
        inlet.open_stream(timeout=5.0)
        self.correction = inlet.time_correction(timeout=5.0)
        while True:
            try:
                samples, stamps = inlet.pull_chunk(timeout=0.05)
            except pylsl.util.LostError:  # the session closed its outlet: everything sent has arrived
                break
            self.markers.extend(zip(samples, stamps, strict=True))
            if self._stop.is_set() and not samples:
                break

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=10.0)


def test_every_marker_of_a_session_arrives_on_the_lsl_clock(tmp_path: Path) -> None:
    protocol = load_protocol(fast_protocol(tmp_path, "detection", repetitions=1, phase_s=0.05))
    data = tmp_path / "data"
    participant = f"P{abs(hash(str(tmp_path))) % 10**6}"  # a source id no other test publishes
    recorder = MarkerRecorder(f"psyop:{protocol.study.name}:{participant}:1")
    before = pylsl.local_clock()
    try:
        options = SessionOptions(participant=participant, seed=4, clock="real", data_root=data, progress=False,
                                 render="cameras", lsl_markers=True)
        outcome = run_session(protocol, compile_schedule, options)
        after = pylsl.local_clock()
    finally:
        recorder.stop()
    assert outcome.status == "complete"
    assert recorder.info is not None and recorder.info.name() == STREAM_NAME and recorder.info.type() == "Markers"
    labels, channel = [], recorder.info.desc().child("channels").child("channel")
    while not channel.empty():
        labels.append(channel.child_value("label"))
        channel = channel.next_sibling("channel")
    assert tuple(labels) == CHANNELS
    assert recorder.info.desc().child("psyop").child_value("participant") == participant
    paths = session_paths(data, protocol.study.name, participant, 1)
    assert json.loads(paths.metadata.read_text())["lsl_markers_recorder_at_start"] is True
    trials = pd.read_parquet(paths.trials_parquet)
    phases = [p.name for p in compile_plan(protocol).phases] + [compile_plan(protocol).response.phase.name]
    markers = pd.DataFrame([dict(zip(CHANNELS, m, strict=True), t=t + recorder.correction) for m, t in recorder.markers])
    markers["trial"] = markers["trial"].astype(int)
    # every trial: start, each phase onset in order, the response, the end, with its condition
    expected = []
    for row in trials.itertuples():
        expected += [("trial_start", row.trial, row.condition, "")]
        expected += [("phase", row.trial, row.condition, name) for name in phases]
        expected += [("response", row.trial, row.condition, row.response),
                     ("trial_end", row.trial, row.condition, f"{row.trial_end_s - row.trial_start_s:.6f}")]
    got = list(markers[["event", "trial", "condition", "value"]].itertuples(index=False, name=None))
    assert got == expected
    # on the right clock: within the session's LSL-clock span, spaced exactly like the logged times
    assert before <= markers["t"].min() and markers["t"].max() <= after
    starts = markers[markers["event"] == "trial_start"].set_index("trial")["t"]
    ends = markers[markers["event"] == "trial_end"].set_index("trial")["t"]
    logged = trials.set_index("trial")
    np.testing.assert_allclose(starts - starts.iloc[0], logged["trial_start_s"] - logged["trial_start_s"].iloc[0],
                               atol=2e-4)
    np.testing.assert_allclose(ends - starts, logged["trial_end_s"] - logged["trial_start_s"], atol=2e-4)


def test_markers_on_the_virtual_clock_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    protocol = fast_protocol(tmp_path, "detection", repetitions=1)
    code = cli_main(["run", str(protocol), "--participant", "P1", "--data", str(tmp_path / "data"), "--no-progress",
                     "--lsl-markers"])
    assert code == 2 and "--lsl-markers" in capsys.readouterr().err
