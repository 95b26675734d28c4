"""Replay the head and hand pose recorded in a logged session.

Head (frames.parquet, ``head_*``): a logged head sample becomes available at the render
start of the first frame that used it (as for gaze replay), so the session sees the
poses when the original did. Hand (trials.parquet, ``hand_sample_*``): the samples
logged for the same trial, shifted in time so that the last one falls at the new
response time; the reach computed from them equals the logged one exactly.

Which logged trial is "the same trial": by default the source session must have run the
same schedule (same protocol hash, seed and condition sequence), and trial k replays trial
k; a source with another schedule is refused (exit 2), since pairing by trial number would
give a reach made to one target to another target. ``--pose replay-by-condition:DIR``
pairs each trial with the next unused logged trial of the same condition instead.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from psyop import datacontract as dc
from psyop.session.rows import TrialRow
from psyop.errors import UserError
from psyop.input_files import read_logged_table
from psyop.session.log.record import SessionRecord, read_record_file
from psyop.session.pose import IDENTITY_WXYZ, PoseSample

HEAD_COLUMNS = ("head_sample_t_s", "head_x_m", "head_y_m", "head_z_m", "head_qw", "head_qx", "head_qy", "head_qz", "head_valid")
HAND_COLUMNS = ("hand_sample_t_s", "hand_sample_x_m", "hand_sample_y_m", "hand_sample_z_m", "hand_sample_valid")


def _flag(value: object) -> bool:
    return bool(value) if value is not None and not (isinstance(value, float) and math.isnan(value)) else False


@dataclass(frozen=True)
class ReplaySchedule:
    """What the replaying session will run: compared with the source session's."""

    protocol_sha256: str
    seed: int
    conditions: tuple[str, ...]  # condition of trial 0, 1, ...


def pair_trials(source: SessionRecord, source_trials: pd.DataFrame, target: ReplaySchedule,
                by_condition: bool, where: str) -> dict[int, int]:
    """Map each trial of ``target`` to the source trial whose hand samples it replays.

    Same schedule (protocol hash, seed, conditions in order): trial k -> k. Otherwise a
    :class:`UserError` naming what differs, unless ``by_condition``: then trial k gets the
    j-th logged trial of its condition when it is the j-th of that condition (cycling when
    the source logged fewer; counted in the session summary as ``hand_trials_reused``).
    """
    source_conditions = dict(zip(source_trials["trial"].astype(int), source_trials["condition"].astype(str), strict=True)) \
        if "condition" in source_trials.columns else {}
    if not by_condition:
        differs = []
        if source.protocol_sha256 != target.protocol_sha256:
            differs.append(f"protocol hash {str(source.protocol_sha256)[:12]} vs {target.protocol_sha256[:12]}")
        if source.seed != target.seed:
            differs.append(f"seed {source.seed} vs {target.seed}")
        mismatched = [k for k, c in source_conditions.items() if k < len(target.conditions) and target.conditions[k] != c]
        if mismatched:
            k = mismatched[0]
            differs.append(f"{len(mismatched)} trials have another condition (trial {k}: "
                           f"{source_conditions[k]} logged, {target.conditions[k]} now)")
        if differs:
            raise UserError("pose replay: the source session ran another schedule (" + "; ".join(differs) + "), so "
                            "replaying by trial number would pair reaches with other targets. Run with the "
                            f"source's seed (--seed {source.seed}) and protocol, or pair trials by "
                            "condition: --pose replay-by-condition:DIR", where)
        return {k: k for k in source_conditions}
    pools: dict[str, list[int]] = {}
    for k in sorted(source_conditions):
        pools.setdefault(source_conditions[k], []).append(k)
    missing = sorted(set(target.conditions) - set(pools))
    if missing:
        raise UserError(f"pose replay by condition: the source session logged no trial of {len(missing)} "
                        f"condition(s) this schedule has (e.g. {missing[0]})", where)
    used: dict[str, int] = {}
    pairs = {}
    for k, condition in enumerate(target.conditions):
        j = used.get(condition, 0)
        used[condition] = j + 1
        pool = pools[condition]
        pairs[k] = pool[j % len(pool)]  # a condition run more often than logged reuses its trials in order
    return pairs


def n_reused(pairs: Mapping[int, int]) -> int:
    """How many trials replay a logged trial that an earlier trial already replayed."""
    return len(pairs) - len(set(pairs.values()))


class ReplayPose:
    """Serves the head and hand poses of a logged session (see the module docstring)."""

    def __init__(self, frames: pd.DataFrame, trials: pd.DataFrame | None,
                 pairs: Mapping[int, int] | None = None) -> None:
        missing = [c for c in HEAD_COLUMNS if c not in frames.columns]
        if missing:
            raise UserError(f"pose replay: frame log lacks columns {missing} (logged before poses were recorded?)")
        head = frames.dropna(subset=["head_sample_t_s"])
        available = dc.RENDER_START_S if dc.RENDER_START_S in head.columns else "head_sample_t_s"
        head = head.drop_duplicates(subset="head_sample_t_s").sort_values(available, kind="stable")
        self._head_t = head[available].astype(float).tolist()
        self._head = list(head[list(HEAD_COLUMNS)].itertuples(index=False, name=None))
        self._hand: dict[int, tuple[Any, ...]] = {}  # Any: the trials table's hand columns, as pandas gives them
        if trials is not None and all(c in trials.columns for c in HAND_COLUMNS):
            for trial, *values in trials[["trial", *HAND_COLUMNS]].itertuples(index=False, name=None):
                if values[0] is not None and len(values[0]):
                    self._hand[int(trial)] = tuple(values)
        self.n_missing_hand_trials = 0
        self._pairs = dict(pairs) if pairs is not None else None
        self.n_reused_hand_trials = n_reused(self._pairs) if self._pairs is not None else 0

    @classmethod
    def from_path(cls, path: Path, target: ReplaySchedule | None = None, *, by_condition: bool = False) -> ReplayPose:
        """A session directory holding frames.parquet (head) and trials.parquet (hand).

        With ``target``, the source's schedule is checked against it (see :func:`pair_trials`).
        """
        path = Path(path)
        frames_path, trials_path = path / "frames.parquet", path / "trials.parquet"
        if not path.is_dir():
            raise UserError("pose replay: no such session directory; give data/<study>/sub-<ID>/ses-<N> of a "
                            "finished session (frames.parquet)", str(path))
        if not frames_path.exists():
            raise UserError("pose replay: expected a session directory with frames.parquet (run `psyop recover` "
                            "on a crashed session first)", str(path))
        context = "--pose replay"
        frames = read_logged_table(frames_path, context)
        trials = read_logged_table(trials_path, context) if trials_path.exists() else None
        meta_path = path / "session.json"
        source = read_record_file(meta_path) or SessionRecord()  # none: the schedule cannot be matched
        pairs = None
        if target is not None and trials is not None:
            pairs = pair_trials(source, trials, target, by_condition, str(path))
        return cls(frames, trials, pairs)

    def head(self, now_s: float) -> PoseSample | None:
        i = bisect.bisect_right(self._head_t, now_s) - 1
        if i < 0:
            return None
        t, x, y, z, qw, qx, qy, qz, valid = self._head[i]
        return PoseSample(float(t), (float(x), float(y), float(z)), (float(qw), float(qx), float(qy), float(qz)), _flag(valid))

    def hand(self, row: TrialRow, end_s: float, n: int, endpoint_m: Sequence[float] | None) -> list[PoseSample]:
        trial = int(row["trial"])
        source = trial if self._pairs is None else self._pairs.get(trial, -1)
        logged = self._hand.get(source)
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
