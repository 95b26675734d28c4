"""Censored thresholds in the group analysis: a Tobit (censored-normal) likelihood, not the drop rule.

A threshold fit whose status is ``censored_below`` says only "the threshold is below the lowest
tested level"; ``censored_above`` and ``lapse_at_bound`` say "above the highest". Leaving such fits
out biases a group mean (dropping the best observers raises it). Here they enter the likelihood as
what they are: an observed threshold contributes the normal density, a censored one the normal
probability of lying beyond its bound (Tobin 1958; the model of R's ``AER::tobit`` /
``survival::survreg(dist="gaussian")``).

- :func:`censoring_of`: the per-fit value, bound and side (-1 below, 0 observed, +1 above) from a fit
  table; statuses that are neither usable nor censored (bimodal, grid edge, no fit) stay left out.
- :func:`tobit_fit`: maximum-likelihood y = X beta + e, e ~ N(0, sigma^2), with left/right censoring;
  standard errors from the observed information, intervals from t with n - k df.
- :func:`tobit_mean`: the one-column case (a group mean).

Fits of one participant are not independent (one observer's thresholds at several conditions). Given
``clusters`` (the participant of each fit, as :func:`censored_report` passes them), the standard errors
are participant-clustered: the sandwich of the observed information and the per-participant score sums
(R's ``survreg(..., cluster = participant)`` robust variance), times G / (G - 1) for G participants,
with t intervals on G - 1 df (the convention of Stata's clustered errors), flagged ``LOW DF`` below
:data:`psyop.statistics.small_sample.MIN_RELIABLE_DF`. Without clusters (one fit per participant, or
the caller's choice) fits are independent observations with t on n - k df; the ``model`` text says
which.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import optimize, stats

from psyop.statistics.psychometric import USABLE_STATUSES

#: statuses whose threshold lies below the lowest tested level / above the highest
CENSORED_BELOW = ("censored_below",)
CENSORED_ABOVE = ("censored_above", "lapse_at_bound")


@dataclass(frozen=True)
class TobitFit:
    """Censored-normal regression. ``coef``/``se``/``ci_*`` follow the columns of the design."""

    names: tuple[str, ...]
    coef: tuple[float, ...]
    se: tuple[float, ...]
    ci_low: tuple[float, ...]
    ci_high: tuple[float, ...]
    sigma: float
    n: int
    n_below: int
    n_above: int
    df_resid: int
    converged: bool
    model: str
    #: the maximised log-likelihood (normal densities of observed values, probabilities of censored ones)
    loglik: float = float("nan")
    #: participants (clusters) behind a participant-clustered sandwich; 0: fits treated as independent
    n_clusters: int = 0
    #: the df of the t intervals: n - k (independent fits) or G - 1 (participant-clustered)
    df_interval: int = 0
    #: the sandwich before the G / (G - 1) factor (R's survreg robust variance), SEs of every coefficient
    se_sandwich: tuple[float, ...] = ()

    @property
    def low_df(self) -> bool:
        """The intervals' df are below :data:`~psyop.statistics.small_sample.MIN_RELIABLE_DF`."""
        from psyop.statistics.small_sample import MIN_RELIABLE_DF

        return not self.df_interval >= MIN_RELIABLE_DF

    def get(self, name: str) -> tuple[float, float, float]:
        """(estimate, CI low, CI high) of one coefficient."""
        i = self.names.index(name)
        return self.coef[i], self.ci_low[i], self.ci_high[i]


def censoring_of(fits: pd.DataFrame, value: str = "threshold_D",
                 bound: str = "threshold_bound_D") -> tuple[pd.DataFrame, dict[str, int]]:
    """Rows that enter a censored-data model, with ``y`` (value or bound) and ``side`` (-1/0/+1).

    Returns the rows (usable and censored) and ``{status: count}`` of the rows still left out
    (ambiguous fits: bimodal, grid edge, no fit), so a caller can say what happened to each.
    """
    status = fits["status"].astype(str)
    side = np.where(status.isin(CENSORED_BELOW), -1, np.where(status.isin(CENSORED_ABOVE), 1, 0))
    enters = status.isin(USABLE_STATUSES) | (side != 0)
    out = fits[enters].copy()
    out["side"] = side[enters.to_numpy()]
    y = pd.to_numeric(out[value], errors="coerce")
    if bound in out:
        y = y.where(out["side"] == 0, pd.to_numeric(out[bound], errors="coerce"))
    out["y"] = y.astype(float)
    out = out[np.isfinite(out["y"])]
    left = status[~enters].value_counts().sort_index()
    return out, {str(k): int(v) for k, v in left.items()}


