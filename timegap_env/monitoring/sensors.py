"""What each follower measures of its own spacing and speed: Gaussian noise and dropouts.

Every tick a follower reads its bumper-to-bumper spacing [m] and its speed [m/s], each with
zero-mean Gaussian noise (``SensorConfig``'s standard deviations); with an env's dropout
probability the whole reading is missing (NaN in both). The monitor skips missing readings.

The noise is counter-based (:mod:`timegap_env.sim.counter_noise`): a reading's three uniforms are
a hash of the env's noise key, the tick since reset, the follower and the stream, so an env's
readings depend only on its own key and ticks: a vector of envs reproduces the same envs run one
by one.

A degraded radar (:class:`SensorFaults`, set per episode) adds, while its degradation acts, a
bias [m] to the spacing reading and more spacing noise [m].
"""

from __future__ import annotations

from typing import Annotated, NamedTuple, cast

import numba
import numpy as np

from timegap_env.compiled import INLINED_STAGE_KERNEL, follow_sources
from timegap_env.config import PlatoonConfig, SensorConfig, write_nominal_levers
from timegap_env.sim.counter_noise import counter_uniform
from timegap_env.state import OnState, PerEnv, State

UNIFORM_STREAMS = 3  # per follower and tick: two for the Gaussian pair, one for the dropout


class Readings(NamedTuple):
    """Spacings and speeds, true or measured, arrays (n_ticks, n_envs, n_followers); NaN = dropout."""

    spacing: np.ndarray  # [m]
    speed: np.ndarray  # [m/s]


class NoiseModel(NamedTuple):
    """What a reading's noise depends on besides the tick, per env."""

    keys: Annotated[np.ndarray, PerEnv(np.uint64)]  # noise key of each env
    dropout_probability: Annotated[np.ndarray, PerEnv(float)]  # chance per tick that a reading is missing [-]
    spacing_noise_std: Annotated[np.ndarray, PerEnv(float)]  # [m]
    speed_noise_std: Annotated[np.ndarray, PerEnv(float)]  # [m/s]


class SensorFaults(NamedTuple):
    """A degraded radar per follower: it acts in ticks [start, end) since reset."""

    start: Annotated[np.ndarray, PerEnv(np.int64, "followers")]  # first tick it acts [ticks]
    end: Annotated[np.ndarray, PerEnv(np.int64, "followers")]  # first tick it no longer acts; start == end: never
    radar_bias: Annotated[np.ndarray, PerEnv(float, "followers")]  # added to the spacing reading [m]
    radar_noise: Annotated[np.ndarray, PerEnv(float, "followers")]  # the spacing noise's std, replacing the config's [m]


class SensorParts(NamedTuple):
    """Everything per env :class:`Sensors` hold."""

    noise: NoiseModel
    faults: SensorFaults


class Sensors(OnState):
    """The spacing and speed sensors of every follower of ``n_envs`` platoons.

    Their arrays are :attr:`parts` (:class:`SensorParts`), views of ``state`` at ``path`` (their own state when
    None), changed in place. ``noise`` (:class:`NoiseModel`) holds, per env: ``keys`` (uint64) of the noise, drawn
    from ``seed`` and replaced at each episode by the env; ``dropout_probability`` [-],
    ``config.dropout_probability`` until the env draws its own (both also attributes of the sensors); the config's
    noise. ``faults`` (:class:`SensorFaults`, none at first) is the degraded radar of each follower.
    """

    def __init__(self, config: SensorConfig = SensorConfig(), n_envs: int = 1, seed: int | None = None,
                 n_followers: int = 1, state: State | None = None, path: tuple[str, ...] = ()) -> None:
        # n_followers sizes ``faults``; readings of another width are measured without faults
        self.config = config
        self._bind(State(SensorParts, {"followers": n_followers}, n_envs) if state is None else state, path)
        noise = self.parts.noise
        noise.keys[:] = np.random.default_rng(seed).integers(0, 2**63, size=n_envs, dtype=np.uint64)
        noise.dropout_probability[:] = config.dropout_probability
        noise.spacing_noise_std[:], noise.speed_noise_std[:] = config.spacing_noise_std, config.speed_noise_std
        write_nominal_levers(self.parts.faults, PlatoonConfig(), config)  # the physics' levers are not the sensors'

    noise = property(lambda self: self.parts.noise, doc="The :class:`NoiseModel` (changed in place).")
    faults = property(lambda self: self.parts.faults, doc="The :class:`SensorFaults` (changed in place).")
    keys = property(lambda self: self.parts.noise.keys, doc="Noise key of each env (n_envs,) uint64; write in place.")
    dropout_probability = property(
        lambda self: self.parts.noise.dropout_probability, doc="Each env's dropout probability (n_envs,); write in place."
    )

    def measure(self, true: Readings, ticks_before: np.ndarray) -> Readings:
        """Readings of the ``true`` spacings and speeds of a block of ticks; env e's block starts after
        ``ticks_before[e]`` ticks since its reset (its first reading is tick ``ticks_before[e] + 1``)."""
        faults = tuple(self.faults)
        if true.spacing.shape[1:] != self.faults.start.shape:
            if np.any(self.faults.start < self.faults.end):
                raise ValueError(f"readings of shape {true.spacing.shape}: the sensors' faults are set for "
                                 f"{self.faults.start.shape} (n_envs, n_followers)")
            n_envs, n_followers = cast(tuple[int, int], true.spacing.shape[1:])
            faults = tuple(State(SensorParts, {"followers": n_followers}, n_envs).views.faults)  # none: never acts
        measured = Readings(np.empty_like(true.spacing), np.empty_like(true.speed))
        _measure(tuple(true), ticks_before, tuple(self.noise), faults, tuple(measured))
        return measured


