"""Control charts on the monitor's estimate of tau, and the paper's switching rule.

Every chart takes one estimate per tick (the posterior mean of tau, (n_envs, n_vehicles) [s])
and keeps, per vehicle:

- ``alarm``: the charted statistic is outside its control limits now;
- ``exceedance``: an excursion started this tick. An excursion is a contiguous run of alarm
  ticks on one side, so it counts once however long it lasts; jumping straight from above
  the upper limit to below the lower one starts a new excursion;
- ``exceedances_in_window``: excursions started within the trailing ``exceedance_window``
  seconds, this tick included (a ring buffer of start ticks, O(1) per tick);
- ``run_length``: ticks since the last alarm tick (0 on an alarm tick) or since the chart was
  last (re)started [ticks].

The centre line (``center``) is the applied setting tau*: after a change of setting it ramps
towards the new setting with the controller, and the limits move with it tick by tick.

Charts: :class:`ShewhartChart` (the paper's), and the two standard SPC alternatives on the same
estimate, :class:`EwmaChart` and :class:`CusumChart`, registered by kind in :data:`CHARTS`.
:func:`switch_rule` is the paper's rule (3 exceedances within 35 s -> switch to 1.0 s) as a pure
function of the exceedance count and the setting, for the charts and the policies alike.

Caveat: at 10 Hz the estimate is a sliding-window posterior mean, strongly autocorrelated
from tick to tick (consecutive windows share all but one measurement), and the chart's
baseline sigma_desired is a design choice rather than the estimate's in-control spread.
Textbook in-control ARLs (22 ticks for the paper's 2-sigma Shewhart, 370 for 3-sigma, ~465
for CUSUM k = 0.5, h = 5) assume independent samples and do not apply; calibrate the limits
by simulation if false-alarm rates matter.
"""

from __future__ import annotations

from typing import Annotated, NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike

from timegap_env.compiled import STAGE_KERNEL, follow_sources
from timegap_env.config import CHART_KINDS, ChartConfig
from timegap_env.monitoring.batch import batch_array, batch_shape, check_finite, env_mask, setting_array, vehicle_mask
from timegap_env.state import OnState, PerEnv, State

__all__ = [
    "ChartRule", "ChartState", "ControlChart", "ShewhartChart", "EwmaChart", "CusumChart", "CHARTS", "make_chart", "switch_rule",
]


class ChartState(NamedTuple):
    """A chart after a tick, arrays (n_envs, n_vehicles); from :meth:`ControlChart.update_block`,
    one per tick, arrays (n_ticks, n_envs, n_vehicles)."""

    center: np.ndarray  # the centre line, the applied setting tau* [s]
    alarm: np.ndarray  # charted statistic outside its limits now [bool]
    side: np.ndarray  # -1 below the lower limit, +1 above the upper, 0 inside [-]
    exceedance: np.ndarray  # an excursion started this tick [bool]
    exceedances_in_window: np.ndarray  # excursions started within the trailing exceedance_window [-]
    run_length: np.ndarray  # ticks since the last alarm or (re)start [ticks]

    def tick(self, k: int) -> ChartState:
        """The state after tick ``k`` of a block (views into this one)."""
        return ChartState(*(field[k] for field in self))


class ChartMemory(NamedTuple):
    """What every chart carries from tick to tick besides its statistic, per vehicle ("followers")."""

    side: Annotated[np.ndarray, PerEnv(np.int8, "followers")]  # the charted side after the last tick [-]
    exceedance: Annotated[np.ndarray, PerEnv(bool, "followers")]  # an excursion started at the last tick
    exceedances_in_window: Annotated[np.ndarray, PerEnv(np.int64, "followers")]  # [-]
    run_length: Annotated[np.ndarray, PerEnv(np.int64, "followers")]  # [ticks]
    hold_off: Annotated[np.ndarray, PerEnv(np.int64, "followers")]  # ticks left in which alarms are held off
    # ring over the exceedance window's ticks ("chart_window"): chart tick of an excursion start, -1 none
    starts: Annotated[np.ndarray, PerEnv(np.int64, "followers", "chart_window", fill=-1)]
    # chart tick of each vehicle's last (re)start; older starts do not count
    restarted: Annotated[np.ndarray, PerEnv(np.int64, "followers")]


