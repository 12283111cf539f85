"""The paper's Proposition: the posterior of [s0, tau] from spacing and speed measurements.

Model (Kontar & Ahn, Sec. 2): spacing S = s0 + tau V + eps, eps ~ N(0, sigma^2), with the
random coefficients Gamma = [s0, tau] ~ N(mu_b, Sigma_b). After n measurements with rows
Z_j = [1, V_j] the posterior is N(mu*, Sigma*) with

    Sigma* = (Sigma_b^-1 + Z^T Z / sigma^2)^-1,    mu* = Sigma* (Z^T S / sigma^2 + Sigma_b^-1 mu_b).

The data enter only through Z^T Z (2x2) and Z^T S (2), i.e. five sums per vehicle
(:class:`WindowSums`: n, sum V, sum V^2, sum S, sum V S). :func:`posterior` computes them for
one vehicle's measurements; :class:`~timegap_env.monitoring.monitor.TimeGapMonitor` keeps them
for a sliding window of every vehicle of every env. Both turn them into the posterior with
:func:`posterior_moments`.

Numerics. The 2x2 posterior precision Lambda = P + D (P = Sigma_b^-1, D = Z^T Z / sigma^2)
is inverted through its adjugate, with the determinant assembled from three terms that are
each >= 0 in exact arithmetic,

    det(P + D) = det P + tr(adj(P) D) + det D,

so it can never cancel below det P > 0 (a naive L00 L11 - L01^2 can, when the speed hardly
varies within the window). The covariance is symmetric by construction, and the mean is
computed as a correction of the prior mean, mu* = mu_b + Sigma* Z^T (S - Z mu_b) / sigma^2.
"""

from __future__ import annotations

import math
from typing import Annotated, NamedTuple, cast

import numba
import numpy as np
from numpy.typing import ArrayLike

from timegap_env.compiled import follow_sources
from timegap_env.state import PerEnv

__all__ = ["Moments", "Prior", "WindowSums", "outside_probability", "posterior", "posterior_moments",
           "prior_precision"]


class WindowSums(NamedTuple):
    """The sufficient statistics Z^T Z and Z^T S of some measurements, scalars or arrays of one shape."""

    n: float | np.ndarray  # (forgetting-weighted) number of measurements [-]
    sum_v: float | np.ndarray  # sum of V [m/s]
    sum_vv: float | np.ndarray  # sum of V^2 [m^2/s^2]
    sum_s: float | np.ndarray  # sum of S [m]
    sum_vs: float | np.ndarray  # sum of V S [m^2/s]


class Prior(NamedTuple):
    """What the posterior needs besides the sums and the prior mean of tau (the setting)."""

    standstill_spacing: float  # prior mean of s0 [m]
    p00: float  # prior precision P = Sigma_b^-1 = [[p00, p01], [p01, p11]] [1/m^2]
    p01: float  # [1/(m s)]
    p11: float  # [1/s^2]
    noise_variance: float  # sigma^2 of the spacing model [m^2]

    @classmethod
    def from_cov(cls, standstill_spacing: float, Sigma_b: ArrayLike, noise_variance: float) -> Prior:
        """The prior of mean s0 ``standstill_spacing`` [m] and covariance ``Sigma_b`` (2, 2), noise ``noise_variance`` [m^2]."""
        precision = prior_precision(Sigma_b)
        return cls(float(standstill_spacing), precision[0, 0], precision[0, 1], precision[1, 1], float(noise_variance))


class Moments(NamedTuple):
    """Posterior of [s0, tau], five scalars or arrays of one shape (per vehicle, "followers", in a state)."""

    mean_s0: Annotated[np.ndarray, PerEnv(float, "followers")]  # [m]
    mean_tau: Annotated[np.ndarray, PerEnv(float, "followers")]  # [s]
    var_s0: Annotated[np.ndarray, PerEnv(float, "followers")]  # [m^2]
    cov_s0_tau: Annotated[np.ndarray, PerEnv(float, "followers")]  # [m s]
    var_tau: Annotated[np.ndarray, PerEnv(float, "followers")]  # [s^2]

    def mean(self) -> np.ndarray:
        """Mean of [s0, tau], shape (..., 2)."""
        return np.stack([self.mean_s0, self.mean_tau], axis=-1)

    def cov(self) -> np.ndarray:
        """Covariance of [s0, tau], shape (..., 2, 2), symmetric by construction."""
        row_s0 = np.stack([self.var_s0, self.cov_s0_tau], axis=-1)
        row_tau = np.stack([self.cov_s0_tau, self.var_tau], axis=-1)
        return np.stack([row_s0, row_tau], axis=-2)