@numba.njit(cache=True, error_model="numpy")
def _measure(true, ticks_before, noise, faults, out):  # noqa: ANN001, ANN202
    """:meth:`Sensors.measure`, env by env (:func:`measure_env`)."""
    n_ticks, n_envs, n_followers = true[0].shape
    uniforms = np.empty((UNIFORM_STREAMS, n_ticks * n_followers))
    for e in range(n_envs):
        measure_env(true, ticks_before[e], noise, faults, out, e, e, uniforms)


@numba.njit(**INLINED_STAGE_KERNEL)
def measure_env(true, ticks_before, noise, faults, out, e, column, uniforms):  # noqa: ANN001, ANN201, PLR0913
    """Fill column ``column`` of ``out`` (:class:`Readings`) from that of ``true`` for env ``e``, whose block starts
    after ``ticks_before`` ticks since its reset, under ``noise`` (:class:`NoiseModel`) and ``faults``
    (:class:`SensorFaults`), each a plain tuple (see :mod:`timegap_env.sim.platoon`).

    ``uniforms`` (3, n_ticks * n_followers) float64 is scratch: the block's uniforms are drawn first, all of them
    (integer hashing that the compiler vectorises), then turned into readings."""
    true, noise, faults, out = Readings(*true), NoiseModel(*noise), SensorFaults(*faults), Readings(*out)
    n_ticks, n_followers = true.spacing.shape[0], true.spacing.shape[2]
    c, key = column, noise.keys[e]
    first = np.uint64(ticks_before + 1) * np.uint64(UNIFORM_STREAMS * n_followers)  # the block's first counter
    for j in range(n_ticks * n_followers):  # reading j = k n_followers + f: counter first + 3 j + stream
        counter = first + np.uint64(UNIFORM_STREAMS * j)
        uniforms[0, j] = counter_uniform(key, counter)  # the Gaussian pair's
        uniforms[1, j] = counter_uniform(key, counter + np.uint64(1))
        uniforms[2, j] = counter_uniform(key, counter + np.uint64(2))  # the dropout's
    for k in range(n_ticks):
        tick = ticks_before + 1 + k
        for f in range(n_followers):
            j = k * n_followers + f
            if uniforms[2, j] < noise.dropout_probability[e]:
                out.spacing[k, c, f] = out.speed[k, c, f] = np.nan
                continue
            radius = np.sqrt(-2.0 * np.log(uniforms[0, j]))  # Box-Muller: two independent standard normals
            angle = 2.0 * np.pi * uniforms[1, j]
            if faults.start[e, f] <= tick - 1 < faults.end[e, f]:  # the reading after physics tick tick - 1
                out.spacing[k, c, f] = (true.spacing[k, c, f] + faults.radar_bias[e, f]
                                        + faults.radar_noise[e, f] * radius * np.cos(angle))
            else:
                out.spacing[k, c, f] = true.spacing[k, c, f] + noise.spacing_noise_std[e] * radius * np.cos(angle)
            out.speed[k, c, f] = true.speed[k, c, f] + noise.speed_noise_std[e] * radius * np.sin(angle)


follow_sources(__name__)
