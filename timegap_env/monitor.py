"""Bayesian monitor of every follower's actual time gap: the paper's Proposition, streamed.

Model (Kontar & Ahn, Sec. 2): spacing S = s0 + tau V + eps, eps ~ N(0, sigma^2), with the
random coefficients Gamma = [s0, tau] ~ N(mu_b, Sigma_b). After n measurements with rows
Z_j = [1, V_j] the posterior is N(mu*, Sigma*) with

    Sigma* = (Sigma_b^-1 + Z^T Z / sigma^2)^-1,    mu* = Sigma* (Z^T S / sigma^2 + Sigma_b^-1 mu_b).

The data enter only through Z^T Z (2x2) and Z^T S (2), i.e. five sums per vehicle,
``[n, sum V, sum V^2, sum S, sum V S]`` (the "stats" below). :func:`posterior` computes them
for one vehicle's measurements; :class:`TimeGapMonitor` keeps them for a sliding window of
every vehicle of every env, tick by tick or a block of ticks at a time.

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
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike

from timegap_env.config import MonitorConfig

__all__ = ["posterior", "prior_precision", "TimeGapMonitor", "MonitorTicks", "Moments", "outside_probability"]

N_STATS = 5  # channels of the sufficient statistics: n, sum V, sum V^2, sum S, sum V S


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
    precision = prior_precision(Sigma_b)
    if isinstance(sigma2, bool) or not isinstance(sigma2, (int, float, np.integer, np.floating)) or not (
        np.isfinite(sigma2) and sigma2 > 0
    ):
        raise ValueError(f"sigma2 = {sigma2!r}: must be a finite number > 0 [m^2]")

    Z = np.column_stack([np.ones_like(V), V])
    with np.errstate(over="ignore", invalid="ignore"):  # checked just below
        ztz = Z.T @ (w[:, None] * Z)
        zts = Z.T @ (w * S)
    stats = np.array([ztz[0, 0], ztz[0, 1], ztz[1, 1], zts[0], zts[1]])
    if not np.all(np.isfinite(stats)):
        raise ValueError(
            f"V, S: Z^T Z or Z^T S overflows float64 (max |V| = {np.max(np.abs(V))}, max |S| = {np.max(np.abs(S))})"
        )
    moments = _moments_from_stats(stats, (mu_b[0], mu_b[1]), precision, float(sigma2))
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


class Moments(NamedTuple):
    """Posterior of [s0, tau] as five arrays of one shape (one value per vehicle)."""

    mean_s0: np.ndarray  # [m]
    mean_tau: np.ndarray  # [s]
    var_s0: np.ndarray  # [m^2]
    cov_s0_tau: np.ndarray  # [m s]
    var_tau: np.ndarray  # [s^2]

    def mean(self) -> np.ndarray:
        """Mean of [s0, tau], shape (..., 2)."""
        return np.stack([self.mean_s0, self.mean_tau], axis=-1)

    def cov(self) -> np.ndarray:
        """Covariance of [s0, tau], shape (..., 2, 2), symmetric by construction."""
        row_s0 = np.stack([self.var_s0, self.cov_s0_tau], axis=-1)
        row_tau = np.stack([self.cov_s0_tau, self.var_tau], axis=-1)
        return np.stack([row_s0, row_tau], axis=-2)


def _moments_from_stats(
    stats: np.ndarray, prior_mean: tuple[ArrayLike, ArrayLike], precision: np.ndarray, sigma2: float
) -> Moments:
    """Posterior from stats (5, ...) = [n, sum V, sum V^2, sum S, sum V S] and prior mean (s0, tau)."""
    n, sum_v, sum_vv, sum_s, sum_vs = stats
    prior_s0, prior_tau = prior_mean
    return Moments(*_posterior_moments(
        n, sum_v, sum_vv, sum_s, sum_vs, prior_s0, prior_tau, precision[0, 0], precision[0, 1], precision[1, 1], sigma2
    ))


@numba.njit(cache=True)
def _posterior_moments(n, sum_v, sum_vv, sum_s, sum_vs, m0, m1, p00, p01, p11, sigma2):  # noqa: ANN001, ANN201
    """(mean_s0, mean_tau, var_s0, cov_s0_tau, var_tau) from the five sums, the prior mean (m0, m1),
    the prior precision P = [[p00, p01], [p01, p11]] and the noise variance sigma2; scalars or arrays.

    See the module docstring for the determinant that cannot cancel.
    """
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
    return m0 + var_s0 * r0 + cov_s0_tau * r1, m1 + cov_s0_tau * r0 + var_tau * r1, var_s0, cov_s0_tau, var_tau


class MonitorTicks(NamedTuple):
    """What :meth:`TimeGapMonitor.update_block` returns, arrays (n_ticks, n_envs, n_vehicles)."""

    used: np.ndarray  # the measurement was used (else skipped) [bool]
    tau_mean: np.ndarray  # posterior mean of tau after the tick [s]


class TimeGapMonitor:
    """Streaming posterior of [s0, tau] for every vehicle of every env, O(1) work per measurement.

    Arrays are shaped (n_envs, n_vehicles); one tick (``config.dt``) brings one measurement
    per vehicle. :meth:`update` takes one tick, :meth:`update_block` several at once, every
    vehicle and env in one compiled pass; the result does not depend on how the ticks are
    grouped. Read-outs (after the last tick): ``mean`` (..., 2) and ``cov``
    (..., 2, 2) of [s0, tau], ``tau_mean``, ``tau_std``, :meth:`prob_outside`, ``skipped``,
    ``n_measurements``, ``ztz``, ``zts``.

    Forgetting. With all data since t = 0 the estimate would freeze, so old data are
    forgotten by a sliding window of the last ``config.window`` seconds (W ticks), by an
    exponential factor ``config.forgetting`` per tick (a measurement a ticks old has
    weight forgetting^a), or both; ``window=None, forgetting=1`` keeps everything.

    Skipped measurements. A NaN, infinite, negative or implausibly large speed or spacing
    (``config.max_speed``, ``config.max_spacing``) is skipped for that vehicle only and
    counted in ``skipped``. No data are added, so nothing NaN ever comes out; but the tick
    still passes: it occupies a window slot as an empty measurement and ages the data by one
    tick, so the window always spans W seconds of time. With a window (or forgetting) the
    posterior therefore drifts back towards the prior during a long dropout: no recent
    evidence, no confident estimate. Without either, a skipped tick leaves it unchanged.

    Drift guard. The window sums are never updated by subtracting the outgoing measurement
    (which would accumulate round-off over a long run). The ring buffer is filled in blocks of
    W ticks: slots 0..p hold this block's per-tick stats, and their running sum is kept;
    slots p+1..W-1 hold the previous block as suffix sums (slot k = the total of that block's
    slots k..W-1). The window total is then the running sum plus one suffix slot: only
    additions of at most 2W terms, so the error is bounded and does not grow with time. When
    a block is full it is turned into suffix sums in place: O(W) work every W ticks,
    amortised O(1) per tick. A block of ticks makes the same additions in the same order as
    tick by tick.
    """

    def __init__(
        self, n_envs: int, n_vehicles: int, time_gap: ArrayLike, config: MonitorConfig = MonitorConfig()
    ) -> None:
        self.config = config
        self.shape = batch_shape(n_envs, n_vehicles)
        self._precision = prior_precision(config.prior_cov)
        self._prior_tau = np.empty(self.shape)  # prior mean of tau, the setting tau* [s]
        self.skipped = np.zeros(self.shape, dtype=np.int64)  # measurements skipped since reset [-]
        stats_shape = (N_STATS,) + self.shape
        self._block_sum = np.zeros(stats_shape)  # forgetting-weighted sum of this block
        self._window_stats = np.zeros(stats_shape)  # forgetting-weighted sum of the window
        W, decay = config.window_ticks or 0, config.forgetting  # W = 0: no window
        self._slots = np.zeros((W + 1,) + stats_shape)  # ring of per-tick stats; slot W stays zero
        self._slot = 0 if W else -1  # slot of the next measurement, p; -1: no window
        self._suffix_weight = decay ** np.arange(1, W + 1)  # weight of suffix slot p+1 at slot p
        self._age_weight = decay ** np.arange(W - 1, -1, -1.0)  # weight of slot m when the block is full
        self.reset(None, time_gap)

    # ---- streaming ------------------------------------------------------------------------

    def update(self, speed: ArrayLike, spacing: ArrayLike) -> np.ndarray:
        """Add one tick of measurements, speed [m/s] and spacing [m], each (n_envs, n_vehicles).

        Returns the boolean mask (n_envs, n_vehicles) of the measurements used; the others
        were skipped (see the class docstring).
        """
        speed = batch_array("speed", speed, self.shape)
        spacing = batch_array("spacing", spacing, self.shape)
        return self.update_block(speed[None], spacing[None]).used[0]

    def update_block(self, speed: ArrayLike, spacing: ArrayLike) -> MonitorTicks:
        """Add n_ticks ticks of measurements, speed [m/s] and spacing [m], each (n_ticks, n_envs, n_vehicles)."""
        speed, spacing = np.ascontiguousarray(speed, dtype=float), np.ascontiguousarray(spacing, dtype=float)
        if speed.ndim != 3 or speed.shape[1:] != self.shape or spacing.shape != speed.shape or not len(speed):
            raise ValueError(
                f"speed, spacing have shapes {speed.shape}, {spacing.shape}: expected (n_ticks >= 1, *{self.shape})"
            )
        cfg, precision = self.config, self._precision
        ticks = MonitorTicks(used=np.empty(speed.shape, dtype=bool), tau_mean=np.empty(speed.shape))
        moments = np.empty((len(Moments._fields),) + self.shape)  # the posterior after the last tick
        self._slot = _update_kernel(
            speed, spacing, cfg.max_speed, cfg.max_spacing, cfg.forgetting,
            self._slots, self._slot, self._suffix_weight, self._age_weight,
            cfg.prior_standstill_spacing, self._prior_tau, precision[0, 0], precision[0, 1], precision[1, 1],
            cfg.noise_variance, self._block_sum, self._window_stats, self.skipped, ticks.used, ticks.tau_mean, moments,
        )
        self._moments = Moments(*moments)
        return ticks

    # ---- changes of setting ------------------------------------------------------------------

    def reset(self, mask: ArrayLike | None, time_gap: ArrayLike) -> None:
        """Start the envs in ``mask`` ((n_envs,) bool, None = all) afresh.

        Their prior mean of tau becomes ``time_gap`` [s] (broadcastable to (n_envs, n_vehicles)),
        their window is emptied and their ``skipped`` counters are zeroed.
        """
        vehicles = np.broadcast_to(env_mask(mask, self.shape[0])[:, None], self.shape)
        self.skipped[vehicles] = 0
        self.recenter(time_gap, vehicles)

    def recenter(self, time_gap: ArrayLike, mask: ArrayLike | None = None) -> None:
        """The setting tau* changed to ``time_gap`` [s] for the vehicles in ``mask``.

        ``mask``: bool, broadcastable to (n_envs, n_vehicles), None = all. The prior mean of
        tau moves to the new tau* (paper: 1.6 -> 1.0) and the window's data of those vehicles
        are cleared, so their posterior restarts from the prior. Why clear: the model treats
        [s0, tau] as the coefficients of one setting; measurements taken under the old
        setting describe the old coefficients. Kept, they would pull the estimate towards the
        old tau for a whole window, and the chart, re-centred on the new tau*, would read that
        stale estimate as excursions (e.g. 1.6 s against limits 0.75-1.25 s) and count them
        towards the next switch. ``skipped`` is sensor health and is kept.
        """
        self._recenter(time_gap_array(time_gap, self.shape), vehicle_mask(mask, self.shape))

    def _recenter(self, tau: np.ndarray, vehicles: np.ndarray) -> None:
        """:meth:`recenter` with ``tau`` and ``vehicles`` already checked and broadcast."""
        np.copyto(self._prior_tau, tau, where=vehicles)
        for stats in (self._block_sum, self._window_stats, self._slots):  # (..., n_envs, n_vehicles)
            np.copyto(stats, 0.0, where=vehicles)
        self._moments = None  # the prior, recomputed when first read

    def _latest(self) -> Moments:
        """The posterior after the last tick (or change of setting)."""
        if self._moments is None:
            prior_mean = (self.config.prior_standstill_spacing, self._prior_tau)
            self._moments = _moments_from_stats(
                self._window_stats, prior_mean, self._precision, self.config.noise_variance
            )
        return self._moments

    # ---- read-outs ----------------------------------------------------------------------------

    @property
    def mean(self) -> np.ndarray:
        """Posterior mean of [s0 [m], tau [s]] (n_envs, n_vehicles, 2)."""
        return self._latest().mean()

    @property
    def cov(self) -> np.ndarray:
        """Posterior covariance of [s0, tau] (n_envs, n_vehicles, 2, 2), symmetric positive definite."""
        return self._latest().cov()

    @property
    def prior_mean(self) -> np.ndarray:
        """Prior mean of [s0 [m], tau [s]] (n_envs, n_vehicles, 2); tau's is the setting tau*."""
        return np.stack([np.full(self.shape, self.config.prior_standstill_spacing), self._prior_tau], axis=-1)

    @property
    def tau_mean(self) -> np.ndarray:
        """Posterior mean of tau (n_envs, n_vehicles) [s]."""
        return self._latest().mean_tau.copy()

    @property
    def moments(self) -> Moments:
        """The posterior after the last tick, channel by channel (the monitor's own arrays: read, do not write)."""
        return self._latest()

    @property
    def tau_std(self) -> np.ndarray:
        """Posterior standard deviation of tau (n_envs, n_vehicles) [s]."""
        return np.sqrt(self._latest().var_tau)

    @property
    def n_measurements(self) -> np.ndarray:
        """Forgetting-weighted number of measurements in the window (n_envs, n_vehicles) [-]."""
        return self._window_stats[0].copy()

    @property
    def ztz(self) -> np.ndarray:
        """The window's forgetting-weighted Z^T Z (n_envs, n_vehicles, 2, 2)."""
        n, sum_v, sum_vv = self._window_stats[:3]
        return np.stack([np.stack([n, sum_v], axis=-1), np.stack([sum_v, sum_vv], axis=-1)], axis=-2)

    @property
    def zts(self) -> np.ndarray:
        """The window's forgetting-weighted Z^T S (n_envs, n_vehicles, 2)."""
        return np.stack([self._window_stats[3], self._window_stats[4]], axis=-1)

    def prob_outside(self, lcl: ArrayLike, ucl: ArrayLike) -> np.ndarray:
        """Posterior P(tau < lcl or tau > ucl) (n_envs, n_vehicles) under tau's normal marginal.

        lcl, ucl [s]: broadcastable to (n_envs, n_vehicles), lcl <= ucl (infinite limits allowed).
        """
        low, high = (np.asarray(limit, dtype=float) for limit in (lcl, ucl))
        low, high = (limit if limit.shape == self.shape else np.broadcast_to(limit, self.shape) for limit in (low, high))
        if not (low <= high).all():
            raise ValueError(f"lcl = {lcl!r}, ucl = {ucl!r}: need lcl <= ucl everywhere")
        moments = self._latest()
        return outside_probability(moments.mean_tau, moments.var_tau, low, high)


