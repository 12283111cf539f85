"""Two non-Bayesian baselines for the detection benchmark: estimates of a follower's time gap tau [s]
from its measured speed V [m/s] and spacing S [m], one per tick (10 Hz).

- :func:`raw_time_gap`: the instantaneous (S - s0) / V of each reading, s0 the known standstill
  spacing, NaN below a minimum speed or on a dropout;
- :class:`RecursiveLeastSquares`: the usual online identification of an ACC's spacing policy,
  recursive least squares with exponential forgetting on S = s0 + tau V, its tau charted.

Both work on tick blocks (n_ticks, n_envs, n_vehicles), like
:meth:`~timegap_env.monitoring.monitor.TimeGapMonitor.update_block`, and return the estimate of tau of
every tick, so the caller can chart it with any chart of :mod:`~timegap_env.monitoring.charts`
(which reject NaN: the caller decides what a tick without a raw gap charts).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike

from timegap_env.compiled import follow_sources
from timegap_env.config import PlatoonConfig
from timegap_env.monitoring.batch import batch_array, batch_shape, env_mask, setting_array
from timegap_env.sim.platoon import actual_time_gap
from timegap_env.config import TIME_GAP_MIN_SPEED

__all__ = ["RecursiveLeastSquares", "RlsMemory", "raw_time_gap"]


def raw_time_gap(
    speed: ArrayLike, spacing: ArrayLike, standstill_spacing: float, min_speed: float = TIME_GAP_MIN_SPEED
) -> np.ndarray:
    """The instantaneous time gap (S - s0) / V of each reading [s], any shape (speed and spacing alike).

    ``speed`` V [m/s], ``spacing`` S [m], ``standstill_spacing`` s0 [m]. NaN where the speed is below
    ``min_speed`` [m/s] (> 0; the gap is not meaningful near standstill) or a reading is missing (NaN).
    """
    speed, spacing = np.asarray(speed, dtype=float), np.asarray(spacing, dtype=float)
    if speed.shape != spacing.shape:
        raise ValueError(f"speed, spacing have shapes {speed.shape}, {spacing.shape}: must be equal")
    standstill_spacing = _number("standstill_spacing", standstill_spacing)
    min_speed = _number("min_speed", min_speed, positive=True)
    return np.where(speed >= min_speed, actual_time_gap(spacing, speed, standstill_spacing), np.nan)


class RlsMemory(NamedTuple):
    """What :class:`RecursiveLeastSquares` carries from tick to tick, arrays (n_envs, n_vehicles).

    P = [[p_s0, p_s0_tau], [p_s0_tau, p_tau]] = (sum_j lambda^age_j Z_j^T Z_j + lambda^t P0^-1)^-1 over the
    readings j used, rows Z_j = [1, V_j], ages and t in ticks: in units of the spacing noise variance
    sigma^2, the estimate's covariance (exactly so without forgetting, lambda = 1).
    """

    s0: np.ndarray  # estimate of the standstill spacing [m]
    tau: np.ndarray  # estimate of the time gap [s]
    p_s0: np.ndarray  # P[0, 0] [-]
    p_s0_tau: np.ndarray  # P[0, 1] [s/m]
    p_tau: np.ndarray  # P[1, 1] [s^2/m^2]


class RecursiveLeastSquares:
    """Recursive least squares with exponential forgetting of S = s0 + tau V + eps, per vehicle of every env.

    Regressor Z = [1, V], parameters theta = [s0, tau]. Each reading updates, with forgetting factor
    ``forgetting`` = lambda in (0, 1] per tick (a reading ``age`` ticks old weighs lambda^age; memory about
    1 / (1 - lambda) ticks: 100 ticks = 10 s at 0.99, 1000 ticks = 100 s at 0.999)::

        e = S - Z theta,   g = P Z^T / (lambda + Z P Z^T),   theta += g e,   P = (P - g Z P) / lambda

    Initialisation (:meth:`reset`): theta0 = [``prior_standstill_spacing`` [m], the setting tau* [s]],
    P0 = ``prior_cov`` / ``noise_variance``: ``prior_cov`` is the covariance of theta0,
    ((var s0 [m^2], cov [m s]), (cov [m s], var tau [s^2])), and ``noise_variance`` sigma^2 [m^2] that of
    eps, so the first readings weigh against theta0 as in the Bayesian monitor's prior; the prior's
    weight then fades as lambda^t, like old readings.

    A reading with a NaN or infinite speed or spacing (a dropout) is skipped: the estimate stays and
    that tick reports it, but the tick still ages the data (P = P / lambda), so that lambda counts
    ticks like the Bayesian monitor's ``MonitorConfig.forgetting`` whatever the dropout rate. Without
    excitation (constant speed) P grows as lambda^-t in the unexcited direction (windup); sensor noise
    on V bounds it in practice.
    """

    def __init__(
        self,
        n_envs: int,
        n_vehicles: int,
        setting: ArrayLike,
        forgetting: float = 0.99,
        prior_standstill_spacing: float = PlatoonConfig.standstill_spacing,
        prior_cov: ArrayLike = ((1.0, 0.0), (0.0, 0.25)),  # vague: the readings dominate within a few ticks
        noise_variance: float = 0.01,
    ) -> None:
        self.shape = batch_shape(n_envs, n_vehicles)
        self.forgetting = _number("forgetting", forgetting)
        if not 0 < self.forgetting <= 1:
            raise ValueError(f"forgetting = {forgetting!r}: must be in (0, 1]")
        self.prior_standstill_spacing = _number("prior_standstill_spacing", prior_standstill_spacing)
        cov = np.asarray(prior_cov, dtype=float)
        symmetric = cov.shape == (2, 2) and np.isfinite(cov).all() and cov[0, 1] == cov[1, 0]
        if not symmetric or np.linalg.eigvalsh(cov)[0] <= 0:
            raise ValueError(f"prior_cov = {prior_cov!r}: must be a symmetric positive definite 2x2 matrix")
        noise_variance = _number("noise_variance", noise_variance, positive=True)
        self.initial_p = cov / noise_variance  # P0 [[-, s/m], [s/m, s^2/m^2]]
        self._memory = RlsMemory(*np.empty((len(RlsMemory._fields), *self.shape)))
        self._memory_args = tuple(self._memory)  # the same arrays, as the kernel takes them
        self.reset(None, setting)

    memory = property(lambda self: self._memory, doc="The :class:`RlsMemory` (its own arrays: read, do not write).")

    @property
    def tau(self) -> np.ndarray:
        """Estimate of the time gap (n_envs, n_vehicles) [s]."""
        return self._memory.tau.copy()

    def update(self, speed: ArrayLike, spacing: ArrayLike) -> np.ndarray:
        """Add one tick's readings, speed [m/s] and spacing [m], each (n_envs, n_vehicles); return tau [s]."""
        speed, spacing = batch_array("speed", speed, self.shape), batch_array("spacing", spacing, self.shape)
        return self.update_block(speed[None], spacing[None])[0]

    def update_block(self, speed: ArrayLike, spacing: ArrayLike) -> np.ndarray:
        """Add n_ticks ticks of readings, speed [m/s] and spacing [m], each (n_ticks, n_envs, n_vehicles);
        return the estimate of tau after each tick (n_ticks, n_envs, n_vehicles) [s]."""
        speed, spacing = np.ascontiguousarray(speed, dtype=float), np.ascontiguousarray(spacing, dtype=float)
        if speed.ndim != 3 or speed.shape[1:] != self.shape or spacing.shape != speed.shape or not len(speed):
            raise ValueError(
                f"speed, spacing have shapes {speed.shape}, {spacing.shape}: expected (n_ticks >= 1, *{self.shape})"
            )
        tau = np.empty(speed.shape)
        _rls_kernel(speed, spacing, self._memory_args, self.forgetting, tau)
        return tau

    def reset(self, mask: ArrayLike | None, setting: ArrayLike) -> None:
        """Restart the envs in ``mask`` ((n_envs,) bool, None = all) from theta0 = [prior s0, ``setting``] and P0;
        ``setting`` tau* [s] broadcastable to (n_envs, n_vehicles)."""
        setting = setting_array(setting, self.shape)
        vehicles = np.broadcast_to(env_mask(mask, self.shape[0])[:, None], self.shape)
        memory, initial_p = self._memory, self.initial_p
        for array, value in ((memory.s0, self.prior_standstill_spacing), (memory.tau, setting),
                             (memory.p_s0, initial_p[0, 0]), (memory.p_s0_tau, initial_p[0, 1]),
                             (memory.p_tau, initial_p[1, 1])):
            np.copyto(array, value, where=vehicles)


