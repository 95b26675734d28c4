"""Who uses each field of the protocol language (a protocol field is used or refused).

Every field of every protocol model is listed here with the part of psyop that reads it:

- ``plan``: the session plan compiler (psyop.session.plan);
- ``schedule``: the trial-table compiler (psyop.schedule.compile);
- ``stimulus``: the scene builder (psyop.stimulus.build);
- ``display``: display profile / eye model resolution (psyop.protocol.display -> psyop.optics);
- ``observer``: the simulated observers (psyop.session.responses.simulated; the plan hands them
  the whole ``observer:`` section);
- ``summary``: ``psyop show`` and session.json's copy of the protocol text (descriptive fields);
- ``validation``: a field that only selects or checks (discriminators, the format version);
- ``refused``: validated structurally, then refused with its file:line (not available yet);
- ``adaptive``: the session's adaptive levels (psyop.adaptive.session builds each procedure);
- ``quality``: the exclusion rules at analysis time (psyop.quality.rules);
- ``timing``: the session loop's dropped-frame rule (psyop.session.loop, psyop.protocol.timing);
- ``gaze_validation``: the session's gaze validations (psyop.session.validation);
- ``screens``: the session's screens around the trials (psyop.session.screens: instructions, breaks,
  questionnaires, end screen);
- ``tracker``: the simulated tracker (psyop.session.gaze.simulated.tracker_config reads ``observer: eye:``);
- ``analysis``: the two-interval thresholds analysis (analysis/fig_detection_thresholds.py, reading
  ``study.reported`` through psyop.statistics.studies);
- ``kinds``: a response kind's own module (psyop.protocol.kinds): each kind lists the users of its models'
  fields in its ``fields`` (merged here).

tests/protocol/test_protocol_fields.py walks the pydantic schema and checks that every field is
listed, and that each listed field's name appears in its user's source.
"""

from __future__ import annotations

from pathlib import Path

from psyop.protocol.kinds import KINDS

USERS: dict[str, tuple[str, ...]] = {
    "plan": ("psyop/session/plan.py",),
    "schedule": ("psyop/schedule/compile.py", "psyop/protocol/conditions.py", "psyop/protocol/design.py"),
    "stimulus": ("psyop/stimulus/build.py", "psyop/protocol/scene.py"),
    "display": ("psyop/protocol/display.py", "psyop/optics/display.py"),
    "observer": ("psyop/session/responses/simulated.py",),
    "image_observer": ("psyop/session/responses/image_observer.py", "psyop/session/responses/image_choices.py",
                       "psyop/session/image_observer/stages.py"),
    "summary": ("psyop/schedule/summary.py", "psyop/protocol/conditions.py"),
    "validation": ("psyop/protocol/semantics.py", "psyop/protocol/model.py", "psyop/protocol/scene.py",
                   "psyop/protocol/trial.py", "psyop/protocol/response.py", "psyop/protocol/observer.py",
                   "psyop/protocol/design.py", "psyop/protocol/display.py"),
    "refused": ("psyop/protocol/semantics.py",),
    "adaptive": ("psyop/adaptive/session.py",),
    "tracker": ("psyop/session/gaze/simulated.py",),
    "quality": ("psyop/quality/rules.py", "psyop/protocol/quality.py"),
    "timing": ("psyop/session/loop.py", "psyop/protocol/timing.py"),
    "gaze_validation": ("psyop/session/validation.py",),
    "screens": ("psyop/session/screens.py",),
    # the two-interval thresholds analysis (study.reported, beside the measured thresholds)
    "analysis": ("analysis/fig_detection_thresholds.py", "psyop/statistics/studies.py"),
    # the response kinds' own modules (columns, checks, scoring): psyop.protocol.kinds
    "kinds": tuple(f"psyop/protocol/kinds/{p.name}" for p in sorted(Path(__file__).with_name("kinds").glob("*.py"))),
}

_SCENE_COMMON = {"id": "stimulus", "kind": "validation"}


def _scene(**fields: str) -> dict[str, str]:
    return {**_SCENE_COMMON, **fields}