@numba.vectorize(["float64(float64, float64, float64, float64)"], cache=True)
def outside_probability(mean: float, variance: float, low: float, high: float) -> float:
    """P(X < low or X > high) for X ~ N(mean, variance), as a NumPy ufunc (also callable inside kernels)."""
    scale = math.sqrt(2.0 * variance)
    return 0.5 * (math.erfc((mean - low) / scale) + math.erfc((high - mean) / scale))


# ---- batch argument checks (shared with charts.py) ---------------------------------------------


def batch_shape(n_envs: int, n_vehicles: int) -> tuple[int, int]:
    """(n_envs, n_vehicles), both checked to be integers >= 1."""
    for name, value in (("n_envs", n_envs), ("n_vehicles", n_vehicles)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} = {value!r}: must be an integer >= 1")
    return int(n_envs), int(n_vehicles)


def batch_array(name: str, value: ArrayLike, shape: tuple[int, int]) -> np.ndarray:
    """``value`` as a float array of exactly ``shape`` (n_envs, n_vehicles); ValueError naming ``name``."""
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r}: must be numbers") from None
    if array.shape != shape:
        raise ValueError(f"{name} has shape {array.shape}: expected {shape} (n_envs, n_vehicles)")
    return array


def time_gap_array(time_gap: ArrayLike, shape: tuple[int, int]) -> np.ndarray:
    """``time_gap`` [s] broadcast to ``shape``, every value finite and > 0."""
    array = np.asarray(time_gap, dtype=float)
    if array.shape != shape:
        try:
            array = np.broadcast_to(array, shape)
        except ValueError:
            raise ValueError(f"time_gap has shape {array.shape}: not broadcastable to {shape}") from None
    valid = (array > 0) & (array < np.inf)  # NaN fails both
    if not valid.all():  # called every tick: find the culprit only when there is one
        bad = np.argwhere(~valid)
        index = tuple(int(i) for i in bad[0])
        raise ValueError(f"time_gap{list(index)} = {float(array[index])}: must be finite and > 0 [s]")
    return array


