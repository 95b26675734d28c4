"""The modes of a grid posterior: zooms into each local maximum (psyop's replacement for psignifit's
scalar Nelder-Mead MAP search), separated grid peaks, and hill-climbs on the exact posterior that tell
two modes from one ridge seen on a grid."""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage, optimize

from psyop.statistics.psignifit_posterior import _grid_argmax, _t75, log_posterior_2afc


def _local_maxima(values: np.ndarray) -> np.ndarray:
    """``values == maximum_filter(values, size=3, mode="nearest")``: every point >= its 3^d grid
    neighbourhood. The filter runs on the axes longer than 1 only (along an axis of length 1 its
    'nearest' neighbourhood is the point itself), so the answer is the same."""
    core = values.reshape([s for s in values.shape if s > 1] or [1])
    return (core == ndimage.maximum_filter(core, size=3, mode="nearest")).reshape(values.shape)


def _find_modes(data, priors, grid, bounds, zooms: int, lp: np.ndarray, max_starts: int = 4,
                min_log_ratio: float = -1.0) -> list[tuple[float, dict[str, float]]]:
    """Local posterior maxima: every grid local maximum within ``min_log_ratio`` of the highest
    (at most ``max_starts``), each zoomed into ``zooms`` times; distinct modes, best first.

    psignifit starts one Nelder-Mead search at the grid maximum; two modes a few hundredths
    of a log unit apart can swap places on a grid, so psyop zooms from each candidate.
    """
    finite = np.where(np.isfinite(lp), lp, -np.inf)
    is_max = _local_maxima(finite) & (finite >= finite.max() + min_log_ratio)
    starts = sorted(np.argwhere(is_max), key=lambda i: -finite[tuple(i)])[:max_starts]
    names = sorted(grid)
    steps = {n: (np.ptp(np.atleast_1d(grid[n])) / max(len(np.atleast_1d(grid[n])) - 1, 1)) for n in names}
    # 15 points per free axis shrink the box seven-fold per zoom; with eta free (4 axes) 9 points
    # (four-fold) keep each zoom at ~6,500 points, and 1.4x the zooms reach the same resolution.
    n_free = sum(len(np.atleast_1d(grid[n])) > 1 for n in names)
    points = 15 if n_free <= 3 else 9
    zooms = zooms if n_free <= 3 else int(np.ceil(zooms * np.log(7) / np.log(4)))
    modes: list[tuple[float, dict[str, float]]] = []
    for idx in starts:
        point = {n: float(np.atleast_1d(grid[n])[i]) for n, i in zip(names, idx)}
        zoom = grid
        for _ in range(zooms):
            zoom = _shrink(zoom, point, bounds, points)
            point = _refine_map(data, priors, zoom, point)
        value = float(log_posterior_2afc(data, priors, {k: np.atleast_1d(v) for k, v in point.items()}).max())
        same = [m for m in modes if all(abs(m[1][n] - point[n]) <= 0.5 * steps[n] for n in names)]
        if not same:
            modes.append((value, point))
    return sorted(modes, key=lambda m: -m[0])


def _shrink(grid: dict[str, np.ndarray], centre: dict[str, float], bounds, points: int = 15) -> dict[str, np.ndarray]:
    """The next MAP zoom box: +-1 step of ``grid`` around ``centre`` at ``points`` points."""
    out = {}
    for name, values in grid.items():
        values = np.atleast_1d(values)
        if len(values) < 2:
            out[name] = values
            continue
        step = (values[-1] - values[0]) / (len(values) - 1)
        lo = max(bounds[name][0], centre[name] - step)
        hi = min(bounds[name][1], centre[name] + step)
        out[name] = _linspace(lo, hi, points)
    return out


def _linspace(start: float, stop: float, num: int) -> np.ndarray:
    """``np.linspace(start, stop, num)`` for two float scalars and ``num >= 2``: NumPy's own steps
    (``arange(num) * step + start``, the last point ``stop``, and its ``/ div * delta`` where the step
    underflows to 0) without its argument handling."""
    delta = np.subtract(stop, start, dtype=float)
    div = num - 1
    y = np.arange(0, num, dtype=float)
    step = delta / div
    if step == 0:
        y /= div
        y *= delta
    else:
        y *= step
    y += start
    y[-1] = stop
    return y


def _refine_map(data, priors, local, grid_max) -> dict[str, float]:
    """One zoom into the posterior mode: the maximum of the posterior on the small grid ``local``
    (plus the current best point, so the posterior never decreases). Replaces psignifit's scalar
    Nelder-Mead MAP search by vectorised grid evaluations."""
    local = {n: _with_point(v, grid_max[n]) if len(np.atleast_1d(v)) > 1 else v for n, v in local.items()}
    return _grid_argmax(local, log_posterior_2afc(data, priors, local))[1]


def _with_point(values: np.ndarray, x: float) -> np.ndarray:
    """``np.unique(np.append(values, x))``: for strictly increasing ``values`` and a finite, non-zero
    ``x`` (no signed zero to pick between), ``x`` inserted at its sorted place unless already there;
    otherwise NumPy's."""
    values = np.asarray(values)
    if values.dtype == np.float64 and values.ndim == 1 and math.isfinite(x) and x != 0.0 \
            and bool((values[1:] > values[:-1]).all()):
        i = int(np.searchsorted(values, x))
        if i < len(values) and values[i] == x:
            return values.copy()
        return np.insert(values, i, x)
    return np.unique(np.append(values, x))


