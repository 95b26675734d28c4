"""`psyop calibrate` against photometers emulated on real ptys (photometer_emulators.py): the calibration
recovers the emulated display's transfer function within 1 % at every measured level, and every fault ends in
one line, exit 2, with the readings so far kept in the partial file the line names."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from photometer_emulators import (ColorCalEmulator, DisplayModel, LS100Emulator, PR650Emulator, PR655Emulator,
                                  PtyPhotometer, wait_until)

from psyop.calibration.model import CHANNELS, predict_luminance
from psyop.calibration.patches import level_codes, patch_rgb, patch_sequence
from psyop.calibration.record import FORMAT, load_calibration
from psyop.cli import main

REPO = Path(__file__).resolve().parents[2]


def calibrate(tmp_path: Path, photometer: str, *extra: str, levels: int = 5) -> tuple[int, Path]:
    out = tmp_path / "cal.json"
    code = main(["calibrate", "--photometer", photometer, "--display", "headless", "--patch-log",
                 str(tmp_path / "patches.jsonl"), "--levels", str(levels), "--out", str(out), "--no-progress", *extra])
    return code, out


def assert_recovers(record: dict, display: DisplayModel, tolerance: float = 0.01) -> float:
    """Every measured level of every channel within ``tolerance`` (relative) of the display's true luminance."""
    worst = 0.0
    for channel in CHANNELS:
        for code in record["levels"]:
            truth = display.luminance(list(patch_rgb(channel, code)))
            predicted = float(predict_luminance(record["fit"][channel], code))
            worst = max(worst, abs(predicted - truth) / truth)
    assert worst < tolerance, worst
    return worst


def start(emulator: type[PtyPhotometer], tmp_path: Path, **kwargs) -> PtyPhotometer:
    (tmp_path / "patches.jsonl").write_text("")
    return emulator(tmp_path / "patches.jsonl", **kwargs)


def test_ls100_calibration_recovers_gamma_black_and_peak(tmp_path: Path, capsys) -> None:
    display = DisplayModel()
    device = start(LS100Emulator, tmp_path, display=display)
    try:
        code, out = calibrate(tmp_path, f"ls100:{device.path}", "--repeats", "2", "--display-name", "test LCD",
                              levels=9)
    finally:
        device.close()
    assert code == 0, capsys.readouterr().err
    record = load_calibration(out)
    assert record["format"] == FORMAT and record["complete"] is True
    assert record["device"] == {"kind": "ls100", "model": "Konica Minolta LS-100/LS-110", "port": device.path,
                                "serial_number": None, "settings": "4800 baud 7E2, CR LF", "mode": "MDS,04 (absolute)"}
    assert record["display"]["kind"] == "headless" and record["display"]["name"] == "test LCD"
    assert len(record["readings"]) == 4 * 9 * 2 == device.measurements
    assert device.commands[0] == "MDS,04" and set(device.commands[1:]) == {"MES"}
    assert record["readings"][5]["raw"].startswith("OK00,+")
    shown = [json.loads(line)["rgb"] for line in (tmp_path / "patches.jsonl").read_text().splitlines()]
    assert shown == [r["rgb"] for r in record["readings"]]  # each patch logged before its reading
    worst = assert_recovers(record, display)
    for channel in CHANNELS:
        fit = record["fit"][channel]
        assert fit["model"] == "gog"
        assert fit["gog"]["gamma"] == pytest.approx(2.4, rel=2e-3)
        assert fit["gog"]["black_cd_m2"] == pytest.approx(0.3, rel=5e-3)
        assert len(fit["residuals_relative"]) == 18 and fit["max_abs_residual_relative"] < 1e-3
    assert record["luminance_cd_m2"]["min"] == pytest.approx(0.3, rel=1e-3)
    assert record["luminance_cd_m2"]["max"] == pytest.approx(100.0, rel=1e-3)
    assert record["chromaticity"] == {}  # the LS-100 measures no chromaticity
    print(f"ls100 worst recovery error {100 * worst:.3f} %", file=sys.__stderr__)
    assert "largest residual" in capsys.readouterr().out


