"""Headset sessions against a real OpenXR runtime: Monado, headless (null compositor), with its
simulated HMD or its remote driver (injected head pose, per-eye poses and fields of view, eye gaze,
controller buttons). Every test runs psyop in a child process (the runtime lives in the process
that opens it). Without a runtime the tests skip with the reason (tests/devices/xr/monado.py)."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from monado import RemoteDriver, RemoteState, free_port, runtime_env
from protocol_texts import TWO_INTERVAL_TAIL, disc_on_wall_head

HERE = Path(__file__).parent
REPO = HERE.parents[2]
NC_M = 0.0076916  # gullstrand_emsley_relaxed

TINY_HEAD = disc_on_wall_head("xr_tiny")


def _protocol(tmp_path: Path, repetitions: int = 1, interval_s: float = 0.3, timeout_s: float = 0.2,
              prompt: str | None = "1 or 2?") -> Path:
    """A small stereo 2IFC study (the shared two-interval tail) with short phases and a response
    timeout, so ``--responses none`` runs it; a short ``prompt`` (None: the default prompt, whose key lines
    with ``--responses openxr`` need more than the 8 lines the runtime's 320x240 view fits at session start)."""
    given = "" if prompt is None else f", prompt: '{prompt}'"
    tail = (TWO_INTERVAL_TAIL.replace("duration_s: 1}", f"duration_s: {interval_s}}}")
            .replace("{kind: response, expected_s: 1}",
                     f"{{kind: response, expected_s: 0.2, timeout_s: {timeout_s}{given}}}")
            .replace("repetitions: 1", f"repetitions: {repetitions}"))
    path = tmp_path / "xr_tiny.yaml"
    path.write_text(TINY_HEAD + tail)
    return path


def _psyop_run(tmp_path: Path, protocol: Path, *extra: str, env: dict | None = None,
               timeout_s: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "H1",
                           "--data", str(tmp_path / "data"), "--display", "openxr", "--pose", "openxr",
                           "--clock", "real", "--responses", "none", "--no-progress", *extra],
                          env=env or runtime_env(tmp_path), cwd=REPO, capture_output=True, text=True,
                          timeout=timeout_s, stdin=subprocess.DEVNULL)


def _session_dir(tmp_path: Path) -> Path:
    return tmp_path / "data" / "xr_tiny" / "sub-H1" / "ses-1"


def test_a_session_runs_to_completion_on_the_simulated_hmd(tmp_path):
    done = _psyop_run(tmp_path, _protocol(tmp_path))
    assert done.returncode == 0, done.stderr[-3000:]
    meta = json.loads((_session_dir(tmp_path) / "session.json").read_text())
    assert meta["status"] == "complete"
    display = meta["summary"]["display"]
    assert display["display"] == "openxr" and "Monado" in display["runtime"]
    assert display["system"] == "Monado: Simulated HMD"
    assert "FOCUSED" in display["session_states"] and display["session_states"][-1] == "EXITING"
    assert "openxr display's swapchain images" in meta["rendering"]
    frames = pd.read_parquet(_session_dir(tmp_path) / "frames.parquet")
    trials = pd.read_parquet(_session_dir(tmp_path) / "trials.parquet")
    assert sorted(trials["trial"]) == [0, 1]
    # every trial drew frames; how many depends on the machine's speed (5 in all under two busy loops, CI
    # beside it: a count floor of 6 failed there), so only their presence is asserted
    assert set(frames["trial"]) == {0, 1} and frames["display_should_render"].all()
    assert (np.diff(frames["display_time_s"].to_numpy()) > 0).all()  # the runtime's display times move on
    assert (frames["display_period_s"] > 0).all()
    for eye in ("left", "right"):  # every frame logs the runtime's views of both eyes
        assert frames[[f"view_{eye}_tan_{s}" for s in ("left", "right", "bottom", "top")]].notna().all().all()
    assert (frames["view_left_x_m"] < 0).all() and (frames["view_right_x_m"] > 0).all()
    assert frames["head_valid"].all()  # --pose openxr: the head pose of every frame
    assert frames["image_ok"].dropna().all() and frames["image_checked"].any()


