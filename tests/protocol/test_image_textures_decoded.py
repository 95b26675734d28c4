"""An image surface whose file is not an image is refused at validation (issue 26, item 7).

Before, a text file named ``checker.png`` passed ``psyop validate`` and ``run``/``render``/``audit``
ended in a traceback (``SyntaxError: not a PNG file``), leaving the session marked running.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

PROTOCOLS = Path(__file__).resolve().parents[2] / "protocols"
SOLID = "surface: {kind: solid, rgb: [1, 0, 0]}"


def _psyop(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "psyop", *args], capture_output=True, text=True, timeout=300,
                          cwd=cwd, env={"PYTHONPATH": str(Path(__file__).resolve().parents[2]),
                                        "PATH": "/usr/bin:/bin", "HOME": str(cwd)})


def _study(tmp_path: Path, texture: bytes) -> Path:
    text = (PROTOCOLS / "detection.yaml").read_text()
    assert SOLID in text
    (tmp_path / "checker.png").write_bytes(texture)
    study = tmp_path / "study.yaml"
    study.write_text(text.replace(SOLID, "surface: {kind: image, path: checker.png}", 1))
    return study


@pytest.mark.parametrize("texture", [b"this is a text file, not a PNG\n", b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR\0\0"],
                         ids=["text", "truncated_png"])
def test_undecodable_texture_is_refused_by_validate_run_render_and_audit(tmp_path: Path, texture: bytes) -> None:
    study = _study(tmp_path, texture)
    line = next(i for i, text in enumerate(study.read_text().splitlines(), 1) if "checker.png" in text)
    validate = _psyop("validate", str(study), cwd=tmp_path)
    assert validate.returncode == 2, validate.stderr
    assert "Traceback" not in validate.stderr + validate.stdout
    message = validate.stderr.strip()
    assert f"study.yaml:{line}:" in message and "'checker.png' is not a readable image" in message, message
    run = _psyop("run", str(study), "--participant", "P01", "--data", str(tmp_path / "data"), "--no-progress",
                 cwd=tmp_path)
    assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
    assert "checker.png" in run.stderr
    assert not (tmp_path / "data").exists() or not any((tmp_path / "data").rglob("session.json"))
    render = _psyop("render", str(study), "--out", str(tmp_path / "frame.png"), cwd=tmp_path)
    assert render.returncode == 2 and "Traceback" not in render.stderr and "checker.png" in render.stderr, render.stderr
    assert not (tmp_path / "frame.png").exists()
    audit = _psyop("audit", str(study), cwd=tmp_path)
    assert audit.returncode == 2 and "Traceback" not in audit.stderr and "checker.png" in audit.stderr, audit.stderr


def test_a_real_image_still_validates(tmp_path: Path) -> None:
    study = _study(tmp_path, b"")
    mpimg.imsave(tmp_path / "checker.png", np.random.default_rng(0).uniform(size=(8, 8, 3)))
    result = _psyop("validate", str(study), cwd=tmp_path)
    assert result.returncode == 0, result.stderr


def test_renderer_decoder_turns_every_decoder_error_into_a_user_error(tmp_path: Path) -> None:
    from psyop.errors import UserError
    from psyop.rendering.textures import decode_image_rgb

    (tmp_path / "checker.png").write_text("not a PNG\n")
    with pytest.raises(UserError, match="cannot read image"):
        decode_image_rgb(tmp_path / "checker.png")