def test_pr650_calibration_recovers_luminance_and_chromaticity(tmp_path: Path, capsys) -> None:
    display = DisplayModel()
    device = start(PR650Emulator, tmp_path, display=display)
    try:
        code, out = calibrate(tmp_path, f"pr650:{device.path}", levels=5)
    finally:
        device.close()
    assert code == 0, capsys.readouterr().err
    record = load_calibration(out)
    assert device.commands[:2] == ["B1", "S01,,,,,,01,1"]
    assert record["device"]["kind"] == "pr650" and record["device"]["serial_number"] is None
    assert_recovers(record, display)
    for channel, (x, y) in {"red": (0.64, 0.33), "green": (0.30, 0.60), "blue": (0.15, 0.06)}.items():
        measured = record["chromaticity"][channel]
        expected = display.chromaticity(list(patch_rgb(channel, 255)))
        assert (measured["x"], measured["y"]) == pytest.approx(expected, abs=1e-4)
        assert (measured["x"], measured["y"]) == pytest.approx((x, y), abs=0.01)  # near the primary (plus black)
    black = [r for r in record["readings"] if r["code"] == 0]
    assert black and all(r["quality"] == "light low (code 18)" for r in black)  # kept, flagged


def test_pr655_reports_model_and_serial_number(tmp_path: Path, capsys) -> None:
    display = DisplayModel(black_cd_m2=0.05, peak_cd_m2=250.0, weights=(0.25, 0.68, 0.07))
    device = start(PR655Emulator, tmp_path, display=display)
    try:
        code, out = calibrate(tmp_path, f"pr655:{device.path}", levels=6)
    finally:
        device.close()
    assert code == 0, capsys.readouterr().err
    record = load_calibration(out)
    assert device.commands[:4] == ["PHOTO", "D111", "D110", "SU1"]
    assert record["device"]["serial_number"] == "65104321" and record["device"]["model_reported"] == "PR-655"
    assert record["fit"]["grey"]["gog"]["offset_fitted"] is True
    assert_recovers(record, display)


def test_colorcal_applies_its_calibration_matrix(tmp_path: Path, capsys) -> None:
    display = DisplayModel()
    device = start(ColorCalEmulator, tmp_path, display=display)
    try:
        code, out = calibrate(tmp_path, f"colorcal:{device.path}", levels=5)
    finally:
        device.close()
    assert code == 0, capsys.readouterr().err
    record = load_calibration(out)
    assert device.commands[:4] == ["IDR", "r01", "r02", "r03"]
    assert record["device"]["serial_number"] == "CC2-01234"
    assert record["device"]["calibration_matrix"][0] == pytest.approx([1.0631, -0.0347, 0.0120])
    assert_recovers(record, display)
    expected = display.chromaticity(list(patch_rgb("green", 255)))
    assert tuple(record["chromaticity"]["green"].values()) == pytest.approx(expected, abs=1e-4)


def test_a_transfer_that_is_no_power_law_gets_the_monotone_spline(tmp_path: Path, capsys) -> None:
    display = DisplayModel(transfer=lambda v: 3 * np.asarray(v) ** 2 - 2 * np.asarray(v) ** 3)  # an S curve
    device = start(LS100Emulator, tmp_path, display=display)
    try:
        code, out = calibrate(tmp_path, f"ls100:{device.path}", levels=9)
    finally:
        device.close()
    assert code == 0, capsys.readouterr().err
    record = load_calibration(out)
    for channel in CHANNELS:
        fit = record["fit"][channel]
        assert fit["model"] == "spline", fit
        assert fit["spline"]["loo_rms_relative"] < fit["gog"]["loo_rms_relative"]
    assert_recovers(record, display)