def test_a_start_validation_waits_for_focus_and_the_session_completes(tmp_path):
    """A gaze validation at the start runs only once the headset session is FOCUSED, as a trial does: it
    ended the session at once with display_lost (focus 'lost' in state READY) before the fix."""
    path = _protocol(tmp_path)
    path.write_text(path.read_text() + "gaze_validation:\n  when: [start]\n  points_deg: [[0, 0], [10, 0]]\n"
                    "  settle_s: 0.1\n  dwell_s: 0.2\n")
    done = _psyop_run(tmp_path, path)
    assert done.returncode == 0, done.stderr[-3000:]
    meta = json.loads((_session_dir(tmp_path) / "session.json").read_text())
    assert meta["status"] == "complete" and not meta.get("display_interruptions")
    points = pd.read_parquet(_session_dir(tmp_path) / "validation.parquet").query("point >= 0")
    assert len(points) == 2
    # the validation asked for gaze (every frame it began asks once, so at least one sample) and measured each
    # point from the samples of its dwell window; how many frames fall in a 0.2 s window depends on the machine's
    # speed (point 0 got none under two busy loops with CI beside it), so only the accounting is asserted
    gaze = pd.read_parquet(_session_dir(tmp_path) / "gaze.parquet").query("trial == -1")
    assert len(gaze) >= 1
    t = gaze["gaze_sample_t_s"].to_numpy()
    for point in points.itertuples():
        assert point.n_samples == int(((t >= point.start_s) & (t < point.end_s)).sum()), point


