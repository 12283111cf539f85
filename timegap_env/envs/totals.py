"""What an episode adds up, step by step, and the episode summary made of it (``info["episode_<name>"]``)."""

from __future__ import annotations

from typing import Annotated, NamedTuple

import numba
import numpy as np

from timegap_env.compiled import STAGE_KERNEL, follow_sources
from timegap_env.config import EnvConfig
from timegap_env.envs.reward import StepReadouts
from timegap_env.state import PerEnv, State

TOTAL = Annotated[np.ndarray, PerEnv(float)]  # a float per env


class EpisodeTotals(NamedTuple):
    """Sums (and extremes) over the steps of each env's episode so far, arrays (n_envs,)."""

    steps: TOTAL  # [-]
    gap_deviation: TOTAL  # follower-ticks' capped abs(actual time gap - applied setting), the tracking term's [s]
    alarm_ticks: TOTAL  # follower-ticks in alarm [-]
    exceedances: TOTAL  # excursion starts, all followers [-]
    max_deviation: TOTAL  # largest abs(estimate - the chart's centre line) [s]
    jerk_squared: TOTAL  # per step: sum over ticks of jerk^2, mean over followers [m^2/s^6]
    switches: TOTAL  # follower setting changes [-]
    setting: TOTAL  # per step: mean setting over followers [s]
    capacity: TOTAL  # per step: mean capacity implied by the settings at the speeds driven [veh/h]
    collision: TOTAL  # 1 once a collision happened [-]
    min_ttc: Annotated[np.ndarray, PerEnv(float, fill=np.inf)]  # smallest time-to-collision [s]

    @classmethod
    def zeros(cls, n_envs: int) -> EpisodeTotals:
        """Totals of no step (zeros, and an infinite min TTC) in a state of their own."""
        return State(cls, {}, n_envs).views

    def restart(self, mask: np.ndarray) -> None:
        """Back to no step for the envs in ``mask`` (n_envs,) bool."""
        for name, total in zip(self._fields, self):
            total[mask] = np.inf if name == "min_ttc" else 0.0

    def add_step(
        self, readouts: StepReadouts, setting: np.ndarray, changed: np.ndarray, gap_per_vehicle: float
    ) -> None:
        """Add a step from its ``readouts``; ``setting`` [s] and ``changed`` (n_envs, n_followers) are the settings
        at its end and which changed at its start, ``gap_per_vehicle`` [m] the standstill spacing plus a vehicle length."""
        _add_step(tuple(self), tuple(readouts), setting, changed, float(gap_per_vehicle))

    def summary(self, config: EnvConfig) -> dict[str, np.ndarray]:
        """Episode statistics so far under ``config``, each (n_envs,)."""
        steps = np.maximum(self.steps, 1)
        follower_ticks = steps * config.ticks_per_decision * config.platoon.n_followers
        return {
            "mean_gap_deviation": self.gap_deviation / follower_ticks,  # true |actual gap - setting|, capped [s]
            "time_out_of_control": self.alarm_ticks * config.platoon.dt / config.platoon.n_followers,  # per follower [s]
            "exceedances": self.exceedances.copy(),  # all followers [-]
            "max_deviation": self.max_deviation.copy(),  # largest |estimate - centre line| [s]
            "min_ttc": self.min_ttc.copy(),  # [s]
            # sqrt of the mean over steps of a step's summed squared jerk: sqrt(ticks per step) times
            # the RMS of the per-tick jerk (info["jerk"] divides by the ticks) [m/s^3]
            "rms_jerk": np.sqrt(self.jerk_squared / steps),
            "switches": self.switches.copy(),  # follower setting changes [-]
            "mean_setting": self.setting / steps,  # [s]
            "mean_capacity": self.capacity / steps,  # implied by the settings at the speeds driven [veh/h]
            "collision": self.collision.astype(bool),
            "duration": self.steps * config.decision_interval,  # [s]
        }




@numba.njit(cache=True, error_model="numpy")
def _add_step(totals, readouts, setting, changed, gap_per_vehicle):  # noqa: ANN001, ANN202
    """:meth:`EpisodeTotals.add_step`; the structures come as plain tuples (see :mod:`timegap_env.sim.platoon`)."""
    for e in range(setting.shape[0]):
        add_step_env(totals, readouts, setting, changed, gap_per_vehicle, e)


@numba.njit(**STAGE_KERNEL)
def add_step_env(totals, readouts, setting, changed, gap_per_vehicle, e):  # noqa: ANN001, ANN201, PLR0913
    """Env ``e``'s part of :func:`_add_step`."""
    totals, readouts = EpisodeTotals(*totals), StepReadouts(*readouts)
    n_followers = setting.shape[1]
    jerk_squared = switches = setting_sum = capacity = 0.0
    min_ttc = np.inf
    for f in range(n_followers):
        v = readouts.final_speed[e, f]  # [m/s]
        jerk_squared += readouts.jerk_squared[e, f]
        switches += changed[e, f]
        setting_sum += setting[e, f]
        capacity += 3600.0 * v / (v * setting[e, f] + gap_per_vehicle)  # [veh/h] at the current speed
        min_ttc = min(min_ttc, readouts.min_ttc[e, f])
    totals.steps[e] += 1
    totals.gap_deviation[e] += readouts.gap_deviation_sum[e]
    totals.alarm_ticks[e] += readouts.alarm_ticks[e]
    totals.exceedances[e] += readouts.exceedances[e]
    totals.max_deviation[e] = max(totals.max_deviation[e], readouts.max_deviation[e])
    totals.jerk_squared[e] += jerk_squared / n_followers
    totals.switches[e] += switches
    totals.setting[e] += setting_sum / n_followers
    totals.capacity[e] += capacity / n_followers
    totals.collision[e] = max(totals.collision[e], 1.0 if readouts.collided[e] else 0.0)
    totals.min_ttc[e] = min(totals.min_ttc[e], min_ttc)


follow_sources(__name__)
