"""Arrow schemas of the trial log and the frame log (docs/architecture.md contracts)."""

from __future__ import annotations

import pandas as pd
import pyarrow as pa

from psyop import datacontract as dc
from psyop.session.latency import GAZE_AGE_COLUMNS, GAZE_AGE_FIELDS

#: Columns the session adds to every schedule row (architecture contract + psyop extras).
TRIAL_LOG_FIELDS: tuple[pa.Field, ...] = (
    pa.field("study", pa.string()),
    pa.field("participant", pa.string()),
    pa.field("session", pa.int64()),
    pa.field("response", pa.string()),
    # the typed form of response (psyop.datacontract.typed_response): a number where it is one, and the outcome
    pa.field("response_value", pa.float64()),
    pa.field("outcome", pa.string()),
    pa.field("correct", pa.bool_()),
    pa.field("reach_m", pa.float64()),
    pa.field("chosen_mode", pa.string()),
    pa.field(dc.TRIAL_START_S, pa.float64()),
    pa.field(dc.TRIAL_END_S, pa.float64()),
    pa.field("response_time_s", pa.float64()),
    pa.field("drift_correction_deg", pa.float64()),
    pa.field("gaze_valid_fraction", pa.float64()),
    # gaze_valid_fraction >= the protocol's trial.min_valid_gaze_share (null: no frame measured gaze)
    pa.field("gaze_ok", pa.bool_()),
    pa.field("n_frames", pa.int64()),
    pa.field("run", pa.int64()),
    # the intervals' gaze-to-photon age (median, p95, max), the share over trial.max_gaze_age_ms and whether it
    # stayed within trial.max_gaze_age_over_share (psyop.session.latency)
    *GAZE_AGE_FIELDS,
    # egocentric (reach) trials: the participant's arm reach, the target distance and the
    # mean hand position (head space) over the samples the reach was taken from
    pa.field("arm_reach_m", pa.float64()),
    pa.field("target_m", pa.float64()),
    pa.field("hand_x_m", pa.float64()),
    pa.field("hand_y_m", pa.float64()),
    pa.field("hand_z_m", pa.float64()),
    # ... and the hand samples (after hold-last-valid) the reach was computed from, oldest
    # first, so that it can be recomputed from the log and replayed (psyop.session.pose_replay)
    pa.field("hand_sample_t_s", pa.list_(pa.float64())),
    pa.field("hand_sample_x_m", pa.list_(pa.float64())),
    pa.field("hand_sample_y_m", pa.list_(pa.float64())),
    pa.field("hand_sample_z_m", pa.list_(pa.float64())),
    pa.field("hand_sample_valid", pa.list_(pa.bool_())),
    pa.field("hand_sample_held", pa.list_(pa.bool_())),
)

#: Columns that depend on wall/virtual time or on where a crash split the session;
#: everything else in trials.parquet is a pure function of (protocol, seed, participant).
TIMING_COLUMNS: tuple[str, ...] = (
    dc.TRIAL_START_S, dc.TRIAL_END_S, "response_time_s", "n_frames", "run", "gaze_valid_fraction",
    "gaze_ok", "hand_sample_t_s", *GAZE_AGE_COLUMNS,
)

def pose_fields(prefix: str) -> list[pa.Field]:
    """Pose columns of the frame log: sample time, position (m), quaternion, valid, held."""
    return [
        pa.field(f"{prefix}_sample_t_s", pa.float64()),
        *(pa.field(f"{prefix}_{axis}_m", pa.float64()) for axis in "xyz"),
        *(pa.field(f"{prefix}_q{c}", pa.float64()) for c in "wxyz"),
        pa.field(f"{prefix}_valid", pa.bool_()),
        pa.field(f"{prefix}_held", pa.bool_()),
    ]

VIEW_TANGENTS: tuple[str, ...] = ("left", "right", "bottom", "top")


def view_fields(eye: str) -> list[pa.Field]:
    """One eye's view columns of the frame log (see FRAME_SCHEMA)."""
    return [
        *(pa.field(f"view_{eye}_{axis}_m", pa.float64()) for axis in "xyz"),
        *(pa.field(f"view_{eye}_q{c}", pa.float64()) for c in "wxyz"),
        *(pa.field(f"view_{eye}_tan_{side}", pa.float64()) for side in VIEW_TANGENTS),
    ]


