"""The Bayesian monitor of every follower's actual time gap: the paper's Proposition, streamed.

:class:`TimeGapMonitor` keeps the sufficient statistics (:class:`~timegap_env.monitoring.posterior.WindowSums`)
of a sliding window of measurements for every vehicle of every env and turns them into the
posterior of [s0, tau] with :func:`~timegap_env.monitoring.posterior.posterior_moments`, the
Proposition of :mod:`timegap_env.monitoring.posterior`. The prior mean of tau is each vehicle's
time gap setting; :meth:`TimeGapMonitor.recenter` moves it when the setting changes.
"""

from __future__ import annotations

from typing import Annotated, NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike

from timegap_env.compiled import INLINED_STAGE_KERNEL, STAGE_KERNEL, follow_sources
from timegap_env.config import MonitorConfig
from timegap_env.monitoring.batch import batch_array, batch_shape, env_mask, setting_array, vehicle_mask
from timegap_env.monitoring.posterior import Moments, Prior, WindowSums, outside_probability, posterior_moments
from timegap_env.state import OnState, PerEnv, State

__all__ = ["MonitorTicks", "TimeGapMonitor", "WindowRule", "monitor_prior"]

N_SUMS = len(WindowSums._fields)  # channels of the window sums: n, sum V, sum V^2, sum S, sum V S
UPDATE_WORK_ROWS = N_SUMS + 3  # rows of update_env's scratch: the window sums, prior mean, mean and variance of tau


class MonitorTicks(NamedTuple):
    """What :meth:`TimeGapMonitor.update_block` returns, arrays (n_ticks, n_envs, n_vehicles)."""

    used: np.ndarray  # the measurement was used (else skipped) [bool]
    tau_mean: np.ndarray  # posterior mean of tau after the tick [s]
    tau_var: np.ndarray  # posterior variance of tau after the tick [s^2]


class WindowMemory(NamedTuple):
    """What the monitor carries from tick to tick per vehicle ("followers"), sums with a last axis of N_SUMS
    channels ("sums")."""

    # ring of per-tick sums, W + 1 slots ("window_slots"); slot W stays zero (drift guard)
    slots: Annotated[np.ndarray, PerEnv(float, "followers", "window_slots", "sums")]
    block_sum: Annotated[np.ndarray, PerEnv(float, "followers", "sums")]  # forgetting-weighted sum of the block
    window_sums: Annotated[np.ndarray, PerEnv(float, "followers", "sums")]  # forgetting-weighted sum of the window
    skipped: Annotated[np.ndarray, PerEnv(np.int64, "followers")]  # measurements skipped since reset [-]
    prior_tau: Annotated[np.ndarray, PerEnv(float, "followers")]  # prior mean of tau, the setting tau* [s]
    # the window was cleared by a change of setting (or a reset) when the block had reached this slot: this
    # block's slots below it, and the previous block's suffix sums, read as zeros until the block is full; -1:
    # nothing cleared since
    cleared_below: Annotated[np.ndarray, PerEnv(np.int64, "followers", fill=-1)]


class MonitorParts(NamedTuple):
    """Everything per env a :class:`TimeGapMonitor` holds."""

    memory: WindowMemory
    # the ring slot of the env's next measurement, p, counted from its reset (so an env's sums do not depend on
    # when other envs reset, nor on earlier episodes); -1: no window
    slot: Annotated[np.ndarray, PerEnv(np.int64)]
    posterior: Moments  # after the last tick (or change of setting)


def monitor_dims(config: MonitorConfig, n_vehicles: int) -> dict[str, int]:
    """The sizes of :class:`MonitorParts`' dimensions for ``n_vehicles`` vehicles ("followers") under ``config``."""
    return {"followers": n_vehicles, "window_slots": (config.window_ticks or 0) + 1, "sums": N_SUMS}


