"""Calibrate the follower model to recorded cars: replay the recorded predecessor, minimise spacing error.

A car's records (its speed and its spacing to the car ahead, with the predecessor's speed) are cut
into :class:`Segment` s without gaps. :func:`simulate_follower` drives the project's follower (GLVD
under the CTH controller, in ACC: no V2V feed-forward; the same :func:`~timegap_env.sim.platoon.cth_command`
and :func:`~timegap_env.sim.platoon.follower_tick` as the platoon) behind the recorded predecessor,
from the segment's first record; :func:`fit_follower` finds the :class:`FollowerModel` that minimises
the squared spacing error over all segments (``scipy.optimize.least_squares``, trust region
reflective, three starts).

What can be fitted. Without V2V the closed loop of T da/dt = -a + K u, u = k_s dd + k_v dv + k_a a
depends on T, K, k_s, k_v and k_a only through (1 - K k_a) / T, K k_s / T and K k_v / T as long as
the command stays within its bounds: spacing and speed records cannot tell K from the gains, nor
k_a from T. So the fit holds K = 1 and k_a at :class:`~timegap_env.config.PlatoonConfig`'s and fits
the lag T, the gains k_s and k_v, the highest command (commercial ACCs accelerate gently) and one
tau* per distance setting (:data:`FITTED`). Two more parameters come from ``base`` instead:
s0, because where a car's speed hardly varies only s0 + tau* v is pinned down and a free s0 trades
off against tau* (on OpenACC it ran to 13 m with tau* at 0.1 s), so the caller measures it (the
spacing of stopped cars); and the lowest command, because recorded ACC driving seldom brakes at
the car's limit, so records do not reveal it. The analytic string stability (``string_stability``)
depends on the same combinations as the closed loop, so it does not depend on these choices.

Two references, fitted to the same segments: :func:`simulate_constant_time_gap`, a follower that
always keeps s = s0 + tau v (x' = (x_predecessor - x - s0) / tau; tau and s0 fitted), and the
project's default follower with only tau* fitted (:func:`fit_follower` with ``free=False``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numba
import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from timegap_env.compiled import follow_sources
from timegap_env.config import PlatoonConfig
from timegap_env.leaders.openacc import valid_stretches
from timegap_env.sim.platoon import Controller, ZOHCoefficients, cth_command, follower_tick

FITTED = ("lag", "k_s", "k_v", "accel_max")  # the FollowerModel fields fit_follower fits; the rest come from base
# Bounds of the fitted parameters: physically plausible; a fit that ends on one is reported as such.
BOUNDS = {
    "lag": (0.05, 5.0),  # T [s]
    "k_s": (1e-3, 3.0),  # [1/s^2]
    "k_v": (0.0, 5.0),  # [1/s]
    "accel_max": (0.3, 4.0),  # [m/s^2]
}
SETTING_BOUNDS = (0.1, 6.0)  # tau* [s]
STANDSTILL_SPACING_BOUNDS = (0.0, 20.0)  # s0 of the constant time-gap reference [m]
STARTS = (1.0, 0.5, 2.0)  # the fit starts from the base follower's lag and gains times each of these [-]
START_ACCEL_MAX = 2.0  # ... and from this highest command [m/s^2]
MAX_EVALUATIONS = 300  # of the residuals, per start [-]


class Segment(NamedTuple):
    """A stretch of one follower's records without a gap, and what its predecessor did meanwhile, (n,) each."""

    predecessor_position: np.ndarray  # [m], in a frame where the follower starts at 0
    predecessor_speed: np.ndarray  # [m/s]
    speed: np.ndarray  # the follower's recorded speed [m/s]
    spacing: np.ndarray  # recorded bumper-to-bumper spacing [m]
    initial_accel: float  # the follower's acceleration at the first record [m/s^2]


def record_segments(
    speed: np.ndarray, predecessor_speed: np.ndarray, spacing: np.ndarray, dt: float, min_duration: float
) -> list[Segment]:
    """The stretches of at least ``min_duration`` [s] in which the follower's ``speed`` [m/s], its predecessor's
    and the ``spacing`` [m] between them are all recorded (finite, spacing > 0), each (n_ticks,) every ``dt`` [s].

    The predecessor's position is the follower's recorded position (its speed integrated by the
    trapezoid rule) plus the recorded spacing, so the recorded follower reproduces the recorded spacing.
    """
    valid = np.isfinite(speed) & np.isfinite(predecessor_speed) & np.isfinite(spacing) & (spacing > 0)
    segments = []
    for start, end in valid_stretches(valid):
        if (end - start - 1) * dt < min_duration:
            continue
        v, s = speed[start:end], spacing[start:end]
        position = np.r_[0.0, np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)]
        segments.append(Segment(position + s, predecessor_speed[start:end].copy(), v.copy(), s.copy(),
                                float((v[1] - v[0]) / dt)))
    return segments