def separated_peaks(post: np.ndarray, min_ratio: float = 0.1, max_dip: float = 0.75) -> list[tuple[np.ndarray, np.ndarray]]:
    """Pairs (highest peak, other peak) of grid indices that :func:`is_bimodal` calls separated.

    Local maxima of the joint posterior (each >= its 3^d grid neighbourhood) with at least
    ``min_ratio`` of the highest density are candidates; two are separate modes when the
    density along the straight line between them (linear interpolation on the grid) drops
    below ``max_dip`` of the lower one.
    """
    p = np.asarray(post, float)
    if p.size == 0 or p.max() <= 0:
        return []
    p = p / p.max()
    is_max = _local_maxima(p) & (p >= min_ratio)
    peaks = np.argwhere(is_max)
    if len(peaks) < 2:
        return []
    top = peaks[np.argmax(p[tuple(peaks.T)])]
    pairs = []
    for other in peaks:
        dist = np.abs(other - top).max()
        if dist < 2:
            continue
        t = np.linspace(0.0, 1.0, 4 * int(dist) + 1)
        line = top[:, None] + (other - top)[:, None] * t[None, :]
        along = ndimage.map_coordinates(p, line, order=1, mode="nearest")
        if along.min() < max_dip * p[tuple(other)]:
            pairs.append((top, other))
    return pairs


def is_bimodal(post: np.ndarray, min_ratio: float = 0.1, max_dip: float = 0.75) -> bool:
    """Whether a grid posterior has two separated modes (the MAP is then arbitrary between them).

    See :func:`separated_peaks`. Two modes within a few hundredths of a log unit (e.g. a
    small-lapse shallow curve and a large-lapse steep one) are the typical case. On a grid, a
    narrow diagonal ridge also shows separated peaks; :func:`fit_psychometric` therefore
    confirms each pair by climbing the exact posterior (:func:`climbs_apart`).
    """
    p = np.squeeze(np.asarray(post, float))
    if p.ndim == 0:
        return False
    return bool(separated_peaks(p, min_ratio, max_dip))


def _climb(data, priors, grid: dict[str, np.ndarray], bounds, index: np.ndarray) -> np.ndarray:
    """The local maximum of the exact log posterior reached from grid point ``index`` (free axes
    only, in grid-step units)."""
    names = sorted(grid)
    free = [n for n in names if len(np.atleast_1d(grid[n])) > 1]
    start = {n: float(np.atleast_1d(grid[n])[i]) for n, i in zip(names, index)}
    step = np.array([np.ptp(grid[n]) / (len(grid[n]) - 1) for n in free])
    x0 = np.array([start[n] for n in free])
    lo = np.array([bounds[n][0] for n in free])
    hi = np.array([bounds[n][1] for n in free])

    def negative(u: np.ndarray) -> float:
        x = np.clip(x0 + u * step, lo, hi)
        point: dict[str, float | np.ndarray] = dict(start, **{n: np.atleast_1d(v) for n, v in zip(free, x)})
        value = float(log_posterior_2afc(data, priors, {k: np.atleast_1d(v) for k, v in point.items()}).max())
        return -value if np.isfinite(value) else 1e300

    res = optimize.minimize(negative, np.zeros(len(free)), method="Nelder-Mead",
                            bounds=list(zip((lo - x0) / step, (hi - x0) / step)),
                            options={"xatol": 1e-3, "fatol": 1e-9, "maxiter": 2000})
    return np.asarray(res.x, float)  # offset from ``index`` in grid steps


def climbs_apart(data, priors, grid: dict[str, np.ndarray], bounds, top: np.ndarray, other: np.ndarray) -> bool:
    """Whether hill-climbs on the exact posterior from two grid peaks end more than one grid step
    apart on some axis, i.e. whether the two peaks are two modes and not one ridge seen on a grid."""
    names = sorted(grid)
    free_axes = [i for i, n in enumerate(names) if len(np.atleast_1d(grid[n])) > 1]
    top_free = np.asarray(top)[free_axes].astype(float)
    other_free = np.asarray(other)[free_axes].astype(float)
    end_top = top_free + _climb(data, priors, grid, bounds, top)
    end_other = other_free + _climb(data, priors, grid, bounds, other)
    return bool(np.abs(end_top - end_other).max() > 1.0)


def _distinct_thresholds(modes, ci_width_D: float, min_log_ratio: float = -1.0, min_shift: float = 0.25,
                         target_kw: dict | None = None) -> bool:
    """A second posterior mode, within ``min_log_ratio`` of the best, whose 75 % point (``target_kw``:
    :func:`_target_kwargs`) differs from the best one's by more than ``min_shift`` of the CI width (or
    is unreachable)."""
    if len(modes) < 2:
        return False
    best_lp, best = modes[0]
    t_best = _t75(best, **(target_kw or {}))
    for lp, other in modes[1:]:
        if lp - best_lp < min_log_ratio:
            continue
        t_other = _t75(other, **(target_kw or {}))
        if not (np.isfinite(t_best) and np.isfinite(t_other)):
            return True
        if abs(t_other - t_best) > min_shift * (ci_width_D if np.isfinite(ci_width_D) else 0.0):
            return True
    return False
