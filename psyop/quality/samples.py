"""A session's raw gaze stream on the tracker's clock grid, in degrees, with its faults counted by name.

Samples are placed on the grid ``t_first + k / rate_hz`` (the nominal rate: the simulated tracker's
stated rate, else the median interval between samples, ``rate_source`` says which). A tick without a
valid sample is NaN (loss); duplicated timestamps, timestamps that go backwards, samples between ticks
(a mixed rate) and non-finite times are dropped and counted (``flags``), never a traceback.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from psyop.optics.angles import fick_angles_deg

FLAG_NAMES = ("n_non_finite_time", "n_duplicate_timestamps", "n_non_monotonic", "n_off_grid")


@dataclass(frozen=True)
class GazeGrid:
    """Samples on a regular grid: ``t_s`` (s, session clock), Fick ``az_deg``/``el_deg`` of the binocular
    gaze (NaN: no valid sample at that tick), ``valid``; ``eyes``: per eye (left/right) the (az, el) of
    its gaze normal where the tracker gives it; ``flags``: counts by :data:`FLAG_NAMES`."""

    t_s: np.ndarray
    az_deg: np.ndarray
    el_deg: np.ndarray
    valid: np.ndarray
    rate_hz: float
    rate_source: str
    flags: dict[str, int]
    eyes: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    #: per eye with a gaze normal: its centre (n, 3) in head space (m; NaN where the tracker gave none)
    eye_centres_m: dict[str, np.ndarray] = field(default_factory=dict)

    @staticmethod
    def empty(rate_hz: float, rate_source: str, flags: dict[str, int]) -> GazeGrid:
        nothing = np.zeros(0)
        return GazeGrid(nothing, nothing, nothing, np.zeros(0, dtype=bool), rate_hz, rate_source, flags)


def _angles(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    d = np.stack([x, y, z], axis=-1)
    usable = np.all(np.isfinite(d), axis=-1) & (np.linalg.norm(d, axis=-1) > 0)
    az, el = fick_angles_deg(np.where(usable[:, None], d, [0.0, 0.0, -1.0]))
    az = np.where(usable, np.asarray(az, dtype=np.float64).reshape(-1), np.nan)
    el = np.where(usable, np.asarray(el, dtype=np.float64).reshape(-1), np.nan)
    return az, el


def gaze_grid(gaze: pd.DataFrame, nominal_rate_hz: float | None) -> GazeGrid:
    """``gaze`` (columns of :data:`psyop.session.log.schema.GAZE_SCHEMA`; one session) on its grid.

    Examples
    --------
    >>> g = pd.DataFrame({"gaze_sample_t_s": [0.0, 0.01, 0.01, 0.03, 0.02], "gaze_valid": [True] * 5,
    ...                   "fixation_x_m": [0.0] * 5, "fixation_y_m": [0.0] * 5, "fixation_z_m": [-1.0] * 5})
    >>> grid = gaze_grid(g, 100.0)
    >>> len(grid.t_s), grid.flags["n_duplicate_timestamps"], grid.flags["n_non_monotonic"]
    (4, 1, 1)
    """
    flags = dict.fromkeys(FLAG_NAMES, 0)
    if len(gaze) == 0 or "gaze_sample_t_s" not in gaze:
        return GazeGrid.empty(float(nominal_rate_hz or math.nan), "no samples", flags)
    kept, t = _ordered_samples(gaze, flags)
    if len(t) == 0:
        return GazeGrid.empty(float(nominal_rate_hz or math.nan), "no samples", flags)
    if nominal_rate_hz is not None:
        rate, source = float(nominal_rate_hz), "the simulated tracker's rate_hz"
    elif len(t) > 1:
        rate, source = 1.0 / float(np.median(np.diff(t))), "median interval between samples"
    else:
        return GazeGrid.empty(math.nan, "one sample: no rate", flags)
    tick, on = _ticks(t, rate, flags)
    tick, rows = tick[on], _Rows(gaze, kept[on])
    n = int(tick[-1]) + 1
    grid_t = t[0] + np.arange(n) / rate
    valid_col = rows.column("gaze_valid", bool) if "gaze_valid" in rows else np.ones(len(tick), dtype=bool)
    columns = [f"fixation_{a}_m" for a in "xyz"]
    if all(c in rows for c in columns):
        az, el = _angles(*(rows.column(c, np.float64) for c in columns))
    else:
        az = el = np.full(len(tick), np.nan)
    ok = valid_col & np.isfinite(az) & np.isfinite(el)
    grid_az, grid_el = _place(tick, n, az, el, ok)
    eyes, centres = _placed_eyes(rows, valid_col, tick, n)
    return GazeGrid(grid_t, grid_az, grid_el, np.isfinite(grid_az), rate, source, flags, eyes, centres)


@dataclass(frozen=True)
class _Rows:
    """The rows ``index`` (positions) of ``gaze``, read a column at a time (no copy of the whole frame)."""

    gaze: pd.DataFrame
    index: np.ndarray

    def __contains__(self, name: str) -> bool:
        return name in self.gaze

    def column(self, name: str, dtype: type) -> np.ndarray:
        return self.gaze[name].to_numpy(dtype=dtype)[self.index]


def _ordered_samples(gaze: pd.DataFrame, flags: dict[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """The rows (positions) of ``gaze`` with a finite, strictly increasing ``gaze_sample_t_s`` and those times;
    counts the non-finite, backwards and duplicated ones into ``flags``."""
    t = gaze["gaze_sample_t_s"].to_numpy(dtype=np.float64)
    finite = np.isfinite(t)
    flags["n_non_finite_time"] = int((~finite).sum())
    running = np.fmax.accumulate(np.where(finite, t, -np.inf))
    backwards = finite & (t < np.concatenate([[-np.inf], running[:-1]]))
    flags["n_non_monotonic"] = int(backwards.sum())
    keep = finite & ~backwards
    duplicate = keep & np.concatenate([[False], t[1:] == t[:-1]])
    flags["n_duplicate_timestamps"] = int(duplicate.sum())
    keep &= ~duplicate
    return np.flatnonzero(keep), t[keep]


def _ticks(t: np.ndarray, rate_hz: float, flags: dict[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """(grid tick of each time, whether it is on the grid): off by more than a quarter tick, or a second
    sample on the same tick, is off grid (counted as ``n_off_grid`` in ``flags``)."""
    tick = np.rint((t - t[0]) * rate_hz).astype(np.int64)
    off = np.abs((t - t[0]) * rate_hz - tick) > 0.25
    same = np.concatenate([[False], tick[1:] == tick[:-1]])
    flags["n_off_grid"] = int((off | same).sum())
    return tick, ~(off | same)


def _place(tick: np.ndarray, n: int, az: np.ndarray, el: np.ndarray,
           ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``az``, ``el`` where ``ok`` at their ``tick`` of an ``n``-tick grid; NaN elsewhere."""
    out_az, out_el = np.full(n, np.nan), np.full(n, np.nan)
    out_az[tick[ok]], out_el[tick[ok]] = az[ok], el[ok]
    return out_az, out_el