class FollowerModel(NamedTuple):
    """A follower in ACC as the calibration sees it (gain K = 1 and k_a held, see the module docstring; :data:`FITTED`
    the fields it fits); tau* is apart, one per distance setting."""

    lag: float  # GLVD T [s]
    k_s: float  # gain on the spacing error [1/s^2]
    k_v: float  # gain on the speed difference [1/s]
    standstill_spacing: float  # s0 [m]
    accel_min: float  # lowest command [m/s^2]
    accel_max: float  # highest command [m/s^2]

    @classmethod
    def of(cls, config: PlatoonConfig) -> FollowerModel:
        """The follower of ``config`` (its first follower's lag)."""
        return cls(float(config.per_follower("actuation_lag")[0]), config.k_s, config.k_v, config.standstill_spacing,
                   config.accel_min, config.accel_max)


@dataclasses.dataclass(frozen=True)
class FollowerFit:
    """A car's fitted follower: the model, tau* per distance setting, and how well it fitted."""

    model: FollowerModel
    settings: dict[str, float]  # tau* [s] by distance setting ("S", "L")
    spacing_rmse: float  # over the segments it was fitted on [m]
    n_segments: int
    duration: float  # of those segments [s]

    def platoon_config(self, distance_setting: str, base: PlatoonConfig = PlatoonConfig(), **overrides: object) -> PlatoonConfig:
        """A platoon of this car in ACC at ``distance_setting``: ``base`` with this follower (gain 1), ``overrides`` on top."""
        fields = {"actuation_lag": self.model.lag, "actuation_gain": 1.0, "k_s": self.model.k_s, "k_v": self.model.k_v,
                  "standstill_spacing": self.model.standstill_spacing, "accel_min": self.model.accel_min,
                  "accel_max": self.model.accel_max, "initial_setting": self.settings[distance_setting], "v2v": False,
                  **overrides}
        return base.with_overrides(fields)


def simulate_follower(
    segment: Segment, model: FollowerModel, setting: float, base: PlatoonConfig = PlatoonConfig()
) -> tuple[np.ndarray, np.ndarray]:
    """Spacing [m] and speed [m/s], (n,) each, of ``model`` in ACC at ``setting`` tau* [s] behind the segment's
    predecessor, from the segment's first record; k_a and the tick from ``base``."""
    return _simulate(segment, _kernel_model(model, base), setting)


def _kernel_model(model: FollowerModel, base: PlatoonConfig) -> tuple[tuple, tuple]:
    """The (ZOHCoefficients, Controller) plain tuples of ``model`` in ACC, for :func:`_follow`."""
    zoh = ZOHCoefficients.for_glvd(np.array([model.lag]), np.array([1.0]), base.dt)
    controller = Controller.from_config(base)._replace(
        k_s=float(model.k_s), k_v=float(model.k_v), k_f=0.0, standstill_spacing=float(model.standstill_spacing),
        accel_min=float(model.accel_min), accel_max=float(model.accel_max),
    )
    return tuple(zoh), tuple(controller)


def _simulate(segment: Segment, kernel_model: tuple[tuple, tuple], setting: float) -> tuple[np.ndarray, np.ndarray]:
    spacing, speed = np.empty(segment.speed.size), np.empty(segment.speed.size)
    _follow(segment.predecessor_position, segment.predecessor_speed, segment.speed[0], segment.initial_accel,
            *kernel_model, float(setting), spacing, speed)
    return spacing, speed


@numba.njit(cache=True)
def _follow(predecessor_position, predecessor_speed, speed0, accel0, zoh, controller, setting, out_spacing, out_speed):  # noqa: ANN001, ANN202, PLR0913
    """:func:`simulate_follower`, tick by tick; ``zoh`` (:class:`ZOHCoefficients` of (1,) arrays) and ``controller``
    (:class:`Controller`) come as plain tuples, as in every kernel of the package."""
    zoh, controller = ZOHCoefficients(*zoh), Controller(*controller)
    coefficients = ZOHCoefficients(zoh.a_from_a[0], zoh.a_from_u[0], zoh.v_from_a[0], zoh.v_from_u[0],
                                   zoh.x_from_a[0], zoh.x_from_u[0])
    x, v, a = 0.0, speed0, accel0
    no_feedforward = (0.0, 0.0)
    for k in range(predecessor_position.size):
        spacing = predecessor_position[k] - x
        out_spacing[k], out_speed[k] = spacing, v
        command = cth_command(spacing, v, predecessor_speed[k], a, no_feedforward, setting, controller)
        x, v, a = follower_tick(x, v, a, command, coefficients, controller.dt)


def simulate_constant_time_gap(
    segment: Segment, setting: float, standstill_spacing: float, dt: float
) -> tuple[np.ndarray, np.ndarray]:
    """Spacing [m] and speed [m/s] of a follower that always keeps s = s0 + tau v behind the segment's predecessor:
    x' = (x_predecessor - x - s0) / tau, solved exactly over each tick with the predecessor's speed held."""
    spacing = np.empty(segment.speed.size)
    decay = math.exp(-dt / setting)
    s = segment.spacing[0]
    for k in range(spacing.size):  # s' = v_p - (s - s0) / tau
        spacing[k] = s
        target = standstill_spacing + setting * segment.predecessor_speed[k]
        s = target + (s - target) * decay
    return spacing, (spacing - standstill_spacing) / setting


