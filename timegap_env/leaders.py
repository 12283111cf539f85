"""Leader speed profiles: the disturbance every platoon follows.

A :class:`LeaderProfile` is a speed series [m/s] with its acceleration [m/s^2]
sampled every ``dt`` [s]. Sources:

- ``LeaderProfile.from_acceleration``: integrate an acceleration profile from an
  initial speed, kept within a speed band (the paper's method);
- ``LeaderProfile.from_speed`` / ``LeaderProfile.from_csv``: the user's own data;
- the seeded synthetic families below (``aggressive_cycles``, ``sinusoid``,
  ``hard_braking``, ``stochastic_human``);
- :mod:`timegap_env.ngsim` (real NGSIM I-80 vehicles) and
  :mod:`timegap_env.human_leader` (highway-env's IDM driver).
"""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

import numba
import numpy as np

from timegap_env.config import (
    AggressiveCyclesConfig,
    HardBrakingConfig,
    LeaderConfig,
    SinusoidConfig,
    StochasticHumanConfig,
)


def _series(name: str, values: np.ndarray) -> np.ndarray:
    """``values`` as a finite 1-D float array of at least 2 samples; ValueError naming ``name`` otherwise."""
    array = np.asarray(values, dtype=float)
    if array.ndim != 1 or array.size < 2:
        raise ValueError(f"{name} has shape {array.shape}: must be 1-D with at least 2 samples")
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] = {array[bad[0]]}: every sample must be finite ({bad.size} are not)")
    return array


@dataclasses.dataclass(frozen=True)
class LeaderProfile:
    """A leader's speed and acceleration, one sample every ``dt``."""

    speed: np.ndarray  # (n,) [m/s]
    accel: np.ndarray  # (n,) [m/s^2]
    dt: float  # [s]
    name: str = "custom"

    def __post_init__(self) -> None:
        if not (isinstance(self.dt, (int, float)) and math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"LeaderProfile.dt = {self.dt!r}: must be a finite number > 0")
        for field in ("speed", "accel"):
            values = _series(f"LeaderProfile.{field}", getattr(self, field)).copy()
            values.setflags(write=False)
            object.__setattr__(self, field, values)
        if self.speed.shape != self.accel.shape:
            raise ValueError(
                f"LeaderProfile.accel has shape {self.accel.shape}, speed has {self.speed.shape}: must match"
            )
        negative = np.flatnonzero(self.speed < 0)
        if negative.size:
            raise ValueError(f"LeaderProfile.speed[{negative[0]}] = {self.speed[negative[0]]}: must be >= 0")

    @property
    def t(self) -> np.ndarray:
        """Sample times [s]."""
        return np.arange(self.speed.size) * self.dt

    @property
    def duration(self) -> float:
        """Time from the first to the last sample [s]."""
        return (self.speed.size - 1) * self.dt

    @classmethod
    def from_speed(cls, speed: np.ndarray, dt: float = LeaderConfig.dt, name: str = "custom") -> LeaderProfile:
        """A profile from a speed series [m/s]; the acceleration is its central difference."""
        speed = _series("speed", speed)
        return cls(speed=speed, accel=np.gradient(speed, dt), dt=dt, name=name)

    @classmethod
    def from_acceleration(
        cls,
        accel: np.ndarray,
        leader: LeaderConfig = LeaderConfig(),
        name: str = "integrated",
    ) -> LeaderProfile:
        """Integrate ``accel`` [m/s^2] from ``leader.initial_speed``, holding the speed inside ``leader.speed_band``.

        Where the band stops the integration the realised acceleration is the
        clipped one, so speed and acceleration stay consistent.
        """
        accel = _series("accel", accel)
        speed = _integrate_in_band(accel, leader.initial_speed, leader.dt, *leader.speed_band)  # one sample longer
        realised = np.diff(speed) / leader.dt
        speed = speed[:-1]
        return cls(speed=speed, accel=realised, dt=leader.dt, name=name)

    @classmethod
    def from_csv(cls, path: str | Path, dt: float = LeaderConfig.dt, name: str | None = None) -> LeaderProfile:
        """Read a profile from a CSV file with a header.

        Columns: ``speed`` [m/s] (required); ``time`` [s] (optional, evenly
        spaced, sets ``dt``); ``accel`` [m/s^2] (optional, else differentiated).
        """
        path = Path(path)
        with path.open(newline="") as handle:
            reader = csv.DictReader(handle)
            columns = reader.fieldnames or []
            if "speed" not in columns:
                raise ValueError(f"{path}: missing column 'speed' (found columns {columns})")
            rows = list(reader)
        data = {}
        for column in ("time", "speed", "accel"):
            if column not in columns:
                continue
            values = np.empty(len(rows))
            for i, row in enumerate(rows):
                try:
                    values[i] = float(row[column])
                except (TypeError, ValueError):
                    raise ValueError(
                        f"{path}: row {i + 2}, column '{column}' = {row[column]!r} is not a number"
                    ) from None
            data[column] = values
        if "time" in data:
            steps = np.diff(data["time"])
            if steps.size == 0 or not np.allclose(steps, steps[0], rtol=1e-6, atol=1e-9) or steps[0] <= 0:
                raise ValueError(f"{path}: column 'time' must increase in even steps")
            dt = float(steps[0])
        name = name or path.stem
        if "accel" in data:
            return cls(speed=data["speed"], accel=data["accel"], dt=dt, name=name)
        return cls.from_speed(data["speed"], dt=dt, name=name)


