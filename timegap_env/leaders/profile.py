"""Leader speed profiles: the disturbance every platoon follows.

A :class:`LeaderProfile` is a speed series [m/s] with its acceleration [m/s^2]
sampled every ``dt`` [s]. Sources:

- ``LeaderProfile.from_acceleration``: integrate an acceleration profile from an
  initial speed, kept within a speed band (the paper's method);
- ``LeaderProfile.from_speed`` / ``LeaderProfile.from_csv``: the user's own data;
- the seeded synthetic families of :mod:`timegap_env.leaders.synthetic`, real NGSIM
  I-80 vehicles (:mod:`timegap_env.leaders.ngsim`) and highway-env's IDM driver
  (:mod:`timegap_env.leaders.idm`), named in :mod:`timegap_env.leaders.scenarios`.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

import numba
import numpy as np

from timegap_env.config import LeaderConfig


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


# Runs in order: every step depends on the speed reached so far.
@numba.njit(cache=True)
def _integrate_in_band(accel, initial_speed, dt, low, high):  # noqa: ANN001, ANN202
    """Speeds [m/s] (accel.size + 1) integrated from ``initial_speed``, each step clipped to [low, high]."""
    speed = np.empty(accel.size + 1)
    speed[0] = initial_speed
    for k in range(accel.size):
        speed[k + 1] = min(max(speed[k] + accel[k] * dt, low), high)
    return speed
