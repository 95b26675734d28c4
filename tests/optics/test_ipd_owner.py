"""One owner of the ipd rule (issue 43 item 2): its bound (psyop.optics.ranges.IPD_M), its default
(DEFAULT_IPD_M) and the eye centres it gives (psyop.optics.nodal.eye_centre_x_m) live in psyop.optics and
nothing else defines them: an 85 mm participant can be audited as well as run."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from psyop.audit import AuditSettings
from psyop.cli.render import ipd_arg_m
from psyop.errors import UserError
from psyop.optics.nodal import eye_centre_m
from psyop.optics.ranges import DEFAULT_IPD_M, IPD_M
from psyop.protocol import load_protocol
from psyop.session.plan import compile_plan
from tests.session.session_helpers import small_protocol

PSYOP = Path(__file__).resolve().parents[2] / "psyop"


def _protocol_with_ipd(directory: Path, mm: float):
    path = small_protocol(directory, "detection", 1)
    text, n = re.subn(r"(?m)^(\s*ipd:).*$", rf"\g<1> {{mm: {mm:g}}}", path.read_text())
    assert n == 1
    path.write_text(text)
    return load_protocol(path)


def test_an_85_mm_ipd_passes_audit_and_run_alike(tmp_path: Path) -> None:
    assert IPD_M.contains(0.085)
    assert AuditSettings(ipd_m=0.085).ipd_m == 0.085 and ipd_arg_m(85.0) == pytest.approx(0.085)
    assert compile_plan(_protocol_with_ipd(tmp_path, 85)).rig.ipd_m == pytest.approx(0.085)
    protocol = load_protocol(small_protocol(tmp_path, "detection", 1))
    assert compile_plan(protocol, tracker_ipd_m=0.085).rig.ipd_m == 0.085
    # and above the bound, both refuse
    with pytest.raises(UserError, match=r"\[40, 90\] mm"):
        AuditSettings(ipd_m=0.095)
    with pytest.raises(UserError, match=r"\[40, 90\] mm"):
        ipd_arg_m(95.0)
    with pytest.raises(UserError):
        compile_plan(protocol, tracker_ipd_m=0.095)


def test_the_default_and_the_eye_centres_come_from_optics() -> None:
    assert IPD_M.contains(DEFAULT_IPD_M) and ipd_arg_m(None) == DEFAULT_IPD_M
    assert AuditSettings().ipd_m == DEFAULT_IPD_M
    assert compile_plan(load_protocol(PSYOP.parent / "protocols" / "detection.yaml")).rig.centre_m("left").tolist() \
        == eye_centre_m("left", DEFAULT_IPD_M).tolist()


def test_no_module_outside_optics_defines_an_ipd_bound_default_or_eye_centre() -> None:
    """grep: outside psyop/optics no ipd constant, no ipd compared with a number, no ``ipd / 2``."""
    definition = re.compile(r"^\s*\w*IPD\w*\s*(:[^=]+)?=\s*[0-9(]", re.I | re.M)
    bound = re.compile(r"ipd\w*\s*[<>]=?\s*[0-9.]|[0-9.]+\s*[<>]=?\s*[\w.]*ipd", re.I)
    centre = re.compile(r"ipd\w*\s*/\s*2\b|0\.5\s*\*\s*(float\()?[\w.]*ipd", re.I)
    found = []
    for path in sorted(PSYOP.rglob("*.py")):
        if path.parent.name == "optics":
            continue
        text = path.read_text()
        found += [f"{path.relative_to(PSYOP)}: {m.group(0).strip()}" for rx in (bound, centre)
                  for m in rx.finditer(text)]
        found += [f"{path.relative_to(PSYOP)}: {m.group(0).strip()}" for m in definition.finditer(text)
                  if "FIXTURE_IPD_M" not in m.group(0)]
    assert not found, found
    definitions = [p for p in PSYOP.rglob("*.py") if re.search(r"(?m)^(IPD_M|DEFAULT_IPD_M)\s*=", p.read_text())]
    assert [p.relative_to(PSYOP).as_posix() for p in definitions] == ["optics/ranges.py"]