class ChartParts(NamedTuple):
    """Everything per env a :class:`ControlChart` holds."""

    memory: ChartMemory
    center: Annotated[np.ndarray, PerEnv(float, "followers")]  # the centre line, the applied setting tau* [s]
    # the statistic of EWMA (z [s] in column 0) and CUSUM (C+, C- [sigma_desired]) charts, unused by Shewhart's
    statistic: Annotated[np.ndarray, PerEnv(float, "followers", "statistic")]
    tick: Annotated[np.ndarray, PerEnv(np.int64)]  # ticks charted so far (the same in every env); slot tick % window


def chart_dims(config: ChartConfig, n_vehicles: int) -> dict[str, int]:
    """The sizes of :class:`ChartParts`' dimensions for ``n_vehicles`` vehicles ("followers") under ``config``."""
    return {"followers": n_vehicles, "chart_window": config.exceedance_window_ticks, "statistic": 2}

EWMA, CUSUM = CHART_KINDS.index("ewma"), CHART_KINDS.index("cusum")  # ChartRule.kind; the third, Shewhart, the default
if len(CHART_KINDS) != 3:  # chart_sides_env and restart_env handle these three; a new kind is a branch in each
    raise ImportError(f"timegap_env.config.CHART_KINDS {CHART_KINDS}: the chart kernels know shewhart, ewma, cusum")


class ChartRule(NamedTuple):
    """A chart's constants, as its kernels take them."""

    kind: int  # index of CHART_KINDS
    half_width: float  # the charted statistic's limits are centre -/+ this [s] (Shewhart, EWMA)
    ewma_lambda: float  # [-]
    baseline_std: float  # sigma_desired [s]
    cusum_k: float  # [sigma_desired]
    cusum_h: float  # [sigma_desired]

    @classmethod
    def from_config(cls, config: ChartConfig, kind: str) -> ChartRule:
        """The constants of a chart of ``kind`` (one of CHART_KINDS) under ``config``: the limits are centre -/+ L
        sigma_desired, the EWMA's its asymptotic L_ewma sigma_desired sqrt(lambda / (2 - lambda))."""
        lam = float(config.ewma_lambda)
        half_width = (config.ewma_width * config.baseline_std * np.sqrt(lam / (2.0 - lam)) if kind == "ewma"
                      else config.half_width)
        return cls(kind=CHART_KINDS.index(kind), half_width=float(half_width), ewma_lambda=lam,
                   baseline_std=float(config.baseline_std), cusum_k=float(config.cusum_k),
                   cusum_h=float(config.cusum_h))