def vehicle_mask(mask: ArrayLike | None, shape: tuple[int, int]) -> np.ndarray:
    """Boolean mask of vehicles broadcast to ``shape`` (n_envs, n_vehicles); None selects all."""
    if mask is None:
        return np.ones(shape, dtype=bool)
    array = np.asarray(mask)
    if array.dtype != bool:
        raise ValueError(f"mask has dtype {array.dtype}: must be bool")
    if array.shape == shape:
        return array
    try:
        return np.broadcast_to(array, shape)
    except ValueError:
        raise ValueError(f"mask has shape {array.shape}: not broadcastable to {shape} (n_envs, n_vehicles)") from None


def env_mask(mask: ArrayLike | None, n_envs: int) -> np.ndarray:
    """Boolean mask of envs, shape (n_envs,); None selects all."""
    if mask is None:
        return np.ones(n_envs, dtype=bool)
    array = np.asarray(mask)
    if array.dtype != bool or array.shape != (n_envs,):
        raise ValueError(f"mask has dtype {array.dtype} and shape {array.shape}: must be bool of shape ({n_envs},)")
    return array


@numba.njit(cache=True)
def _update_kernel(  # noqa: ANN202, PLR0913 -- the kernel takes the monitor's arrays one by one
    speed, spacing, max_speed, max_spacing, forgetting,
    slots, slot, suffix_weight, age_weight,
    prior_s0, prior_tau, p00, p01, p11, sigma2,
    block_sum, window_stats, skipped, out_used, out_tau_mean, out_moments,
):
    """:meth:`TimeGapMonitor.update_block`, tick by tick and vehicle by vehicle, in place; returns the next slot.

    ``out_tau_mean`` gets the posterior mean of tau after each tick, ``out_moments`` (5, n_envs,
    n_vehicles) the whole posterior after the last one, in :class:`Moments` order.

    ``slot = -1`` means no window: the window sums are the block sums, which never close.
    The additions are those of the class docstring's drift guard, in the same order.
    """
    n_ticks, n_envs, n_vehicles = speed.shape
    window_ticks = slots.shape[0] - 1
    x = np.empty(N_STATS)
    for k in range(n_ticks):
        for e in range(n_envs):
            for i in range(n_vehicles):
                v, s = speed[k, e, i], spacing[k, e, i]
                used = 0.0 <= v <= max_speed and 0.0 <= s <= max_spacing  # NaN -> False
                out_used[k, e, i] = used
                if not used:
                    skipped[e, i] += 1
                    v = s = 0.0
                x[0], x[1], x[2], x[3], x[4] = (1.0 if used else 0.0), v, v * v, s, v * s
                for c in range(N_STATS):
                    if forgetting < 1.0:
                        block_sum[c, e, i] *= forgetting
                    block_sum[c, e, i] += x[c]
                    if slot < 0:
                        window_stats[c, e, i] = block_sum[c, e, i]
                    else:
                        slots[slot, c, e, i] = x[c]
                        window_stats[c, e, i] = slots[slot + 1, c, e, i] * suffix_weight[slot] + block_sum[c, e, i]
                moments = _posterior_moments(
                    window_stats[0, e, i], window_stats[1, e, i], window_stats[2, e, i], window_stats[3, e, i],
                    window_stats[4, e, i], prior_s0, prior_tau[e, i], p00, p01, p11, sigma2,
                )
                out_tau_mean[k, e, i] = moments[1]
                if k == n_ticks - 1:
                    for m in range(len(moments)):
                        out_moments[m, e, i] = moments[m]
        if slot < 0:  # no window
            continue
        if slot < window_ticks - 1:
            slot += 1
        else:  # the block is full: turn it into suffix sums
            for m in range(window_ticks - 2, -1, -1):
                slots[m] *= age_weight[m]
                slots[m] += slots[m + 1]
            block_sum[:] = 0.0
            slot = 0
    return slot
