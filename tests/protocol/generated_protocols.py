"""A hypothesis strategy that writes protocols from the whole protocol language.

Mostly valid protocols (every primitive kind, surface, phase kind, response kind, eyes, display
profile built in and inline, fixed and tracker ipd, named and calibrated eye models, factor
shapes, randomisation kinds, practice trials), with a share of mistakes a user makes (a value
out of range, a wrong interval count, an unknown id, an adaptive level) so that the refusal path
is exercised too. Trial counts and durations are kept small: each example is run as a session.
"""

from __future__ import annotations

from typing import Any

import yaml
from hypothesis import strategies as st

MODES = ["conventional", "ocular", "reversed"]
EYE_MODELS = ["gullstrand_no1_relaxed", "gullstrand_no1_accommodated", "gullstrand_emsley_relaxed",
              "gullstrand_emsley_accommodated", "emsley_reduced"]
TEXTURE = "texture.png"  # written next to the generated protocols by the test

small = st.floats(0.05, 0.4, allow_nan=False).map(lambda x: round(x, 3))
rgb = st.tuples(*[st.sampled_from([0.0, 0.25, 0.5, 1.0])] * 3).map(list)


@st.composite
def surfaces(draw: Any) -> dict[str, Any]:
    kind = draw(st.sampled_from(["solid", "white_noise", "one_over_f", "image"]))
    if kind == "solid":
        return {"kind": "solid", "rgb": draw(rgb)}
    if kind == "white_noise":
        return {"kind": "white_noise", "grain_deg": draw(st.sampled_from([0.05, 0.1, 0.5])), "seed": draw(st.integers(0, 3))}
    if kind == "one_over_f":
        return {"kind": "one_over_f", "exponent": 1, "contrast": 0.8}  # only 1/f is rendered
    return {"kind": "image", "path": TEXTURE, **draw(st.sampled_from([{}, {"tile_deg": 2.0}]))}


def _depth(draw: Any, depth_factors: list[str]) -> dict[str, Any]:
    options: list[dict[str, Any]] = [{"D": draw(st.sampled_from([0, 0.5, 1, 2.5]))}, {"m": draw(st.sampled_from([0.3, 1, 4]))}]
    if depth_factors:
        options.append({"factor": draw(st.sampled_from(depth_factors))})
        options.append({"D": 0.5, "factor": depth_factors})
    return draw(st.sampled_from(options))


@st.composite
def primitives(draw: Any, index: int, depth_factors: list[str], border_schedule: bool) -> dict[str, Any]:
    kinds = ["disc", "quad", "aperture", "grid_planes", "target_field", "fixation_target", "room", "reach_target",
             "sinusoidal_border"]
    kind = draw(st.sampled_from(kinds))
    pid = f"p{index}"
    if kind == "disc":
        return {"id": pid, "kind": "disc", "size_deg": draw(st.sampled_from([1, 5, 20])),
                "depth": _depth(draw, depth_factors), "surface": draw(surfaces()),
                "centre_deg": draw(st.sampled_from([[0, 0], [3, -2]]))}
    if kind == "quad":
        return {"id": pid, "kind": "quad", "width_deg": 6, "height_deg": draw(st.sampled_from([3, 6])),
                "depth": _depth(draw, depth_factors), "surface": draw(surfaces())}
    if kind == "aperture":
        return {"id": pid, "kind": "aperture", "diameter_deg": draw(st.sampled_from([10, 40])), "surround_rgb": draw(rgb)}
    if kind == "grid_planes":
        return {"id": pid, "kind": "grid_planes", "planes": draw(st.lists(st.sampled_from(["floor", "ceiling", "left", "right"]),
                                                                         min_size=1, max_size=4, unique=True)),
                "half_width_m": 1.0, "half_height_m": 1.0, "spacing_m": 0.25, "far_m": 10}
    if kind == "target_field":
        return {"id": pid, "kind": "target_field", "count": draw(st.integers(1, 8)), "size_deg": 2.0,
                "near": {"D": 3}, "far": {"D": draw(st.sampled_from([0, 0.5]))}, "field_deg": 40,
                "surface": draw(surfaces())}
    if kind == "fixation_target":
        item: dict[str, Any] = {"id": pid, "kind": "fixation_target", "size_deg": 0.5, "depth": _depth(draw, depth_factors)}
        if draw(st.booleans()):
            item["path"] = {"kind": "circle", "eccentricity_deg": draw(st.sampled_from([5, 16])), "speed_deg_s": 90,
                            "direction": draw(st.sampled_from(["random", "clockwise", "counterclockwise"]))}
        return item
    if kind == "room":
        return {"id": pid, "kind": "room", "width_m": 4, "depth_m": 5, "height_m": 2.6}
    if kind == "reach_target":
        return {"id": pid, "kind": "reach_target", "object": draw(st.sampled_from(["pencil", "sphere", "cube"])),
                "size_m": 0.1, "distance_fraction": draw(st.sampled_from([0.5, 0.9]))}
    return {"id": pid, "kind": "sinusoidal_border", "size_deg": 20, "amplitude_deg": 2, "period_deg": 5,
            "orientation_deg": draw(st.sampled_from([0, 45])), "left": draw(surfaces()), "right": draw(surfaces()),
            "near_depth": {"D": 2}, "far_depth": {"D": 1},
            "near_side": "schedule" if border_schedule else draw(st.sampled_from(["left", "right"]))}