FAULTS = [
    ("ls100", LS100Emulator, "timeout", "no reply to MES within 0.5 s"),
    ("ls100", LS100Emulator, "error", "answered ER10 (measuring range over) to MES"),
    ("ls100", LS100Emulator, "garbage", "answered garbage"),
    ("ls100", LS100Emulator, "pulled", "the cable was pulled"),
    ("pr650", PR650Emulator, "error", "answered error code 09 to M1"),
    ("pr650", PR650Emulator, "pulled", "the cable was pulled"),
    ("pr655", PR655Emulator, "garbage", "answered garbage"),
    ("pr655", PR655Emulator, "timeout", "no reply to M1 within 0.5 s"),
    ("pr655", PR655Emulator, "error", "answered error code 00010 to M1"),
    ("pr655", PR655Emulator, "pulled", "the cable was pulled"),
    ("pr650", PR650Emulator, "garbage", "answered garbage"),
    ("pr650", PR650Emulator, "timeout", "no reply to M1 within 0.5 s"),
    ("colorcal", ColorCalEmulator, "error", "answered ER11 to MES"),
    ("colorcal", ColorCalEmulator, "pulled", "the cable was pulled"),
]


@pytest.mark.parametrize(("kind", "emulator", "fault", "says"), FAULTS, ids=[f"{f[0]}-{f[2]}" for f in FAULTS])
def test_device_faults_end_in_one_line_and_keep_the_readings(tmp_path: Path, capsys, kind, emulator, fault,
                                                             says) -> None:
    device = start(emulator, tmp_path, fault=fault, fault_after=7)
    try:
        code, out = calibrate(tmp_path, f"{kind}:{device.path}", "--timeout-s", "0.5")
    finally:
        device.close()
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("psyop calibrate:")]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    line = lines[0]
    partial = tmp_path / "cal.partial.json"
    assert line.startswith(f"psyop calibrate: error: {kind} on {device.path}: "), line
    assert says in line and f"the 7 readings so far are kept in {partial}" in line, line
    assert not out.exists()
    record = json.loads(partial.read_text())
    assert record["complete"] is False and len(record["readings"]) == 7
    assert record["error"] in line and record["device"]["kind"] == kind


def test_non_monotone_readings_are_refused_with_the_readings_kept(tmp_path: Path, capsys) -> None:
    def dip(v: np.ndarray) -> np.ndarray:
        v = np.asarray(v, dtype=np.float64)
        return np.where(np.isclose(v, 191 / 255), 0.05, v**2.4)  # level 191 falls below level 128

    device = start(LS100Emulator, tmp_path, display=DisplayModel(transfer=dip))
    try:
        code, _ = calibrate(tmp_path, f"ls100:{device.path}")
    finally:
        device.close()
    err = capsys.readouterr().err
    assert code == 2 and "non-monotone" in err and "level 191" in err and len(err.strip().splitlines()) == 1, err
    record = json.loads((tmp_path / "cal.partial.json").read_text())
    assert len(record["readings"]) == 20 and "non-monotone" in record["error"]


def test_noisy_repeats_are_refused(tmp_path: Path, capsys) -> None:
    device = start(LS100Emulator, tmp_path, display=DisplayModel(noise_relative=0.15, seed=3))
    try:
        code, _ = calibrate(tmp_path, f"ls100:{device.path}", "--repeats", "3")
    finally:
        device.close()
    err = capsys.readouterr().err
    assert code == 2 and "readings are noisy" in err and "cal.partial.json" in err, err
    assert len(json.loads((tmp_path / "cal.partial.json").read_text())["readings"]) == 60


def test_a_device_that_never_answers_fails_at_open(tmp_path: Path, capsys) -> None:
    device = start(LS100Emulator, tmp_path)
    device.answer = lambda command: None  # silent from the first command
    try:
        code, _ = calibrate(tmp_path, f"ls100:{device.path}", "--timeout-s", "0.3")
    finally:
        device.close()
    err = capsys.readouterr().err
    assert code == 2 and "no reply to MDS,04 within 0.3 s" in err and "hold" not in err.split(";")[0], err


def manual_lines(display: DisplayModel, levels: int) -> list[str]:
    sequence = patch_sequence(level_codes(levels), 1, CHANNELS)
    return [f"{display.luminance(list(patch_rgb(c, code))):.5g}" for c, code, _ in sequence]


