"""QUEST+ (Watson 2017, J. Vision 17(3):10) for a 2AFC cumulative normal on the level's own axis.

p(correct | x) = guess + (1 - guess - lapse) * Phi((x - threshold) / width), the observer model
psyop's simulated observers and psignifit's 2AFC fit use (``threshold`` is the 75 % point without
lapse). The posterior lives on a threshold x width x lapse grid; the next level is the point of
the stimulus grid that minimises the expected posterior entropy after the next response.

Vectorised numpy rather than the ``questplus`` package: that package's next stimulus plus one
update took 18x longer at the median than this module's whole per-trial step for the default grids
(xarray over the full stimulus x parameter x outcome array; benchmarks/bench_adaptive.py, figures
in docs/adaptive.md), and rebuilding its state from a history replays one update per trial. This
module gives the same next stimulus and posterior (tests/adaptive/test_quest_plus_vs_package.py).

The expected entropy uses, for each stimulus s and outcome o with likelihood L = L(o|s, theta) and
posterior p(theta), pk = sum_theta L p and
    sum_o pk * H(posterior after o) = -sum_o [ L @ (p log p) + (L log L) @ p - pk log pk ],
so one step is three (2S x P) matrix-vector products; nothing of size S x O x P is formed per trial.
The state after a history is rebuilt from scratch each time (log prior + sum of log likelihoods,
counted per grid level), so there is no state to lose.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Sequence

import numpy as np
from scipy.special import ndtr, xlogy
from threadpoolctl import ThreadpoolController

from psyop.adaptive.history import Observation
from psyop.adaptive.state import ProcedureState
from psyop.adaptive.stopping import StopRule

_ON_GRID_TOL = 1e-9
_TINY = 1e-300


def _grid(values: Sequence[float], name: str, positive: bool = False) -> tuple[float, ...]:
    array = np.asarray(values, dtype=float)
    if array.ndim != 1 or array.size == 0 or not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: need a non-empty list of finite numbers")
    if array.size > 1 and not np.all(np.diff(array) > 0):
        raise ValueError(f"{name}: values must be strictly increasing")
    if positive and not np.all(array > 0):
        raise ValueError(f"{name}: values must be > 0")
    return tuple(float(v) for v in array)


def exact_linspace(low: float, high: float, count: int) -> tuple[float, ...]:
    """``count`` levels from ``low`` to ``high`` in equal steps, each the float nearest the exact decimal
    value ``low + k (high - low) / (count - 1)`` (0.3, not ``np.linspace``'s 0.30000000000000004).

    Examples
    --------
    >>> exact_linspace(0.0, 1.5, 76)[15]
    0.3
    """
    if count < 2:
        raise ValueError(f"need at least two grid points, got {count}")
    a, b = Fraction(repr(float(low))), Fraction(repr(float(high)))
    return tuple(float(a + (b - a) * k / (count - 1)) for k in range(count))


@dataclass(frozen=True)
class QuestPlusSpec:
    """Grids of a QUEST+ run (uniform prior over the parameter grid).

    Use :meth:`default` for the grids psyop uses when a protocol gives only the level range."""

    stimulus: tuple[float, ...]
    threshold: tuple[float, ...]
    width: tuple[float, ...]
    lapse: tuple[float, ...] = (0.0, 0.01, 0.02, 0.04)
    guess: float = 0.5
    stop: StopRule = field(default_factory=lambda: StopRule(max_trials=64))
    first_level: float | None = None  # the first trial's level (None: QUEST+'s own choice)

    def __post_init__(self) -> None:
        object.__setattr__(self, "stimulus", _grid(self.stimulus, "stimulus grid"))
        object.__setattr__(self, "threshold", _grid(self.threshold, "threshold grid"))
        object.__setattr__(self, "width", _grid(self.width, "width grid", positive=True))
        object.__setattr__(self, "lapse", _grid(self.lapse, "lapse grid"))
        if not 0 <= self.guess < 1:
            raise ValueError(f"guess rate must be in [0, 1), got {self.guess}")
        if not all(0 <= l < 1 - self.guess for l in self.lapse):
            raise ValueError(f"lapse grid values must be in [0, {1 - self.guess})")
        first_level = self.first_level
        if first_level is not None:
            # the protocol's start, a declared level too: the grid point it stands for, else its exact decimal
            nearest = min(self.stimulus, key=lambda v: abs(v - float(first_level)))
            first = nearest if abs(nearest - float(first_level)) <= _ON_GRID_TOL else \
                float(Fraction(repr(float(first_level))))
            object.__setattr__(self, "first_level", first)

    @classmethod
    def default(cls, min_level: float, max_level: float, stop: StopRule | None = None,
                stimulus_count: int = 101, threshold_count: int = 101,
                width: Sequence[float] | None = None, first_level: float | None = None) -> "QuestPlusSpec":
        """Stimulus and threshold grids of 101 points over [min, max]; widths 13 log-spaced
        values from 2.5 % to 40 % of the range; lapse 0, 1, 2, 4 %. For a 0-2 D range that is
        0.02 D steps and widths 0.05-0.8 D (P = 101 x 13 x 4 = 5252 parameter points)."""
        if not max_level > min_level:
            raise ValueError(f"need max > min, got min {min_level}, max {max_level}")
        span = max_level - min_level
        widths = np.geomspace(0.025 * span, 0.4 * span, 13) if width is None else width
        return cls(stimulus=exact_linspace(min_level, max_level, stimulus_count),
                   threshold=exact_linspace(min_level, max_level, threshold_count),
                   width=tuple(widths), stop=stop or StopRule(max_trials=64), first_level=first_level)

    def on_grid(self, level: float) -> bool:
        """True when ``level`` is (as a float, exactly) one of the declared levels: the stimulus grid, or the
        first level (the protocol's ``start``, which need not be a grid point)."""
        return float(level) in set(self.stimulus) or (self.first_level is not None and float(level) == self.first_level)


class QuestPlus:
    """QUEST+ over a :class:`QuestPlusSpec`. Holds only arrays derived from the spec; every
    answer is a function of the history passed in."""

    name = "quest_plus"

    def __init__(self, spec: QuestPlusSpec) -> None:
        self.spec = spec
        t, w, l = np.meshgrid(spec.threshold, spec.width, spec.lapse, indexing="ij")
        self._t, self._w, self._l = t.ravel(), w.ravel(), l.ravel()
        self._stim = np.asarray(spec.stimulus)
        p_correct = self._p_correct(self._stim[:, None])              # (S, P)
        self._L = np.concatenate([p_correct, 1.0 - p_correct])        # (2S, P): correct rows, then incorrect
        # log 0 (a response impossible under a zero-lapse parameter point) becomes a finite floor so
        # that a zero count times it stays 0; exp of it is 0 in float64, as in an exact product.
        self._logL = np.log(np.maximum(self._L, _TINY))
        self._LlogL_rows = xlogy(self._L, self._L)                    # (2S, P)
        self._log_prior = np.full(self._t.size, -math.log(self._t.size))
        self.parameter_shape = t.shape
        # One BLAS thread for the per-trial step: the matrices are small (2S x P), and a
        # multi-threaded BLAS on a busy 2-core machine turned a 1 ms step into 60-95 ms at p99.
        self._blas = ThreadpoolController()

    def _p_correct(self, x: np.ndarray) -> np.ndarray:
        g = self.spec.guess
        return g + (1.0 - g - self._l) * ndtr((x - self._t) / self._w)

    def log_posterior(self, history: Sequence[Observation]) -> np.ndarray:
        """Unnormalised log posterior over the flattened (threshold, width, lapse) grid."""
        S = self._stim.size
        counts = np.zeros(2 * S)
        off_grid: list[Observation] = []
        if history:
            levels = np.fromiter((o.level for o in history), float, len(history))
            wrong = np.fromiter((not o.correct for o in history), bool, len(history))
            index = np.clip(np.searchsorted(self._stim, levels), 0, S - 1)
            below = np.clip(index - 1, 0, S - 1)
            closer = np.where(np.abs(self._stim[below] - levels) < np.abs(self._stim[index] - levels), below, index)
            on_grid = np.abs(self._stim[closer] - levels) <= _ON_GRID_TOL
            np.add.at(counts, closer[on_grid] + S * wrong[on_grid], 1.0)
            off_grid = [o for o, ok in zip(history, on_grid) if not ok]
        rows = np.flatnonzero(counts)
        log_post = self._log_prior + counts[rows] @ self._logL[rows]
        for obs in off_grid:
            p = self._p_correct(np.asarray(obs.level))
            log_post = log_post + np.log(np.maximum(p if obs.correct else 1.0 - p, _TINY))
        return log_post

    def posterior(self, history: Sequence[Observation]) -> np.ndarray:
        """Normalised posterior, shape (threshold, width, lapse)."""
        log_post = self.log_posterior(history)
        post = np.exp(log_post - log_post.max())
        return (post / post.sum()).reshape(self.parameter_shape)

    def expected_entropy(self, posterior: np.ndarray) -> np.ndarray:
        """Expected posterior entropy (nats) after a trial at each stimulus grid point, (S,)."""
        p = posterior.ravel()
        pk = self._L @ p                                              # (2S,)
        total = self._L @ xlogy(p, p) + self._LlogL_rows @ p - xlogy(pk, pk)
        S = self._stim.size
        return -(total[:S] + total[S:])

    def expected_entropy_batch(self, posteriors: np.ndarray) -> np.ndarray:
        """:meth:`expected_entropy` for many posteriors at once: (n, P) -> (n, S) (simulation sweeps)."""
        p = posteriors.reshape(posteriors.shape[0], -1).T               # (P, n)
        pk = self._L @ p                                              # (2S, n)
        total = self._L @ xlogy(p, p) + self._LlogL_rows @ p - xlogy(pk, pk)
        S = self._stim.size
        return -(total[:S] + total[S:]).T

    def log_likelihood(self, stimulus_index: np.ndarray, correct: np.ndarray) -> np.ndarray:
        """log p(response | stimulus grid point, theta) for each (index, correct) pair: (n, P)."""
        rows = np.asarray(stimulus_index) + self._stim.size * (~np.asarray(correct, dtype=bool))
        return self._logL[rows]

    @property
    def log_prior(self) -> np.ndarray:
        return self._log_prior.copy()

    def state(self, history: Sequence[Observation]) -> ProcedureState:
        with self._blas.limit(limits=1, user_api="blas"):
            return self._state(history)

    def threshold_estimate(self, history: Sequence[Observation]) -> tuple[float, float]:
        """Posterior mean and SD of the threshold after ``history`` (no next-level search)."""
        with self._blas.limit(limits=1, user_api="blas"):
            return self._threshold_moments(self.posterior(history))

    def _threshold_moments(self, post: np.ndarray) -> tuple[float, float]:
        marginal = post.sum(axis=(1, 2))
        thresholds = np.asarray(self.spec.threshold)
        mean = float(marginal @ thresholds)
        return mean, float(math.sqrt(max(float(marginal @ (thresholds - mean) ** 2), 0.0)))

    def _state(self, history: Sequence[Observation]) -> ProcedureState:
        post = self.posterior(history)
        mean, sd = self._threshold_moments(post)
        if not history and self.spec.first_level is not None:
            next_level = float(self.spec.first_level)
        else:
            next_level = float(self._stim[int(np.argmin(self.expected_entropy(post)))])
        reason = self.spec.stop.reason(len(history), sd)
        return ProcedureState(procedure=self.name, trials=len(history), next_level=next_level,
                              finished=bool(reason), stop_reason=reason, estimate_mean=mean, estimate_sd=sd)

    def parameter_means(self, history: Sequence[Observation]) -> dict[str, float]:
        """Posterior means of threshold, width and lapse."""
        post = self.posterior(history)
        return {"threshold": float(post.sum(axis=(1, 2)) @ np.asarray(self.spec.threshold)),
                "width": float(post.sum(axis=(0, 2)) @ np.asarray(self.spec.width)),
                "lapse": float(post.sum(axis=(0, 1)) @ np.asarray(self.spec.lapse))}