def _inject_and_probe(tmp_path: Path, state: RemoteState, n_frames: int = 40, press_after_s: float | None = None
                      ) -> dict:
    port = free_port()
    probe = subprocess.Popen([sys.executable, str(HERE / "probe.py"), "cameras", str(_protocol(tmp_path)),
                              str(n_frames)], env=runtime_env(tmp_path, port), cwd=REPO,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    try:
        driver = RemoteDriver(port)
        start = time.monotonic()
        while probe.poll() is None and time.monotonic() - start < 200:
            elapsed = time.monotonic() - start
            state.right_trigger = press_after_s is not None and press_after_s <= elapsed < press_after_s + 0.3
            try:
                driver.send(state)
            except OSError:  # the probe finished and the runtime closed the connection
                break
            time.sleep(0.02)
        out, err = probe.communicate(timeout=120)
    finally:
        if probe.poll() is None:
            probe.kill()
    assert probe.returncode == 0, err[-3000:]
    return json.loads(out.strip().splitlines()[-1])


def _quat_wxyz_yaw(deg: float) -> np.ndarray:
    return np.array([math.cos(math.radians(deg) / 2), 0.0, math.sin(math.radians(deg) / 2), 0.0])


def test_injected_fovs_eye_positions_head_yaw_and_gaze_reach_the_cameras_exactly(tmp_path):
    state = RemoteState()
    report = _inject_and_probe(tmp_path, state, n_frames=40, press_after_s=1.0)
    assert report["summary"]["eye_gaze_supported"] is True
    last = report["frames"][-1]
    # the head: 30 deg yaw at (0.1, 1.5, -0.2) in the runtime's STAGE space, reported in LOCAL (psyop's
    # world), whose origin the runtime puts at its own height above the stage (located independently)
    position, orientation, valid = last["head"]
    assert valid
    np.testing.assert_allclose(position, np.add(state.head_position_m, last["stage_in_world"]), atol=1e-6)
    np.testing.assert_allclose(np.abs(orientation), np.abs(_quat_wxyz_yaw(state.head_yaw_deg)), atol=1e-6)
    # gaze: 10 deg down in head space, placed 1 m along the ray (XR_EXT_eye_gaze_interaction has no vergence)
    t_sample, fixation, gaze_valid = last["gaze"]
    assert gaze_valid and t_sample <= last["display_time_s"] + 1e-9
    pitch = math.radians(state.gaze_pitch_deg)
    expected_fixation = np.array([0.0, math.sin(pitch), -math.cos(pitch)])
    np.testing.assert_allclose(fixation, expected_fixation, atol=1e-5)
    for i, eye in enumerate(("left", "right")):
        view = last["views"][eye]
        angle_l, angle_r, angle_u, angle_d = state.fovs[i]
        expected_tangents = [math.tan(angle_l), math.tan(angle_r), math.tan(angle_d), math.tan(angle_u)]
        np.testing.assert_allclose(view["tangents"], expected_tangents, atol=1e-6)
        centre = np.array(state.eye_positions_m[i])
        np.testing.assert_allclose(view["centre"], centre, atol=1e-6)
        conventional, ocular = view["cameras"]["conventional"], view["cameras"]["ocular"]
        np.testing.assert_allclose(conventional["cop"], centre, atol=1e-6)
        # the nodal point NC from this eye's centre of rotation, towards the fixation
        towards = expected_fixation - centre
        np.testing.assert_allclose(ocular["cop"], centre + NC_M * towards / np.linalg.norm(towards), atol=1e-6)
        # independent ray geometry: the image's edge midpoints look along the injected half-angles
        for cam in (conventional, ocular):
            rays = {k: np.array(v) for k, v in cam["rays"].items()}
            assert rays["left"][0] / -rays["left"][2] == pytest.approx(math.tan(angle_l), abs=1e-6)
            assert rays["right"][0] / -rays["right"][2] == pytest.approx(math.tan(angle_r), abs=1e-6)
            assert rays["top"][1] / -rays["top"][2] == pytest.approx(math.tan(angle_u), abs=1e-6)
            assert rays["bottom"][1] / -rays["bottom"][2] == pytest.approx(math.tan(angle_d), abs=1e-6)
    # the right controller's trigger answered "interval 2" exactly once
    assert [f["response"] for f in report["frames"] if f["response"] is not None] == ["2"]
    # the right controller's grip and aim poses (--pose openxr:right, openxr:right:aim): Monado's remote
    # controller reports one pose for both, placed in LOCAL like the head
    for kind in ("hand", "aim"):
        (*position, qw, qx, qy, qz, valid), = report["frames"][-1][kind]
        assert valid, kind
        np.testing.assert_allclose(position, np.add(state.right_controller_position_m,
                                                    report["frames"][-1]["stage_in_world"]), atol=1e-6)
        np.testing.assert_allclose(np.abs([qw, qx, qy, qz]), [1.0, 0.0, 0.0, 0.0], atol=1e-6)


def _on_x_display(graphics: str, argv: list[str]) -> list[str]:
    """``argv`` as run for the binding ``graphics``: under a private Xvfb server for GLX/Xlib."""
    if graphics != "xlib":
        return argv
    if shutil.which("xvfb-run") is None:
        pytest.skip("the GLX/Xlib binding needs an X server: xvfb-run (Debian xvfb) is not installed")
    return ["xvfb-run", "-a", "-s", "-screen 0 640x480x24", *argv]


@pytest.mark.parametrize("graphics", ["egl", "xlib"])
def test_a_frame_read_back_from_the_swapchain_equals_the_headless_render(tmp_path, graphics):
    # the swapchain images are drawn by psyop's context bound through EGL or through GLX on an X
    # display; the reference is the headless (EGL) renderer in its own context
    argv = _on_x_display(graphics, [sys.executable, str(HERE / "probe.py"), "readback", str(_protocol(tmp_path)), "40",
                                    graphics])
    done = subprocess.run(argv, env=runtime_env(tmp_path), cwd=REPO, capture_output=True, text=True, timeout=240,
                          stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["summary"]["graphics"] == graphics
    assert report["check_ok"]
    for eye in ("left", "right"):
        got = report["eyes"][eye]
        assert got["distinct_colours"] > 10, "an anti-aliased disc and wall, not a flat frame"
        assert got["max_diff"] == 0 and got["n_diff"] == 0, got


def test_teardown_keeps_fd0_and_leaks_no_descriptor(tmp_path):
    stdin_file = tmp_path / "stdin.txt"
    stdin_file.write_text("not a terminal\n")
    with stdin_file.open() as fh:
        done = subprocess.run([sys.executable, str(HERE / "probe.py"), "teardown", str(_protocol(tmp_path))],
                              env=runtime_env(tmp_path), cwd=REPO, capture_output=True, text=True, timeout=240,
                              stdin=fh)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["fd0_before"] == report["fd0_after"] == str(stdin_file)
    assert report["fds_after"] == report["fds_before"]


def test_a_session_runs_through_the_glx_xlib_binding_when_the_runtime_lacks_egl(tmp_path):
    # SteamVR on Linux offers only XR_KHR_opengl_enable's Xlib binding; Monado offers both, so the
    # binding is forced here, on a private X server
    argv = _on_x_display("xlib", [sys.executable, "-m", "psyop", "run", str(_protocol(tmp_path)), "--participant", "H1",
                                  "--data", str(tmp_path / "data"), "--display", "openxr:xlib", "--pose", "openxr",
                                  "--clock", "real", "--responses", "none", "--no-progress"])
    done = subprocess.run(argv, env=runtime_env(tmp_path), cwd=REPO, capture_output=True, text=True, timeout=240,
                          stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr[-3000:]
    meta = json.loads((_session_dir(tmp_path) / "session.json").read_text())
    assert meta["status"] == "complete" and meta["summary"]["display"]["graphics"] == "xlib"
    frames = pd.read_parquet(_session_dir(tmp_path) / "frames.parquet")
    assert frames["image_ok"].dropna().all() and frames["image_checked"].any()


def test_openxr_binding_errors_are_one_line(tmp_path):
    env = runtime_env(tmp_path)
    env.pop("DISPLAY", None)
    argv = [sys.executable, "-m", "psyop", "run", str(_protocol(tmp_path)), "--participant", "H1", "--data",
            str(tmp_path / "data"), "--clock", "real", "--responses", "none", "--no-progress"]
    unknown = subprocess.run(argv + ["--display", "openxr:vulkan"], env=env, cwd=REPO, capture_output=True, text=True,
                             timeout=240, stdin=subprocess.DEVNULL)
    assert unknown.returncode == 2 and "openxr:egl or openxr:xlib" in unknown.stderr, unknown.stderr[-2000:]
    no_x = subprocess.run(argv + ["--display", "openxr:xlib"], env=env, cwd=REPO, capture_output=True, text=True,
                          timeout=240, stdin=subprocess.DEVNULL)
    assert no_x.returncode == 3 and "DISPLAY is not set" in no_x.stderr, no_x.stderr[-2000:]
    assert "Traceback" not in unknown.stderr + no_x.stderr
    assert not (tmp_path / "data" / "xr_tiny" / "sub-H1" / "ses-1" / "trials.parquet").exists()


def test_ctrl_c_while_the_runtime_starts_exits_130_and_the_session_then_runs(tmp_path):
    # The signal lands as the in-process runtime reports its devices, before the session is focused and
    # before any trial: the runtime is closed, nothing is recorded as done, and the same command then runs.
    import signal

    protocol = _protocol(tmp_path)
    argv = [sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "H1", "--data", str(tmp_path / "data"),
            "--display", "openxr", "--pose", "openxr", "--clock", "real", "--responses", "none", "--no-progress"]
    env = runtime_env(tmp_path)
    env["XRT_LOG"] = "info"  # the runtime's start-up lines are the trigger
    process = subprocess.Popen(argv, env=env, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                               stdin=subprocess.DEVNULL, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    seen = []
    for line in process.stderr:
        seen.append(line)
        if "Selected devices" in line:
            process.send_signal(signal.SIGINT)
            break
    rest = process.stderr.read()
    process.wait(timeout=120)
    stderr = "".join(seen) + rest
    assert any("Selected devices" in line for line in seen), stderr[-3000:]
    assert process.returncode == 130, stderr[-3000:]
    assert "Traceback" not in stderr and "psyop run: interrupted" in stderr
    done = _psyop_run(tmp_path, protocol)
    assert done.returncode == 0, done.stderr[-3000:]
    assert json.loads((_session_dir(tmp_path) / "session.json").read_text())["status"] == "complete"


def test_closing_mid_frame_with_draws_still_rasterising_does_not_crash(tmp_path):
    # What a Ctrl-C between a frame's draws and xrEndFrame leaves: GL draws queued into the swapchain
    # images and not finished. Before close() waited for them, destroying the swapchains and the
    # session freed the memory llvmpipe's raster threads were still writing: SIGSEGV in 4 of 4 runs.
    done = subprocess.run([sys.executable, str(HERE / "probe.py"), "abandon", str(_protocol(tmp_path)), "20"],
                          env=runtime_env(tmp_path), cwd=REPO, capture_output=True, text=True, timeout=240,
                          stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["draws_queued"] == 20 and report["frame_open"]
    assert report["summary"]["session_states"][-1] == "EXITING"


def test_the_runtime_stopping_mid_trial_discards_it_and_a_resume_completes(tmp_path):
    # 4 trials of 2 x 1 s intervals (about 44 frames a trial at the test runtime's 20 Hz; cameras only, so
    # frames stay cheap under load): frame 50 falls inside a trial after the first
    protocol = _protocol(tmp_path, repetitions=2, interval_s=1.0)
    stopped = _psyop_run(tmp_path, protocol, "--xr-request-exit-at-frame", "50", "--render", "cameras")
    assert stopped.returncode == 3, stopped.stderr[-3000:]
    assert "Traceback" not in stopped.stderr
    meta = json.loads((_session_dir(tmp_path) / "session.json").read_text())
    assert meta["status"] == "incomplete" and meta["summary"]["outcome"] == "display_lost"
    interruptions = meta["display_interruptions"]
    # the runtime takes the session out of focus first (FOCUSED -> VISIBLE: the trial is discarded, to be
    # re-run once focused again), then stops it (STOPPING: the session ends, resumable)
    assert interruptions[0]["rerun"] is True and "lost focus (state VISIBLE)" in interruptions[0]["reason"]
    assert interruptions[-1]["rerun"] is False and "STOPPING" in interruptions[-1]["reason"]
    assert len({i["trial"] for i in interruptions}) == 1
    before = pd.read_parquet(_session_dir(tmp_path) / "trials.parquet")
    assert 0 < len(before) < 4 and interruptions[0]["trial"] not in set(before["trial"])
    resumed = _psyop_run(tmp_path, protocol, "--render", "cameras")
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    after = pd.read_parquet(_session_dir(tmp_path) / "trials.parquet")
    assert sorted(after["trial"]) == [0, 1, 2, 3]  # each trial once, the discarded one re-run
    kept = after.set_index("trial").loc[before["trial"], "trial_start_s"].to_numpy()
    np.testing.assert_array_equal(kept, before["trial_start_s"].to_numpy())  # recorded trials untouched


def test_an_absent_runtime_is_one_line_and_exit_3(tmp_path):
    env = runtime_env(tmp_path)
    env["XR_RUNTIME_JSON"] = str(tmp_path / "no_such_runtime.json")
    done = _psyop_run(tmp_path, _protocol(tmp_path), env=env, timeout_s=120)
    assert done.returncode == 3
    assert "Traceback" not in done.stderr
    line = [ln for ln in done.stderr.splitlines() if ln.startswith("psyop")][-1]
    assert "OpenXR runtime" in line and "XR_RUNTIME_JSON" in line
    assert not (tmp_path / "data").exists() or not any((tmp_path / "data").rglob("trials.parquet"))


def test_openxr_tracking_needs_the_openxr_display(tmp_path):
    protocol = _protocol(tmp_path)
    for option in (["--pose", "openxr"], ["--tracker", "openxr"]):
        done = subprocess.run([sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "H1",
                               "--data", str(tmp_path / "data"), "--clock", "real", "--responses", "none",
                               "--no-progress", *option], cwd=REPO, capture_output=True, text=True, timeout=120)
        assert done.returncode == 2, done.stderr
        assert "use it with --display openxr" in done.stderr and "Traceback" not in done.stderr


def test_a_session_with_injected_views_gaze_and_trigger_logs_them_exactly(tmp_path):
    """``psyop run`` end to end on the remote driver: every OpenXR source at once."""
    state = RemoteState()
    port = free_port()
    protocol = _protocol(tmp_path, repetitions=1, interval_s=0.5, timeout_s=5.0)
    cmd = [sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "H1", "--data",
           str(tmp_path / "data"), "--display", "openxr", "--pose", "openxr:right", "--tracker", "openxr",
           "--responses", "openxr", "--clock", "real", "--no-progress"]
    run = subprocess.Popen(cmd, env=runtime_env(tmp_path, port), cwd=REPO, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    try:
        driver = RemoteDriver(port)
        start = time.monotonic()
        while run.poll() is None and time.monotonic() - start < 200:
            state.right_trigger = int((time.monotonic() - start) / 0.15) % 2 == 1  # pressed every 0.3 s
            try:
                driver.send(state)
            except OSError:
                break
            time.sleep(0.02)
        out, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0, err[-3000:]
    trials = pd.read_parquet(_session_dir(tmp_path) / "trials.parquet")
    assert list(trials["response"]) == ["2", "2"]  # the right trigger answers "interval 2"
    assert (trials["response_time_s"] > 0).all()
    frames = pd.read_parquet(_session_dir(tmp_path) / "frames.parquet")
    last = frames.iloc[-1]
    for i, eye in enumerate(("left", "right")):
        angle_l, angle_r, angle_u, angle_d = state.fovs[i]
        got = [last[f"view_{eye}_tan_{s}"] for s in ("left", "right", "bottom", "top")]
        np.testing.assert_allclose(got, [math.tan(angle_l), math.tan(angle_r), math.tan(angle_d), math.tan(angle_u)],
                                   atol=1e-6)
        np.testing.assert_allclose([last[f"view_{eye}_{a}_m"] for a in "xyz"], state.eye_positions_m[i], atol=1e-6)
    pitch = math.radians(state.gaze_pitch_deg)
    np.testing.assert_allclose([last[f"fixation_{a}_m"] for a in "xyz"], [0.0, math.sin(pitch), -math.cos(pitch)],
                               atol=1e-5)
    assert last["gaze_valid"] and np.isfinite(last["gaze_age_at_display_s"])
    np.testing.assert_allclose(np.abs([last[f"head_q{c}"] for c in "wxyz"]), np.abs(_quat_wxyz_yaw(30.0)), atol=1e-6)
    meta = json.loads((_session_dir(tmp_path) / "session.json").read_text())
    assert meta["summary"]["display"]["system"] == "Monado: Remote HMD"
    assert meta["summary"]["tracker"]["fixation_distance_m"] == 1.0


def test_ctrl_c_mid_frame_ends_the_headset_session_cleanly_and_it_resumes(tmp_path):
    import signal

    from psyop.session.log.layout import session_paths

    protocol = _protocol(tmp_path, repetitions=2, interval_s=1.0)
    argv = [sys.executable, "-m", "psyop", "run", str(protocol), "--participant", "H1", "--data", str(tmp_path / "data"),
            "--display", "openxr", "--pose", "openxr", "--clock", "real", "--responses", "none", "--no-progress",
            "--render", "cameras"]
    process = subprocess.Popen(argv, env=runtime_env(tmp_path), cwd=REPO, stdout=subprocess.DEVNULL,
                               stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL,
                               preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    from psyop.session.log.store import recover_tables

    paths = session_paths(tmp_path / "data", "xr_tiny", "H1", 1)
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and process.poll() is None:  # once the first trial is durable in the log
        if paths.trial_segment(0).exists():
            logged = recover_tables(paths)[0]
            if logged is not None and len(logged) >= 1:
                break
        time.sleep(0.05)
    assert process.poll() is None, "the session ended before a trial was durable"
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130, stderr[-3000:]
    assert "Traceback" not in stderr
    meta = json.loads((_session_dir(tmp_path) / "session.json").read_text())
    assert meta["status"] == "incomplete" and meta["summary"]["display"]["session_states"][-1] == "EXITING"
    recorded = pd.read_parquet(_session_dir(tmp_path) / "trials.parquet")
    assert 1 <= len(recorded) < 4
    resumed = _psyop_run(tmp_path, protocol, "--render", "cameras")
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert sorted(pd.read_parquet(_session_dir(tmp_path) / "trials.parquet")["trial"]) == [0, 1, 2, 3]


#: psyop run with a shorter controller wait (the real code path; 30 s by default)
_SHORT_CONTROLLER_WAIT = ("import sys; import psyop.devices.xr.runtime as r; r.CONTROLLER_TIMEOUT_S = 2.0; "
                          "from psyop.cli import main; sys.exit(main(sys.argv[1:]))")


def test_controller_responses_on_a_runtime_without_controllers_end_before_the_first_trial(tmp_path):
    """Monado's simulated HMD has no controllers: `--responses openxr` recorded every trial as a timeout
    and ended 'complete'. Now it waits for one before the first trial, then ends with one line, exit 3,
    no trial recorded."""
    protocol = _protocol(tmp_path, timeout_s=0.5)
    argv = ["run", str(protocol), "--participant", "H1", "--data", str(tmp_path / "data"), "--display", "openxr",
            "--pose", "openxr", "--clock", "real", "--responses", "openxr", "--no-progress"]
    done = subprocess.run([sys.executable, "-c", _SHORT_CONTROLLER_WAIT, *argv], env=runtime_env(tmp_path), cwd=REPO,
                          capture_output=True, text=True, timeout=240, stdin=subprocess.DEVNULL)
    assert done.returncode == 3, done.stderr[-3000:]
    last = done.stderr.strip().splitlines()[-1]
    assert "no controller became active within 2 s" in last and "--responses keyboard" in last, done.stderr[-2000:]
    assert "Traceback" not in done.stderr and "waiting up to 2 s for a controller" in done.stderr
    assert pd.read_parquet(_session_dir(tmp_path) / "trials.parquet").empty
    assert json.loads((_session_dir(tmp_path) / "session.json").read_text())["status"] == "incomplete"  # resumable
