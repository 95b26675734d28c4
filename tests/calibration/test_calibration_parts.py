"""The parts of `psyop calibrate` on their own: reply parsers, the readings' checks, the model, the file."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from psyop.calibration.model import check_readings, fit_channel, predict_luminance
from psyop.calibration.record import load_calibration, partial_path
from psyop.devices.photometers.minolta import _MEASURED
from psyop.devices.photometers.photo_research import FOOTLAMBERT_CD_M2, parse_data_code_1
from psyop.errors import UserError


@pytest.mark.parametrize(("reply", "value"), [("OK00,+123.4", 123.4), ("OK11,  12.34", 12.34), ("OK00,.3000", 0.3),
                                               ("OK00,+1.234E+02", 123.4), ("OK00, + 0.052", 0.052)])
def test_ls100_measurement_replies(reply: str, value: float) -> None:
    match = _MEASURED.match(reply)
    assert match is not None and float(match.group(2).replace(" ", "")) == pytest.approx(value)


@pytest.mark.parametrize("reply", ["OK00", "OK00,abc", "OK0,12", "ER10", "OK00,12,13"])
def test_ls100_replies_that_are_no_measurement(reply: str) -> None:
    assert _MEASURED.match(reply) is None


def test_pr_data_code_1_metric_english_light_low_and_errors() -> None:
    metric = parse_data_code_1("00,1,1.234e+02,0.3127,0.3290", "pr650 on X", "M1", light_low={"18"})
    assert (metric.luminance_cd_m2, metric.x, metric.y, metric.quality) == (123.4, 0.3127, 0.329, None)
    english = parse_data_code_1("00000,0,1.000e+01,.4035,.4202", "pr655 on X", "M1", light_low=set())
    assert english.luminance_cd_m2 == pytest.approx(10 * FOOTLAMBERT_CD_M2)
    low = parse_data_code_1("18,1,2.000e-01,0.3,0.3", "pr650 on X", "M1", light_low={"18"})
    assert low.quality == "light low (code 18)" and low.luminance_cd_m2 == 0.2
    with pytest.raises(UserError, match="answered error code 19 to M1"):
        parse_data_code_1("19", "pr650 on X", "M1", light_low={"18"})
    with pytest.raises(UserError, match="answered garbage"):
        parse_data_code_1("00,1,abc,0.3,0.3", "pr650 on X", "M1", light_low={"18"})


def test_dark_levels_may_scatter_bright_ones_may_not() -> None:
    codes = [0, 0, 128, 128, 255, 255]
    check_readings("grey", codes, [0.3, 0.36, 22.0, 22.1, 100.0, 100.2], "dev")  # 13 % at black: not judged
    with pytest.raises(UserError, match="grey readings are noisy .level 128"):
        check_readings("grey", codes, [0.3, 0.3, 20.0, 24.0, 100.0, 100.2], "dev")
    with pytest.raises(UserError, match="negative or non-finite"):
        check_readings("grey", codes, [0.3, float("nan"), 22.0, 22.1, 100.0, 100.2], "dev")


def test_small_dips_within_tolerance_pass_larger_ones_do_not() -> None:
    codes = [0, 64, 128, 191, 255]
    check_readings("red", codes, [0.30, 0.29, 4.0, 9.0, 21.0], "dev")  # 0.01 below black: within 0.5 % of max
    with pytest.raises(UserError, match=r"non-monotone \(4 cd/m² at level 128, 3 at level 191\)"):
        check_readings("red", codes, [0.3, 1.0, 4.0, 3.0, 21.0], "dev")


def test_gog_fit_recovers_an_offset() -> None:
    codes = np.round(np.linspace(0, 255, 11)).astype(int)
    truth = 0.5 + 80.0 * np.maximum(0, 0.9 * codes / 255 + 0.1) ** 2.2
    fit = fit_channel(codes, truth)
    assert fit["model"] == "gog" and fit["gog"]["offset_fitted"]
    assert (fit["gog"]["offset"], fit["gog"]["gamma"]) == pytest.approx((0.1, 2.2), abs=1e-6)
    assert predict_luminance(fit, np.arange(256)) == pytest.approx(
        0.5 + 80.0 * (0.9 * np.arange(256) / 255 + 0.1) ** 2.2, rel=1e-6)


def test_the_file_loader_refuses_partial_and_foreign_files(tmp_path: Path) -> None:
    assert partial_path(Path("a/cal.json")) == Path("a/cal.partial.json")
    (tmp_path / "p.json").write_text(json.dumps({"format": "psyop-display-calibration/1", "complete": False}))
    with pytest.raises(UserError, match="a partial calibration"):
        load_calibration(tmp_path / "p.json")
    (tmp_path / "f.json").write_text("{}")
    with pytest.raises(UserError, match="not a psyop display calibration"):
        load_calibration(tmp_path / "f.json")
