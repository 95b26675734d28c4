"""The raw gaze stream as an Arrow table: samples -> :data:`~psyop.session.log.schema.GAZE_SCHEMA` rows."""

from __future__ import annotations

import math
from collections.abc import Sequence

import pyarrow as pa

from psyop.session.gaze.sample import EyeSample, RawGazeSample
from psyop.session.log.schema import GAZE_SCHEMA

_NO_EYE = EyeSample()
_NAN = math.nan


def raw_gaze_table(samples: Sequence[RawGazeSample], *, run: int, trial: int) -> pa.Table:
    """The rows of ``samples`` (oldest first) recorded in ``run`` while ``trial`` was in progress.

    Examples
    --------
    >>> table = raw_gaze_table([RawGazeSample(5.0, 1.0, 1.01, True, 0.9, (0.0, 0.0, -1.0))], run=0, trial=3)
    >>> table.num_rows, table.column("trial").to_pylist(), table.column("pupil_diameter_left_mm").to_pylist()
    (1, [3], [nan])
    """
    n = len(samples)
    columns: dict[str, list[float] | list[int] | list[bool]] = {
        "run": [run] * n, "trial": [trial] * n,
        "tracker_t_s": [s.tracker_t_s for s in samples], "gaze_sample_t_s": [s.t_s for s in samples],
        "received_s": [s.received_s for s in samples], "gaze_valid": [bool(s.valid) for s in samples],
        "gaze_confidence": [s.confidence for s in samples],
    }
    for i, axis in enumerate("xyz"):
        columns[f"fixation_{axis}_m"] = [s.fixation_m[i] for s in samples]
    columns["norm_pos_x"] = [s.norm_pos[0] for s in samples]
    columns["norm_pos_y"] = [s.norm_pos[1] for s in samples]
    for eye in ("left", "right"):
        parts = [((s.left if eye == "left" else s.right) or _NO_EYE) for s in samples]
        for i, axis in enumerate("xyz"):
            columns[f"eye_centre_{eye}_{axis}_m"] = [p.centre_m[i] for p in parts]
        for i, axis in enumerate("xyz"):
            columns[f"gaze_normal_{eye}_{axis}"] = [p.normal[i] for p in parts]
        columns[f"pupil_diameter_{eye}_mm"] = [p.pupil_diameter_mm for p in parts]
        columns[f"pupil_diameter_{eye}_px"] = [p.pupil_diameter_px for p in parts]
    return pa.Table.from_pydict(columns, schema=GAZE_SCHEMA)