class WindowRule(NamedTuple):
    """How measurements are screened and weighted; from :class:`MonitorConfig`."""

    max_speed: float  # speeds above this are skipped [m/s]
    max_spacing: float  # spacings above this are skipped [m]
    min_speed: float  # measurements below this speed are left out, not skipped [m/s]
    forgetting: float  # exponential forgetting factor per tick [-]
    suffix_weight: np.ndarray  # (W,) weight of suffix slot p + 1 seen from slot p [-]
    age_weight: np.ndarray  # (W,) weight of slot m when its block is full [-]
    raw_gap: bool  # MonitorConfig.estimator == "raw_gap": report each tick's (s - s0) / v instead of the posterior

    @classmethod
    def from_config(cls, config: MonitorConfig) -> WindowRule:
        W, decay = config.window_ticks or 0, float(config.forgetting)  # W = 0: no window
        return cls(max_speed=float(config.max_speed), max_spacing=float(config.max_spacing),
                   min_speed=float(config.min_speed), forgetting=decay, suffix_weight=decay ** np.arange(1, W + 1),
                   age_weight=decay ** np.arange(W - 1, -1, -1.0), raw_gap=config.estimator == "raw_gap")


def monitor_prior(config: MonitorConfig) -> Prior:
    """The prior's constants under ``config`` (:class:`Prior`)."""
    return Prior.from_cov(config.prior_standstill_spacing, config.prior_cov, config.noise_variance)


