"""Batched platoon physics: a human leader and automated followers at 10 Hz.

State arrays are shaped (n_envs, n_vehicles) with column 0 the leader, so many
platoons advance in the same NumPy operations. Followers obey the generalised
linear vehicle dynamics (GLVD) T da/dt = -a + K u under the constant time
headway (CTH) controller

    u = k_s dd + k_v dv + k_a a_i + k_f a_{i-1}(t - theta),
    dd = s - s0 - tau* v_i,   dv = v_{i-1} - v_i,

with u held over each tick (zero-order hold) and the GLVD integrated exactly
over the tick, not with Euler. The feed-forward term comes over V2V with a
delay of ``v2v_delay_ticks`` ticks; a follower without V2V (ACC mode) drops it.
"""

from __future__ import annotations

import dataclasses

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
        x_next = x + self.dt * v + self.x_from_a * a + self.x_from_u * u
        v_next = v + self.v_from_a * a + self.v_from_u * u
        a_next = self.a_from_a * a + self.a_from_u * u
        return x_next, v_next, a_next


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
        speed = self._per_env("leader_speed", leader_speed)[mask]
        accel = self._per_env("leader_accel", leader_accel)[mask]
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
        setting = np.broadcast_to(np.asarray(setting, dtype=float), self.time_gap_setting.shape)
        if not np.all(np.isfinite(setting)) or np.any(setting <= 0):
            raise ValueError(f"time_gap_setting = {setting}: every value must be finite and > 0")
        if mask is None:
            self.time_gap_setting[:] = setting
        else:
            mask = np.broadcast_to(np.asarray(mask, dtype=bool), setting.shape)
            self.time_gap_setting[mask] = setting[mask]

    def set_v2v(self, enabled: np.ndarray | bool) -> None:
        """Switch CACC (True) or ACC (False) per follower, broadcast to (n_envs, n_followers)."""
        self.v2v[:] = np.broadcast_to(np.asarray(enabled, dtype=bool), self.v2v.shape)

    # ----------------------------------------------------------------- physics
    @property
    def spacing(self) -> np.ndarray:
        """Bumper-to-bumper gap of each follower to its predecessor, (n_envs, n_followers) [m]."""
        return self.x[:, :-1] - self.x[:, 1:] - self.config.vehicle_length

    def step(self, leader_speed: np.ndarray | float, leader_accel: np.ndarray | float) -> np.ndarray:
        """Advance one tick to a leader at ``leader_speed`` [m/s] with ``leader_accel`` [m/s^2].

        Returns the followers that reached a gap <= 0 during this tick, (n_envs, n_followers) bool.
        """
        cfg = self.config
        leader_speed = self._per_env("leader_speed", leader_speed)
        leader_accel = self._per_env("leader_accel", leader_accel)

        max_change = cfg.time_gap_ramp_rate * cfg.dt
        self.time_gap += np.clip(self.time_gap_setting - self.time_gap, -max_change, max_change)

        slot = self.tick % self._feedforward_buffer.shape[0]
        self._feedforward_buffer[slot] = self.a[:, :-1]
        delayed_slot = (self.tick - cfg.v2v_delay_ticks) % self._feedforward_buffer.shape[0]
        predecessor_accel = self._feedforward_buffer[delayed_slot]

        followers = slice(1, None)
        spacing_error = self.spacing - cfg.standstill_spacing - self.time_gap * self.v[:, followers]
        speed_difference = self.v[:, :-1] - self.v[:, followers]
        command = (
            cfg.k_s * spacing_error
            + cfg.k_v * speed_difference
            + cfg.k_a * self.a[:, followers]
            + cfg.k_f * self.v2v * predecessor_accel
        )
        command = np.clip(command, cfg.accel_min, cfg.accel_max)

        x, v, a = self._zoh.step(self.x[:, followers], self.v[:, followers], self.a[:, followers], command)
        stopped = v < 0.0  # a vehicle does not reverse: it stays at standstill
        v[stopped] = 0.0
        a[stopped] = np.maximum(a[stopped], 0.0)
        self.x[:, followers], self.v[:, followers], self.a[:, followers] = x, v, a
        self.u[:, followers] = command

        self.x[:, 0] += 0.5 * (self.v[:, 0] + leader_speed) * cfg.dt
        self.v[:, 0] = leader_speed
        self.a[:, 0] = leader_accel
        self.u[:, 0] = leader_accel
        self.tick += 1

        new_collisions = (self.spacing <= 0.0) & ~self.collided
        self.collided |= new_collisions
        return new_collisions

    def _per_env(self, name: str, value: np.ndarray | float) -> np.ndarray:
        """``value`` as a finite float array of shape (n_envs,)."""
        array = np.asarray(value, dtype=float)
        if array.ndim == 0:
            array = np.full(self.n_envs, float(array))
        if array.shape != (self.n_envs,):
            raise ValueError(f"{name} has shape {array.shape}: must be a scalar or ({self.n_envs},)")
        if not np.all(np.isfinite(array)):
            raise ValueError(f"{name} = {array}: must be finite")
        return array
