"""Luminance in a protocol (psyop.protocol.luminance, docs/gratings_and_luminance.md): the display's calibration file
is read at validation, every luminance is checked against its range at its file:line:column, and gratings build."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from psyop.calibration.model import predict_luminance
from psyop.calibration.record import FORMAT
from psyop.errors import UserError
from psyop.protocol.loader import parse_protocol
from psyop.protocol.luminance import CALIBRATION_FORMAT, load_transfer, protocol_transfer
from psyop.rendering.scene import Grating, Solid
from psyop.schedule import compile_schedule
from psyop.stimulus import build_scene

from tests.protocol.calibration_files import power_law, s_shaped, write_calibration

PROTOCOL = """\
psyop_protocol: 1
study: {{name: gabor_luminance, title: A Gabor on a calibrated display}}
display:
  profile: vive_pro
  ipd: tracker{calibration}
eyes: right
scene:
  - id: patch
    kind: disc
    size_deg: 4
    depth: {{D: 1, factor: level_D}}
    surface: {surface}
  - id: fixation
    kind: fixation_target
    size_deg: 0.5
    depth: {{D: 1}}
    centre_deg: [0, 3]
trial:
  phases:
    - {{kind: interval, duration_s: 0.5}}
    - {{kind: response}}
design:
  factors:
    contrast_fraction: {{levels: [0.01, 0.02]}}
    level_D: {{levels: [0.5]}}
  repetitions: 2
  randomisation: {{kind: full}}
response:
  kind: yes_no
  question: Did you see it?
  signal: {{mode: ocular}}
  noise: {{mode: conventional}}
  level_factor: level_D
  signal_trials: balanced
observer: {{kind: psychometric_yes_no, level_column: level_D, threshold: 0.5, width: 0.2, false_alarm_rate: 0.1,
            lapse: 0.02}}
