"""Cluster-robust inference that holds with few clusters: CR2 standard errors with Satterthwaite
degrees of freedom (one coefficient) and the HTZ Wald test (several), for OLS.

Cluster-robust ("sandwich") standard errors with participant clusters are biased downwards and
their z / chi2 tests reject far too often when the clusters are few (3 participants gave
``chi2(2) = 148.76, p < 0.0001`` on null data). The established remedy is the bias-reduced
linearisation (CR2, Bell & McCaffrey 2002) with small-sample degrees of freedom: Satterthwaite for a
single contrast, and the Hotelling T^2 approximation "HTZ" for a joint test (Tipton 2015;
Pustejovsky & Tipton 2018, J. Bus. Econ. Stat. 36:672). This module computes them as R's
``clubSandwich`` does for ``lm`` (``vcovCR(type = "CR2")``, ``coef_test(test = "Satterthwaite")``,
``Wald_test(test = "HTZ")``) with the working model Phi = I: checked against clubSandwich's own output
(tests/fixtures/r/clubsandwich_golden.R, tests/statistics/test_statistics_small_sample.py).

Notation: X (N x p), M = (X'X)^-1, residual maker I - H with H = X M X'. For cluster j with rows
X_j, A_j = (I - X_j M X_j')^(-1/2) (symmetric), and for a contrast c the N-vector
g_j = (I - H)[j, :]' A_j X_j M c, so that c' V^CR2 c = sum_j (g_j' y)^2. Under Phi = I its moments
are E = sum_j g_j'g_j and Var = 2 sum_jk (g_j'g_k)^2, giving df = 2 E^2 / Var.

Tipton (2015) and clubSandwich's documentation: tests whose small-sample df fall below 4 may not
hold their level even with CR2; :data:`MIN_RELIABLE_DF` flags them (psyop flags every test with
fewer error df the same way).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

#: Below this many denominator (error) degrees of freedom a t or F approximation is flagged as
#: unreliable (Tipton 2015, "Small sample adjustments for robust variance estimation with
#: meta-regression", Psychol. Methods 20:375: Satterthwaite df < 4 do not keep the nominal level).
MIN_RELIABLE_DF = 4.0
#: the smallest eigenvalue of C V C' relative to its largest below which the contrasts' covariance is taken as
#: singular and the test refused. A covariance that is singular in exact arithmetic (2 clusters of the same design
#: and 2 contrasts: the CR2 scores sum to zero) comes out of floating point with a smallest eigenvalue of a few
#: 1e-16 of the largest, positive or negative by the last bits of the CPU's kernels; 1e-9 sits six orders of
#: magnitude above that noise, so the same data are refused on every machine (tests/statistics/test_small_sample.py)
SINGULAR_RATIO = 1e-9


@dataclass(frozen=True)
class ClusterRobustTest:
    """One CR2 test: a single contrast (``df_num`` 1, ``t`` set) or a joint HTZ test (``F`` set).

    ``df_denom`` is the Satterthwaite df (one contrast) or HTZ's nu - q + 1 (joint); ``low_df`` says
    it is below :data:`MIN_RELIABLE_DF`; ``p`` is NaN when df_denom <= 0 (the test is undefined)."""

    estimate: tuple[float, ...]
    se: tuple[float, ...]
    statistic: float  # t (one contrast) or F (joint)
    df_num: int
    df_denom: float
    p: float
    n_clusters: int
    wald_q: float  # the Wald statistic Q = (Cb)' (C V C')^-1 (Cb) before the HTZ scaling
    low_df: bool


def _inv_sqrt_psd(a: np.ndarray) -> np.ndarray:
    """Symmetric inverse square root of a symmetric positive semi-definite matrix (generalised: zero
    eigenvalues stay zero, as clubSandwich's ``matrix_power`` for CR2's ``I - H_jj``)."""
    w, v = np.linalg.eigh((a + a.T) / 2.0)
    tol = max(a.shape) * np.finfo(float).eps * max(float(np.abs(w).max(initial=0.0)), 1.0)
    inv = np.where(w > tol, 1.0 / np.sqrt(np.clip(w, tol, None)), 0.0)
    return (v * inv) @ v.T


def _g_vectors(x: np.ndarray, clusters: np.ndarray, contrasts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(G, M): G[s, j] is the N-vector g_{sj} for contrast row s and cluster j (shape q x J x N)."""
    n, _ = x.shape
    m = np.linalg.inv(x.T @ x)
    residual_maker = np.eye(n) - x @ m @ x.T
    labels = np.unique(clusters)
    mc = m @ contrasts.T  # p x q
    g = np.zeros((contrasts.shape[0], len(labels), n))
    for j, label in enumerate(labels):
        rows = np.flatnonzero(clusters == label)
        xj = x[rows]
        a_j = _inv_sqrt_psd(np.eye(len(rows)) - xj @ m @ xj.T)
        # g_j = (I - H)[rows, :]' A_j X_j M c  for every contrast at once: N x q
        g[:, j, :] = (residual_maker[rows].T @ (a_j @ (xj @ mc))).T
    return g, m