def fit_follower(
    segments: Sequence[Segment], distance_settings: Sequence[str], base: PlatoonConfig = PlatoonConfig(), free: bool = True
) -> FollowerFit:
    """Fit to ``segments`` (``distance_settings[i]`` the distance setting of segment i) the :data:`FITTED`
    parameters and one tau* per distance setting, minimising the squared spacing error over all segments; the
    other parameters are ``base``'s. ``free=False`` fits only tau*: the reference "default follower, tau* fitted"."""
    names = sorted(set(distance_settings))
    index = [names.index(name) for name in distance_settings]
    base_model = FollowerModel.of(base)
    n_fitted = len(FITTED) if free else 0

    def model_of(p: np.ndarray) -> FollowerModel:
        return base_model._replace(**{name: float(value) for name, value in zip(FITTED, p[:n_fitted])})

    def spacing_errors(p: np.ndarray) -> np.ndarray:
        kernel_model = _kernel_model(model_of(p), base)
        return np.concatenate([_simulate(segment, kernel_model, p[n_fitted + i])[0] - segment.spacing
                               for segment, i in zip(segments, index)])

    _, initial_settings = static_fit(segments, index, len(names))
    lower = [BOUNDS[name][0] for name in FITTED[:n_fitted]] + [SETTING_BOUNDS[0]] * len(names)
    upper = [BOUNDS[name][1] for name in FITTED[:n_fitted]] + [SETTING_BOUNDS[1]] * len(names)
    starts = [[base_model.lag * scale, base_model.k_s * scale, base_model.k_v * scale, START_ACCEL_MAX][:n_fitted]
              + list(initial_settings) for scale in (STARTS if free else STARTS[:1])]
    best = _best_fit(spacing_errors, starts, lower, upper)
    return FollowerFit(
        model=model_of(best.x),
        settings={name: float(value) for name, value in zip(names, best.x[n_fitted:])},
        spacing_rmse=float(np.sqrt(2.0 * best.cost / sum(segment.speed.size for segment in segments))),
        n_segments=len(segments),
        duration=float(sum(segment.speed.size - 1 for segment in segments) * base.dt),
    )


def fit_constant_time_gap(
    segments: Sequence[Segment], distance_settings: Sequence[str], dt: float
) -> tuple[float, dict[str, float]]:
    """The reference constant time-gap follower fitted to ``segments``: (s0 [m], tau [s] per distance setting)."""
    names = sorted(set(distance_settings))
    index = [names.index(name) for name in distance_settings]
    initial_s0, initial_settings = static_fit(segments, index, len(names))

    def spacing_errors(p: np.ndarray) -> np.ndarray:
        return np.concatenate([simulate_constant_time_gap(segment, p[1 + i], p[0], dt)[0] - segment.spacing
                               for segment, i in zip(segments, index)])

    lower = [STANDSTILL_SPACING_BOUNDS[0]] + [SETTING_BOUNDS[0]] * len(names)
    upper = [STANDSTILL_SPACING_BOUNDS[1]] + [SETTING_BOUNDS[1]] * len(names)
    best = _best_fit(spacing_errors, [[initial_s0, *initial_settings]], lower, upper)
    return float(best.x[0]), {name: float(value) for name, value in zip(names, best.x[1:])}


def static_fit(segments: Sequence[Segment], index: Sequence[int], n_settings: int) -> tuple[float, np.ndarray]:
    """s0 [m] and one tau [s] per setting from one least-squares fit of s = s0 + tau v over the segments' records,
    ``index[i]`` the setting of segment i."""
    rows, targets = [], []
    for segment, i in zip(segments, index):
        design = np.zeros((segment.speed.size, 1 + n_settings))
        design[:, 0], design[:, 1 + i] = 1.0, segment.speed
        rows.append(design)
        targets.append(segment.spacing)
    solution = np.linalg.lstsq(np.concatenate(rows), np.concatenate(targets), rcond=None)[0]
    return float(solution[0]), solution[1:]


def _best_fit(
    residuals: Callable[[np.ndarray], np.ndarray], starts: Sequence[Sequence[float]], lower: list[float], upper: list[float]
) -> OptimizeResult:
    """The ``least_squares`` result of least cost over the starts (each clipped into the bounds)."""
    results = [least_squares(residuals, np.clip(start, lower, upper), bounds=(lower, upper), x_scale="jac",
                             max_nfev=MAX_EVALUATIONS) for start in starts]
    return min(results, key=lambda result: result.cost)


# Its kernel, which runs the platoon's: numba's cache by content
follow_sources(__name__)
