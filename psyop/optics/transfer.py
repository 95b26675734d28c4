"""A display's transfer function from its calibration file (``psyop calibrate``, docs/calibration.md), numpy only.

The file's ``fit`` holds per channel a gain-offset-gamma model or a monotone cubic (PCHIP) through the level means
(psyop.calibration.model). :class:`DisplayTransfer` evaluates the grey channel's model as the file records it (the
PCHIP here is scipy's ``PchipInterpolator`` written out in numpy, tested equal to it), and inverts it for the
renderer's output lookup table (docs/gratings_and_luminance.md).

Why the grey channel: every luminance a protocol states is achromatic (r = g = b), and the grey channel's readings
are that patch measured directly, so its model is the transfer such a pixel has; the red, green and blue fits stay
in the file (for colour work, not done here). The renderer's table still has one column per output channel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from psyop.records import JsonMapping

MAX_CODE = 255
#: the points the forward model is evaluated at to build the inverse (codes 0..255 in 1/64 steps)
INVERSE_SAMPLES = MAX_CODE * 64 + 1


def _pchip_slopes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """PCHIP derivatives at the knots (Fritsch-Carlson weighted harmonic mean; scipy's end-point rule)."""
    h = np.diff(x)
    m = np.diff(y) / h
    n = len(x)
    if n == 2:
        return np.full(2, m[0])
    d = np.zeros(n)
    w1 = 2.0 * h[1:] + h[:-1]
    w2 = h[1:] + 2.0 * h[:-1]
    same = (np.sign(m[:-1]) * np.sign(m[1:]) > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        harmonic = (w1 / m[:-1] + w2 / m[1:]) / (w1 + w2)
        d[1:-1] = np.where(same, 1.0 / harmonic, 0.0)

    def edge(h0: float, h1: float, m0: float, m1: float) -> float:
        value = ((2.0 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
        if np.sign(value) != np.sign(m0):
            return 0.0
        if np.sign(m0) != np.sign(m1) and abs(value) > abs(3.0 * m0):
            return 3.0 * m0
        return value

    d[0] = edge(h[0], h[1], m[0], m[1])
    d[-1] = edge(h[-1], h[-2], m[-1], m[-2])
    return d


def pchip(x: ArrayLike, y: ArrayLike, at: ArrayLike) -> np.ndarray:
    """The monotone piecewise-cubic Hermite interpolant through (x, y) at ``at`` (extrapolating with the end cubics,
    as scipy's ``PchipInterpolator(extrapolate=True)``)."""
    xs, ys = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    t = np.asarray(at, dtype=np.float64)
    d = _pchip_slopes(xs, ys)
    k = np.clip(np.searchsorted(xs, t, side="right") - 1, 0, len(xs) - 2)
    h = xs[k + 1] - xs[k]
    s = (t - xs[k]) / h
    h00, h10 = (1 + 2 * s) * (1 - s) ** 2, s * (1 - s) ** 2
    h01, h11 = s**2 * (3 - 2 * s), s**2 * (s - 1)
    return np.asarray(h00 * ys[k] + h10 * h * d[k] + h01 * ys[k + 1] + h11 * h * d[k + 1])



@dataclass(frozen=True)
class ChannelModel:
    """One channel's fitted transfer, ``L(code)`` in cd/m² (the file's ``fit[channel]``)."""

    model: str  # "gog" | "spline"
    gog: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)  # black, gain, offset, gamma
    knots_code: tuple[float, ...] = ()
    knots_cd_m2: tuple[float, ...] = ()

    def __call__(self, code: ArrayLike) -> np.ndarray:
        c = np.asarray(code, dtype=np.float64)
        if self.model == "gog":
            black, gain, offset, gamma = self.gog
            base = np.maximum(0.0, (1.0 - offset) * (c / MAX_CODE) + offset)
            return np.asarray(black + gain * base**gamma)
        return pchip(np.asarray(self.knots_code) / MAX_CODE, self.knots_cd_m2, c / MAX_CODE)


def channel_model(fit: object, channel: str) -> ChannelModel:
    """A channel's model from the file's ``fit`` entry (ValueError naming what is missing or wrong)."""
    if not isinstance(fit, dict):
        raise ValueError(f"fit.{channel} is missing")
    kind = fit.get("model")
    try:
        if kind == "gog":
            g = fit["gog"]
            numbers = tuple(float(g[k]) for k in ("black_cd_m2", "gain_cd_m2", "offset", "gamma"))
            if not all(math.isfinite(v) for v in numbers) or numbers[1] <= 0 or numbers[3] <= 0:
                raise ValueError("non-finite or non-positive gain or gamma")
            return ChannelModel("gog", gog=(numbers[0], numbers[1], numbers[2], numbers[3]))
        if kind == "spline":
            s = fit["spline"]
            codes = tuple(float(c) for c in s["codes"])
            values = tuple(float(v) for v in s["luminance_cd_m2"])
            if len(codes) != len(values) or len(codes) < 2 or not np.all(np.diff(codes) > 0) \
                    or not all(math.isfinite(v) for v in values):
                raise ValueError("spline knots must be two or more increasing codes with finite luminances")
            return ChannelModel("spline", knots_code=codes, knots_cd_m2=values)
    except (KeyError, TypeError, ValueError) as error:
        raise ValueError(f"fit.{channel} ({kind}) is not a model psyop can read: {error}") from None
    raise ValueError(f"fit.{channel}.model is {kind!r}; expected gog or spline")


@dataclass(frozen=True)
class DisplayTransfer:
    """The display's grey transfer: ``luminance_cd_m2(code)`` and its inverse, from a calibration file's record.

    ``peak_cd_m2`` (code 255) normalises: the renderer's values are ``L / peak_cd_m2`` (normalised luminance).
    ``key`` names the calibration (its path and SHA-256) for caches and records."""

    grey: ChannelModel
    key: str = "calibration"
    black_cd_m2: float = field(init=False)
    peak_cd_m2: float = field(init=False)

    def __post_init__(self) -> None:
        codes = np.linspace(0.0, MAX_CODE, INVERSE_SAMPLES)
        values = self.grey(codes)
        if not np.all(np.isfinite(values)) or not np.all(np.diff(values) > 0) or values[0] < 0:
            raise ValueError("the grey channel's model does not rise with the code everywhere in 0..255 (or gives a "
                             "negative luminance); rerun psyop calibrate")
        object.__setattr__(self, "black_cd_m2", float(values[0]))
        object.__setattr__(self, "peak_cd_m2", float(values[-1]))

    @classmethod
    def from_record(cls, record: JsonMapping, key: str = "calibration") -> DisplayTransfer:
        """From a complete calibration file's JSON object (ValueError naming the problem)."""
        fit = record.get("fit")
        if not isinstance(fit, dict) or "grey" not in fit:
            raise ValueError("the file has no fit for the grey channel (fit.grey); rerun psyop calibrate")
        return cls(channel_model(fit["grey"], "grey"), key=key)

    def luminance_cd_m2(self, code: ArrayLike) -> np.ndarray:
        """The grey luminance (cd/m²) at 8-bit code(s), fractional codes allowed."""
        return self.grey(code)

    def normalised(self, cd_m2: ArrayLike) -> np.ndarray:
        """A luminance as the renderer's value: ``L / peak``."""
        return np.asarray(cd_m2, dtype=np.float64) / self.peak_cd_m2

    def code_for(self, cd_m2: ArrayLike) -> np.ndarray:
        """The fractional code whose luminance is ``cd_m2`` (clamped to 0..255 outside the range)."""
        codes = np.linspace(0.0, MAX_CODE, INVERSE_SAMPLES)
        return np.interp(np.asarray(cd_m2, dtype=np.float64), self.grey(codes), codes)

    def forward_table(self, size: int = INVERSE_SAMPLES) -> np.ndarray:
        """(size,) normalised luminance at the codes ``255 k / (size - 1)`` (the renderer's table, which its final
        pass inverts; the default samples every 1/64 of a code, so every whole code is an entry)."""
        return np.asarray(self.normalised(self.grey(np.linspace(0.0, MAX_CODE, size))))