def _negloglik(params: np.ndarray, y: np.ndarray, X: np.ndarray, side: np.ndarray) -> float:
    beta, log_sigma = params[:-1], params[-1]
    sigma = np.exp(log_sigma)
    z = (y - X @ beta) / sigma
    ll = np.where(side == 0, stats.norm.logpdf(z) - log_sigma,
                  np.where(side < 0, stats.norm.logcdf(z), stats.norm.logsf(z)))
    return float(-ll.sum())


def _negloglik_derivatives(params: np.ndarray, y: np.ndarray, X: np.ndarray,
                           side: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Analytic gradient and Hessian of :func:`_negloglik` in (beta, log sigma).

    Each row's log-likelihood is g(z) (minus log sigma when observed), z = (y - x beta) / sigma:
    g = -z^2/2 (observed), log Phi(z) (below), log Phi(-z) (above); with dz/dbeta = -x/sigma,
    dz/dlog sigma = -z, d2z/dbeta dlog sigma = x/sigma, d2z/dlog sigma^2 = z."""
    beta, sigma = params[:-1], float(np.exp(params[-1]))
    z = (y - X @ beta) / sigma
    below = np.exp(stats.norm.logpdf(z) - stats.norm.logcdf(z))  # phi / Phi
    above = np.exp(stats.norm.logpdf(z) - stats.norm.logsf(z))   # phi / (1 - Phi)
    g1 = np.where(side == 0, -z, np.where(side < 0, below, -above))
    g2 = np.where(side == 0, -1.0, np.where(side < 0, -below * (z + below), -above * (above - z)))
    dz = np.column_stack([-X / sigma, -z])
    grad = dz.T @ g1 + np.r_[np.zeros(X.shape[1]), -float((side == 0).sum())]
    hess = (dz * g2[:, None]).T @ dz
    hess[:-1, -1] += X.T @ g1 / sigma
    hess[-1, :-1] = hess[:-1, -1]
    hess[-1, -1] += float(g1 @ z)
    return -grad, -hess


def _newton_polish(x: np.ndarray, y: np.ndarray, X: np.ndarray, side: np.ndarray,
                   steps: int = 20) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Newton steps from BFGS's optimum with the analytic derivatives, while the gradient shrinks:
    near the maximum the log-likelihood no longer changes in double precision (so BFGS stops about
    1e-8 short), its gradient still does. Returns (parameters, gradient, Hessian) at the end."""
    grad, hess = _negloglik_derivatives(x, y, X, side)
    for _ in range(steps):
        if np.max(np.abs(grad)) < 1e-13:
            break
        try:
            trial = x - np.linalg.solve(hess, grad)
        except np.linalg.LinAlgError:
            break
        grad_t, hess_t = _negloglik_derivatives(trial, y, X, side)
        if not np.max(np.abs(grad_t)) < np.max(np.abs(grad)):
            break
        x, grad, hess = trial, grad_t, hess_t
    return x, grad, hess


def _row_scores(params: np.ndarray, y: np.ndarray, X: np.ndarray, side: np.ndarray) -> np.ndarray:
    """(n, k + 1) per-row gradients of the log-likelihood in (beta, log sigma); their column sums are
    minus :func:`_negloglik_derivatives`' gradient."""
    sigma = float(np.exp(params[-1]))
    z = (y - X @ params[:-1]) / sigma
    below = np.exp(stats.norm.logpdf(z) - stats.norm.logcdf(z))
    above = np.exp(stats.norm.logpdf(z) - stats.norm.logsf(z))
    g1 = np.where(side == 0, -z, np.where(side < 0, below, -above))
    scores = np.column_stack([-X / sigma, -z]) * g1[:, None]
    scores[:, -1] -= (side == 0).astype(float)
    return scores


def cluster_sandwich(params: np.ndarray, hess: np.ndarray, y: np.ndarray, X: np.ndarray, side: np.ndarray,
                     clusters: np.ndarray) -> np.ndarray:
    """H^-1 (sum_g u_g u_g') H^-1 over (beta, log sigma), u_g the score sum of cluster g: R's
    ``survreg(..., cluster = g)`` robust variance (no small-sample factor)."""
    bread = np.linalg.pinv(hess)
    scores = _row_scores(params, y, X, side)
    sums = pd.DataFrame(scores).groupby(np.asarray(clusters), sort=True).sum().to_numpy()
    return bread @ (sums.T @ sums) @ bread


def tobit_fit(y: np.ndarray, X: np.ndarray, side: np.ndarray, names: tuple[str, ...],
              ci_level: float = 0.95, clusters: np.ndarray | None = None) -> TobitFit:
    """Maximum-likelihood censored-normal regression.

    Parameters
    ----------
    y : observed value, or the bound for a censored row
    X : (n, k) design matrix
    side : -1 (true value < y), 0 (observed), +1 (true value > y)
    names : the k column names
    clusters : the participant of each row: participant-clustered SEs, t on G - 1 df (module docstring)
    """
    y, X, side = np.asarray(y, float), np.asarray(X, float), np.asarray(side, int)
    n, k = X.shape
    if int((side == 0).sum()) < k + 1:
        raise ValueError(f"a censored-data model needs at least {k + 1} uncensored values, have "
                         f"{int((side == 0).sum())} of {n}")
    beta0 = np.linalg.lstsq(X, y, rcond=None)[0]
    start = np.r_[beta0, np.log(max(float(np.std(y - X @ beta0)), 1e-6))]
    res = optimize.minimize(_negloglik, start, args=(y, X, side), method="BFGS",
                            jac=lambda p, *a: _negloglik_derivatives(p, *a)[0], options={"gtol": 1e-9})
    x, grad, hess = _newton_polish(res.x, y, X, side)
    se, df, n_clusters, se_sandwich = _tobit_se(x, hess, y, X, side, clusters)
    half = stats.t.ppf(0.5 + ci_level / 2, df) * se
    coef = x[:k]
    n_below, n_above = int((side < 0).sum()), int((side > 0).sum())
    return TobitFit(
        names=tuple(names), coef=tuple(map(float, coef)), se=tuple(map(float, se)),
        ci_low=tuple(map(float, coef - half)), ci_high=tuple(map(float, coef + half)),
        sigma=float(np.exp(x[-1])), n=n, n_below=n_below, n_above=n_above, df_resid=n - k,
        converged=bool(np.max(np.abs(grad)) < 1e-6), loglik=-_negloglik(x, y, X, side),
        n_clusters=n_clusters, df_interval=df, se_sandwich=se_sandwich,
        model=(f"censored-normal (Tobit) ML over {n} fits, {n_below} censored below and {n_above} above "
               "the tested levels entered at their bounds as censored; "
               + (f"participant-clustered SEs ({n_clusters} participants, t on {df} df)" if n_clusters
                  else "fits treated as independent")))


def _tobit_se(x: np.ndarray, hess: np.ndarray, y: np.ndarray, X: np.ndarray, side: np.ndarray,
              clusters: np.ndarray | None) -> tuple[np.ndarray, int, int, tuple[float, ...]]:
    """(SEs of beta, interval df, clusters, sandwich SEs of every parameter): the observed information
    with n - k df, or the participant-clustered sandwich times G / (G - 1) with G - 1 df."""
    n, k = X.shape
    if clusters is None:
        cov = np.linalg.pinv(hess)
        return np.sqrt(np.clip(np.diag(cov)[:k], 0, None)), max(n - k, 1), 0, ()
    g = int(pd.Series(np.asarray(clusters)).nunique())
    if g < 2:
        raise ValueError(f"participant-clustered errors need at least 2 participants, have {g}")
    sandwich = cluster_sandwich(x, hess, y, X, side, clusters)
    se_all = np.sqrt(np.clip(np.diag(sandwich), 0, None))
    return se_all[:k] * np.sqrt(g / (g - 1)), g - 1, g, tuple(map(float, se_all))


def tobit_mean(y: np.ndarray, side: np.ndarray, ci_level: float = 0.95,
               clusters: np.ndarray | None = None) -> TobitFit:
    """The group mean of values some of which are censored (the intercept-only Tobit model)."""
    y = np.asarray(y, float)
    return tobit_fit(y, np.ones((len(y), 1)), side, ("mean",), ci_level, clusters)


def substituted(rows: pd.DataFrame) -> pd.DataFrame:
    """The substitution rule: censored thresholds replaced by their bound (``threshold_D`` = ``y``)."""
    out = rows.copy()
    out["threshold_D"] = out["y"]
    return out


def format_tobit(fit: TobitFit, name: str, unit: str = "") -> str:
    """'0.41 D [95 % CI 0.33, 0.49]; censored-normal (Tobit) ML over ...'."""
    est, lo, hi = fit.get(name)
    u = f" {unit}" if unit else ""
    from psyop.statistics.small_sample import low_df_note

    warn = "" if fit.converged else "; NOT CONVERGED"
    note = low_df_note(float(fit.df_interval), "participant" if fit.n_clusters else "residual")
    warn += f" [{note.replace('p-value', 'interval')}]" if note else ""
    return f"{est:.3f}{u} [95 % CI {lo:.3f}, {hi:.3f}; df = {fit.df_interval}]; {fit.model}{warn}"


def censored_condition_means(rows: pd.DataFrame, cond: str, clusters: np.ndarray | None = None) -> TobitFit:
    """One Tobit mean per level of ``cond`` (cell-means design, a common sigma)."""
    levels = sorted(rows[cond].unique())
    X = np.column_stack([(rows[cond] == lv).to_numpy(float) for lv in levels])
    return tobit_fit(rows["y"].to_numpy(), X, rows["side"].to_numpy(), tuple(str(lv) for lv in levels),
                     clusters=clusters)


def censored_line(rows: pd.DataFrame, x: str, clusters: np.ndarray | None = None) -> TobitFit:
    """Tobit regression of the threshold on a numeric ``x`` (intercept, slope)."""
    xs = rows[x].to_numpy(float)
    X = np.column_stack([np.ones_like(xs), xs])
    return tobit_fit(rows["y"].to_numpy(), X, rows["side"].to_numpy(), ("intercept", "slope"), clusters=clusters)


def participant_clusters(rows: pd.DataFrame) -> np.ndarray | None:
    """The participant of each row when some participant has several fits (then they are not independent),
    else None (one fit each: independent)."""
    if "participant" not in rows or not rows["participant"].duplicated().any():
        return None
    return rows["participant"].astype(str).to_numpy()


def censored_report(fits: pd.DataFrame, cond: str, unit: str, numeric: bool = False) -> dict:
    """The censored-data analysis of a fit table, for a results JSON: how many fits were censored,
    what was done with them, and the Tobit estimates (or why none could be made)."""
    rows, left = censoring_of(fits)
    n_b, n_a = int((rows["side"] < 0).sum()), int((rows["side"] > 0).sum())
    out: dict = {"n_censored_below": n_b, "n_censored_above": n_a, "still_left_out_by_status": left,
                 "rule": ("censored thresholds enter a censored-normal (Tobit) likelihood at their bound "
                          "(the lowest / highest tested level); bimodal, grid-edge and no-fit fits stay out")}
    clusters = participant_clusters(rows)
    try:
        mean = tobit_mean(rows["y"].to_numpy(), rows["side"].to_numpy(), clusters=clusters)
        out["mean"] = {**mean.__dict__, "low_df": mean.low_df}
        out["text_mean"] = format_tobit(mean, "mean", unit)
        if numeric:
            line = censored_line(rows, cond, clusters)
            out["line"] = {**line.__dict__, "low_df": line.low_df}
            out["text_slope"] = format_tobit(line, "slope", "")
        else:
            out["condition_means"] = {**censored_condition_means(rows, cond, clusters).__dict__}
    except ValueError as exc:
        out["text_mean"] = f"not computed: {exc}"
    out["headline"] = (f"{n_b + n_a} of {len(fits)} fits censored ({n_b} below, {n_a} above the tested levels): "
                       f"entered as censored (Tobit) at their bounds, not dropped; "
                       f"{sum(left.values())} ambiguous fits left out: {left or 'none'}")
    return out


def fit_fates(fits: pd.DataFrame, cond: str) -> list[dict]:
    """Every fit with what each analysis did with it, so that no participant is dropped unseen.

    One record per fit: ``participant``, ``cond``'s value, ``status``, ``flags``, the threshold, its
    bound and CI; ``in_plain_analysis`` (a usable status: in the plain mean and rm-ANOVA) and
    ``in_censored_model``: ``observed``, ``censored_below`` / ``censored_above`` (entered at
    ``threshold_bound_D``) or ``left out (<status>)`` (ambiguous: bimodal, grid edge, no fit)."""
    status = fits["status"].astype(str)
    side = np.where(status.isin(CENSORED_BELOW), -1, np.where(status.isin(CENSORED_ABOVE), 1, 0))
    records = []
    for (_, row), s, sd in zip(fits.iterrows(), status, side):
        usable = s in USABLE_STATUSES
        bound = pd.to_numeric(pd.Series([row.get("threshold_bound_D")]), errors="coerce").iloc[0]
        fate = ("observed" if usable else f"left out ({s})" if sd == 0
                else "left out (censored, no bound recorded)" if not np.isfinite(bound)
                else "censored_below" if sd < 0 else "censored_above")
        records.append({"participant": str(row["participant"]), cond: row[cond], "status": s,
                        "flags": str(row.get("flags", "") or ""), "threshold_D": row.get("threshold_D"),
                        "threshold_bound_D": row.get("threshold_bound_D"),
                        "threshold_ci_D": [row.get("threshold_ci_low_D"), row.get("threshold_ci_high_D")],
                        "in_plain_analysis": bool(usable), "in_censored_model": fate})
    return records


__all__ = ["censored_condition_means", "fit_fates", "censored_line", "cluster_sandwich", "participant_clusters", "censored_report", "CENSORED_ABOVE", "CENSORED_BELOW", "TobitFit", "censoring_of", "format_tobit", "substituted",
           "tobit_fit", "tobit_mean"]
