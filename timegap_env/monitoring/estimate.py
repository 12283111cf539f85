"""The monitor on measured data: a follower's time gap estimated from its recorded speeds and spacings.

:func:`estimate_time_gap` streams the same Bayesian monitor the environment uses
(:class:`~timegap_env.monitoring.monitor.TimeGapMonitor`, the paper's Proposition over a sliding
window) over the records of real cars, e.g. an :class:`~timegap_env.leaders.openacc.OpenAccRun`'s
``speed[:, 1:]`` and ``spacing``. Records with a gap (NaN) are skipped as the monitor skips
sensor dropouts, so nothing NaN comes out.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from timegap_env.config import MonitorConfig, PlatoonConfig
from timegap_env.monitoring.monitor import TimeGapMonitor


class TimeGapEstimate(NamedTuple):
    """The posterior of tau after every record, shaped like the records: (n_ticks,) or (n_ticks, n_followers)."""

    mean: np.ndarray  # posterior mean of tau [s]
    std: np.ndarray  # posterior standard deviation of tau [s]
    used: np.ndarray  # the record was used; False where it was skipped (a gap, or implausible) [bool]


def estimate_time_gap(
    speed: ArrayLike,
    spacing: ArrayLike,
    *,
    setting: float = PlatoonConfig.initial_setting,
    config: MonitorConfig = MonitorConfig(),
) -> TimeGapEstimate:
    """The monitor's estimate of tau after each record of one follower or several.

    ``speed`` [m/s] and ``spacing`` [m] (bumper-to-bumper gap to the car ahead): (n_ticks,) for one
    follower or (n_ticks, n_followers), one record per ``config.dt``; NaN marks a gap. ``setting``
    [s]: the prior mean of tau, the setting the car is believed to keep (the prior's spread and
    the standstill spacing are ``config``'s).
    """
    speed, spacing = (np.asarray(values, dtype=float) for values in (speed, spacing))
    if speed.shape != spacing.shape or speed.ndim not in (1, 2) or not speed.shape[0]:
        raise ValueError(f"speed, spacing have shapes {speed.shape}, {spacing.shape}: expected one shape, "
                         "(n_ticks >= 1,) or (n_ticks >= 1, n_followers)")
    one_follower = speed.ndim == 1
    records = speed.reshape(speed.shape[0], 1, -1), spacing.reshape(spacing.shape[0], 1, -1)  # (n_ticks, 1 env, n)
    monitor = TimeGapMonitor(1, records[0].shape[2], setting, config)
    ticks = monitor.update_block(*records)
    mean, std, used = ticks.tau_mean[:, 0], np.sqrt(ticks.tau_var[:, 0]), ticks.used[:, 0]
    if one_follower:
        return TimeGapEstimate(mean[:, 0], std[:, 0], used[:, 0])
    return TimeGapEstimate(mean, std, used)
