"""psyop.export.gaze.run_display: each BIDS run is described with the display that run recorded using
(session.json ``runs[].display_used``), and says so when it falls back to the protocol's profile."""

from __future__ import annotations

import math

import pytest

from psyop.errors import UserError
from psyop.export.gaze import gaze_on_image_px, run_display
from psyop.optics.display import VIVE_PRO

LEFT = {"width_px": 320, "height_px": 240, "tan_left": -1.2, "tan_right": 0.8, "tan_bottom": -0.9, "tan_top": 1.0}
RIGHT = {**LEFT, "tan_left": -0.8, "tan_right": 1.2}


def _meta(**used: object) -> dict:
    return {"runs": [{"run": 0, "display_mode": "openxr"},
                     {"run": 1, "display_mode": "openxr", "display_used": {
                         "display": "openxr", "measured": True, "runtime": "R", "system": "S",
                         "eyes": {"left": LEFT, "right": RIGHT}, "refresh_hz": 20.0, **used}}]}


def test_a_measured_run_gives_each_eye_its_own_size_fov_and_rate() -> None:
    got = run_display(_meta(), 1, VIVE_PRO, "session.json")
    assert got.measured and "OpenXR runtime 'R'" in got.note and "measured from the runtime" in got.note
    for eye, entry in (("left", LEFT), ("right", RIGHT)):
        display = got.eyes[eye]
        assert (display.width_px, display.height_px, display.refresh_hz) == (320, 240, 20.0)
        assert display.frustum_tangents(eye) == tuple(entry[k] for k in ("tan_left", "tan_right", "tan_bottom",
                                                                          "tan_top"))
        assert math.isinf(display.d_m)  # a runtime's view is a set of directions
    # straight ahead of the left eye's centre lands where tan 0 is on its asymmetric image
    px = gaze_on_image_px([[-0.032, 0.0, -1.0]], got.eyes["left"], "left", 0.064)
    assert px[0, 0] == pytest.approx(1.2 / 2.0 * 320) and px[0, 1] == pytest.approx(1.0 / 1.9 * 240)


def test_a_run_without_a_measured_rate_says_the_rate_is_the_profiles() -> None:
    got = run_display(_meta(refresh_hz=None), 1, VIVE_PRO, "session.json")
    assert got.eyes["left"].refresh_hz == 90.0 and "too few frames" in got.note


def test_a_headset_run_that_recorded_nothing_falls_back_to_the_profile_and_says_why() -> None:
    got = run_display(_meta(), 0, VIVE_PRO, "session.json")
    assert not got.measured and got.eyes["left"] is VIVE_PRO
    assert "not finalised by psyop run" in got.note and "view_<eye>_tan_*" in got.note
    headless = run_display({"runs": [{"run": 0, "display_used": {"display": "headless", "measured": False}}]}, 0,
                           VIVE_PRO, "session.json")
    assert not headless.measured and "no screen (headless)" in headless.note


def test_a_damaged_display_record_is_one_located_error() -> None:
    with pytest.raises(UserError, match="display_used of run 1, left eye, is not usable") as caught:
        run_display(_meta(eyes={"left": {"width_px": 320}}), 1, VIVE_PRO, "x/session.json")
    assert "x/session.json" in str(caught.value)


def test_a_headset_run_that_showed_no_frame_is_not_measured() -> None:
    from psyop.devices.xr.views_used import ViewsSeen

    record = ViewsSeen().record([(320, 240), (320, 240)], "R", "S")
    assert record["measured"] is False and record["refresh_hz"] is None
    got = run_display({"runs": [{"run": 0, "display_used": record}]}, 0, VIVE_PRO, "session.json")
    assert not got.measured and "showed no frame" in got.note
