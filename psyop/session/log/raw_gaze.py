"""The raw gaze stream as an Arrow table: samples -> :data:`~psyop.session.log.schema.GAZE_SCHEMA` rows."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import pyarrow as pa

from psyop import datacontract as dc
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
        "tracker_t_s": [s.tracker_t_s for s in samples], dc.GAZE_SAMPLE_T_S: [s.t_s for s in samples],
        "received_s": [s.received_s for s in samples], dc.GAZE_VALID: [bool(s.valid) for s in samples],
        dc.GAZE_CONFIDENCE: [s.confidence for s in samples],
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


def raw_gaze_block_table(t_s: np.ndarray, received_s: np.ndarray, valid: np.ndarray, confidence: np.ndarray,
                         fixation_m: np.ndarray, *, run: int, trial: int) -> pa.Table:
    """:func:`raw_gaze_table` of samples given as columns (a source that delivers the session clock's times
    and a binocular fixation point only: ``tracker_t_s`` = ``t_s``, every per-eye and 2-D field NaN), built
    without a Python object per sample (the analysis rebuilds whole streams, psyop.quality.resimulate).

    Examples
    --------
    >>> s = RawGazeSample(5.0, 5.0, 5.01, True, 0.9, (0.0, 0.1, -1.0))
    >>> block = raw_gaze_block_table(np.array([5.0]), np.array([5.01]), np.array([True]), np.array([0.9]),
    ...                              np.array([[0.0, 0.1, -1.0]]), run=0, trial=3)
    >>> block.to_pandas().equals(raw_gaze_table([s], run=0, trial=3).to_pandas())  # (NaN equal to NaN)
    True
    """
    n = len(t_s)
    nan = np.full(n, _NAN)
    given: dict[str, np.ndarray] = {
        "run": np.full(n, run, dtype=np.int64), "trial": np.full(n, trial, dtype=np.int64),
        "tracker_t_s": t_s, dc.GAZE_SAMPLE_T_S: t_s, "received_s": received_s,
        dc.GAZE_VALID: np.asarray(valid, dtype=bool), dc.GAZE_CONFIDENCE: confidence,
        **{f"fixation_{axis}_m": fixation_m[:, i] for i, axis in enumerate("xyz")},
    }
    return pa.Table.from_pydict({f.name: given.get(f.name, nan) for f in GAZE_SCHEMA}, schema=GAZE_SCHEMA)
