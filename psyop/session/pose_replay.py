"""Replay the head and hand pose recorded in a logged session.

Head (frames.parquet, ``head_*``): a logged head sample becomes available at the render
start of the first frame that used it (as for gaze replay), so the session sees the
poses when the original did. Hand (trials.parquet, ``hand_sample_*``): the samples
logged for the same trial number, shifted in time so that the last one falls at the new
response time; the reach computed from them equals the logged one exactly.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from psyop.errors import UserError
from psyop.session.pose import IDENTITY_WXYZ, PoseSample

HEAD_COLUMNS = ("head_sample_t_s", "head_x_m", "head_y_m", "head_z_m", "head_qw", "head_qx", "head_qy", "head_qz", "head_valid")
HAND_COLUMNS = ("hand_sample_t_s", "hand_sample_x_m", "hand_sample_y_m", "hand_sample_z_m", "hand_sample_valid")


def _flag(value: Any) -> bool:
    return bool(value) if value is not None and not (isinstance(value, float) and math.isnan(value)) else False


class ReplayPose:
    """Serves the head and hand poses of a logged session (see the module docstring)."""

    def __init__(self, frames: pd.DataFrame, trials: pd.DataFrame | None) -> None:
        missing = [c for c in HEAD_COLUMNS if c not in frames.columns]
        if missing:
            raise UserError(f"pose replay: frame log lacks columns {missing} (logged before poses were recorded?)")
        head = frames.dropna(subset=["head_sample_t_s"])
        available = "render_start_s" if "render_start_s" in head.columns else "head_sample_t_s"
        head = head.drop_duplicates(subset="head_sample_t_s").sort_values(available, kind="stable")
        self._head_t = head[available].astype(float).tolist()
        self._head = list(head[list(HEAD_COLUMNS)].itertuples(index=False, name=None))
        self._hand: dict[int, tuple[Any, ...]] = {}
        if trials is not None and all(c in trials.columns for c in HAND_COLUMNS):
            for trial, *values in trials[["trial", *HAND_COLUMNS]].itertuples(index=False, name=None):
                if values[0] is not None and len(values[0]):
                    self._hand[int(trial)] = tuple(values)
        self.n_missing_hand_trials = 0

    @classmethod
    def from_path(cls, path: Path) -> ReplayPose:
        """A session directory holding frames.parquet (head) and trials.parquet (hand)."""
        path = Path(path)
        frames_path, trials_path = path / "frames.parquet", path / "trials.parquet"
        if not path.is_dir() or not frames_path.is_file():
            raise UserError("pose replay: expected a session directory with frames.parquet (run `psyop recover` "
                            "on a crashed session first)", str(path))
        try:
            frames = pd.read_parquet(frames_path)
            trials = pd.read_parquet(trials_path) if trials_path.is_file() else None
        except Exception as exc:  # noqa: BLE001 - an unreadable log is the user's input
            raise UserError(f"pose replay: cannot read the session's logs: {exc}", str(path)) from exc
        return cls(frames, trials)

    def head(self, now_s: float) -> PoseSample | None:
        i = bisect.bisect_right(self._head_t, now_s) - 1
        if i < 0:
            return None
        t, x, y, z, qw, qx, qy, qz, valid = self._head[i]
        return PoseSample(float(t), (float(x), float(y), float(z)), (float(qw), float(qx), float(qy), float(qz)), _flag(valid))

    def hand(self, row: Mapping[str, Any], end_s: float, n: int, endpoint_m: Sequence[float] | None) -> list[PoseSample]:
        logged = self._hand.get(int(row["trial"]))
        if logged is None:
            self.n_missing_hand_trials += 1
            return []
        times, xs, ys, zs, valid = (np.asarray(v)[-n:] for v in logged)
        times = times.astype(np.float64)
        shift = end_s - times[-1] if math.isfinite(times[-1]) else 0.0
        return [PoseSample(float(t + shift), (float(x), float(y), float(z)), IDENTITY_WXYZ, _flag(v))
                for t, x, y, z, v in zip(times, xs, ys, zs, valid, strict=True)]

    def close(self) -> None:
        return None