def _number(name: str, value: object, positive: bool = False) -> float:
    """``value`` as a float; ValueError naming ``name`` and the value unless it is finite (and > 0 if ``positive``)."""
    if (not isinstance(value, (int, float, np.integer, np.floating)) or isinstance(value, bool)
            or not math.isfinite(value)):
        raise ValueError(f"{name} = {value!r}: must be a finite number")
    if positive and value <= 0:
        raise ValueError(f"{name} = {value!r}: must be > 0")
    return float(value)


@numba.njit(cache=True)
def _rls_kernel(speed, spacing, memory, forgetting, tau_out):  # noqa: ANN001, ANN202
    """:meth:`RecursiveLeastSquares.update_block`, tick by tick and vehicle by vehicle, in place.

    ``memory`` (:class:`RlsMemory`, a plain tuple; see :mod:`timegap_env.sim.platoon`) is updated
    with forgetting factor ``forgetting`` [-]; ``tau_out`` (n_ticks, n_envs, n_vehicles) gets the
    estimate of tau after each tick [s]. P stays symmetric: only its three distinct entries are kept.
    """
    memory = RlsMemory(*memory)
    n_ticks, n_envs, n_vehicles = speed.shape
    for k in range(n_ticks):
        for e in range(n_envs):
            for i in range(n_vehicles):
                v, s = speed[k, e, i], spacing[k, e, i]
                if np.isfinite(v) and np.isfinite(s):
                    p_s0, p_s0_tau, p_tau = memory.p_s0[e, i], memory.p_s0_tau[e, i], memory.p_tau[e, i]
                    pz_s0, pz_tau = p_s0 + p_s0_tau * v, p_s0_tau + p_tau * v  # P Z^T [-], [s/m]
                    denominator = forgetting + pz_s0 + pz_tau * v  # lambda + Z P Z^T [-]
                    error = s - memory.s0[e, i] - memory.tau[e, i] * v  # prediction error [m]
                    memory.s0[e, i] += pz_s0 * error / denominator
                    memory.tau[e, i] += pz_tau * error / denominator
                    memory.p_s0[e, i] = (p_s0 - pz_s0 * pz_s0 / denominator) / forgetting
                    memory.p_s0_tau[e, i] = (p_s0_tau - pz_s0 * pz_tau / denominator) / forgetting
                    memory.p_tau[e, i] = (p_tau - pz_tau * pz_tau / denominator) / forgetting
                else:  # skipped: no reading, but the data age by a tick
                    memory.p_s0[e, i] /= forgetting
                    memory.p_s0_tau[e, i] /= forgetting
                    memory.p_tau[e, i] /= forgetting
                tau_out[k, e, i] = memory.tau[e, i]


# Its kernel: numba's cache by content
follow_sources(__name__)
