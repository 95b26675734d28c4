"""Depths that validate but no eye or display can show get a located warning with the range
(`depth: {D: 50}`, 2 cm, validated and only `psyop audit` noticed); a unitless depth says how to
write the unit."""

from __future__ import annotations

from pathlib import Path

import pytest

from psyop.cli import main

ROOT = Path(__file__).resolve().parents[2]
LINE = "    depth: {D: 0}                       # Sec. 5.2 Conditions: back surface fixed to 0 D"


def _variant(tmp_path: Path, new: str) -> tuple[Path, int]:
    text = (ROOT / "protocols" / "discrimination.yaml").read_text()
    assert LINE in text
    path = tmp_path / "near.yaml"
    path.write_text(text.replace(LINE, new, 1))
    line = next(i for i, t in enumerate(path.read_text().splitlines(), 1) if t == new)
    return path, line


def test_a_depth_nearer_than_an_eye_focuses_is_a_located_warning(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    path, line = _variant(tmp_path, "    depth: {D: 50}")
    assert main(["validate", str(path)]) == 0  # a warning, not an error: a deliberate near stimulus stays possible
    captured = capsys.readouterr()
    assert captured.err.count("\n") == 1 and f"{path}:{line}:" in captured.err and "warning" in captured.err
    assert "50 D (2.0 cm" in captured.err and "0-10 D" in captured.err and "{m: 50}" in captured.err
    assert ": ok (" in captured.out


def test_factor_levels_reaching_too_near_are_warned(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, _ = _variant(tmp_path, "    depth: {D: 9.9, factor: [offset_D]}")
    assert main(["validate", str(path)]) == 0
    assert "warning: this depth reaches" in capsys.readouterr().err


def test_shipped_protocols_have_no_warning(capsys: pytest.CaptureFixture[str]) -> None:
    paths = sorted(str(p) for p in [*ROOT.glob("protocols/*.yaml"), *ROOT.glob("protocols/examples/*.yaml")])
    assert main(["validate", *paths]) == 0
    assert "warning" not in capsys.readouterr().err


def test_a_depth_without_unit_suggests_both(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, line = _variant(tmp_path, "    depth: 1")
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}:{line}:" in err and "{D: 1}" in err and "{m: 1}" in err, err


@pytest.mark.parametrize(("new", "words"), [
    ('    depth: "1"', ["{D: 1}", "{m: 1}"]),  # a number quoted as text was "expected a mapping of keys (Depth)"
    ("    depth: near", ["{D: 2}", "{m: 0.5}", "{factor: NAME}"]),
    ("    depth: {d: 1}", ["{D: 1}"]),  # was "unknown key 'd'", no reading offered
    ("    depth: {dioptres: 2}", ["{D: 2}"]),
    ("    depth: {metres: 0.5}", ["{m: 0.5}"]),
    ("    depth: {cm: 50}", ["{m: 0.5}"]),
])
def test_a_depth_without_its_unit_says_how_to_write_it(tmp_path: Path, capsys: pytest.CaptureFixture[str], new: str,
                                                       words: list[str]) -> None:
    path, line = _variant(tmp_path, new)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}:{line}:" in err and all(w in err for w in words), err


def test_a_metric_depth_too_near_suggests_dioptres_not_metres(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    # {m: 0.02} was told "if you meant metres, write {m: ...}": it is metres already
    path, line = _variant(tmp_path, "    depth: {m: 0.02}")
    assert main(["validate", str(path)]) == 0
    err = capsys.readouterr().err
    assert f"{path}:{line}:" in err and "50 D (2.0 cm" in err and "{D: 0.02}" in err and "{m:" not in err, err


def test_a_grid_nearer_than_an_eye_focuses_is_a_located_warning(tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    text = (ROOT / "protocols" / "realism.yaml").read_text()
    old = "    near_m: 0.2 "
    assert old in text
    path = tmp_path / "grid.yaml"
    path.write_text(text.replace(old, "    near_m: 0.02 ", 1))
    line = next(i for i, t in enumerate(path.read_text().splitlines(), 1) if "near_m: 0.02" in t)
    assert main(["validate", str(path)]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}:{line}:" in err and "0.02 m (50 D)" in err and "0.1 m" in err, err


def test_a_phase_of_minutes_is_warned_as_likely_milliseconds(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                                             ) -> None:
    """``duration_s: 200`` meant as milliseconds validated silently (807 minutes in `psyop show`, issue 41)."""
    text = (ROOT / "protocols" / "detection.yaml").read_text()
    old = "      duration_s: 2                     # Sec. 5.1: 2-second intervals"
    assert old in text
    path = tmp_path / "ms.yaml"
    path.write_text(text.replace(old, "      duration_s: 200", 1))
    line = next(i for i, t in enumerate(path.read_text().splitlines(), 1) if t == "      duration_s: 200")
    assert main(["validate", str(path)]) == 0
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{path}:{line}:" in err and "warning" in err
    assert "if you meant milliseconds, write duration_s: 0.2" in err


def test_a_left_right_study_whose_scene_ignores_the_near_side_is_refused(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """The schedule drew near_side per trial while nothing in the scene read it: the right surface was always the
    nearer, and validation, simulation and the audit passed (issue 41)."""
    text = (ROOT / "protocols" / "ordinal.yaml").read_text()
    line = next(t for t in text.splitlines() if t.strip().startswith("near_side: schedule"))
    path = tmp_path / "fixed_side.yaml"
    path.write_text(text.replace(line, line.replace("near_side: schedule", "near_side: right"), 1))
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "no scene item reads it" in err and "near_side: schedule" in err and err.count("\n") == 1


def test_a_size_wider_than_the_whole_view_is_warned_as_arcmin_or_pixels(tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    text = (ROOT / "protocols" / "detection.yaml").read_text()
    old = next(line for line in text.splitlines() if line.strip().startswith("size_deg: 2"))
    path = tmp_path / "huge.yaml"
    path.write_text(text.replace(old, old.replace("size_deg: 2", "size_deg: 170"), 1))
    assert main(["validate", str(path)]) == 0  # a warning: the value is valid
    err = capsys.readouterr().err
    line = next(i for i, t in enumerate(path.read_text().splitlines(), 1) if "size_deg: 170" in t)
    assert f"{path}:{line}:" in err and "warning: size_deg: 170 deg is wider than the display's whole field" in err
    assert "if you meant arcmin, write size_deg: 2.83333" in err and "if pixels, about 13 deg" in err
    assert main(["validate", str(ROOT / "protocols" / "detection.yaml")]) == 0
    assert "warning" not in capsys.readouterr().err  # the shipped sizes are not warned


HIDDEN = """psyop_protocol: 1
study: {name: hidden, title: a disc behind a nearer quad}
display:
  profile: {name: lab_hmd, width_px: 1600, height_px: 1600, refresh_hz: 120, horizontal_fov_deg: 96}
  eye_model: gullstrand_emsley_relaxed
  ipd: {mm: 61}
eyes: stereo
scene:
  - {id: back, kind: disc, size_deg: SIZE, depth: {factor: back_D}, surface: {kind: solid, rgb: [1, 0, 0]}}
  - {id: front, kind: quad, width_deg: 40, height_deg: 40, depth: {D: 3}, surface: {kind: solid, rgb: [0.1, 0.1, 0.5]}}
trial:
  phases:
    - {kind: interval, duration_s: 0.5}
    - {kind: interval, duration_s: 0.5}
    - {kind: interval, duration_s: 0.5}
    - {kind: response, expected_s: 0.5}
design:
  factors:
    back_D: {levels: [0.5, 2.0]}
  repetitions: 1
  randomisation: {kind: full}
response: {kind: n_afc, n: 3, target: {mode: ocular}, reference: {mode: conventional}, level_factor: back_D}
"""


@pytest.mark.parametrize(("size_deg", "hidden"), [(6, True), (36, False)])
def test_a_disc_a_nearer_quad_covers_in_every_frame_is_warned_at_its_depth(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], size_deg: int, hidden: bool) -> None:
    """A 6 deg disc behind a 40 deg quad 1-2.5 D nearer is hidden from either eye at any gaze (psyop audit agrees:
    never visible); a 36 deg disc shows around the quad's sides (its margin, ~4 deg of eye offset, reaches past)."""
    path = tmp_path / "hidden.yaml"
    path.write_text(HIDDEN.replace("SIZE", str(size_deg)))
    assert main(["validate", str(path)]) == 0  # a warning: a head moved in a world-fixed scene may look around it
    err = capsys.readouterr().err
    assert ("warning: 'back' is hidden behind the nearer quad 'front'" in err) is hidden, err
    if hidden:
        assert f"{path}:9:" in err and "covers 20 deg" in err
        assert main(["audit", str(path), "--no-progress", "--scale", "0.05", "--gazes", "2"]) == 1
        assert "FAIL back (item back): never visible" in capsys.readouterr().out