# --------------------------------------------------------------------------- synthetic families
def aggressive_cycles(
    seed: int | None,
    params: AggressiveCyclesConfig = AggressiveCyclesConfig(),
    leader: LeaderConfig = LeaderConfig(),
) -> LeaderProfile:
    """The paper's leader: alternating acceleration and deceleration phases, e.g. +/-1.5-3.5 m/s^2 for 3-9 s.

    The acceleration moves between phases at ``max_jerk``. A phase whose sign
    would drive the speed out of the band takes the other sign, and is cut
    short where it would still leave the band.
    """
    rng = np.random.default_rng(seed)
    low, high = leader.speed_band
    jerk_step = params.max_jerk * leader.dt  # largest change of acceleration in one tick [m/s^2]
    accel = np.zeros(leader.n_samples)
    sign = rng.choice([-1.0, 1.0])
    speed, current, k = leader.initial_speed, 0.0, 0
    while k < leader.n_samples:  # phase by phase, then tick by tick: each phase depends on the speed reached
        length = int(round(rng.uniform(*params.phase_duration_range) / leader.dt))
        magnitude = rng.uniform(*params.accel_range)
        target = 0.0
        if rng.random() >= params.cruise_probability:
            if not low <= speed + sign * magnitude * length * leader.dt <= high:
                sign = -sign
            ramp_margin = (magnitude + abs(current)) ** 2 / params.max_jerk  # gained while ramping in and out [m/s]
            room = (high - speed if sign > 0 else speed - low) - ramp_margin  # [m/s]
            length = max(1, min(length, int(room / (magnitude * leader.dt))))
            target = sign * magnitude
            sign = -sign
        ticks = min(length, leader.n_samples - k)
        current, speed = _jerk_limited_phase(accel[k : k + ticks], current, target, jerk_step, speed, leader.dt)
        k += ticks
    return LeaderProfile.from_acceleration(accel, leader, name="aggressive_cycles")


def sinusoid(
    seed: int | None, params: SinusoidConfig = SinusoidConfig(), leader: LeaderConfig = LeaderConfig()
) -> LeaderProfile:
    """Speed oscillation around the initial speed with a seeded amplitude, period and phase, inside the band."""
    rng = np.random.default_rng(seed)
    low, high = leader.speed_band
    amplitude = min(rng.uniform(*params.amplitude_range), 0.5 * (high - low))
    period = rng.uniform(*params.period_range)
    phase = rng.uniform(0.0, 2.0 * np.pi)
    mean = min(max(leader.initial_speed, low + amplitude), high - amplitude)
    omega = 2.0 * np.pi / period
    t = np.arange(leader.n_samples) * leader.dt
    speed = mean + amplitude * np.sin(omega * t + phase)
    accel = amplitude * omega * np.cos(omega * t + phase)
    return LeaderProfile(speed=speed, accel=accel, dt=leader.dt, name="sinusoid")