"""

GABOR = ("{kind: grating, cycles_per_deg: 2, orientation_deg: 45, phase_deg: 90, luminance: {cd_m2: 40}, "
         "contrast: {factor: contrast_fraction}, window: {kind: gaussian, sigma_deg: 0.6}}")


def _protocol(tmp_path: Path, surface: str = GABOR, calibration: str | None = "cal.json") -> Path:
    text = PROTOCOL.format(surface=surface, calibration="" if calibration is None else f"\n  calibration: {calibration}")
    path = tmp_path / "gabor.yaml"
    path.write_text(text)
    return path


def _load(path: Path):
    return parse_protocol(path.read_text(), str(path), path.parent)


def _line_of(path: Path, needle: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if needle in line)


def test_the_format_name_is_the_calibration_files():
    assert CALIBRATION_FORMAT == FORMAT


@pytest.mark.parametrize("transfer, model", [(power_law(), "gog"), (s_shaped(), "spline")])
def test_the_loaded_transfer_is_the_files_model(tmp_path, transfer, model):
    """The protocol's transfer (numpy, psyop.optics.transfer) equals psyop.calibration.model.predict_luminance at
    every code (1e-9 relative), GOG and PCHIP spline alike; its range is the grey channel at codes 0 and 255."""
    write_calibration(tmp_path / "cal.json", transfer)
    protocol = _load(_protocol(tmp_path))
    fit = json.loads((tmp_path / "cal.json").read_text())["fit"]["grey"]
    assert fit["model"] == model
    got = protocol_transfer(protocol, tmp_path)
    assert got is not None
    codes = np.linspace(0, 255, 1021)
    np.testing.assert_allclose(got.luminance_cd_m2(codes), predict_luminance(fit, codes), rtol=1e-9)
    assert got.black_cd_m2 == pytest.approx(float(predict_luminance(fit, 0)))
    assert got.peak_cd_m2 == pytest.approx(float(predict_luminance(fit, 255)))
    np.testing.assert_allclose(got.luminance_cd_m2(got.code_for(np.array([1.0, 40.0, 99.0]))), [1.0, 40.0, 99.0],
                               rtol=1e-6)


def test_a_missing_or_corrupt_calibration_is_one_line_at_its_key(tmp_path):
    path = _protocol(tmp_path, calibration="missing.json")
    line = _line_of(path, "calibration:")
    with pytest.raises(UserError, match="not found") as missing:
        _load(path)
    assert f"gabor.yaml:{line}:" in str(missing.value)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(UserError, match="cannot be read as JSON"):
        _load(_protocol(tmp_path, calibration="bad.json"))
    (tmp_path / "other.json").write_text(json.dumps({"format": "something/1"}))
    with pytest.raises(UserError, match="not a psyop display calibration"):
        _load(_protocol(tmp_path, calibration="other.json"))
    write_calibration(tmp_path / "cal.json", power_law())
    partial = json.loads((tmp_path / "cal.json").read_text()) | {"complete": False, "error": "no reply"}
    (tmp_path / "partial.json").write_text(json.dumps(partial))
    with pytest.raises(UserError, match="partial calibration"):
        _load(_protocol(tmp_path, calibration="partial.json"))
    broken = json.loads((tmp_path / "cal.json").read_text())
    broken["fit"]["grey"]["gog"]["gamma"] = "x"
    (tmp_path / "broken.json").write_text(json.dumps(broken))
    with pytest.raises(UserError, match="fit.grey"):
        _load(_protocol(tmp_path, calibration="broken.json"))


def test_a_luminance_on_an_uncalibrated_display_is_refused(tmp_path):
    path = _protocol(tmp_path, surface="{kind: solid, luminance: {cd_m2: 40}}", calibration=None)
    with pytest.raises(UserError, match="needs a calibrated display") as error:
        _load(path)
    assert f"gabor.yaml:{_line_of(path, 'surface:')}:" in str(error.value)


@pytest.mark.parametrize("surface, says", [
    ("{kind: solid, luminance: {cd_m2: 150}}", "150 cd/m²"),
    ("{kind: solid, luminance: {cd_m2: 0.1}}", "0.1 cd/m²"),
    ("{kind: grating, cycles_per_deg: 1, luminance: {cd_m2: 60}, contrast: 0.8}", "12 to 108 cd/m²"),
    ("{kind: grating, cycles_per_deg: 1, luminance: {cd_m2: 60}, contrast: {weber: 0.9}}", "6 to 114 cd/m²"),
    ("{kind: white_noise, luminance: {cd_m2: 101}}", "101 cd/m²"),
])
def test_a_luminance_outside_the_calibrated_range_is_refused_at_its_place(tmp_path, surface, says):
    write_calibration(tmp_path / "cal.json", power_law())
    path = _protocol(tmp_path, surface=surface)
    with pytest.raises(UserError, match="outside the calibrated range 0.3 to 100 cd/m²") as error:
        _load(path)
    assert says in str(error.value)
    assert f"gabor.yaml:{_line_of(path, 'surface:')}:" in str(error.value)


def test_a_contrast_factor_level_outside_the_range_is_named(tmp_path):
    write_calibration(tmp_path / "cal.json", power_law(peak_cd_m2=40.5))
    with pytest.raises(UserError, match="contrast_fraction = 0.02") as error:
        _load(_protocol(tmp_path))
    assert "39.2 to 40.8 cd/m²" in str(error.value)


def test_mean_and_luminance_together_and_gratings_above_nyquist_are_refused(tmp_path):
    write_calibration(tmp_path / "cal.json", power_law())
    with pytest.raises(UserError, match="not both"):
        _load(_protocol(tmp_path, surface="{kind: grating, cycles_per_deg: 1, mean: 0.5, luminance: {cd_m2: 40}}"))
    with pytest.raises(UserError, match=r"Nyquist frequency at its centre \(4.4 cycles/deg"):
        _load(_protocol(tmp_path, surface="{kind: grating, cycles_per_deg: 5}"))
    with pytest.raises(UserError, match="image surfaces hold pixel values"):
        (tmp_path / "t.png").write_bytes(b"")
        _load(_protocol(tmp_path, surface="{kind: image, path: t.png}"))


def test_a_calibrated_gabor_builds_in_normalised_luminance(tmp_path):
    """The scene builder turns the protocol's Gabor into the renderer's Grating in normalised luminance (L / peak):
    mean 40 / 100, amplitude 1 % of it, 2 cycles per surface degree at 45 deg, cosine phase, sigma 0.6 deg; the
    fixation target's pixel colours become the luminance of their own codes."""
    write_calibration(tmp_path / "cal.json", power_law())
    protocol = _load(_protocol(tmp_path))
    transfer = load_transfer(tmp_path / "cal.json")
    row = compile_schedule(protocol, 1).iloc[0].to_dict()
    scene = build_scene(protocol, row, 0.0, np.array([0.032, 0.0, 0.0]), interval=1, base_dir=tmp_path)
    grating = next(p.material for p in scene.primitives if p.name == "patch")
    assert isinstance(grating, Grating)
    assert grating.mean == pytest.approx(40.0 / transfer.peak_cd_m2)
    assert grating.amplitude == pytest.approx(grating.mean * row["contrast_fraction"])
    assert np.hypot(grating.cycles_u, grating.cycles_v) == pytest.approx(2.0)
    assert grating.cycles_u == pytest.approx(grating.cycles_v)
    assert (grating.phase_cycles, grating.window_1) == (0.25, 0.6)
    outer = next(p.material for p in scene.primitives if p.name == "fixation_outer")
    assert isinstance(outer, Solid)
    assert outer.colour[0] == pytest.approx(1.0) and outer.colour[1] == pytest.approx(transfer.black_cd_m2 / 100.0)
    assert scene.output is not None and scene.output.key == transfer.key


def test_a_drifting_grating_moves_with_time_on_an_uncalibrated_display(tmp_path):
    """drift_deg_s: the phase falls by cycles_per_deg * drift_deg_s cycles per second (the bars move towards +x), the
    item depends on time (the session rebuilds it each frame), and pixel-valued means stay as they are."""
    from psyop.stimulus.build import depends_on_time

    surface = "{kind: grating, waveform: square, cycles_per_deg: 2, drift_deg_s: 1.5, mean: 0.4, contrast: {michelson: {factor: contrast_fraction}}}"
    protocol = _load(_protocol(tmp_path, surface=surface, calibration=None))
    row = compile_schedule(protocol, 1).iloc[0].to_dict()
    at = [next(p.material for p in build_scene(protocol, row, t, np.array([0.032, 0.0, 0.0])).primitives
               if p.name == "patch") for t in (0.0, 0.5)]
    assert at[0].phase_cycles - at[1].phase_cycles == pytest.approx(2 * 1.5 * 0.5)
    assert (at[0].mean, at[0].amplitude) == (0.4, pytest.approx(0.4 * row["contrast_fraction"]))
    assert depends_on_time(protocol.scene[0]) and not depends_on_time(protocol.scene[1])
    assert build_scene(protocol, row, 0.0, np.array([0.032, 0.0, 0.0])).output is None