def posterior(
    V: ArrayLike,
    S: ArrayLike,
    mu_b: ArrayLike,
    Sigma_b: ArrayLike,
    sigma2: float,
    weights: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The paper's Proposition for one vehicle: posterior mean (2,) and covariance (2, 2) of [s0, tau].

    V: speeds (n,) [m/s]; S: spacings (n,) [m]; mu_b: prior mean (2,) [m, s];
    Sigma_b: prior covariance (2, 2); sigma2: noise variance of the spacing [m^2].
    weights (n,), optional, >= 0: measurement j counts weights[j] times (its likelihood is
    raised to that power); this is what the monitor's forgetting factor does. n = 0 gives the prior.
    """
    V = _vector("V", V)
    S = _vector("S", S)
    if S.shape != V.shape:
        raise ValueError(f"S has shape {S.shape}: must match V's shape {V.shape}")
    w = np.ones_like(V) if weights is None else _vector("weights", weights)
    if w.shape != V.shape:
        raise ValueError(f"weights has shape {w.shape}: must match V's shape {V.shape}")
    if np.any(w < 0):
        raise ValueError(f"weights = {w}: must be >= 0")
    mu_b = np.asarray(mu_b, dtype=float)
    if mu_b.shape != (2,) or not np.all(np.isfinite(mu_b)):
        raise ValueError(f"mu_b = {mu_b!r}: must be 2 finite numbers [s0, tau]")
    if isinstance(sigma2, bool) or not isinstance(sigma2, (int, float, np.integer, np.floating)) or not (
        np.isfinite(sigma2) and sigma2 > 0
    ):
        raise ValueError(f"sigma2 = {sigma2!r}: must be a finite number > 0 [m^2]")
    prior = Prior.from_cov(mu_b[0], Sigma_b, sigma2)

    Z = np.column_stack([np.ones_like(V), V])
    with np.errstate(over="ignore", invalid="ignore"):  # checked just below
        ztz = Z.T @ (w[:, None] * Z)
        zts = Z.T @ (w * S)
    sums = WindowSums(ztz[0, 0], ztz[0, 1], ztz[1, 1], zts[0], zts[1])
    if not np.all(np.isfinite(cast(tuple[float, ...], sums))):  # five scalars here
        raise ValueError(
            f"V, S: Z^T Z or Z^T S overflows float64 (max |V| = {np.max(np.abs(V))}, max |S| = {np.max(np.abs(S))})"
        )
    moments = Moments(*posterior_moments(sums, mu_b[1], prior))
    return moments.mean(), moments.cov()


def _vector(name: str, value: ArrayLike) -> np.ndarray:
    """``value`` as a finite 1-D float array; ValueError naming ``name`` otherwise."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r}: must be numbers") from None
    if array.ndim != 1:
        raise ValueError(f"{name} has shape {array.shape}: must be 1-D (n,)")
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] = {array[bad[0]]}: every value must be finite ({bad.size} are not)")
    return array


def prior_precision(Sigma_b: ArrayLike) -> np.ndarray:
    """Sigma_b^-1 (2, 2) of a symmetric positive definite Sigma_b, through its Cholesky factor."""
    cov = np.asarray(Sigma_b, dtype=float)
    if cov.shape != (2, 2) or not np.all(np.isfinite(cov)):
        raise ValueError(f"Sigma_b = {Sigma_b!r}: must be a finite 2x2 matrix")
    if not np.isclose(cov[0, 1], cov[1, 0], rtol=1e-9, atol=0.0):
        raise ValueError(f"Sigma_b = {Sigma_b!r}: must be symmetric")
    try:
        cholesky = np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise ValueError(f"Sigma_b = {Sigma_b!r}: must be positive definite") from None
    inverse_factor = np.linalg.solve(cholesky, np.eye(2))  # L^-1, Sigma_b^-1 = L^-T L^-1
    precision = inverse_factor.T @ inverse_factor
    return 0.5 * (precision + precision.T)


@numba.njit(cache=True, error_model="numpy")
def posterior_moments(sums, prior_tau, prior):  # noqa: ANN001, ANN201
    """The posterior (:class:`Moments`) from :class:`WindowSums` ``sums``, the prior mean of tau
    ``prior_tau`` [s] and the rest of the :class:`Prior`; scalars or arrays of one shape.

    See the module docstring for the determinant that cannot cancel.
    """
    p00, p01, p11, sigma2 = prior.p00, prior.p01, prior.p11, prior.noise_variance
    n, sum_v, sum_vv, sum_s, sum_vs = sums
    m0, m1 = prior.standstill_spacing, prior_tau
    d00, d01, d11 = n / sigma2, sum_v / sigma2, sum_vv / sigma2  # D = Z^T Z / sigma^2
    det = (
        (p00 * p11 - p01 * p01)  # det P
        + np.maximum(p11 * d00 + p00 * d11 - 2.0 * p01 * d01, 0.0)  # tr(adj(P) D)
        + np.maximum(d00 * d11 - d01 * d01, 0.0)  # det D
    )
    var_s0 = (p11 + d11) / det  # Sigma* = adj(P + D) / det(P + D)
    cov_s0_tau = -(p01 + d01) / det
    var_tau = (p00 + d00) / det
    r0 = (sum_s - n * m0 - sum_v * m1) / sigma2  # Z^T (S - Z mu_b) / sigma^2
    r1 = (sum_vs - sum_v * m0 - sum_vv * m1) / sigma2
    return Moments(m0 + var_s0 * r0 + cov_s0_tau * r1, m1 + cov_s0_tau * r0 + var_tau * r1, var_s0, cov_s0_tau, var_tau)


@numba.vectorize(["float64(float64, float64, float64, float64)"], cache=True)
def outside_probability(mean: float, variance: float, low: float, high: float) -> float:
    """P(X < low or X > high) for X ~ N(mean, variance), as a NumPy ufunc (also callable inside kernels)."""
    scale = math.sqrt(2.0 * variance)
    return 0.5 * (math.erfc((mean - low) / scale) + math.erfc((high - mean) / scale))


follow_sources(__name__)