def cr2_vcov(x: np.ndarray, y: np.ndarray, clusters: np.ndarray) -> np.ndarray:
    """CR2 cluster-robust covariance of the OLS coefficients (clubSandwich ``vcovCR(fit, cluster, "CR2")``)."""
    x = np.asarray(x, float)
    g, _ = _g_vectors(x, np.asarray(clusters), np.eye(x.shape[1]))
    scores = g @ np.asarray(y, float)  # p x J: c_s' M X_j' A_j e_j
    return scores @ scores.T


def cr2_test(x: np.ndarray, y: np.ndarray, clusters: np.ndarray, contrasts: np.ndarray) -> ClusterRobustTest:
    """Test C b = 0 with CR2 errors: a Satterthwaite t for one row of ``contrasts``, HTZ F for several.

    Parameters
    ----------
    x, y : the OLS design (N x p, full column rank) and response (N).
    clusters : N labels; at least 2 distinct.
    contrasts : q x p constraint matrix C.

    Raises
    ------
    ValueError : fewer than 2 clusters, a rank-deficient design, or C V C' singular (its smallest eigenvalue
        not above :data:`SINGULAR_RATIO` of its largest: a contrast no cluster informs): the test cannot be computed.
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    clusters = np.asarray(clusters)
    c = np.atleast_2d(np.asarray(contrasts, float))
    n_clusters = len(np.unique(clusters))
    if n_clusters < 2:
        raise ValueError(f"cluster-robust errors need at least 2 clusters, have {n_clusters}")
    if np.linalg.matrix_rank(x) < x.shape[1]:
        raise ValueError("the design matrix is rank deficient")
    q = c.shape[0]
    g, m = _g_vectors(x, clusters, c)
    beta = m @ x.T @ y
    cb = c @ beta
    scores = g @ y  # q x J
    v = scores @ scores.T  # C V^CR2 C'
    eigenvalues = np.linalg.eigvalsh(v)
    if not eigenvalues[0] > SINGULAR_RATIO * max(float(eigenvalues[-1]), 0.0):
        raise ValueError(f"the CR2 covariance of the contrasts is singular (smallest eigenvalue {eigenvalues[0]:.3g} "
                         f"of largest {eigenvalues[-1]:.3g}, ratio below {SINGULAR_RATIO:g}: with {n_clusters} "
                         f"clusters the {q} contrast(s) are not all informed); the test cannot be computed")
    chol = np.linalg.cholesky(v)
    z = np.linalg.solve(chol, cb)
    wald_q = float(z @ z)
    # P[s, t, j, k] = g_sj' g_tk ; Omega = sum_j P[:, :, j, j]
    p_arr = np.einsum("sjn,tkn->stjk", g, g)
    omega = np.einsum("stjj->st", p_arr)
    w, vecs = np.linalg.eigh(omega)
    omega_nsqrt = (vecs / np.sqrt(w)) @ vecs.T
    b = np.einsum("as,stjk,tb->abjk", omega_nsqrt, p_arr, omega_nsqrt)
    var_mat = np.empty((q, q))
    for s in range(q):
        for t in range(q):
            var_mat[s, t] = float(np.sum(b[s, t] * b[t, s]) + np.sum(b[s, s] * b[t, t]))
    nu = q * (q + 1) / float(var_mat.sum())
    df_denom = nu - q + 1
    se = tuple(float(s) for s in np.sqrt(np.diag(v)))
    if q == 1:
        statistic = float(cb[0] / se[0])
        p = float(2 * stats.t.sf(abs(statistic), df_denom)) if df_denom > 0 else float("nan")
    else:
        statistic = max((nu - q + 1) / nu, 0.0) * wald_q / q
        p = float(stats.f.sf(statistic, q, df_denom)) if df_denom > 0 else float("nan")
    return ClusterRobustTest(estimate=tuple(float(e) for e in cb), se=se, statistic=float(statistic), df_num=q,
                             df_denom=float(df_denom), p=p, n_clusters=n_clusters, wald_q=wald_q,
                             low_df=bool(not df_denom >= MIN_RELIABLE_DF))


def low_df_note(df: float, what: str = "error") -> str:
    """'' when ``df`` is enough, else the flag text naming the df and the threshold."""
    if df >= MIN_RELIABLE_DF:
        return ""
    return (f"LOW DF: {df:.3g} {what} df < {MIN_RELIABLE_DF:g}, the approximation behind this p-value is "
            "unreliable (Tipton 2015); treat it as descriptive")


__all__ = ["MIN_RELIABLE_DF", "SINGULAR_RATIO", "ClusterRobustTest", "cr2_vcov", "cr2_test", "low_df_note"]