@st.composite
def levels(draw: Any, values: list[float]) -> Any:
    """A factor's levels as a list or a stepped range."""
    if len(values) > 1 and draw(st.booleans()):
        step = round(values[1] - values[0], 6)
        if step > 0 and all(abs(values[i] - (values[0] + i * step)) < 1e-9 for i in range(len(values))):
            return {"levels": {"start": values[0], "step": step, "count": len(values)}}
    return {"levels": values}


@st.composite
def designs(draw: Any, kind: str) -> tuple[dict[str, Any], dict[str, Any], dict[str, Any], list[str]]:
    """(design, response, observer, numeric dioptre factors)."""
    factors: dict[str, Any] = {}
    depth_factors: list[str] = []
    back = [1.0, 2.0][: draw(st.integers(1, 2))]
    if draw(st.booleans()):
        factors["back_D"] = draw(levels(back))
        depth_factors.append("back_D")
    if kind == "two_interval":
        level = draw(levels([0.0, 0.5, 1.0][: draw(st.integers(2, 3))]))
        if "back_D" in factors and draw(st.booleans()):
            level = {"depends_on": "back_D", "levels_by": {b: [0.0, 0.25 * (1 + i)] for i, b in enumerate(back)}}
        adaptive = draw(st.sampled_from([None, None, "staircase", "quest_plus"]))
        if adaptive is not None:  # the level chosen while the session runs (psyop.adaptive)
            level = {"adaptive": {"procedure": adaptive, "start": 0.5, "min": 0, "max": 1.5}}
            if draw(st.booleans()):  # a condition may stop early (its remaining trials are not run)
                level["adaptive"]["target_sd"] = 0.42 if adaptive == "quest_plus" else 0.3  # prior SD 0.433
        factors["level_D"] = level
        depth_factors.append("level_D")
        test: dict[str, Any] = {"mode": draw(st.sampled_from(MODES))}
        reference: dict[str, Any] = {"mode": draw(st.sampled_from(MODES))}
        if draw(st.booleans()):
            factors["mode"] = {"levels": ["ocular", "reversed"]}
            test = {"mode": {"factor": "mode"}}
        if draw(st.booleans()):
            reference["set"] = {"level_D": 0}
        response = {"kind": "two_interval", "test": test, "reference": reference,
                    "order": draw(st.sampled_from(["balanced", "random"]))}
        observer = {"kind": "psychometric_2afc", "threshold_D": 0.4, "width_D": 0.3,
                    "lapse": draw(st.sampled_from([0.0, 0.02]))}
        if "back_D" in factors and draw(st.booleans()):
            observer.update(threshold_slope=0.1, threshold_offset_column="back_D")
    elif kind == "left_right_nearer":
        separation = draw(st.sampled_from(["separation_D", "gap_D"]))
        seps = [1.0, 2.0][: draw(st.integers(1, 2))]
        factors[separation] = draw(levels(seps))
        depth_factors.append(separation)
        fixed_mode = draw(st.booleans())
        modes = [draw(st.sampled_from(MODES))] if fixed_mode else ["conventional", "ocular"]
        if not fixed_mode:
            factors["mode"] = {"levels": modes}
        response = {"kind": "left_right_nearer", "mode": modes[0] if fixed_mode else {"factor": "mode"},
                    "separation_factor": separation, "near_side": draw(st.sampled_from(["balanced", "random"]))}
        observer = {"kind": "ordinal_accuracy", "p_correct": {m: {s: 0.7 for s in seps} for m in modes}}
    elif kind == "pairwise_preference":
        pairs = draw(st.lists(st.sampled_from(["conventional|ocular", "conventional|reversed", "ocular|reversed"]),
                              min_size=1, max_size=3, unique=True))
        factors["pair"] = {"levels": pairs}
        response = {"kind": "pairwise_preference", "order": draw(st.sampled_from(["balanced", "random"]))}
        observer = {"kind": "pairwise_preference", "strength": {"conventional": 1.0, "ocular": 1.5, "reversed": 0.7}}
    elif kind == "with_against":  # NC nulling: a signed rendered NC (display.rendering_nc, set in protocols())
        factors["nc_mm"] = draw(levels([-4.0, 0.0, 4.0][: draw(st.integers(2, 3))]))
        response = {"kind": "with_against", "nc_factor": "nc_mm"}
        observer = {"kind": "nc_nulling", "nc_mm": 3.0, "width_mm": 3.0, "lapse": draw(st.sampled_from([0.0, 0.02]))}
    else:
        names = draw(st.sampled_from([["enabled", "disabled"], ["with_parallax", "flat"], ["a1"]]))
        factors["rendering"] = {"levels": names}
        factors["target_fraction"] = draw(levels([0.5, 0.75]))  # a line per condition needs >= 3 reaches
        response = {"kind": "reach", "modes": {n: draw(st.sampled_from(MODES)) for n in names},
                    "average_last_samples": draw(st.sampled_from([1, 10]))}
        observer = {"kind": "reach", "arm_reach_m": 0.7,
                    "by_condition": {n: {"slope": 1.0, "intercept_m": 0.05, "noise_sd_m": 0.02} for n in names}}
    randomisation = draw(st.sampled_from(["full", "blocked", "sequential"]))
    design: dict[str, Any] = {"factors": factors, "repetitions": 2 if kind == "reach" else draw(st.integers(1, 2)),
                              "practice_trials": draw(st.integers(0, 2)),
                              "randomisation": {"kind": randomisation}}
    if randomisation == "blocked":
        design["randomisation"]["by"] = [next(iter(factors))]
        design["randomisation"]["block_order"] = draw(st.sampled_from(["random", "fixed"]))
    return design, response, observer, depth_factors


