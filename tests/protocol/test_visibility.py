"""A fixation target or stimulus that an aperture hides in every frame showing it is refused at its line with the
reason; one the participant sees somewhere is not. The refusal agrees with what ``psyop audit`` renders."""

from __future__ import annotations

from pathlib import Path

import pytest

from psyop.audit import AuditSettings, run_audit
from psyop.cli import main
from psyop.protocol import load_protocol
from protocol_texts import TWO_INTERVAL_TAIL

HEADER = """psyop_protocol: 1
study: {{name: hidden_target, title: A target behind an aperture}}
display: {{profile: vive_pro, ipd: {{mm: 63}}}}
eyes: stereo
scene:
  - {{id: stimulus, kind: disc, size_deg: 2, depth: {{D: 1}}, surface: {{kind: solid, rgb: [1, 1, 1]}}, centre_deg: {disc}}}
  - {{id: window, kind: aperture, diameter_deg: {diameter}}}
  - id: fixation
    kind: fixation_target
    size_deg: 0.4
    depth: {{D: 0.5}}
    path: {{kind: circle, eccentricity_deg: {ecc}, speed_deg_s: 60}}
"""


def _protocol(tmp_path: Path, *, ecc: float = 3, diameter: float = 12, disc: str = "[0, 0]",
              tail: str = TWO_INTERVAL_TAIL) -> Path:
    path = tmp_path / "hidden.yaml"
    path.write_text(HEADER.format(ecc=ecc, diameter=diameter, disc=disc) + tail)
    return path


def _line_of(path: Path, text: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if text in line)


def test_a_circling_target_outside_the_opening_is_refused_at_its_path(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    path = _protocol(tmp_path, ecc=10, diameter=12)  # the docs' former example: 10 deg path, 6 deg opening
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}:{_line_of(path, 'path:')}:" in err, err
    assert "'fixation' is hidden in every frame by aperture 'window'" in err
    assert "9.8 deg" in err and "6 deg opening" in err and "diameter_deg larger than 19.6" in err


def test_a_disc_outside_the_opening_is_refused_at_its_centre(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    path = _protocol(tmp_path, disc="[20, 0]")
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}:{_line_of(path, 'id: stimulus')}:" in err and "'stimulus' is hidden" in err and "19 deg" in err


@pytest.mark.parametrize("ecc", [3, 6.5])  # well inside; its edge at the opening's edge
def test_a_target_that_reaches_the_opening_passes(tmp_path: Path, ecc: float) -> None:
    assert main(["validate", str(_protocol(tmp_path, ecc=ecc))]) == 0


def test_a_phase_without_the_aperture_shows_the_target(tmp_path: Path) -> None:
    tail = TWO_INTERVAL_TAIL.replace("- {kind: interval, duration_s: 1}\n    - {kind: response",
                                     "- {kind: interval, duration_s: 1, show: [stimulus, fixation]}\n"
                                     "    - {kind: response", 1)
    assert tail != TWO_INTERVAL_TAIL
    assert main(["validate", str(_protocol(tmp_path, ecc=10, tail=tail))]) == 0


def test_the_margin_keeps_a_target_the_audit_sees(tmp_path: Path) -> None:
    """A path whose inner edge lies just outside the opening as seen from the head's centre passes the check (each
    eye sees it past the edge on its own side): the audit, rendering each eye, sees the target."""
    path = _protocol(tmp_path, ecc=6.3)
    assert main(["validate", str(path)]) == 0
    report = run_audit(load_protocol(path), AuditSettings(scale=0.0625, gazes=4, samples_per_axis=8),
                       base_dir=tmp_path)
    fixation = [i for i, name in enumerate(report.records[0].names) if name.startswith("fixation")]
    assert fixation and all(any(r.visible_px2[i] > 0 for r in report.records) for i in fixation)
