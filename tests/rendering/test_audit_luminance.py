"""``psyop audit`` on a calibrated display records each stimulus's luminance and contrast after quantisation
(psyop.audit.luminance)."""

from __future__ import annotations

from psyop.audit import AuditSettings, format_table, run_audit

from tests.protocol.calibration_files import power_law, write_calibration
from tests.protocol.test_luminance_protocol import _load, _protocol

GABOR = ("{kind: grating, cycles_per_deg: 1, luminance: {cd_m2: 40}, contrast: {factor: contrast_fraction}, "
         "window: {kind: gaussian, sigma_deg: 1.2}}")


def test_the_audit_reports_achieved_luminance_and_contrast(gl_context, tmp_path):
    """Each audited frame of a calibrated Gabor (1 % and 2 % Michelson on 40 cd/m², Vive Pro at a third of its
    pixels) lists the Gabor's intended and achieved mean and contrast: the mean within 0.5 %, the contrast within
    0.2 percentage points (one frame's dither over a few hundred pixels), and the table prints them."""
    write_calibration(tmp_path / "cal.json", power_law())
    protocol = _load(_protocol(tmp_path, surface=GABOR))
    report = run_audit(protocol, AuditSettings(scale=0.34, gazes=1, samples_per_axis=4, mesh_check=False),
                       ctx=gl_context, base_dir=tmp_path)
    checks = [c for r in report.records for c in r.luminance if c.name == "patch"]
    assert checks
    for check in checks:
        assert abs(check.achieved_cd_m2 / check.intended_cd_m2 - 1) < 0.005
        assert abs(check.achieved_contrast - check.intended_contrast) < 0.002, check
    assert {round(c.intended_contrast, 6) for c in checks} == {0.01, 0.02}
    assert "luminance after quantisation" in format_table(report)