INTERVALS = {"two_interval": 2, "left_right_nearer": 1, "pairwise_preference": 2, "reach": 1, "with_against": 1}


@st.composite
def phases(draw: Any, kind: str, ids: list[str]) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    if draw(st.booleans()):
        out.append({"kind": "drift_recalibration", "target_size_deg": draw(st.sampled_from([0.5, 1, 3])),
                    "expected_s": draw(small)})
    for i in range(INTERVALS[kind]):
        if i:
            blank: dict[str, Any] = {"kind": "blank", "duration_s": draw(small)}
            if draw(st.booleans()):
                blank["show"] = draw(st.lists(st.sampled_from(ids), min_size=1, max_size=2, unique=True))
                blank["mode"] = draw(st.sampled_from(MODES))
            elif draw(st.booleans()):
                blank["display_off"] = True
            out.append(blank)
        interval: dict[str, Any] = {"kind": "interval"}
        if draw(st.booleans()):
            interval["duration_s"] = draw(small)
        else:
            interval.update(min_duration_s=draw(small), expected_s=0.5)
        if draw(st.booleans()):
            interval["show"] = draw(st.lists(st.sampled_from(ids), min_size=1, max_size=len(ids), unique=True))
        out.append(interval)
    response: dict[str, Any] = {"kind": "response", "expected_s": 1.0}
    if draw(st.booleans()):
        response["timeout_s"] = draw(st.sampled_from([0.5, 3.0]))
    if draw(st.booleans()):
        response["prompt"] = "Answer now."
    if draw(st.booleans()):
        response["display_off"] = True
    out.append(response)
    return out