def hard_braking(
    seed: int | None, params: HardBrakingConfig = HardBrakingConfig(), leader: LeaderConfig = LeaderConfig()
) -> LeaderProfile:
    """Cruise at the initial speed, brake hard ``n_events`` times at seeded moments, recover each time."""
    rng = np.random.default_rng(seed)
    accel = np.zeros(leader.n_samples)
    slot = leader.n_samples // params.n_events  # one event per slot, so events never overlap
    for event in range(params.n_events):
        decel = rng.uniform(*params.decel_range)
        drop = min(rng.uniform(*params.speed_drop_range), leader.initial_speed - leader.speed_band[0])
        brake_ticks = int(round(drop / decel / leader.dt))
        recover_ticks = int(round(drop / params.recovery_accel / leader.dt))
        latest_start = max(slot - brake_ticks - recover_ticks, 1)
        start = event * slot + int(rng.integers(0, latest_start))
        accel[start : start + brake_ticks] = -decel
        accel[start + brake_ticks : start + brake_ticks + recover_ticks] = params.recovery_accel
    return LeaderProfile.from_acceleration(accel, leader, name="hard_braking")


def stochastic_human(
    seed: int | None,
    params: StochasticHumanConfig = StochasticHumanConfig(),
    leader: LeaderConfig = LeaderConfig(),
) -> LeaderProfile:
    """A human-like leader: a target speed that changes at random moments, pursued with correlated noise.

    acceleration = speed_gain (target - v) + eta, eta an Ornstein-Uhlenbeck process.
    """
    rng = np.random.default_rng(seed)
    low, high = leader.speed_band
    n, dt = leader.n_samples, leader.dt
    decay = np.exp(-dt / params.accel_correlation_time)
    innovations = params.accel_std * np.sqrt(1.0 - decay**2) * rng.standard_normal(n)
    target_changes = rng.random(n) < dt / params.target_change_interval
    new_targets = rng.uniform(low, high, size=n)
    accel = _pursue_targets(target_changes, new_targets, innovations, leader.initial_speed, decay,
                            params.speed_gain, dt, low, high)
    return LeaderProfile.from_acceleration(accel, leader, name="stochastic_human")


# --------------------------------------------------------------------------- compiled loops
# Each runs in order because every step depends on the speed reached so far.
@numba.njit(cache=True)
def _integrate_in_band(accel, initial_speed, dt, low, high):  # noqa: ANN001, ANN202
    """Speeds [m/s] (accel.size + 1) integrated from ``initial_speed``, each step clipped to [low, high]."""
    speed = np.empty(accel.size + 1)
    speed[0] = initial_speed
    for k in range(accel.size):
        speed[k + 1] = min(max(speed[k] + accel[k] * dt, low), high)
    return speed


@numba.njit(cache=True)
def _jerk_limited_phase(accel, current, target, jerk_step, speed, dt):  # noqa: ANN001, ANN202
    """Fill ``accel`` [m/s^2] moving from ``current`` towards ``target`` by at most ``jerk_step`` a tick;
    returns the final acceleration and the speed [m/s] reached from ``speed``."""
    for k in range(accel.size):
        current += min(max(target - current, -jerk_step), jerk_step)
        accel[k] = current
        speed += current * dt
    return current, speed


@numba.njit(cache=True)
def _pursue_targets(target_changes, new_targets, innovations, initial_speed, decay, speed_gain, dt, low, high):  # noqa: ANN001, ANN202, PLR0913
    """The stochastic human's acceleration [m/s^2]: speed_gain (target - v) plus an AR(1) noise."""
    accel = np.empty(innovations.size)
    speed, target, noise = initial_speed, initial_speed, 0.0
    for k in range(innovations.size):
        if target_changes[k]:
            target = new_targets[k]
        noise = decay * noise + innovations[k]
        accel[k] = speed_gain * (target - speed) + noise
        speed = min(max(speed + accel[k] * dt, low), high)
    return accel