class ControlChart(OnState):
    """What every chart shares: excursions, their windowed count, run length, re-centring.

    A subclass names its ``kind`` (its key in :data:`CHARTS`; its limits' ``half_width`` is the kind's, in
    :meth:`ChartRule.from_config`). How its statistic moves, on which side of its limits it lies and how it
    restarts are the kind's branches of :func:`chart_sides_env` and :func:`restart_env`, the kernels both the
    chart and the fused step run. A statistic lives in ``statistic`` (n_envs, n_vehicles, 2), in place.

    Its arrays are :attr:`parts` (:class:`ChartParts`), views of ``state`` at ``path`` (its own state when None),
    changed in place. Public state, arrays (n_envs, n_vehicles): ``center`` [s], ``side``, ``alarm``,
    ``exceedance``, ``exceedances_in_window``, ``run_length`` [ticks], ``hold_off`` [ticks].
    """

    kind = ""

    def __init__(self, n_envs: int, n_vehicles: int, center: ArrayLike, config: ChartConfig = ChartConfig(),
                 state: State | None = None, path: tuple[str, ...] = ()) -> None:
        self.config = config
        self.shape = batch_shape(n_envs, n_vehicles)
        # A start counts only if it is no older than the vehicle's last (re)start, so re-centring never clears the ring.
        self._bind(State(ChartParts, chart_dims(config, n_vehicles), n_envs) if state is None else state, path)
        self.rule = ChartRule.from_config(config, self.kind)
        self.reset(None, center)

    center = property(lambda self: self.parts.center, doc="The centre line, the applied setting tau* [s].")
    statistic = property(lambda self: self.parts.statistic, doc="The EWMA's or CUSUM's statistic (n_envs, n_vehicles, 2).")
    side = property(lambda self: self.parts.memory.side, doc="-1 below, +1 above the limits, 0 inside (n_envs, n_vehicles).")
    exceedance = property(lambda self: self.parts.memory.exceedance, doc="An excursion started at the last tick.")
    exceedances_in_window = property(
        lambda self: self.parts.memory.exceedances_in_window, doc="Excursions started within the trailing window [-]."
    )
    run_length = property(lambda self: self.parts.memory.run_length, doc="Ticks since the last alarm or (re)start.")
    hold_off = property(lambda self: self.parts.memory.hold_off, doc="Ticks left in which alarms are held off.")
    @property
    def half_width(self) -> float:
        """Distance from the centre line to either limit of the charted statistic [s]: L sigma_desired (the
        EWMA chart's own, :meth:`ChartRule.from_config`; the CUSUM chart holds its sums against ``cusum_h``
        instead)."""
        return self.rule.half_width

    @property
    def alarm(self) -> np.ndarray:
        """Charted statistic outside its limits now (n_envs, n_vehicles)."""
        return self.side != 0

    @property
    def state(self) -> ChartState:
        """Snapshot of the chart (copies)."""
        return ChartState(
            center=self.center.copy(),
            alarm=self.alarm,
            side=self.side.copy(),
            exceedance=self.exceedance.copy(),
            exceedances_in_window=self.exceedances_in_window.copy(),
            run_length=self.run_length.copy(),
        )

    def update(self, tau_estimate: ArrayLike) -> ChartState:
        """Chart one tick's estimate of tau (n_envs, n_vehicles) [s]; return the new state."""
        estimate = batch_array("tau_estimate", tau_estimate, self.shape)
        check_finite(tau_estimate=estimate)
        return self.update_block(estimate[None], self.center[None]).tick(0)

    def update_block(self, tau_estimates: ArrayLike, centers: ArrayLike) -> ChartState:
        """Chart n_ticks estimates of tau (n_ticks, n_envs, n_vehicles) [s], tick k against centre line
        ``centers[k]`` [s] (same shape; a ramping setting moves the limits with it); return the state after each tick.
        """
        estimates = np.asarray(tau_estimates, dtype=float)
        if estimates.ndim != 3 or estimates.shape[1:] != self.shape or not len(estimates):
            raise ValueError(f"tau_estimates has shape {estimates.shape}: expected (n_ticks >= 1, *{self.shape})")
        centers = np.asarray(centers, dtype=float)
        if centers.shape != estimates.shape:
            raise ValueError(f"centers has shape {centers.shape}: expected {estimates.shape} like tau_estimates")
        check_finite(tau_estimates=estimates, centers=centers)
        flags, counts = np.empty((2, *estimates.shape), dtype=bool), np.empty((2, *estimates.shape), dtype=np.int64)
        block = ChartState(center=centers, alarm=flags[0], side=np.empty(estimates.shape, dtype=np.int8),
                           exceedance=flags[1], exceedances_in_window=counts[0], run_length=counts[1])
        parts = self.parts
        _chart_ticks(tuple(self.rule), tuple(parts.memory), parts.tick, estimates, parts.statistic, tuple(block))
        parts.tick[:] += len(estimates)
        parts.center[:] = centers[-1]
        return block

    def recenter(self, center: ArrayLike, mask: ArrayLike | None = None) -> None:
        """Centre the chart on ``center`` [s] (the applied setting) for the vehicles in ``mask``.

        ``mask``: bool, broadcastable to (n_envs, n_vehicles), None = all. Their excursion
        history is cleared (it was measured against the old limits), their statistic restarts
        and ``run_length`` restarts at 0.
        """
        center, vehicles = setting_array(center, self.shape), vehicle_mask(mask, self.shape)
        parts = self.parts
        _restart(tuple(self.rule), tuple(parts.memory), parts.center, parts.statistic, parts.tick,
                 np.ascontiguousarray(center, dtype=float), np.ascontiguousarray(vehicles))

    def hold(self, ticks: ArrayLike, mask: ArrayLike | None = None) -> None:
        """Hold alarms off for the next ``ticks`` ticks (broadcast to (n_envs, n_vehicles)) where ``mask``.

        After a deliberate change of setting the estimate needs time to reach the
        new centre line; alarms in that time would only report the change itself.
        The statistic keeps updating meanwhile.
        """
        np.copyto(self.parts.memory.hold_off, np.asarray(ticks, dtype=np.int64), where=vehicle_mask(mask, self.shape))

    def reset(self, mask: ArrayLike | None, center: ArrayLike) -> None:
        """Restart the envs in ``mask`` ((n_envs,) bool, None = all), centred on ``center`` [s]."""
        vehicles = np.broadcast_to(env_mask(mask, self.shape[0])[:, None], self.shape)
        self.recenter(center, vehicles)