@st.composite
def displays(draw: Any) -> dict[str, Any]:
    display: dict[str, Any] = {}
    profile = draw(st.sampled_from(["builtin", "fov", "tangents", "default"]))
    if profile == "builtin":
        display["profile"] = "vive_pro"
    elif profile == "fov":
        display["profile"] = {"name": "hmd", "width_px": 640, "height_px": 640, "refresh_hz": 90,
                              "horizontal_fov_deg": 100, "d_m": draw(st.sampled_from(["inf", 1.5]))}
    elif profile == "tangents":
        display["profile"] = {"name": "hmd2", "width_px": 500, "height_px": 600, "refresh_hz": 120,
                              "tan_left": -1.2, "tan_right": 1.0, "tan_bottom": -1.1, "tan_top": 1.1}
    eye = draw(st.sampled_from(["name", "calibrated", "default"]))
    if eye == "name":
        display["eye_model"] = draw(st.sampled_from(EYE_MODELS))
    elif eye == "calibrated":
        display["eye_model"] = {"nc_mm": draw(st.sampled_from([5.0, 7.4, 12.0, 29.0]))}
    ipd = draw(st.sampled_from(["tracker", "fixed", "default"]))
    if ipd == "tracker":
        display["ipd"] = "tracker"
    elif ipd == "fixed":
        display["ipd"] = {"mm": draw(st.sampled_from([40, 58, 63, 90]))}
    return display


MISTAKES = ["nc_30", "ipd_95", "interval_count", "unknown_show", "adaptive", "depth_101", "phase_after_response",
            "observer_mismatch"]


@st.composite
def protocols(draw: Any) -> tuple[str, str | None]:
    """(YAML text, the mistake made or None)."""
    kind = draw(st.sampled_from(list(INTERVALS)))
    design, response, observer, depth_factors = draw(designs(kind))
    n = draw(st.integers(1, 4))
    scene = [draw(primitives(i, depth_factors, kind == "left_right_nearer")) for i in range(n)]
    ids = [p["id"] for p in scene]
    doc: dict[str, Any] = {
        "psyop_protocol": 1,
        "study": {"name": "generated", "title": "A generated protocol"},
        "display": draw(displays()),
        "eyes": draw(st.sampled_from(["right", "left", "stereo"])),
        "scene": scene,
        "trial": {"phases": draw(phases(kind, ids))},
        "design": design,
        "response": response,
        "observer": observer,
    }
    if kind == "with_against":
        doc["display"]["rendering_nc"] = {"mm": {"factor": "nc_mm"}, "signed": True}
    mistake = draw(st.one_of(st.none(), st.none(), st.none(), st.sampled_from(MISTAKES)))
    if mistake == "nc_30":
        doc["display"]["eye_model"] = {"nc_mm": 30}
    elif mistake == "ipd_95":
        doc["display"]["ipd"] = {"mm": 95}
    elif mistake == "interval_count":
        doc["trial"]["phases"].insert(-1, {"kind": "interval", "duration_s": 0.1})
    elif mistake == "unknown_show":
        doc["trial"]["phases"].insert(0, {"kind": "blank", "duration_s": 0.1, "show": ["nope"]})
    elif mistake == "adaptive":
        doc["design"]["factors"]["extra_D"] = {"adaptive": {"procedure": "bisection", "start": 1, "min": 0, "max": 2}}
    elif mistake == "depth_101":
        doc["scene"].append({"id": "far", "kind": "disc", "size_deg": 1, "depth": {"D": 101},
                             "surface": {"kind": "solid", "rgb": [1, 1, 1]}})
    elif mistake == "phase_after_response":
        doc["trial"]["phases"].append({"kind": "blank", "duration_s": 0.1})
    elif mistake == "observer_mismatch":
        doc["observer"] = {"kind": "reach", "arm_reach_m": 0.7, "by_condition": {"x": {"slope": 1, "intercept_m": 0,
                                                                                        "noise_sd_m": 0.1}}} \
            if kind != "reach" else {"kind": "psychometric_2afc", "threshold_D": 0.4, "width_D": 0.3}
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=120), mistake