FIELD_USERS: dict[str, dict[str, str]] = {
    "Protocol": {"psyop_protocol": "validation", "study": "plan", "display": "plan", "eyes": "plan", "scene": "stimulus",
                 "trial": "plan", "design": "schedule", "response": "plan", "observer": "plan",
                 "quality": "quality", "timing": "timing", "gaze_validation": "gaze_validation",
                 "session": "screens"},
    "SessionScreens": {k: "screens" for k in ("instructions", "breaks", "questionnaires", "end_screen",
                                              "feedback", "simulated_answers")},
    "Feedback": {k: "screens" for k in ("practice", "main", "text", "duration_s")},
    "FeedbackText": {k: "screens" for k in ("correct", "incorrect", "answer", "timeout")},
    # image: refused at validation (psyop.protocol.session_screens: only text is drawn in the headset)
    "InstructionPage": {"text": "screens", "image": "screens", "image_width_deg": "screens", "expected_s": "screens"},
    "Instructions": {"pages": "screens", "at_blocks": "screens"},
    "Breaks": {k: "screens" for k in ("every_trials", "between_blocks", "text", "expected_s")},
    "Questionnaire": {k: "screens" for k in ("name", "when", "items", "scale", "title", "item_expected_s")},
    "Scale": {"points": "screens", "labels": "screens"},
    "EndScreen": {"text": "screens", "expected_s": "screens"},
    "SimulatedAnswers": {k: "screens" for k in ("severity_mean", "severity_sd", "item_sd")},
    "GazeValidation": {k: "gaze_validation" for k in ("when", "points_deg", "distance_m", "target_size_deg", "settle_s",
                                                      "dwell_s", "require")},
    "ValidationRequirement": {k: "gaze_validation" for k in ("max_mean_error_deg", "max_point_error_deg",
                                                             "max_attempts")},
    "StudyInfo": {"name": "plan", "title": "summary", "citation": "summary", "description": "summary",
                  "reported": "analysis"},
    "ReportedThreshold": {"condition": "analysis", "threshold": "analysis", "source": "analysis"},
    "DisplaySpec": {"profile": "display", "eye_model": "display", "ipd": "plan", "rendering_nc": "display",
                    "added_latency_ms": "plan", "calibration": "display"},
    "RenderingNc": {"mm": "display", "scale": "display", "signed": "display"},
    "InlineDisplayProfile": {k: "display" for k in ("name", "width_px", "height_px", "refresh_hz", "horizontal_fov_deg",
                                                      "vertical_fov_deg", "tan_left", "tan_right", "tan_bottom",
                                                      "tan_top", "left_tangents", "d_m")},
    "InlineEyeModel": {"nc_mm": "display", "name": "display"},
    "FixedIpd": {"mm": "plan"},
    "Disc": _scene(size_deg="stimulus", depth="stimulus", surface="stimulus", centre_deg="stimulus", facing="stimulus"),
    "PolarPoint": {"eccentricity_deg": "stimulus", "meridian_deg": "stimulus"},
    "Depth": {"D": "stimulus", "m": "stimulus", "factor": "stimulus"},
    "SolidSurface": {"kind": "validation", "rgb": "stimulus", "luminance": "stimulus"},
    "WhiteNoiseSurface": {"kind": "validation", "grain_deg": "stimulus", "mean": "stimulus", "contrast": "stimulus",
                          "seed": "stimulus", "luminance": "stimulus"},
    # exponent: only 1 (1/f) is rendered; other values are refused in semantics.py
    "PinkNoiseSurface": {"kind": "validation", "exponent": "validation", "mean": "stimulus", "contrast": "stimulus",
                         "seed": "stimulus", "luminance": "stimulus"},
    # gratings and luminances (docs/gratings_and_luminance.md): psyop.stimulus.build turns them into the renderer's
    # Grating and values; a luminance needs display.calibration (psyop.protocol.luminance checks it)
    "GratingSurface": {k: "stimulus" for k in ("kind", "waveform", "cycles_per_deg", "orientation_deg", "phase_deg",
                                               "drift_deg_s", "mean", "luminance", "contrast", "window")},
    "GaussianWindow": {"kind": "validation", "sigma_deg": "stimulus"},
    "RaisedCosineWindow": {"kind": "validation", "plateau_radius_deg": "stimulus", "ramp_deg": "stimulus"},
    "Contrast": {"michelson": "stimulus", "weber": "stimulus", "michelson_log10": "stimulus"},
    "Luminance": {"cd_m2": "stimulus"},
    "ImageSurface": {"kind": "validation", "path": "stimulus", "tile_deg": "stimulus"},
    "Quad": _scene(width_deg="stimulus", height_deg="stimulus", depth="stimulus", surface="stimulus",
                   centre_deg="stimulus", facing="stimulus"),
    "SinusoidalBorder": _scene(size_deg="stimulus", amplitude_deg="stimulus", period_deg="stimulus",
                               orientation_deg="stimulus", phase="schedule", left="stimulus", right="stimulus",
                               near_depth="stimulus", far_depth="stimulus", near_side="stimulus"),
    "Aperture": _scene(diameter_deg="stimulus", surround_rgb="stimulus", ignores_ocular_parallax="validation"),
    "GridPlanes": _scene(planes="stimulus", half_width_m="stimulus", half_height_m="stimulus", near_m="stimulus",
                         far_m="stimulus", spacing_m="stimulus", line_width_deg="stimulus", rgb="stimulus",
                         background_rgb="stimulus"),
    "TargetField": _scene(count="stimulus", size_deg="stimulus", near="stimulus", far="stimulus", field_deg="stimulus",
                          min_gap_deg="stimulus", surface="stimulus"),
    "FixationTarget": _scene(size_deg="stimulus", depth="stimulus", rgb="stimulus", centre_rgb="stimulus",
                             centre_deg="stimulus", facing="stimulus", path="plan"),
    "CirclePath": {"kind": "validation", "eccentricity_deg": "plan", "speed_deg_s": "plan", "start": "schedule",
                   "direction": "schedule"},
    "Room": _scene(width_m="stimulus", depth_m="stimulus", height_m="stimulus", table_height_m="stimulus",
                   eye_height_m="stimulus"),
    "ReachTarget": _scene(object="stimulus", size_m="stimulus", distance_fraction="stimulus", height_m="stimulus"),
    "Mesh": _scene(file="stimulus", node="stimulus", position_m="stimulus", centre_deg="stimulus", depth="stimulus",
                   rotation_deg="stimulus", scale="stimulus", size_m="stimulus", size_deg="stimulus",
                   shading="stimulus", light="stimulus"),
    "MeshLight": {"direction": "stimulus", "ambient": "stimulus"},
    "FactorRef": {"factor": "stimulus"},
    "LevelRef": {"factor": "stimulus"},
    "ReachMesh": {"file": "stimulus", "node": "stimulus", "rotation_deg": "stimulus"},  # a mesh's file/node as {factor: NAME} (psyop.protocol.mesh_models)
    "TrialSpec": {"phases": "plan", "min_valid_gaze_share": "plan", "max_gaze_age_ms": "plan",
                  "max_gaze_age_over_share": "plan"},
    "DriftRecalibration": {"kind": "validation", "target_size_deg": "plan", "expected_s": "plan"},
    "Interval": {"kind": "validation", "duration_s": "plan", "min_duration_s": "plan", "expected_s": "plan",
                 "show": "plan"},
    "Blank": {"kind": "validation", "duration_s": "plan", "expected_s": "plan", "show": "plan", "mode": "plan",
              "display_off": "plan"},
    "ResponsePhase": {"kind": "validation", "expected_s": "summary", "timeout_s": "plan", "prompt": "plan",
                      "display_off": "plan"},
    "Design": {"factors": "schedule", "repetitions": "schedule", "practice_trials": "schedule",
               "randomisation": "schedule"},
    "Factor": {"levels": "schedule", "depends_on": "schedule", "levels_by": "schedule", "adaptive": "adaptive",
               "description": "summary"},
    "SteppedLevels": {"start": "schedule", "step": "schedule", "count": "schedule"},
    # adaptive levels: procedure names outside ADAPTIVE_PROCEDURES are refused in semantics.py
    "AdaptiveLevel": {k: "adaptive" for k in ("procedure", "start", "min", "max", "grid_points", "rule", "step_sizes",
                                              "target", "target_sd", "min_trials")},
    "Randomisation": {"kind": "schedule", "by": "schedule", "block_order": "schedule"},
    "QualitySection": {"trials": "quality", "participants": "quality", "min_included_trials": "quality",
                       "min_included_trials_reason": "quality"},
    "QualityRule": {"measure": "quality", "max": "quality", "min": "quality", "reason": "quality"},
    "TimingSection": {"max_dropped_frames": "timing", "on_violation": "timing", "max_reruns": "timing",
                      "max_rerun_share": "timing"},
    "EyeOverride": {k: "tracker" for k in ("precision_deg", "pursuit_gain", "pursuit_lag_s", "blink_rate_hz",
                                           "dropout_rate_hz", "dropout_s", "nan_burst_rate_hz", "error_centre_deg",
                                           "error_per_15deg", "drift_start_deg", "drift_deg_per_min")},
    "SimulatedEye": {k: "tracker" for k in ("precision_deg", "pursuit_gain", "pursuit_lag_s", "blink_rate_hz",
                                            "dropout_rate_hz", "dropout_s", "nan_burst_rate_hz", "rate_hz", "latency_s",
                                            "catch_up_threshold_deg", "main_sequence_vmax_deg_s",
                                            "main_sequence_c_deg", "blink_s", "nan_burst_s", "raw_stream",
                                            "participants", "error_centre_deg", "error_per_15deg", "drift_start_deg",
                                            "drift_deg_per_min")},
}
# the models shared by kinds (psyop.protocol.kinds.base), then each kind's own (its ``fields``)
FIELD_USERS["IntervalSpec"] = {"mode": "kinds", "set": "kinds"}
FIELD_USERS["ModeFromFactor"] = {"factor": "kinds"}
for _kind in KINDS.values():
    for _model, _users in _kind.fields.items():
        FIELD_USERS[_model] = dict(_users)
    for _observer in _kind.observer_models:
        FIELD_USERS[_observer.__name__]["eye"] = "tracker"  # observer: eye: (psyop.protocol.simulated_eye)
        FIELD_USERS[_observer.__name__]["confidence"] = "observer"  # its confidence model (simulated.py)
    FIELD_USERS.setdefault(_kind.model.__name__, {})["confidence"] = "kinds"  # psyop.protocol.kinds.confidence
# the confidence rating after a choice: the scale (its checks, keys and text) and the simulated observer's model
FIELD_USERS["ConfidenceScale"] = {"points": "kinds", "labels": "kinds", "question": "kinds"}
FIELD_USERS["ObserverConfidence"] = {"criteria": "observer", "meta_noise_sd": "observer", "evidence_weight": "observer"}