def test_manual_readings_from_stdin(tmp_path: Path, capsys, monkeypatch) -> None:
    display = DisplayModel()
    lines = manual_lines(display, 5)
    lines.insert(3, "about twelve")  # asked again, not fatal
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n".join(lines) + "\n"))
    code, out = calibrate(tmp_path, "manual", "--device-name", "Minolta LS-110 read by hand", levels=5)
    err = capsys.readouterr().err
    assert code == 0, err
    assert "patch 1/20: grey 0/255" in err and "not a reading: 'about twelve'" in err
    record = load_calibration(out)
    assert record["device"]["kind"] == "manual" and record["device"]["model"] == "Minolta LS-110 read by hand"
    assert_recovers(record, display)


def test_manual_stdin_ending_early_keeps_the_readings(tmp_path: Path, capsys, monkeypatch) -> None:
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n".join(manual_lines(DisplayModel(), 5)[:11]) + "\n"))
    code, _ = calibrate(tmp_path, "manual", levels=5)
    err = capsys.readouterr().err
    assert code == 2 and "stdin ended after 11 readings" in err and "cal.partial.json" in err
    assert len(json.loads((tmp_path / "cal.partial.json").read_text())["readings"]) == 11


def test_the_command_line_end_to_end(tmp_path: Path) -> None:
    """A real `psyop calibrate` process, the emulator in this one: the command line of docs/calibration.md."""
    device = start(LS100Emulator, tmp_path)
    try:
        result = subprocess.run([sys.executable, "-m", "psyop", "calibrate", "--photometer", f"ls100:{device.path}",
                                 "--display", "headless", "--patch-log", str(tmp_path / "patches.jsonl"),
                                 "--levels", "5", "--out", str(tmp_path / "cal.json")],
                                capture_output=True, text=True, timeout=120, cwd=REPO)
    finally:
        device.close()
    assert result.returncode == 0, result.stderr
    assert "calibrate: 20/20 patches" in result.stderr  # the progress, as plain lines off a terminal
    assert f"wrote {tmp_path / 'cal.json'}: 20 readings from ls100" in result.stdout
    assert_recovers(load_calibration(tmp_path / "cal.json"), DisplayModel())


@pytest.mark.parametrize("args", [["--levels", "3"], ["--repeats", "0"], ["--out", "cal.txt"]])
def test_bad_options_are_one_line(tmp_path: Path, capsys, args) -> None:
    out = ["--out", str(tmp_path / "cal.json")] if "--out" not in args else []
    assert main(["calibrate", "--photometer", "manual", "--display", "headless", *out, *args]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_unknown_photometer_is_one_line(tmp_path: Path, capsys) -> None:
    assert main(["calibrate", "--photometer", "cs2000:/dev/null", "--out", str(tmp_path / "c.json")]) == 2
    assert "--photometer must be ls100:PORT" in capsys.readouterr().err


def test_window_display_under_xvfb(tmp_path: Path) -> None:
    """--display window: the patches reach a real (Xvfb) window, read back from its framebuffer."""
    import shutil

    if not os.environ.get("DISPLAY") and shutil.which("xvfb-run") is None:
        pytest.skip("no X display and no xvfb-run")
    device = start(LS100Emulator, tmp_path)
    command = [sys.executable, "-m", "psyop", "calibrate", "--photometer", f"ls100:{device.path}", "--display",
               "window", "--windowed", "--settle-s", "0", "--patch-log", str(tmp_path / "patches.jsonl"),
               "--levels", "4", "--out", str(tmp_path / "cal.json"), "--no-progress"]
    if not os.environ.get("DISPLAY"):
        command = ["xvfb-run", "-a", "-s", "-screen 0 640x480x24", *command]
    try:
        result = subprocess.run(command, capture_output=True, text=True, timeout=120, cwd=REPO)
    finally:
        device.close()
    assert result.returncode == 0, result.stderr
    record = load_calibration(tmp_path / "cal.json")
    assert record["display"]["kind"] == "window" and record["display"]["size_px"] == [640, 480]
    assert_recovers(record, DisplayModel())
    wait_until(lambda: device.closed.is_set(), what="the emulator to close", timeout_s=10)
