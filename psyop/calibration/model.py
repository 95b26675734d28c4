"""The display's transfer function from photometer readings: gain-offset-gamma and a monotone spline.

Per channel (``grey``, ``red``, ``green``, ``blue``) the readings at each digital level ``v = code / 255`` are
fitted twice:

- **gain-offset-gamma** (GOG; Berns 1996, with a black level): ``L(v) = a + k * max(0, (1 - o) v + o) ** gamma``
  with ``a`` the black (plus flare) luminance, ``a + k`` the luminance at full level, ``o`` the offset
  (gain ``1 - o``, so that ``v = 1`` gives ``a + k``) and ``gamma``. With fewer than six levels the offset is held
  at 0 (three parameters). Least squares on relative residuals (each reading over its own luminance, floored at
  0.1 % of the channel's maximum), so the black level counts as much as the white;
- **monotone spline**: a piecewise-cubic Hermite interpolant (PCHIP, Fritsch-Carlson; ``scipy.interpolate.
  PchipInterpolator``) through the level means, monotone wherever the means are.

The one recorded as ``model`` is the one with the smaller leave-one-level-out error (each interior level predicted
by the model fitted without it, relative RMS): GOG unless the spline predicts the held-out levels better, as for a
display whose transfer is no power law. Residuals (reading minus prediction, in cd/m² and relative) are recorded
per reading for the chosen model, with both models' in-sample and leave-one-out RMS.

Before fitting, :func:`check_readings` refuses readings that fall with the level (non-monotone) or whose repeats
scatter (noisy): each a one-line :class:`~psyop.errors.UserError` naming the channel, the levels and the fix.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from psyop.errors import UserError

CHANNELS: tuple[str, ...] = ("grey", "red", "green", "blue")
MAX_CODE = 255
#: relative floor of the fit's weights: a reading counts relative to max(itself, this share of the channel's max)
RELATIVE_FLOOR = 1e-3
#: fewer levels than this: the GOG offset is held at 0
MIN_LEVELS_FOR_OFFSET = 6
#: the repeats of one level may scatter by this relative SD (levels above 2 % of the channel's maximum)
NOISE_LIMIT = 0.03
#: a level mean may fall below an earlier one by this share of the channel's maximum (or 3 repeat SDs)
MONOTONE_TOLERANCE = 0.005


@dataclass(frozen=True)
class Gog:
    """``L(v) = black + gain * max(0, (1 - offset) v + offset) ** gamma``, v in [0, 1], cd/m²."""

    black_cd_m2: float
    gain_cd_m2: float
    offset: float
    gamma: float

    def __call__(self, v: np.ndarray) -> np.ndarray:
        base = np.maximum(0.0, (1.0 - self.offset) * np.asarray(v, dtype=np.float64) + self.offset)
        return np.asarray(self.black_cd_m2 + self.gain_cd_m2 * base**self.gamma)


def fit_gog(v: np.ndarray, luminance: np.ndarray, *, fit_offset: bool) -> Gog:
    """The GOG parameters of readings ``luminance`` at levels ``v`` (relative least squares)."""
    from scipy.optimize import least_squares

    v = np.asarray(v, dtype=np.float64)
    y = np.asarray(luminance, dtype=np.float64)
    scale = np.maximum(y, RELATIVE_FLOOR * max(float(y.max()), 1e-12))
    low = max(float(y.min()), 0.0)
    start = [low, max(float(y.max()) - low, 1e-9), 2.2] + ([0.0] if fit_offset else [])

    def model(p: np.ndarray) -> Gog:
        return Gog(float(p[0]), float(p[1]), float(p[3]) if fit_offset else 0.0, float(p[2]))

    def residuals(p: np.ndarray) -> np.ndarray:
        return np.asarray((model(p)(v) - y) / scale)

    lower = [0.0, 0.0, 0.2] + ([-0.5] if fit_offset else [])
    upper = [np.inf, np.inf, 6.0] + ([0.5] if fit_offset else [])
    result = least_squares(residuals, np.clip(start, lower, [u if np.isfinite(u) else 1e300 for u in upper]),
                           bounds=(lower, upper), xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=5000)
    return model(result.x)


def spline(v: np.ndarray, means: np.ndarray):  # -> scipy.interpolate.PchipInterpolator (untyped)
    """The monotone cubic (PCHIP) through the level means."""
    from scipy.interpolate import PchipInterpolator

    return PchipInterpolator(np.asarray(v, dtype=np.float64), np.asarray(means, dtype=np.float64), extrapolate=True)


def level_means(codes: np.ndarray, luminance: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(levels, mean, sd) of the readings at each distinct code, levels ascending (sd 0 with one repeat)."""
    codes = np.asarray(codes)
    levels = np.unique(codes)
    means = np.array([luminance[codes == c].mean() for c in levels])
    sds = np.array([luminance[codes == c].std(ddof=1) if (codes == c).sum() > 1 else 0.0 for c in levels])
    return levels, means, sds


def _relative_rms(predicted: np.ndarray, measured: np.ndarray) -> float:
    scale = np.maximum(measured, RELATIVE_FLOOR * max(float(measured.max()), 1e-12))
    return float(np.sqrt(np.mean(((predicted - measured) / scale) ** 2)))