class ShewhartChart(ControlChart):
    """The paper's chart: alarm when the estimate leaves [tau* - L sigma_desired, tau* + L sigma_desired].

    Paper: N(1.6, 0.125), L = 2 -> LCL / CL / UCL = 1.35 / 1.6 / 1.85 s; at tau* = 1.0: 0.75 / 1.0 / 1.25 s.
    """

    kind = "shewhart"

    @property
    def lcl(self) -> np.ndarray:
        """Lower control limit (n_envs, n_vehicles) [s]."""
        return self.center - self.half_width

    @property
    def ucl(self) -> np.ndarray:
        """Upper control limit (n_envs, n_vehicles) [s]."""
        return self.center + self.half_width


class EwmaChart(ControlChart):
    """EWMA z_t = lambda x_t + (1 - lambda) z_{t-1}, starting at z = tau*.

    Asymptotic limits tau* -/+ width sigma_desired sqrt(lambda / (2 - lambda))
    (defaults lambda = 0.2, width = 3). Note that x_t is already a smoothed estimate.
    """

    kind = "ewma"

    ewma = property(lambda self: self.statistic[..., 0], doc="z (n_envs, n_vehicles) [s] (the chart's own array).")

    @property
    def lcl(self) -> np.ndarray:
        """Lower control limit of the EWMA (n_envs, n_vehicles) [s]."""
        return self.center - self.half_width

    @property
    def ucl(self) -> np.ndarray:
        """Upper control limit of the EWMA (n_envs, n_vehicles) [s]."""
        return self.center + self.half_width


class CusumChart(ControlChart):
    """Two-sided tabular CUSUM of the standardised deviation y = (x - tau*) / sigma_desired.

    C+ = max(0, C+ + y - k), C- = max(0, C- - y - k), both starting at 0; alarm above when
    C+ > h, below when C- > h (defaults k = 0.5, h = 5). The sums are not restarted after an
    alarm: a sustained shift stays one contiguous excursion until the sums fall back below h.
    """

    kind = "cusum"

    upper_sum = property(lambda self: self.statistic[..., 0], doc="C+ (n_envs, n_vehicles) [sigma_desired].")
    lower_sum = property(lambda self: self.statistic[..., 1], doc="C- (n_envs, n_vehicles) [sigma_desired].")


@numba.njit(cache=True, error_model="numpy")
def _restart(rule, memory, center, statistic, tick, centers, vehicles):  # noqa: ANN001, ANN202, PLR0913
    """:func:`restart_env` for every vehicle of ``vehicles`` (n_envs, n_vehicles) bool, on ``centers`` [s], at each
    env's chart tick ``tick`` (n_envs,)."""
    for e in range(vehicles.shape[0]):
        for f in range(vehicles.shape[1]):
            if vehicles[e, f]:
                restart_env(rule, memory, center, statistic, tick[e], centers[e, f], e, f)