class TimeGapMonitor(OnState):
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

    Skipped measurements. A NaN or infinite speed or spacing, a negative spacing, or an
    implausibly large one or speed of either sign (``config.max_spacing``, ``config.max_speed``)
    is skipped for that vehicle only and counted in ``skipped``. No data are added, so nothing NaN ever comes out; but the tick
    still passes: it occupies a window slot as an empty measurement and ages the data by one
    tick, so the window always spans W seconds of time. With a window (or forgetting) the
    posterior therefore drifts back towards the prior during a long dropout: no recent
    evidence, no confident estimate. Without either, a skipped tick leaves it unchanged.

    Low speeds. Below ``config.min_speed`` the spacing model s = s0 + tau v says (almost)
    nothing of tau, and a small spacing error becomes a huge one in (s - s0) / v: such
    measurements, noisy negative readings about a standstill included, are left out as skipped
    ones are (an empty slot that ages the data), but not counted in ``skipped``, which is
    sensor health. With a window (or forgetting), a standing platoon's posterior therefore
    returns to the prior, whose mean is the setting: the chart sees no deviation; without
    either, it holds the estimate it had when the platoon slowed down.

    Raw gap. ``config.estimator = "raw_gap"`` (an ablation: what the Bayesian monitor adds) reports each
    tick's (s - s0) / v instead of the posterior, with s0 the prior's mean taken as known and variance
    sigma^2 / v^2; a tick left out reports the prior. The window's sums are kept as before, unused.

    Drift guard. The window sums are never updated by subtracting the outgoing measurement
    (which would accumulate round-off over a long run). The ring buffer is filled in blocks of
    W ticks: slots 0..p hold this block's per-tick stats, and their running sum is kept;
    slots p+1..W-1 hold the previous block as suffix sums (slot k = the total of that block's
    slots k..W-1). The window total is then the running sum plus one suffix slot: only
    additions of at most 2W terms, so the error is bounded and does not grow with time. When
    a block is full it is turned into suffix sums in place: O(W) work every W ticks,
    amortised O(1) per tick. A block of ticks makes the same additions in the same order as
    tick by tick. A change of setting clears a vehicle's window by a mark, not by writing its
    ring (``cleared_below``): until its block is full, the block's slots before the mark and the
    previous block's suffix sums read as zeros, the numbers a written clearing would give.
    """

    def __init__(self, n_envs: int, n_vehicles: int, setting: ArrayLike, config: MonitorConfig = MonitorConfig(),
                 state: State | None = None, path: tuple[str, ...] = ()) -> None:
        self.config = config
        self.shape = batch_shape(n_envs, n_vehicles)
        if state is None:
            state = State(MonitorParts, monitor_dims(config, n_vehicles), n_envs)
        self._bind(state, path)  # parts: its arrays (MonitorParts)
        self.parts.slot[:] = 0 if config.window_ticks else -1  # -1: no window
        self._rule = WindowRule.from_config(config)
        self._prior = monitor_prior(config)
        self.reset(None, setting)

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
        ticks = MonitorTicks(used=np.empty(speed.shape, dtype=bool), tau_mean=np.empty(speed.shape),
                             tau_var=np.empty(speed.shape))
        parts = self.parts
        _update_kernel(speed, spacing, tuple(parts.memory), parts.slot, tuple(self._rule), tuple(self._prior),
                       tuple(ticks), tuple(parts.posterior))
        return ticks

    rule = property(lambda self: self._rule, doc="How measurements are screened and weighted (:class:`WindowRule`).")
    prior = property(lambda self: self._prior, doc="The prior's constants (:class:`Prior`).")

    # ---- changes of setting ------------------------------------------------------------------

    def reset(self, mask: ArrayLike | None, setting: ArrayLike) -> None:
        """Start the envs in ``mask`` ((n_envs,) bool, None = all) afresh.

        Their prior mean of tau becomes ``setting`` [s] (broadcastable to (n_envs, n_vehicles)),
        their window is emptied and restarts at ring slot 0, and their ``skipped`` counters are zeroed.
        """
        envs, slot = env_mask(mask, self.shape[0]), self.parts.slot
        self.parts.memory.skipped[envs] = 0
        slot[envs & (slot >= 0)] = 0
        self.recenter(setting, np.broadcast_to(envs[:, None], self.shape))

    def recenter(self, setting: ArrayLike, mask: ArrayLike | None = None) -> None:
        """The setting tau* changed to ``setting`` [s] for the vehicles in ``mask``.

        ``mask``: bool, broadcastable to (n_envs, n_vehicles), None = all. The prior mean of
        tau moves to the new tau* (paper: 1.6 -> 1.0) and the window's data of those vehicles
        are cleared, so their posterior restarts from the prior. Why clear: the model treats
        [s0, tau] as the coefficients of one setting; measurements taken under the old
        setting describe the old coefficients. Kept, they would pull the estimate towards the
        old tau for a whole window, and the chart, re-centred on the new tau*, would read that
        stale estimate as excursions (e.g. 1.6 s against limits 0.75-1.25 s) and count them
        towards the next switch. ``skipped`` is sensor health and is kept.
        """
        setting, vehicles = setting_array(setting, self.shape), vehicle_mask(mask, self.shape)
        vehicles = np.ascontiguousarray(vehicles)
        _recenter(tuple(self.parts.memory), self.parts.slot, np.ascontiguousarray(setting, dtype=float), vehicles)
        self.restart_posterior(vehicles)

    def restart_posterior(self, vehicles: np.ndarray) -> None:
        """The posterior of the vehicles in ``vehicles`` (n_envs, n_vehicles) bool, whose windows were just cleared,
        is their prior now (the others keep their last tick's)."""
        _posterior_of_window(tuple(self.parts.memory), tuple(self._prior), np.ascontiguousarray(vehicles),
                             tuple(self.parts.posterior))

    def _latest(self) -> Moments:
        """The posterior after the last tick (or change of setting)."""
        return self.parts.posterior

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
        return np.stack([np.full(self.shape, self.config.prior_standstill_spacing), self.parts.memory.prior_tau],
                        axis=-1)

    @property
    def skipped(self) -> np.ndarray:
        """Measurements skipped since reset (n_envs, n_vehicles) [-] (the monitor's own array: read, do not write)."""
        return self.parts.memory.skipped

    @property
    def tau_mean(self) -> np.ndarray:
        """Posterior mean of tau (n_envs, n_vehicles) [s] (the raw gap, with ``estimator = "raw_gap"``)."""
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
        return self.parts.memory.window_sums[..., 0].copy()

    @property
    def ztz(self) -> np.ndarray:
        """The window's forgetting-weighted Z^T Z (n_envs, n_vehicles, 2, 2)."""
        n, sum_v, sum_vv = np.moveaxis(self.parts.memory.window_sums[..., :3], -1, 0)
        return np.stack([np.stack([n, sum_v], axis=-1), np.stack([sum_v, sum_vv], axis=-1)], axis=-2)

    @property
    def zts(self) -> np.ndarray:
        """The window's forgetting-weighted Z^T S (n_envs, n_vehicles, 2)."""
        return self.parts.memory.window_sums[..., 3:5].copy()

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


@numba.njit(cache=True, error_model="numpy")
def _recenter(memory, slot, settings, vehicles):  # noqa: ANN001, ANN202
    """:func:`recenter_env` for every vehicle of ``vehicles`` (n_envs, n_vehicles) bool, on ``settings`` [s]; ``slot``
    (n_envs,) each env's next ring slot."""
    for e in range(vehicles.shape[0]):
        for f in range(vehicles.shape[1]):
            if vehicles[e, f]:
                recenter_env(memory, slot, settings[e, f], e, f)


@numba.njit(**STAGE_KERNEL)
def recenter_env(memory, slot, setting, e, f):  # noqa: ANN001, ANN201
    """Vehicle ``f`` of env ``e`` under a new setting [s]: its prior mean of tau moves there and its window's data
    are cleared (see :meth:`TimeGapMonitor.recenter`); ``memory`` is :class:`WindowMemory` (a plain tuple), ``slot``
    (n_envs,) each env's next ring slot. The sums are zeroed; the ring's slots are not written but marked
    (``cleared_below``): :func:`update_env` reads them as the zeros they would hold."""
    memory = WindowMemory(*memory)
    memory.prior_tau[e, f] = setting
    memory.cleared_below[e, f] = slot[e]
    for n in range(memory.block_sum.shape[2]):
        memory.block_sum[e, f, n] = memory.window_sums[e, f, n] = 0.0


@numba.njit(cache=True, error_model="numpy")
def _update_kernel(speed, spacing, memory, slot, rule, prior, out, out_moments):  # noqa: ANN001, ANN202
    """:meth:`TimeGapMonitor.update_block`, env by env (:func:`update_env`), in place.

    ``memory`` (:class:`WindowMemory`) is updated under ``rule`` (:class:`WindowRule`) and ``prior``
    (:class:`Prior`); ``slot`` (n_envs,) is each env's next ring slot, advanced in place; ``out``
    (:class:`MonitorTicks`) gets each tick's verdict and posterior mean and variance of tau,
    ``out_moments`` (:class:`Moments` of (n_envs, n_vehicles) arrays) the whole posterior after the last
    tick; each structure comes as a plain tuple (see :mod:`timegap_env.sim.platoon`).
    """
    n_ticks, n_envs, n_vehicles = speed.shape
    work = np.empty((UPDATE_WORK_ROWS, n_ticks * n_vehicles))
    for e in range(n_envs):
        update_env(speed, spacing, memory, slot, rule, prior, out, out_moments, e, e, work)


@numba.njit(**INLINED_STAGE_KERNEL)
def update_env(  # noqa: ANN201, PLR0913
    speed, spacing, memory, slot, rule, prior, out, out_moments, e, column, work,  # noqa: ANN001
):
    """Env ``e``'s vehicles through a block of measurements, column ``column`` of ``speed``, ``spacing`` and
    ``out`` (the arguments of :func:`_update_kernel`), in place; ``work`` (UPDATE_WORK_ROWS, n_ticks * n_vehicles)
    float64 is scratch.

    Vehicle by vehicle, tick by tick, the window sums after each tick go to ``work`` (column k n_vehicles + i), and
    the whole posterior after the last tick to ``out_moments``; then each tick's mean and variance of tau from
    ``work``, in one loop without branches (which the compiler vectorises). ``slot[e] = -1`` means no window: the window sums are
    the block sums, which never close. The additions are those of the class docstring's drift guard, in the same
    order, as if tick by tick.
    """
    memory, rule, prior = WindowMemory(*memory), WindowRule(*rule), Prior(*prior)
    out, out_moments = MonitorTicks(*out), Moments(*out_moments)
    slots, block_sum, window_sums = memory.slots[e], memory.block_sum[e], memory.window_sums[e]
    n_ticks, n_vehicles = speed.shape[0], speed.shape[2]
    window_ticks = slots.shape[1] - 1
    c, first_slot = column, slot[e]
    sums, prior_taus, mean_tau, var_tau = work[:N_SUMS], work[N_SUMS], work[N_SUMS + 1], work[N_SUMS + 2]
    decay = rule.forgetting
    for i in range(n_vehicles):  # the sums in scalars: b the block's, w the window's
        p, prior_tau, cleared = first_slot, memory.prior_tau[e, i], memory.cleared_below[e, i]
        b0, b1, b2, b3, b4 = block_sum[i, 0], block_sum[i, 1], block_sum[i, 2], block_sum[i, 3], block_sum[i, 4]
        for k in range(n_ticks):
            v, s = speed[k, c, i], spacing[k, c, i]
            valid = -rule.max_speed <= v <= rule.max_speed and 0.0 <= s <= rule.max_spacing  # NaN -> False
            used = valid and v >= rule.min_speed
            out.used[k, c, i] = used
            if not valid:
                memory.skipped[e, i] += 1
            if not used:
                v = s = 0.0
            x0, x1, x2, x3, x4 = (1.0 if used else 0.0), v, v * v, s, v * s  # this tick's terms of the sums
            if decay < 1.0:
                b0, b1, b2, b3, b4 = b0 * decay, b1 * decay, b2 * decay, b3 * decay, b4 * decay
            b0, b1, b2, b3, b4 = b0 + x0, b1 + x1, b2 + x2, b3 + x3, b4 + x4
            if p < 0:
                w0, w1, w2, w3, w4 = b0, b1, b2, b3, b4
            else:
                slots[i, p, 0], slots[i, p, 1], slots[i, p, 2], slots[i, p, 3], slots[i, p, 4] = x0, x1, x2, x3, x4
                h0 = h1 = h2 = h3 = h4 = 0.0  # h: the previous block's suffix sums (zeros if cleared since)
                if cleared < 0:
                    suffix = slots[i, p + 1]
                    h0, h1, h2, h3, h4 = suffix[0], suffix[1], suffix[2], suffix[3], suffix[4]
                weight = rule.suffix_weight[p]
                w0, w1, w2 = h0 * weight + b0, h1 * weight + b1, h2 * weight + b2
                w3, w4 = h3 * weight + b3, h4 * weight + b4
            j = k * n_vehicles + i
            sums[0, j], sums[1, j], sums[2, j], sums[3, j], sums[4, j], prior_taus[j] = w0, w1, w2, w3, w4, prior_tau
            if rule.raw_gap:
                moments = _raw_gap(v, s, used, prior_tau, prior)
                mean_tau[j], var_tau[j] = moments.mean_tau, moments.var_tau
                if k == n_ticks - 1:  # field by field: a tuple indexed by a variable is slow in numba
                    out_moments.mean_s0[e, i], out_moments.mean_tau[e, i] = moments.mean_s0, moments.mean_tau
                    out_moments.var_s0[e, i], out_moments.cov_s0_tau[e, i] = moments.var_s0, moments.cov_s0_tau
                    out_moments.var_tau[e, i] = moments.var_tau
            if p < 0:  # no window
                continue
            if p < window_ticks - 1:
                p += 1
            else:  # the block is full: turn it into suffix sums (its slots before a clearing count as zeros)
                for m in range(window_ticks - 2, -1, -1):
                    for n in range(N_SUMS):
                        kept = slots[i, m, n] if m >= cleared else 0.0
                        slots[i, m, n] = kept * rule.age_weight[m] + slots[i, m + 1, n]
                b0 = b1 = b2 = b3 = b4 = 0.0
                p, cleared = 0, -1
        block_sum[i, 0], block_sum[i, 1], block_sum[i, 2], block_sum[i, 3], block_sum[i, 4] = b0, b1, b2, b3, b4
        memory.cleared_below[e, i] = cleared
        window_sums[i, 0], window_sums[i, 1], window_sums[i, 2] = w0, w1, w2
        window_sums[i, 3], window_sums[i, 4] = w3, w4
        slot[e] = p
        if not rule.raw_gap:  # the whole posterior after the last tick
            moments = posterior_moments(WindowSums(w0, w1, w2, w3, w4), prior_tau, prior)
            out_moments.mean_s0[e, i], out_moments.mean_tau[e, i] = moments.mean_s0, moments.mean_tau
            out_moments.var_s0[e, i], out_moments.cov_s0_tau[e, i] = moments.var_s0, moments.cov_s0_tau
            out_moments.var_tau[e, i] = moments.var_tau
    if not rule.raw_gap:  # each tick's mean and variance of tau, in a loop without branches
        for j in range(n_ticks * n_vehicles):
            moments = posterior_moments(WindowSums(sums[0, j], sums[1, j], sums[2, j], sums[3, j], sums[4, j]),
                                        prior_taus[j], prior)
            mean_tau[j], var_tau[j] = moments.mean_tau, moments.var_tau
    for k in range(n_ticks):
        for i in range(n_vehicles):
            out.tau_mean[k, c, i], out.tau_var[k, c, i] = mean_tau[k * n_vehicles + i], var_tau[k * n_vehicles + i]


@numba.njit(**STAGE_KERNEL)
def _raw_gap(speed, spacing, used, setting, prior):  # noqa: ANN001, ANN202
    """The raw-gap ablation's read-out of one tick (``MonitorConfig.estimator = "raw_gap"``), as :class:`Moments`:
    tau = (s - s0) / v with s0 the prior's mean, taken as known, and the spacing noise's variance sigma^2 / v^2;
    a tick left out (``used`` False, or a speed of 0) gives the prior, whose mean of tau is the setting [s]."""
    det = prior.p00 * prior.p11 - prior.p01 * prior.p01  # of the prior precision
    var_s0 = prior.p11 / det  # the prior's covariance, the inverse of its precision [m^2]
    if not used or speed <= 0.0:
        return Moments(prior.standstill_spacing, setting, var_s0, -prior.p01 / det, prior.p00 / det)
    return Moments(prior.standstill_spacing, (spacing - prior.standstill_spacing) / speed, var_s0, 0.0,
                   prior.noise_variance / (speed * speed))


@numba.njit(cache=True, error_model="numpy")
def _posterior_of_window(memory, prior, vehicles, out):  # noqa: ANN001, ANN202
    """The posterior of every vehicle of ``vehicles`` (n_envs, n_vehicles) bool (into ``out``, :class:`Moments`)
    from its window sums and prior mean of tau [s] (``memory``, :class:`WindowMemory`) under ``prior``
    (:class:`Prior`), each a plain tuple."""
    memory, prior, out = WindowMemory(*memory), Prior(*prior), Moments(*out)
    window_sums, prior_tau = memory.window_sums, memory.prior_tau
    n_envs, n_vehicles = prior_tau.shape
    for e in range(n_envs):
        for i in range(n_vehicles):
            if not vehicles[e, i]:
                continue
            sums = WindowSums(window_sums[e, i, 0], window_sums[e, i, 1], window_sums[e, i, 2], window_sums[e, i, 3],
                              window_sums[e, i, 4])
            moments = posterior_moments(sums, prior_tau[e, i], prior)
            out.mean_s0[e, i], out.mean_tau[e, i], out.var_s0[e, i] = moments.mean_s0, moments.mean_tau, moments.var_s0
            out.cov_s0_tau[e, i], out.var_tau[e, i] = moments.cov_s0_tau, moments.var_tau


follow_sources(__name__)