def leave_one_out(levels: np.ndarray, means: np.ndarray, *, fit_offset: bool) -> tuple[float, float]:
    """Relative RMS error at each interior level predicted without it: (GOG, spline)."""
    v = levels / MAX_CODE
    gog_errors, spline_errors = [], []
    for j in range(1, len(levels) - 1):
        keep = np.arange(len(levels)) != j
        gog = fit_gog(v[keep], means[keep], fit_offset=fit_offset and keep.sum() >= MIN_LEVELS_FOR_OFFSET)
        gog_errors.append(float(gog(v[j : j + 1])[0]))
        spline_errors.append(float(spline(v[keep], means[keep])(v[j])))
    interior = means[1:-1]
    if not len(interior):
        return 0.0, float("inf")
    return _relative_rms(np.array(gog_errors), interior), _relative_rms(np.array(spline_errors), interior)


def fit_channel(codes: Sequence[int], luminance: Sequence[float]) -> dict[str, object]:
    """Both models of one channel, the chosen one, its residuals per reading and per level (a JSON object)."""
    codes_a = np.asarray(codes, dtype=np.int64)
    y = np.asarray(luminance, dtype=np.float64)
    levels, means, sds = level_means(codes_a, y)
    fit_offset = len(levels) >= MIN_LEVELS_FOR_OFFSET
    gog = fit_gog(codes_a / MAX_CODE, y, fit_offset=fit_offset)
    curve = spline(levels / MAX_CODE, means)
    gog_loo, spline_loo = leave_one_out(levels, means, fit_offset=fit_offset)
    chosen = "spline" if spline_loo < gog_loo else "gog"
    predict = (lambda v: gog(v)) if chosen == "gog" else (lambda v: curve(v))
    predicted = np.asarray(predict(codes_a / MAX_CODE))
    level_predicted = np.asarray(predict(levels / MAX_CODE))
    scale = np.maximum(y, RELATIVE_FLOOR * max(float(y.max()), 1e-12))
    return {
        "model": chosen,
        "gog": {"black_cd_m2": gog.black_cd_m2, "gain_cd_m2": gog.gain_cd_m2, "offset": gog.offset,
                "gamma": gog.gamma, "offset_fitted": fit_offset,
                "rms_relative": _relative_rms(gog(codes_a / MAX_CODE), y), "loo_rms_relative": gog_loo},
        "spline": {"kind": "pchip", "codes": levels.tolist(), "luminance_cd_m2": means.tolist(),
                   "rms_relative": _relative_rms(curve(codes_a / MAX_CODE), y), "loo_rms_relative": spline_loo},
        "levels": [{"code": int(c), "mean_cd_m2": float(m), "sd_cd_m2": float(s), "predicted_cd_m2": float(p),
                    "residual_relative": float((m - p) / max(m, RELATIVE_FLOOR * float(means.max())))}
                   for c, m, s, p in zip(levels, means, sds, level_predicted, strict=True)],
        "residuals_cd_m2": (y - predicted).tolist(),
        "residuals_relative": ((y - predicted) / scale).tolist(),
        "max_abs_residual_relative": float(np.max(np.abs((y - predicted) / scale))),
    }


def predict_luminance(channel_fit: dict, code: float | np.ndarray) -> np.ndarray:
    """The luminance (cd/m²) a fitted channel (one entry of the file's ``fit``) predicts at ``code`` (0..255)."""
    v = np.asarray(code, dtype=np.float64) / MAX_CODE
    if channel_fit["model"] == "gog":
        g = channel_fit["gog"]
        return Gog(g["black_cd_m2"], g["gain_cd_m2"], g["offset"], g["gamma"])(v)
    s = channel_fit["spline"]
    return np.asarray(spline(np.asarray(s["codes"]) / MAX_CODE, np.asarray(s["luminance_cd_m2"]))(v))


def check_readings(channel: str, codes: Sequence[int], luminance: Sequence[float], device: str) -> None:
    """Refuse readings that fall with the level or scatter between repeats (a one-line UserError)."""
    codes_a = np.asarray(codes, dtype=np.int64)
    y = np.asarray(luminance, dtype=np.float64)
    if not np.all(np.isfinite(y)) or np.any(y < 0):
        raise UserError(f"{device}: {channel} readings include a negative or non-finite luminance; check the "
                        "photometer's zero (cap it and re-zero, if it offers that) and rerun")
    levels, means, sds = level_means(codes_a, y)
    top = max(float(means.max()), 1e-12)
    bright = means > 0.02 * top
    relative_sd = np.where(bright, sds / np.maximum(means, 1e-12), 0.0)
    if np.any(relative_sd > NOISE_LIMIT):
        j = int(np.argmax(relative_sd))
        raise UserError(f"{device}: {channel} readings are noisy (level {levels[j]}: SD {100 * relative_sd[j]:.1f} % "
                        f"of {means[j]:.4g} cd/m² over the repeats, limit {100 * NOISE_LIMIT:.0f} %); keep the "
                        "photometer still on the patch centre, switch off room lights and let the display warm up "
                        "(30 min), then rerun")
    pooled_sd = float(np.sqrt(np.mean(sds**2))) if np.any(sds > 0) else 0.0
    tolerance = max(MONOTONE_TOLERANCE * top, 3.0 * pooled_sd)
    running = np.maximum.accumulate(means)
    falls = np.flatnonzero(means < running - tolerance)
    if len(falls):
        j = int(falls[0])
        k = int(np.argmax(means[:j]))
        raise UserError(f"{device}: {channel} readings are non-monotone ({means[k]:.4g} cd/m² at level {levels[k]}, "
                        f"{means[j]:.4g} at level {levels[j]}); check that the photometer sees only the patch (no "
                        "room light, screen saver, dimming or automatic brightness) and rerun")