@numba.njit(**STAGE_KERNEL)
def restart_env(rule, memory, center, statistic, tick, line, e, f):  # noqa: ANN001, ANN201, PLR0913
    """Vehicle ``f`` of env ``e`` re-centred on ``line`` [s] at chart tick ``tick``: its excursion history is
    cleared (it was measured against the old limits; starts before ``tick`` no longer count), its run length and
    hold-off restart at 0, and its statistic restarts (EWMA at the centre line, CUSUM's sums at 0); ``rule`` is
    :class:`ChartRule`, ``memory`` :class:`ChartMemory` (plain tuples)."""
    rule, memory = ChartRule(*rule), ChartMemory(*memory)
    center[e, f] = line
    memory.side[e, f], memory.exceedance[e, f] = 0, False
    memory.exceedances_in_window[e, f], memory.run_length[e, f], memory.hold_off[e, f] = 0, 0, 0
    memory.restarted[e, f] = tick
    if rule.kind == EWMA:
        statistic[e, f, 0] = line
    elif rule.kind == CUSUM:
        statistic[e, f, 0] = statistic[e, f, 1] = 0.0


@numba.njit(cache=True, error_model="numpy")
def _chart_ticks(rule, memory, first_tick, estimates, statistic, block):  # noqa: ANN001, ANN202, PLR0913
    """A block of ticks charted env by env, env e's from chart tick ``first_tick[e]``: the statistic's sides
    (:func:`chart_sides_env`), then what every chart does with them (:func:`count_excursions_env`), in place;
    ``block`` (:class:`ChartState`) comes in with its centre lines and leaves filled."""
    centers, sides = block[0], block[2]
    for e in range(estimates.shape[1]):
        chart_sides_env(rule, estimates, centers, statistic, sides, e, e)
        count_excursions_env(memory, first_tick[e], block, e, e)


@numba.njit(**STAGE_KERNEL)
def chart_sides_env(rule, estimates, centers, statistic, sides, e, column):  # noqa: ANN001, ANN201, PLR0913
    """Env ``e``'s charted statistic through a block of ticks and its side (-1, 0, +1) of its limits after each, into
    ``sides``; ``estimates``, ``centers`` and ``sides`` are (n_ticks, n_columns, n_vehicles), env ``e`` in column
    ``column``; ``rule`` is the chart's :class:`ChartRule` (a plain tuple), ``statistic`` its (n_envs, n_vehicles,
    2) array, carried on in place. The one place each chart kind's statistic is written:

    - Shewhart: the estimate itself against centre -/+ half_width;
    - EWMA: z = lambda x + (1 - lambda) z, against centre -/+ half_width;
    - CUSUM of y = (x - centre) / sigma_desired: C+ = max(0, C+ + y - k), C- = max(0, C- - y - k); above when
      C+ > h (and C+ >= C-), below when C- > h.
    """
    rule = ChartRule(*rule)
    n_ticks, n_vehicles = estimates.shape[0], estimates.shape[2]
    c = column
    for k in range(n_ticks):
        for f in range(n_vehicles):
            estimate, line = estimates[k, c, f], centers[k, c, f]
            if rule.kind == CUSUM:
                y = (estimate - line) / rule.baseline_std
                upper = statistic[e, f, 0] = max(0.0, statistic[e, f, 0] + y - rule.cusum_k)
                lower = statistic[e, f, 1] = max(0.0, statistic[e, f, 1] - y - rule.cusum_k)
                above = upper > rule.cusum_h and upper >= lower
                below = lower > rule.cusum_h and not above
                sides[k, c, f] = int(above) - int(below)
                continue
            value = estimate  # Shewhart's
            if rule.kind == EWMA:
                value = statistic[e, f, 0] = rule.ewma_lambda * estimate + (1.0 - rule.ewma_lambda) * statistic[e, f, 0]
            low, high = line - rule.half_width, line + rule.half_width
            sides[k, c, f] = 1 if value > high else (-1 if value < low else 0)


