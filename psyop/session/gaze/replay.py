"""Replay the gaze recorded in a session's frame log (frames.parquet or its streams)."""

from __future__ import annotations

import bisect
import math
from pathlib import Path

import pandas as pd

from psyop import datacontract as dc
from psyop.errors import UserError
from psyop.input_files import read_logged_table
from psyop.session.gaze.plan import FixationPlan
from psyop.session.gaze.sample import GazeSample, RawBuffer, RawGazeSample
from psyop.session.gaze.sync import ClockSync


class ReplayTracker:
    """Serves logged gaze samples as they were available in the logged session.

    A sample becomes available at the render start of the first frame that used it
    (so the original tracker latency is replayed too); ``time_offset_s`` shifts the log.
    """

    def __init__(self, frames: pd.DataFrame, time_offset_s: float = 0.0) -> None:
        needed = [dc.GAZE_SAMPLE_T_S, dc.FIXATION_X_M, dc.FIXATION_Y_M, dc.FIXATION_Z_M, dc.GAZE_CONFIDENCE, dc.GAZE_VALID]
        missing = [c for c in needed if c not in frames.columns]
        if missing:
            raise UserError(f"replay: frame log lacks columns {missing}")
        available = dc.RENDER_START_S if dc.RENDER_START_S in frames.columns else dc.GAZE_SAMPLE_T_S
        table = frames[needed + ([available] if available not in needed else [])].dropna(subset=[dc.GAZE_SAMPLE_T_S])
        table = table.drop_duplicates(subset=dc.GAZE_SAMPLE_T_S).sort_values(available)
        self._t = [float(t) + time_offset_s for t in table[available]]
        self._sample_t = [float(t) + time_offset_s for t in table[dc.GAZE_SAMPLE_T_S]]
        self._rows = list(table.itertuples(index=False))
        self._delivered = 0
        self._raw = RawBuffer()
        self._last_raw = -1

    @classmethod
    def from_path(cls, path: Path) -> ReplayTracker:
        """A frames.parquet file or a session directory holding one."""
        path = Path(path)
        if path.is_dir():
            path = path / "frames.parquet"
        if not path.exists():
            raise UserError("replay: no frames.parquet here (run `psyop recover` on a crashed session first)", str(path))
        return cls(read_logged_table(path, "--tracker replay"))

    def start(self) -> None:
        return None

    def close(self) -> None:
        return None

    def stats(self) -> dict[str, float | int]:
        return {"samples_delivered": self._delivered, "samples_available": len(self._t)}

    def set_plan(self, plan: FixationPlan) -> None:
        """No-op: the logged gaze does not follow this session's fixation plan."""
        return None

    def clock_sync(self) -> ClockSync | None:
        """None: the logged samples are on the (logged) session clock."""
        return None

    def drain_raw(self) -> list[RawGazeSample]:
        """Each logged sample a :meth:`latest` call delivered, once."""
        return self._raw.drain()

    def latest(self, now_s: float) -> GazeSample | None:
        i = bisect.bisect_right(self._t, now_s) - 1
        if i < 0:
            return None
        row = self._rows[i]
        self._delivered += 1
        fixation = (float(row.fixation_x_m), float(row.fixation_y_m), float(row.fixation_z_m))
        valid = bool(row.gaze_valid) and all(math.isfinite(v) for v in fixation)
        sample = GazeSample(self._sample_t[i], fixation, float(row.gaze_confidence), valid)
        if i > self._last_raw:
            self._last_raw = i
            self._raw.add(RawGazeSample.of(sample, received_s=self._t[i]))
        return sample