def _placed_eyes(rows: _Rows, valid_col: np.ndarray, tick: np.ndarray,
                 n: int) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], dict[str, np.ndarray]]:
    """Per eye whose ``gaze_normal_<eye>_<x|y|z>`` the rows hold (with a valid, finite one): its gaze normal's
    (az, el) and its centre on the grid."""
    eyes, centres = {}, {}
    for eye in ("left", "right"):
        names = [f"gaze_normal_{eye}_{a}" for a in "xyz"]
        if not all(c in rows for c in names):
            continue
        normal = [rows.column(c, np.float64) for c in names]
        if not np.any(valid_col & np.isfinite(normal[0]) & np.isfinite(normal[1]) & np.isfinite(normal[2])):
            continue  # no valid normal: no angles to place
        e_az, e_el = _angles(*normal)
        e_ok = valid_col & np.isfinite(e_az)
        if e_ok.any():
            eyes[eye] = _place(tick, n, e_az, e_el, e_ok)
            centres[eye] = _placed_centre(rows, eye, tick, e_ok, n)
    return eyes, centres


def _placed_centre(rows: _Rows, eye: str, tick: np.ndarray, ok: np.ndarray, n: int) -> np.ndarray:
    """The eye's centre (``eye_centre_<eye>_<x|y|z>_m``) on the grid; NaN where absent."""
    out = np.full((n, 3), np.nan)
    names = [f"eye_centre_{eye}_{a}_m" for a in "xyz"]
    if all(c in rows for c in names):
        out[tick[ok]] = np.stack([rows.column(c, np.float64) for c in names], axis=1)[ok]
    return out