@numba.njit(**STAGE_KERNEL)
def count_excursions_env(memory, first_tick, block, e, column):  # noqa: ANN001, ANN201
    """What every chart does with its statistic's sides, tick by tick, for env ``e``, in place.

    Column ``column`` of ``block`` (:class:`ChartState` of (n_ticks, n_envs, n_vehicles) arrays) comes in with
    the statistic's sides in ``block.side``; they leave as the charted sides (0 while alarms are held off) and the
    rest of the column is filled; ``memory`` (:class:`ChartMemory`) carries on. Both come as plain tuples (see
    :mod:`timegap_env.sim.platoon`). Chart tick t uses ring slot t % window; the start it overwrites leaves the
    window, and counts down only if it was recorded since the vehicle's last restart.
    """
    memory, block = ChartMemory(*memory), ChartState(*block)
    side, hold_off, in_window, run_length = memory.side, memory.hold_off, memory.exceedances_in_window, memory.run_length
    n_ticks, n_vehicles = block.side.shape[0], block.side.shape[2]
    starts = memory.starts[e]  # (n_vehicles, window ticks)
    ring_length = starts.shape[1]
    c = column
    slot = first_tick % ring_length - 1  # the ring slot before the block's first tick's, then counted on
    for k in range(n_ticks):
        tick = first_tick + k
        slot = slot + 1 if slot + 1 < ring_length else 0  # tick % ring_length
        for i in range(n_vehicles):
            now = block.side[k, c, i] if hold_off[e, i] == 0 else 0
            hold_off[e, i] = max(hold_off[e, i] - 1, 0)
            started = now != 0 and now != side[e, i]  # a new excursion
            side[e, i], memory.exceedance[e, i] = now, started
            leaving = starts[i, slot] >= memory.restarted[e, i]  # -1 (no start) never counts
            in_window[e, i] += int(started) - int(leaving)
            starts[i, slot] = tick if started else -1
            run_length[e, i] = 0 if now != 0 else run_length[e, i] + 1
            block.side[k, c, i], block.alarm[k, c, i], block.exceedance[k, c, i] = now, now != 0, started
            block.exceedances_in_window[k, c, i], block.run_length[k, c, i] = in_window[e, i], run_length[e, i]


CHARTS: dict[str, type[ControlChart]] = {chart.kind: chart for chart in (ShewhartChart, EwmaChart, CusumChart)}
if tuple(CHARTS) != CHART_KINDS:  # the config validates ChartConfig.kind against CHART_KINDS
    raise ImportError(f"charts {tuple(CHARTS)} differ from timegap_env.config.CHART_KINDS {CHART_KINDS}")


def make_chart(n_envs: int, n_vehicles: int, center: ArrayLike, config: ChartConfig = ChartConfig(),
               state: State | None = None, path: tuple[str, ...] = ()) -> ControlChart:
    """The chart of kind ``config.kind``, centred on ``center`` [s], on ``state`` at ``path`` (its own if None)."""
    return CHARTS[config.kind](n_envs, n_vehicles, center, config, state, path)


def switch_rule(exceedances_in_window: ArrayLike, setting: ArrayLike, config: ChartConfig = ChartConfig()) -> np.ndarray:
    """The paper's rule: which vehicles should switch their setting to ``config.switch_to``.

    True where at least ``config.switch_exceedances`` excursions started within the trailing
    ``config.exceedance_window`` (paper: 3 within 35 s) and the ``setting`` [s] (a chart's centre
    line, or a policy's reading of the setting) is not ``switch_to`` already; arrays of one shape.
    Pure: the caller applies the switch (tau* <- switch_to) and re-centres the monitor and the
    chart, which clears the count.
    """
    enough = np.asarray(exceedances_in_window) >= config.switch_exceedances
    return enough & ~np.isclose(setting, config.switch_to)


follow_sources(__name__)
