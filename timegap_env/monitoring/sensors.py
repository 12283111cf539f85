"""What each follower measures of its own spacing and speed: Gaussian noise and dropouts.

Every tick a follower reads its bumper-to-bumper spacing [m] and its speed [m/s], each with
zero-mean Gaussian noise (``SensorConfig``'s standard deviations); with an env's dropout
probability the whole reading is missing (NaN in both). The monitor skips missing readings.

The noise is counter-based: a reading's three uniforms are a hash (SplitMix64) of the env's
noise key, the tick since reset, the follower and the stream, so no random generator state is
carried between ticks. An env's readings therefore depend only on its own key and ticks, never
on which other envs share the batch or how ticks are grouped into blocks: a vector of envs
reproduces the same envs run one by one.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from timegap_env.config import SensorConfig

_SPLITMIX_INCREMENT = np.uint64(0x9E3779B97F4A7C15)  # SplitMix64 constants (Steele, Lea & Flood 2014)
_SPLITMIX_MULTIPLIERS = (np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB))
_UNIFORM_STREAMS = 3  # per follower and tick: two for the Gaussian pair, one for the dropout


class Readings(NamedTuple):
    """Spacings and speeds, true or measured, arrays (n_ticks, n_envs, n_followers); NaN = dropout."""

    spacing: np.ndarray  # [m]
    speed: np.ndarray  # [m/s]


class NoiseModel(NamedTuple):
    """What a reading's noise depends on besides the tick."""

    keys: np.ndarray  # (n_envs,) uint64 noise key of each env
    dropout_probability: np.ndarray  # (n_envs,) chance per tick that a follower's reading is missing [-]
    spacing_noise_std: float  # [m]
    speed_noise_std: float  # [m/s]


class Sensors:
    """The spacing and speed sensors of every follower of ``n_envs`` platoons.

    ``noise`` (:class:`NoiseModel`) holds, per env, shaped (n_envs,): ``keys`` (uint64) of the
    noise, drawn from ``seed`` and replaced at each episode by the env; ``dropout_probability``
    [-], ``config.dropout_probability`` until the env draws its own. Both are also attributes of
    the sensors; change them in place.
    """

    def __init__(self, config: SensorConfig = SensorConfig(), n_envs: int = 1, seed: int | None = None) -> None:
        self.config = config
        self._noise = NoiseModel(
            keys=np.random.default_rng(seed).integers(0, 2**63, size=n_envs, dtype=np.uint64),
            dropout_probability=np.full(n_envs, config.dropout_probability),
            spacing_noise_std=float(config.spacing_noise_std),
            speed_noise_std=float(config.speed_noise_std),
        )
        self._noise_args = tuple(self._noise)  # the same arrays, as the kernel takes them

    noise = property(lambda self: self._noise, doc="The :class:`NoiseModel` (its arrays change in place).")
    keys = property(lambda self: self.noise.keys, doc="Noise key of each env (n_envs,) uint64; write in place.")
    dropout_probability = property(
        lambda self: self.noise.dropout_probability, doc="Each env's dropout probability (n_envs,); write in place."
    )

    def measure(self, true: Readings, ticks_before: np.ndarray) -> Readings:
        """Readings of the ``true`` spacings and speeds of a block of ticks; env e's block starts after
        ``ticks_before[e]`` ticks since its reset (its first reading is tick ``ticks_before[e] + 1``)."""
        measured = Readings(np.empty_like(true.spacing), np.empty_like(true.speed))
        _measure(tuple(true), ticks_before, self._noise_args, tuple(measured))
        return measured


@numba.njit(cache=True)
def _measure(true, ticks_before, noise, out):  # noqa: ANN001, ANN202
    """:meth:`Sensors.measure`: fill ``out`` (:class:`Readings`) from ``true`` under ``noise`` (:class:`NoiseModel`),
    each a plain tuple (see :mod:`timegap_env.sim.platoon`)."""
    true, noise, out = Readings(*true), NoiseModel(*noise), Readings(*out)
    n_ticks, n_envs, n_followers = true.spacing.shape
    for k in range(n_ticks):
        for e in range(n_envs):
            tick = ticks_before[e] + 1 + k
            key = noise.keys[e]
            for f in range(n_followers):
                u0 = _uniform(key, tick, f, 0, n_followers)
                u1 = _uniform(key, tick, f, 1, n_followers)
                u2 = _uniform(key, tick, f, 2, n_followers)
                if u2 < noise.dropout_probability[e]:
                    out.spacing[k, e, f] = out.speed[k, e, f] = np.nan
                    continue
                radius = np.sqrt(-2.0 * np.log(u0))  # Box-Muller: two independent standard normals
                angle = 2.0 * np.pi * u1
                out.spacing[k, e, f] = true.spacing[k, e, f] + noise.spacing_noise_std * radius * np.cos(angle)
                out.speed[k, e, f] = true.speed[k, e, f] + noise.speed_noise_std * radius * np.sin(angle)


@numba.njit(cache=True)
def _uniform(key, tick, follower, stream, n_followers):  # noqa: ANN001, ANN202
    """The uniform in (0, 1) of counter tick * 3 n_followers + 3 follower + stream, hashed with the env's key."""
    counter = np.uint64(tick) * np.uint64(_UNIFORM_STREAMS * n_followers) + np.uint64(_UNIFORM_STREAMS * follower + stream)
    bits = _splitmix64(_splitmix64(counter * _SPLITMIX_INCREMENT + key))
    return (float(bits >> np.uint64(11)) + 0.5) * 2.0**-53


@numba.njit(cache=True)
def _splitmix64(x):  # noqa: ANN001, ANN202
    """SplitMix64 finaliser: a well-mixed uint64 hash of the uint64 ``x``."""
    x = (x ^ (x >> np.uint64(30))) * _SPLITMIX_MULTIPLIERS[0]
    x = (x ^ (x >> np.uint64(27))) * _SPLITMIX_MULTIPLIERS[1]
    return x ^ (x >> np.uint64(31))