FRAME_SCHEMA = pa.schema(
    [
        pa.field("trial", pa.int64()),
        pa.field("phase", pa.string()),
        pa.field("frame", pa.int64()),
        pa.field(dc.GAZE_SAMPLE_T_S, pa.float64()),
        pa.field(dc.FIXATION_X_M, pa.float64()),
        pa.field(dc.FIXATION_Y_M, pa.float64()),
        pa.field(dc.FIXATION_Z_M, pa.float64()),
        pa.field(dc.GAZE_CONFIDENCE, pa.float64()),
        pa.field(dc.GAZE_VALID, pa.bool_()),
        pa.field("gaze_held", pa.bool_()),
        pa.field(dc.RENDER_START_S, pa.float64()),
        pa.field("submit_s", pa.float64()),
        pa.field("sample_age_s", pa.float64()),
        pa.field("image_checked", pa.bool_()),
        pa.field("image_ok", pa.bool_()),
        # head pose the frame used (head space at session start; unit quaternion w, x, y, z)
        *pose_fields("head"),
        # what the display said of this frame (psyop.session.frames.FrameRequest): predicted display
        # time and period (session clock), whether the runtime asked for an image, the display
        # periods it skipped before this frame, and the gaze sample's age at the display time
        pa.field(dc.DISPLAY_TIME_S, pa.float64()),
        pa.field("display_period_s", pa.float64()),
        pa.field("display_should_render", pa.bool_()),
        pa.field(dc.DISPLAY_MISSED_FRAMES, pa.int64()),
        pa.field("gaze_age_at_display_s", pa.float64()),
        # the latency the protocol added (display.added_latency_ms; 0 without) and the newest sample's age at the
        # display time (the frame's gaze age without the added latency): psyop.session.latency
        pa.field("added_latency_s", pa.float64()),
        pa.field("gaze_age_intrinsic_s", pa.float64()),
        # each eye's view as the display reported it (headset runtimes; null when the protocol's
        # display profile and eye rig placed the cameras): centre of rotation in head space,
        # orientation (w, x, y, z) and field of view as tangents (left, right, bottom, top)
        *view_fields("left"),
        *view_fields("right"),
    ]
)


#: The image observer's per-trial decision values (JSON, psyop.datacontract.OBSERVER_RESPONSES): a column of the
#: sessions whose protocol's observer is ``kind: image`` only
OBSERVER_RESPONSES_FIELD = pa.field(dc.OBSERVER_RESPONSES, pa.string())


def trial_schema(schedule: pd.DataFrame, *, image_observer: bool = False) -> pa.Schema:
    """The schedule's columns (their own types) followed by the log columns (with :data:`OBSERVER_RESPONSES_FIELD`
    where ``image_observer``: the protocol's observer is ``kind: image``)."""
    base = pa.Schema.from_pandas(schedule, preserve_index=False).remove_metadata()
    fields = [f if not pa.types.is_large_string(f.type) else pa.field(f.name, pa.string()) for f in base]
    names = {f.name for f in fields}
    fields += [f for f in TRIAL_LOG_FIELDS if f.name not in names]
    if image_observer and dc.OBSERVER_RESPONSES not in names:
        fields.append(OBSERVER_RESPONSES_FIELD)
    return pa.schema(fields)


def eye_fields(eye: str) -> list[pa.Field]:
    """One eye's columns of the raw gaze stream (NaN where the tracker does not give them)."""
    return [
        *(pa.field(f"eye_centre_{eye}_{axis}_m", pa.float64()) for axis in "xyz"),
        *(pa.field(f"gaze_normal_{eye}_{axis}", pa.float64()) for axis in "xyz"),
        pa.field(f"pupil_diameter_{eye}_mm", pa.float64()),
        pa.field(f"pupil_diameter_{eye}_px", pa.float64()),
    ]


#: The raw gaze stream (``gaze.parquet``): one row per sample a gaze source delivered, in the order
#: it delivered them, whether or not a frame used it (psyop.session.gaze.sample.RawGazeSample).
#:
#: - ``run``: the run (first start, each resume) it was recorded in; ``trial``: the trial in progress
#:   or being prepared when it arrived (-1 after the last trial of a run). Samples of a trial the run
#:   discarded (interrupted, tracker lost) are kept: (``run``, ``trial``) joins them to trials.parquet.
#: Columns that mean what the frame log's do carry the frame log's names.
#:
#: - ``tracker_t_s``: the tracker's own timestamp (Pupil time; the sender's LSL clock; NaN for a
#:   source without timestamps); ``gaze_sample_t_s``: when the eye was in this state, on the
#:   session clock (after clock sync, session.json ``runs[].clock_sync``); ``received_s``: when
#:   psyop received it, session clock.
#: - ``gaze_valid``: the source's verdict (finite, plausible time, confidence >= its threshold);
#:   ``gaze_confidence`` 0..1.
#: - ``fixation_{x,y,z}_m``: binocular fixation point, head space (x right, y up, -z forward, m).
#: - ``norm_pos_{x,y}``: 2-D gaze in the tracker's scene camera, normalised 0..1 (x right, y up).
#: - per eye (``{eye}`` left or right): ``eye_centre_{eye}_{x,y,z}_m`` and
#:   ``gaze_normal_{eye}_{x,y,z}`` (head space), ``pupil_diameter_{eye}_mm`` (3-D eye model) and
#:   ``pupil_diameter_{eye}_px`` (eye image).
GAZE_SCHEMA = pa.schema(
    [
        pa.field("run", pa.int64()),
        pa.field("trial", pa.int64()),
        pa.field("tracker_t_s", pa.float64()),
        pa.field(dc.GAZE_SAMPLE_T_S, pa.float64()),
        pa.field("received_s", pa.float64()),
        pa.field(dc.GAZE_VALID, pa.bool_()),
        pa.field(dc.GAZE_CONFIDENCE, pa.float64()),
        *(pa.field(f"fixation_{axis}_m", pa.float64()) for axis in "xyz"),
        pa.field("norm_pos_x", pa.float64()),
        pa.field("norm_pos_y", pa.float64()),
        *eye_fields("left"),
        *eye_fields("right"),
    ]
)
