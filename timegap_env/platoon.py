"""Batched platoon physics: a human leader and automated followers at 10 Hz.

State arrays are shaped (n_envs, n_vehicles) with column 0 the leader, so many
platoons advance in the same call. Followers obey the generalised
linear vehicle dynamics (GLVD) T da/dt = -a + K u under the constant time
headway (CTH) controller

    u = k_s dd + k_v dv + k_a a_i + k_f a_{i-1}(t - theta),
    dd = s - s0 - tau* v_i,   dv = v_{i-1} - v_i,

with u held over each tick (zero-order hold) and the GLVD integrated exactly
over the tick, not with Euler. The feed-forward term comes over V2V with a
delay of ``v2v_delay_ticks`` ticks; a follower without V2V (ACC mode) drops it.

The tick loop is a compiled kernel (numba): a tick is a recurrence through the
feedback, so it cannot be vectorised over time, and as a few dozen NumPy calls
per tick its cost for small batches was call overhead, not arithmetic.
:meth:`Platoon.advance` runs a whole block of ticks in one call.
"""

from __future__ import annotations

import dataclasses

import numba
import numpy as np

from timegap_env.config import PlatoonConfig


@dataclasses.dataclass(frozen=True)
class ZOHCoefficients:
    """Exact one-tick transition of GLVD under a held command u; arrays broadcast per vehicle.

    With e = exp(-dt/T), over one tick of length dt:
        a' = e a + (1 - e) K u
        v' = v + T (1 - e) a + (dt - T (1 - e)) K u
        x' = x + dt v + T (dt - T (1 - e)) a + (dt^2/2 - T dt + T^2 (1 - e)) K u
    """

    a_from_a: np.ndarray
    a_from_u: np.ndarray
    v_from_a: np.ndarray
    v_from_u: np.ndarray
    x_from_a: np.ndarray
    x_from_u: np.ndarray
    dt: float

    @classmethod
    def for_glvd(cls, lag: np.ndarray, gain: np.ndarray, dt: float) -> ZOHCoefficients:
        """Coefficients for actuation lag ``lag`` [s] and gain ``gain`` [-] over a tick ``dt`` [s]."""
        lag = np.asarray(lag, dtype=float)
        gain = np.asarray(gain, dtype=float)
        decayed = -np.expm1(-dt / lag)  # 1 - e, accurate for small dt/T
        return cls(
            a_from_a=1.0 - decayed,
            a_from_u=decayed * gain,
            v_from_a=lag * decayed,
            v_from_u=(dt - lag * decayed) * gain,
            x_from_a=lag * (dt - lag * decayed),
            x_from_u=(0.5 * dt**2 - lag * dt + lag**2 * decayed) * gain,
            dt=dt,
        )

    def step(
        self, x: np.ndarray, v: np.ndarray, a: np.ndarray, u: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position [m], speed [m/s] and acceleration [m/s^2] one tick later under held command u [m/s^2]."""
        return glvd_tick(x, v, a, u, self.a_from_a, self.a_from_u, self.v_from_a, self.v_from_u,
                         self.x_from_a, self.x_from_u, self.dt)


@numba.njit(cache=True)
def glvd_tick(x, v, a, u, a_from_a, a_from_u, v_from_a, v_from_u, x_from_a, x_from_u, dt):  # noqa: ANN001, ANN201
    """The transition of :class:`ZOHCoefficients`, for scalars (inside the kernel) or arrays."""
    x_next = x + dt * v + x_from_a * a + x_from_u * u
    v_next = v + v_from_a * a + v_from_u * u
    a_next = a_from_a * a + a_from_u * u
    return x_next, v_next, a_next


@dataclasses.dataclass(frozen=True)
class PlatoonTicks:
    """What :meth:`Platoon.advance` records at the end of each tick, arrays (n_ticks, n_envs, n_followers)."""

    spacing: np.ndarray  # bumper-to-bumper gap to the predecessor [m]
    speed: np.ndarray  # follower speed [m/s]
    accel: np.ndarray  # follower acceleration [m/s^2]
    time_gap: np.ndarray  # time gap the controller applied during the tick (ramped) [s]
    collisions: np.ndarray  # gap <= 0 reached for the first time this tick [bool]


class Platoon:
    """``n_envs`` platoons of one leader and ``config.n_followers`` followers, stepped together.

    Public state, shaped (n_envs, n_vehicles) unless noted, vehicle 0 the leader:
    ``x`` front-bumper position [m], ``v`` speed [m/s], ``a`` acceleration [m/s^2],
    ``u`` last command [m/s^2] (the leader's is its acceleration);
    per follower, shaped (n_envs, n_followers): ``time_gap_setting`` [s] (what
    was asked), ``time_gap`` [s] (what the controller uses, ramped towards the
    setting), ``v2v`` (CACC on), ``collided`` (gap <= 0 was reached; sticky).
    """

    def __init__(self, config: PlatoonConfig = PlatoonConfig(), n_envs: int = 1) -> None:
        if isinstance(n_envs, bool) or not isinstance(n_envs, (int, np.integer)) or n_envs < 1:
            raise ValueError(f"n_envs = {n_envs!r}: must be an integer >= 1")
        self.config = config
        self.n_envs = int(n_envs)
        self.n_followers = config.n_followers
        shape = (self.n_envs, self.n_followers + 1)
        follower_shape = (self.n_envs, self.n_followers)
        self.x = np.zeros(shape)
        self.v = np.zeros(shape)
        self.a = np.zeros(shape)
        self.u = np.zeros(shape)
        self.time_gap_setting = np.full(follower_shape, config.time_gap)
        self.time_gap = np.full(follower_shape, config.time_gap)
        self.v2v = np.full(follower_shape, bool(config.v2v))
        self.collided = np.zeros(follower_shape, dtype=bool)
        self.tick = 0
        # Predecessor accelerations of the last v2v_delay_ticks + 1 ticks, for the delayed feed-forward.
        self._feedforward_buffer = np.zeros((config.v2v_delay_ticks + 1, *follower_shape))
        self.set_dynamics(config.per_follower("actuation_lag"), config.per_follower("actuation_gain"))
        self._constants = (  # what the kernel needs of the config
            config.dt, config.k_s, config.k_v, config.k_a, config.k_f, config.accel_min, config.accel_max,
            config.standstill_spacing, config.vehicle_length, config.time_gap_ramp_rate * config.dt,
        )

    # ----------------------------------------------------------------- setup
    def set_dynamics(self, lag: np.ndarray, gain: np.ndarray) -> None:
        """Set GLVD lag T [s] and gain K [-], each broadcastable to (n_envs, n_followers)."""
        follower_shape = (self.n_envs, self.n_followers)
        for name, values in (("actuation_lag", lag), ("actuation_gain", gain)):
            values = np.asarray(values, dtype=float)
            try:
                np.broadcast_to(values, follower_shape)
            except ValueError:
                raise ValueError(f"{name} has shape {values.shape}: must broadcast to {follower_shape}") from None
            if not np.all(np.isfinite(values)) or np.any(values <= 0):
                raise ValueError(f"{name} = {values}: every value must be finite and > 0")
        self._zoh = ZOHCoefficients.for_glvd(
            np.broadcast_to(lag, follower_shape), np.broadcast_to(gain, follower_shape), self.config.dt
        )

    def reset(
        self,
        leader_speed: np.ndarray | float,
        leader_accel: np.ndarray | float = 0.0,
        mask: np.ndarray | None = None,
        time_gap: np.ndarray | float | None = None,
    ) -> None:
        """Put the platoons in ``mask`` (all if None) in equilibrium behind a leader at ``leader_speed`` [m/s].

        Followers drive at the leader's speed with zero acceleration, each at its
        desired spacing s0 + tau* v; the leader's front bumper is at x = 0. The
        time gap setting becomes ``time_gap`` [s] (default ``config.time_gap``,
        broadcast to (n_envs, n_followers)) and V2V returns to ``config.v2v``.
        """
        cfg = self.config
        mask = np.ones(self.n_envs, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        speed = per_env("leader_speed", leader_speed, self.n_envs)[mask]
        accel = per_env("leader_accel", leader_accel, self.n_envs)[mask]
        if np.any(speed < 0):
            raise ValueError(f"leader_speed = {speed}: must be >= 0")
        n_reset = int(mask.sum())
        self.set_time_gap(cfg.time_gap if time_gap is None else time_gap, mask=mask[:, None])
        self.time_gap[mask] = self.time_gap_setting[mask]
        gaps = cfg.standstill_spacing + self.time_gap[mask] * speed[:, None]  # (n_reset, n_followers)
        offsets = np.cumsum(cfg.vehicle_length + gaps, axis=1)
        self.x[mask, 0] = 0.0
        self.x[mask, 1:] = -offsets
        self.v[mask] = speed[:, None]
        self.a[mask] = 0.0
        self.a[mask, 0] = accel
        self.u[mask] = 0.0
        self.u[mask, 0] = accel
        self.v2v[mask] = bool(cfg.v2v)
        self.collided[mask] = False
        self._feedforward_buffer[:, mask] = self.a[mask, :-1]
        if n_reset == self.n_envs:
            self.tick = 0

    def set_time_gap(self, setting: np.ndarray | float, mask: np.ndarray | None = None) -> None:
        """Ask for a new time gap setting [s] (broadcast to (n_envs, n_followers)); the controller ramps to it."""
        setting = np.asarray(setting, dtype=float)
        if setting.shape != self.time_gap_setting.shape:
            setting = np.broadcast_to(setting, self.time_gap_setting.shape)
        if not ((setting > 0) & (setting < np.inf)).all():  # NaN fails both
            raise ValueError(f"time_gap_setting = {setting}: every value must be finite and > 0")
        np.copyto(self.time_gap_setting, setting, where=True if mask is None else np.asarray(mask, dtype=bool))

    def set_v2v(self, enabled: np.ndarray | bool) -> None:
        """Switch CACC (True) or ACC (False) per follower, broadcast to (n_envs, n_followers)."""
        self.v2v[:] = np.broadcast_to(np.asarray(enabled, dtype=bool), self.v2v.shape)

    # ----------------------------------------------------------------- physics
    @property
    def spacing(self) -> np.ndarray:
        """Bumper-to-bumper gap of each follower to its predecessor, (n_envs, n_followers) [m]."""
        return self.x[:, :-1] - self.x[:, 1:] - self.config.vehicle_length

    def step(self, leader_speed: np.ndarray | float, leader_accel: np.ndarray | float) -> np.ndarray:
        """Advance one tick to a leader at ``leader_speed`` [m/s] with ``leader_accel`` [m/s^2], each (n_envs,).

        Returns the followers that reached a gap <= 0 during this tick, (n_envs, n_followers) bool.
        """
        speed = per_env("leader_speed", leader_speed, self.n_envs)
        accel = per_env("leader_accel", leader_accel, self.n_envs)
        return self.advance(speed[None], accel[None]).collisions[0]

    def advance(
        self, leader_speed: np.ndarray, leader_accel: np.ndarray, v2v: np.ndarray | None = None
    ) -> PlatoonTicks:
        """Advance n_ticks ticks; row k of ``leader_speed`` [m/s] and ``leader_accel`` [m/s^2], each (n_ticks, n_envs),
        is where the leader is at the end of tick k.

        ``v2v`` (n_ticks, n_envs, n_followers) bool, optional: CACC status during each tick
        (default: keep the current ``v2v``); ``v2v`` is left at its last row.
        """
        leader_speed = self._per_tick("leader_speed", leader_speed)
        n_ticks = leader_speed.shape[0]
        leader_accel = self._per_tick("leader_accel", leader_accel, n_ticks)
        follower_shape = (n_ticks, self.n_envs, self.n_followers)
        if v2v is None:
            v2v = np.broadcast_to(self.v2v, follower_shape)
        elif np.shape(v2v) != follower_shape:
            raise ValueError(f"v2v has shape {np.shape(v2v)}: expected {follower_shape} (n_ticks, n_envs, n_followers)")
        ticks = PlatoonTicks(*np.empty((4, *follower_shape)), np.empty(follower_shape, dtype=bool))
        zoh = self._zoh
        _advance(
            self.x, self.v, self.a, self.u, self.time_gap, self.time_gap_setting, self.collided,
            self._feedforward_buffer, self.tick, leader_speed, leader_accel, np.ascontiguousarray(v2v, dtype=bool),
            zoh.a_from_a, zoh.a_from_u, zoh.v_from_a, zoh.v_from_u, zoh.x_from_a, zoh.x_from_u, self._constants,
            ticks.spacing, ticks.speed, ticks.accel, ticks.time_gap, ticks.collisions,
        )
        self.v2v[:] = v2v[-1]
        self.tick += n_ticks
        return ticks

    def _per_tick(self, name: str, value: np.ndarray, n_ticks: int | None = None) -> np.ndarray:
        """``value`` as a finite float array of shape (n_ticks, n_envs), n_ticks >= 1 (None: any)."""
        array = np.ascontiguousarray(value, dtype=float)
        if array.ndim != 2 or array.shape[1] != self.n_envs or array.shape[0] != (n_ticks or max(array.shape[0], 1)):
            expected = f"({n_ticks or 'n_ticks >= 1'}, {self.n_envs})"
            raise ValueError(f"{name} has shape {array.shape}: must be {expected} (n_ticks, n_envs)")
        if not np.isfinite(array).all():
            raise ValueError(f"{name} = {array}: must be finite")
        return array


def per_env(name: str, value: np.ndarray | float, n_envs: int) -> np.ndarray:
    """``value`` as a finite float array of shape (n_envs,); a scalar is repeated."""
    array = np.asarray(value, dtype=float)
    if array.ndim == 0:
        array = np.full(n_envs, float(array))
    if array.shape != (n_envs,):
        raise ValueError(f"{name} has shape {array.shape}: must be a scalar or ({n_envs},)")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} = {array}: must be finite")
    return array


@numba.njit(cache=True)
def _advance(  # noqa: ANN202, PLR0913 -- the kernel takes the platoon's arrays one by one
    x, v, a, u, time_gap, time_gap_setting, collided, feedforward_buffer, first_tick,
    leader_speed, leader_accel, v2v,
    a_from_a, a_from_u, v_from_a, v_from_u, x_from_a, x_from_u,
    constants,
    out_spacing, out_speed, out_accel, out_time_gap, out_collisions,
):
    """The physics of :meth:`Platoon.step`, tick by tick, in place; see the module docstring for the model.

    Followers are updated from the last to the first, so each one still sees its
    predecessor's state from the start of the tick, as in the continuous model.
    """
    dt, k_s, k_v, k_a, k_f, accel_min, accel_max, standstill_spacing, vehicle_length, max_change = constants
    n_ticks, n_envs, n_followers = v2v.shape
    buffer_length = feedforward_buffer.shape[0]
    delay = buffer_length - 1
    for k in range(n_ticks):
        tick = first_tick + k
        slot, delayed_slot = tick % buffer_length, (tick - delay) % buffer_length
        for e in range(n_envs):
            for i in range(n_followers, 0, -1):  # vehicle i is follower f = i - 1
                f = i - 1
                time_gap[e, f] += min(max(time_gap_setting[e, f] - time_gap[e, f], -max_change), max_change)
                feedforward_buffer[slot, e, f] = a[e, i - 1]
                spacing = x[e, i - 1] - x[e, i] - vehicle_length
                spacing_error = spacing - standstill_spacing - time_gap[e, f] * v[e, i]
                command = (
                    k_s * spacing_error
                    + k_v * (v[e, i - 1] - v[e, i])
                    + k_a * a[e, i]
                    + k_f * (1.0 if v2v[k, e, f] else 0.0) * feedforward_buffer[delayed_slot, e, f]
                )
                command = min(max(command, accel_min), accel_max)
                x_next, v_next, a_next = glvd_tick(
                    x[e, i], v[e, i], a[e, i], command, a_from_a[e, f], a_from_u[e, f],
                    v_from_a[e, f], v_from_u[e, f], x_from_a[e, f], x_from_u[e, f], dt,
                )
                if v_next < 0.0:  # a vehicle does not reverse: it stays at standstill
                    v_next, a_next = 0.0, max(a_next, 0.0)
                x[e, i], v[e, i], a[e, i], u[e, i] = x_next, v_next, a_next, command
            x[e, 0] += 0.5 * (v[e, 0] + leader_speed[k, e]) * dt
            v[e, 0] = leader_speed[k, e]
            a[e, 0] = u[e, 0] = leader_accel[k, e]
            for f in range(n_followers):
                spacing = x[e, f] - x[e, f + 1] - vehicle_length
                out_collisions[k, e, f] = spacing <= 0.0 and not collided[e, f]
                collided[e, f] = collided[e, f] or spacing <= 0.0
                out_spacing[k, e, f] = spacing
                out_speed[k, e, f] = v[e, f + 1]
                out_accel[k, e, f] = a[e, f + 1]
                out_time_gap[k, e, f] = time_gap[e, f]
