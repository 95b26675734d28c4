"""The controller's stick adjusts on a real OpenXR runtime (Monado's remote driver emulates Valve Index
controllers): an adjustment study run with ``--responses openxr``, the right stick held forward for a while, then
the trigger confirms. The recorded setting moved up from its start at the protocol's ``rate_per_s`` for the time
the stick was held in the response phase, and the select button still answers (so suggesting the
stick's binding did not make the runtime drop the profile's other bindings)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pandas as pd
from monado import RemoteState, run_driven

PROTOCOL = """
psyop_protocol: 1
study: {name: xr_stick, title: move the right disc in depth with the stick}
display: {profile: vive_pro, eye_model: gullstrand_emsley_relaxed, ipd: tracker}
eyes: stereo
scene:
  - {id: reference, kind: disc, size_deg: 4, centre_deg: [-5, 0], depth: {D: 1},
     surface: {kind: solid, rgb: [1, 0, 0]}}
  - {id: test, kind: disc, size_deg: 4, centre_deg: [5, 0], depth: {factor: match_D},
     surface: {kind: solid, rgb: [0, 1, 0]}}
trial:
  phases:
    - {kind: interval, duration_s: 0.2}
    - {kind: response, expected_s: 2, timeout_s: 30}
design:
  factors:
    ref_D: {levels: [1.0]}
  repetitions: 1
  randomisation: {kind: full}
response:
  kind: adjustment
  variable: match_D
  item: test
  field: depth
  stimulus: {mode: conventional}
  start: 1.0
  bounds: {min: 0.25, max: 3.0}
  step: 0.05
  rate_per_s: 0.1
  reference: {factor: ref_D}
"""
#: the stick is held fully forward from the child's start until HOLD_S (the first trial's response phase begins a
#: few seconds in, the stick already held: it counts from the phase's start), then the trigger confirms
HOLD_S = 12.0
RATE_PER_S = 0.1


def test_the_right_stick_adjusts_at_its_rate_and_the_trigger_confirms(tmp_path: Path) -> None:
    protocol = tmp_path / "xr_stick.yaml"
    protocol.write_text(PROTOCOL)
    cmd = [sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "H1", "--data",
           str(tmp_path / "data"), "--display", "openxr", "--responses", "openxr", "--clock", "real", "--no-progress"]

    def drive(state: RemoteState, elapsed_s: float) -> None:
        state.right_thumbstick_y = 1.0 if elapsed_s < HOLD_S else 0.0
        state.right_trigger = elapsed_s > HOLD_S + 0.5 and int(elapsed_s / 0.15) % 2 == 1

    done = run_driven(cmd, tmp_path, RemoteState(), drive)
    assert done.returncode == 0, done.stderr[-3000:]
    trials = pd.read_parquet(tmp_path / "data" / "xr_stick" / "sub-H1" / "ses-1" / "trials.parquet")
    assert len(trials) == 1
    value = float(trials["response"].iloc[0])
    path = json.loads(trials["match_D_path"].iloc[0])
    (t0, v0), (t_release, v_release) = path[0], path[-1]
    assert (t0, v0) == (0.0, 1.0) and len(path) == 2, path  # the start; the release, where the value stopped
    assert t_release > 1.0 and value == v_release, (value, path)  # held a while (the phase may start before the driver)
    # held at full deflection from the phase's start to the release: the protocol's rate, to the runtime's timing
    assert abs((v_release - v0) / t_release - RATE_PER_S) < 0.05 * RATE_PER_S, path
