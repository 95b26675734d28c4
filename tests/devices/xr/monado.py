"""The OpenXR test runtime (Monado, built by ../shared/openxr/build-monado.sh; .ci/run builds it) and
its remote driver, for the headset tests.

Monado runs inside the process that creates the OpenXR instance, so every test runs psyop in a
child process with the runtime's environment: the simulated HMD (``SIMULATED_ENABLE``), or the
remote driver (``P_OVERRIDE_ACTIVE_CONFIG=remote``, a private config file with a private port) into
which :class:`RemoteDriver` injects head pose, per-eye poses and fields of view, controller buttons
and (patch 0002) an eye-gaze pose, over the driver's own TCP protocol.
"""

from __future__ import annotations

import json
import math
import os
import socket
import struct
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from benchmarks.openxr_runtime import NO_RUNTIME, default_runtime_json

REPO = Path(__file__).resolve().parents[3]


def runtime_json() -> str:
    """The runtime manifest, or a skip that says why there is none."""
    path = (os.environ.get("XR_RUNTIME_JSON") or os.environ.get("PSYOP_TEST_XR_RUNTIME_JSON")
            or default_runtime_json() or NO_RUNTIME)
    if not Path(path).is_file():
        pytest.skip(f"no OpenXR runtime: {path} does not exist and XR_RUNTIME_JSON is unset; build the test runtime "
                    "with `bash ../shared/openxr/build-monado.sh` (.ci/run does this, cached)")
    try:
        import xr  # noqa: F401
    except ImportError as exc:
        pytest.skip(f"pyopenxr is not installed ({exc}); pip install 'psyop[xr]'")
    return path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def runtime_env(tmp_path: Path, remote_port: int | None = None) -> dict[str, str]:
    """The child's environment: Monado headless (null compositor) with the simulated HMD, or with
    the remote driver on ``remote_port`` (127.0.0.1 only is ever connected to)."""
    env = dict(os.environ)
    env.update(XR_RUNTIME_JSON=runtime_json(), XRT_COMPOSITOR_NULL="1", XRT_LOG="warning")
    env.pop("SIMULATED_ENABLE", None)
    env.pop("P_OVERRIDE_ACTIVE_CONFIG", None)
    if remote_port is None:
        env["SIMULATED_ENABLE"] = "1"
    else:
        home = tmp_path / "xdg"
        (home / "monado").mkdir(parents=True, exist_ok=True)
        (home / "monado" / "config_v0.json").write_text(json.dumps(
            {"active": "remote", "remote": {"version": 0, "port": remote_port, "view_count": 2}}))
        env.update(P_OVERRIDE_ACTIVE_CONFIG="remote", XDG_CONFIG_HOME=str(home))
    return env


def _pose(q_xyzw: tuple[float, float, float, float], p: tuple[float, float, float]) -> bytes:
    return struct.pack("<4f3f", *q_xyzw, *p)


@dataclass
class RemoteState:
    """What the remote driver reports. Angles in radians, quaternions (x, y, z, w) as Monado packs them."""

    fovs: tuple[tuple[float, float, float, float], ...] = ((-0.90, 0.70, 0.80, -0.85), (-0.70, 0.90, 0.80, -0.85))
    eye_positions_m: tuple[tuple[float, float, float], ...] = ((-0.032, 0.0, 0.0), (0.032, 0.0, 0.0))
    head_yaw_deg: float = 30.0
    head_position_m: tuple[float, float, float] = (0.1, 1.5, -0.2)
    gaze_pitch_deg: float = -10.0  # relative to the head
    right_trigger: bool = False
    right_thumbstick_y: float = 0.0  # the right stick's forward deflection, in [-1, 1]
    right_thumbstick_x: float = 0.0  # the right stick's sideways deflection, in [-1, 1], right positive
    right_controller_position_m: tuple[float, float, float] = (0.2, 1.2, -0.5)  # left: mirrored in x
    extra: dict[str, float] = field(default_factory=dict)

    def head_quat_xyzw(self) -> tuple[float, float, float, float]:
        yaw = math.radians(self.head_yaw_deg)
        return (0.0, math.sin(yaw / 2), 0.0, math.cos(yaw / 2))

    def gaze_quat_xyzw(self) -> tuple[float, float, float, float]:
        pitch = math.radians(self.gaze_pitch_deg)
        return (math.sin(pitch / 2), 0.0, 0.0, math.cos(pitch / 2))

    def packet(self) -> bytes:
        head = b""
        for fov, pos in zip(self.fovs, self.eye_positions_m):
            head += struct.pack("<4f", *fov) + _pose((0.0, 0.0, 0.0, 1.0), pos) + b"\0" * 4
        head += _pose(self.head_quat_xyzw(), self.head_position_m) + struct.pack("<?3x", True)
        controllers = b""
        for side in ("left", "right"):
            buttons = [0, 1] + [0] * 14  # hand tracking off, active; then the 11 buttons and padding
            if side == "right" and self.right_trigger:
                buttons[8] = 1  # trigger_click
            x, y, z = self.right_controller_position_m
            floats = [0.0] * 19  # velocities (6), hand curls (5), trigger, squeeze, squeeze force, stick x y (14, 15),
            if side == "right":  # trackpad force, trackpad x y: Monado's r_remote_controller_data, in order
                floats[14], floats[15] = self.right_thumbstick_x, self.right_thumbstick_y
            controllers += (_pose((0.0, 0.0, 0.0, 1.0), (x if side == "right" else -x, y, z))
                            + struct.pack("<19f", *floats) + bytes(buttons))
        gaze = _pose(self.gaze_quat_xyzw(), (0.0, 0.0, 0.0)) + struct.pack("<?3x", True)
        return b"mndrmtg\0" + head + controllers + gaze


class RemoteDriver:
    """A client of Monado's remote driver (the listening side lives in the psyop child process)."""

    def __init__(self, port: int, deadline_s: float = 60.0) -> None:
        end = time.monotonic() + deadline_s
        while True:
            try:
                self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)
                break
            except OSError:
                if time.monotonic() > end:
                    raise RuntimeError(f"the remote driver never listened on 127.0.0.1:{port}") from None
                time.sleep(0.05)
        self.sock.settimeout(0.5)

    def send(self, state: RemoteState) -> None:
        self.sock.sendall(state.packet())
        try:  # the driver sends its own state back; keep the socket drained
            while self.sock.recv(65536):
                pass
        except (TimeoutError, socket.timeout, BlockingIOError):
            pass

    def close(self) -> None:
        self.sock.close()


def run_driven(cmd: list[str], tmp_path: Path, state: RemoteState, update: Callable[[RemoteState, float], None],
               *, timeout_s: float = 200.0) -> subprocess.CompletedProcess:
    """Run ``cmd`` (a psyop child process) on the remote driver's runtime while sending it ``state``, changed by
    ``update(state, elapsed_s)`` before each packet, until the child ends; the child's completed process (stdout and
    stderr as text)."""
    port = free_port()
    run = subprocess.Popen(cmd, env=runtime_env(tmp_path, port), cwd=REPO, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    try:
        driver = RemoteDriver(port)
        start = time.monotonic()
        while run.poll() is None and time.monotonic() - start < timeout_s:
            update(state, time.monotonic() - start)
            try:
                driver.send(state)
            except OSError:
                break
            time.sleep(0.005)
        out, err = run.communicate(timeout=120)
    finally:
        if run.poll() is None:
            run.kill()
    return subprocess.CompletedProcess(cmd, run.returncode, out, err)
