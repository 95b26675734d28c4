"""The gaze validations a session recorded (validation.parquet, psyop.session.validation), for the quality
table, its summary, the ``quality:`` rules and the BIDS calibration fields. Read only, never changed.

Each trial gets the validation that speaks for it (:func:`trial_validation_measures`): the last attempt of
the latest validation that ended before the trial began (same run, or an earlier one); a trial before any
(a protocol validating only at the end) gets the first validation after it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from psyop import datacontract as dc
from psyop.protocol.validation import VALIDATION_MEASURES

#: validation.parquet column of each per-trial measure (overall row of the attempt)
MEASURE_COLUMNS: dict[str, str] = dict(zip(VALIDATION_MEASURES, (
    "mean_error_deg", "max_error_deg", "precision_rms_s2s_deg", "precision_sd_deg")))


def read_validations(directory: Path) -> pd.DataFrame | None:
    """The session's validation.parquet (None: it validated no gaze)."""
    path = Path(directory) / dc.VALIDATION_FILE
    return pd.read_parquet(path) if path.is_file() else None


def final_attempts(validations: pd.DataFrame) -> pd.DataFrame:
    """Each validation's last attempt, its overall row (point -1), in the order they ran."""
    overall = validations[validations["point"] == -1]
    last = overall.sort_values(["run", "validation", "attempt"], kind="stable").groupby(["run", "validation"]).tail(1)
    return last.sort_values(["run", "end_s"], kind="stable").reset_index(drop=True)


def trial_validation_measures(trials: pd.DataFrame, validations: pd.DataFrame | None) -> pd.DataFrame:
    """Columns ``trial`` and :data:`VALIDATION_MEASURES` for each row of ``trials`` (columns trial, run,
    trial_start_s); NaN for every trial when the session has no validation."""
    out = pd.DataFrame({"trial": trials["trial"].astype(int).to_numpy()})
    for name in VALIDATION_MEASURES:
        out[name] = math.nan
    if validations is None or validations.empty:
        return out
    done = final_attempts(validations)
    keys = list(zip(done["run"].astype(int), done["end_s"].astype(float)))
    runs = trials["run"].astype(int).to_numpy() if "run" in trials else np.zeros(len(trials), dtype=int)
    for i, (run, start) in enumerate(zip(runs, trials["trial_start_s"].astype(float))):
        before = [j for j, key in enumerate(keys) if key <= (int(run), float(start))]
        j = before[-1] if before else 0
        for name, column in MEASURE_COLUMNS.items():
            out.loc[i, name] = float(done[column].iloc[j])
    return out


def validation_summary_lines(validations: pd.DataFrame | None) -> list[str]:
    """One line per validation attempt: when, accuracy, precision, whether it met the protocol's bound."""
    if validations is None or validations.empty:
        return []
    lines = []
    points = validations[validations["point"] >= 0]
    for _, row in validations[validations["point"] == -1].iterrows():
        own = points[(points["run"] == row["run"]) & (points["validation"] == row["validation"])
                     & (points["attempt"] == row["attempt"])]
        lines.append(
            f"validation {int(row['validation'])} ({row['when']}, run {int(row['run'])}, attempt {int(row['attempt'])}): "
            f"{len(own)} points, accuracy mean {row['mean_error_deg']:.2f} deg (worst point "
            f"{own['mean_error_deg'].max():.2f} deg, largest sample error {row['max_error_deg']:.2f} deg), precision "
            f"RMS-S2S {row['precision_rms_s2s_deg']:.3f} deg, SD {row['precision_sd_deg']:.3f} deg; "
            f"{int(row['n_valid'])} of {int(row['n_samples'])} samples valid; "
            + ("passed" if bool(row["passed"]) else "FAILED the protocol's gaze_validation.require"))
    return lines


def validation_sentence(session_dirs: list[Path], bounded: bool) -> str:
    """The study's gaze validations the way a methods section states them ('' when no session has any):
    points, the median and range over sessions of each session's mean accuracy (its validations' last
    attempts), median precision, and how many validations met the protocol's bound at the first attempt."""
    tables = [t for t in (read_validations(d) for d in session_dirs) if t is not None and not t.empty]
    if not tables:
        return ""
    done = [final_attempts(t) for t in tables]
    per_session = pd.Series([float(d["mean_error_deg"].mean()) for d in done])
    last = pd.concat(done, ignore_index=True)
    overall = pd.concat([t[t["point"] == -1] for t in tables], ignore_index=True)
    first = overall[overall["attempt"] == 1]
    n_points = int(tables[0]["point"].max()) + 1
    return (f"Gaze validation ({n_points} points, {len(last)} validations in {len(tables)} sessions): mean accuracy "
            f"{per_session.median():.2f} deg (median over sessions; range {per_session.min():.2f} to "
            f"{per_session.max():.2f} deg), precision RMS-S2S {last['precision_rms_s2s_deg'].median():.3f} deg and SD "
            f"{last['precision_sd_deg'].median():.3f} deg (medians); "
            + (f"{int(first['passed'].sum())} of {len(first)} validations met the protocol's bound at the first "
               "attempt." if bounded else
               "the protocol states no bound (gaze_validation.require), so none was held back."))
