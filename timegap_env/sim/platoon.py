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

A follower may be degraded (:class:`FollowerFaults`, set per episode by
:mod:`timegap_env.sim.degradation`): while its degradation acts, its GLVD transition,
controller gains and highest command are the degraded ones, its V2V messages arrive
later or are lost (the feed-forward then holds the last one received), and its radar
adds a bias to the spacing the controller sees. Nothing of this shows in the V2V flag.

Three time gaps, three names: the **setting** is what was asked for; the
**applied setting** is the tau* the controller uses, which follows a new setting
at ``setting_ramp_rate`` (the ramp law, :func:`ramp_toward` and
:meth:`Platoon.ramp_ticks`); the **actual time gap** (s - s0) / v is what the car
really keeps (:attr:`Trajectory.actual_time_gap <timegap_env.sim.trajectory.Trajectory.actual_time_gap>`).

The tick loop is a compiled kernel (numba): a tick is a recurrence through the
feedback, so it cannot be vectorised over time, and as a few dozen NumPy calls
per tick its cost for small batches was call overhead, not arithmetic.
:meth:`Platoon.advance` runs a whole block of ticks in one call. The kernel takes
the named structures below: the state, the block's inputs, the transition
coefficients, the controller's constants and the arrays it fills. Like every kernel
of the package it receives them as plain tuples and names them again on entry:
numba types a NamedTuple argument in Python on every call, several times slower
than a plain tuple, and a step makes a dozen such calls.
"""

from __future__ import annotations

from typing import Annotated, NamedTuple

import numba
import numpy as np

from timegap_env.compiled import INLINED_STAGE_KERNEL, follow_sources
from timegap_env.config import PlatoonConfig, SensorConfig, write_nominal_levers
from timegap_env.sim.counter_noise import counter_uniform
from timegap_env.state import OnState, PerEnv, State

FOLLOWERS = Annotated[np.ndarray, PerEnv(float, "followers")]  # a float per follower


class ZOHCoefficients(NamedTuple):
    """Exact one-tick transition of GLVD under a held command u, per follower (or scalars, one follower's).

    With e = exp(-dt/T), over one tick of length dt:
        a' = e a + (1 - e) K u
        v' = v + T (1 - e) a + (dt - T (1 - e)) K u
        x' = x + dt v + T (dt - T (1 - e)) a + (dt^2/2 - T dt + T^2 (1 - e)) K u
    """

    a_from_a: FOLLOWERS  # [-]
    a_from_u: FOLLOWERS  # [-]
    v_from_a: FOLLOWERS  # [s]
    v_from_u: FOLLOWERS  # [s]
    x_from_a: FOLLOWERS  # [s^2]
    x_from_u: FOLLOWERS  # [s^2]

    @classmethod
    def for_glvd(cls, lag: np.ndarray, gain: np.ndarray, dt: float) -> ZOHCoefficients:
        """Coefficients for actuation lag ``lag`` [s] and gain ``gain`` [-] over a tick ``dt`` [s]."""
        lag = np.asarray(lag, dtype=float)
        gain = np.asarray(gain, dtype=float)
        decayed = -np.expm1(-dt / lag)  # 1 - e, accurate for small dt/T
        return cls(1.0 - decayed, decayed * gain, lag * decayed, (dt - lag * decayed) * gain,
                   lag * (dt - lag * decayed), (0.5 * dt**2 - lag * dt + lag**2 * decayed) * gain)

    def step(
        self, x: np.ndarray, v: np.ndarray, a: np.ndarray, u: np.ndarray, dt: float
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position [m], speed [m/s] and acceleration [m/s^2] one tick of ``dt`` [s] (the coefficients') later
        under held command u [m/s^2]."""
        return glvd_tick(x, v, a, u, self, dt)


@numba.njit(cache=True, error_model="numpy")
def glvd_tick(x, v, a, u, zoh, dt):  # noqa: ANN001, ANN201
    """The transition of :class:`ZOHCoefficients` ``zoh`` over a tick ``dt`` [s], for scalars (inside the kernel) or
    arrays."""
    x_next = x + dt * v + zoh.x_from_a * a + zoh.x_from_u * u
    v_next = v + zoh.v_from_a * a + zoh.v_from_u * u
    a_next = zoh.a_from_a * a + zoh.a_from_u * u
    return x_next, v_next, a_next


def actual_time_gap(spacing: np.ndarray, speed: np.ndarray, standstill_spacing: float) -> np.ndarray:
    """The time gap a follower really keeps, (s - s0) / v [s]: inf at standstill (NaN at s = s0 too)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return (spacing - standstill_spacing) / speed


@numba.njit(cache=True, error_model="numpy")
def cth_command(spacing, speed, predecessor_speed, accel, feedforward, setting, controller):  # noqa: ANN001, ANN201
    """The CTH controller's command [m/s^2], clipped to the controller's bounds, for a follower at ``spacing`` [m]
    and ``speed`` [m/s] with acceleration ``accel`` [m/s^2] behind a predecessor at ``predecessor_speed`` [m/s],
    under the applied ``setting`` tau* [s] and :class:`Controller` ``controller``; ``feedforward`` is (1 with
    V2V else 0, the predecessor's delayed acceleration [m/s^2])."""
    spacing_error = spacing - controller.standstill_spacing - setting * speed
    command = (
        controller.k_s * spacing_error
        + controller.k_v * (predecessor_speed - speed)
        + controller.k_a * accel
        + controller.k_f * feedforward[0] * feedforward[1]
    )
    return min(max(command, controller.accel_min), controller.accel_max)


@numba.njit(cache=True, error_model="numpy")
def follower_tick(x, v, a, command, zoh, dt):  # noqa: ANN001, ANN201
    """:func:`glvd_tick` of one follower (scalars), which does not reverse: below 0 m/s it stays at standstill."""
    x_next, v_next, a_next = glvd_tick(x, v, a, command, zoh, dt)
    if v_next < 0.0:
        v_next, a_next = 0.0, max(a_next, 0.0)
    return x_next, v_next, a_next


@numba.njit(cache=True, error_model="numpy")
def ramp_toward(applied, setting, max_change):  # noqa: ANN001, ANN201
    """The applied setting [s] one tick later: it moves towards ``setting`` [s] by at most ``max_change`` [s]."""
    return applied + min(max(setting - applied, -max_change), max_change)


class PlatoonState(NamedTuple):
    """The state of ``n_envs`` platoons; vehicle arrays (n_envs, 1 + n_followers) with the leader first,
    follower arrays (n_envs, n_followers)."""

    x: Annotated[np.ndarray, PerEnv(float, "vehicles")]  # front-bumper position [m]
    v: Annotated[np.ndarray, PerEnv(float, "vehicles")]  # speed [m/s]
    a: Annotated[np.ndarray, PerEnv(float, "vehicles")]  # acceleration [m/s^2]
    u: Annotated[np.ndarray, PerEnv(float, "vehicles")]  # last command [m/s^2]; the leader's is its acceleration
    setting: FOLLOWERS  # the time gap setting asked for [s]
    applied_setting: FOLLOWERS  # the tau* the controller uses, ramped towards the setting [s]
    v2v: Annotated[np.ndarray, PerEnv(bool, "followers")]  # CACC on (V2V feed-forward) [bool]
    collided: Annotated[np.ndarray, PerEnv(bool, "followers")]  # gap <= 0 was reached; sticky [bool]
    # ring of recent predecessor accelerations, v2v_delay_ticks + max_v2v_latency_ticks + 1 slots [m/s^2]
    predecessor_accel: Annotated[np.ndarray, PerEnv(float, "v2v_ring", "followers")]
    received_accel: FOLLOWERS  # the last predecessor acceleration a V2V message delivered [m/s^2]
    ticks: Annotated[np.ndarray, PerEnv(np.int64)]  # ticks since each env's reset [-]


class Controller(NamedTuple):
    """The CTH controller's constants, from :class:`PlatoonConfig`."""

    dt: float  # tick [s]
    k_s: float  # [1/s^2]
    k_v: float  # [1/s]
    k_a: float  # [-]
    k_f: float  # [-]
    accel_min: float  # [m/s^2]
    accel_max: float  # [m/s^2]
    standstill_spacing: float  # s0 [m]
    vehicle_length: float  # [m]
    max_setting_change: float  # largest change of the applied setting in one tick [s]
    v2v_delay_ticks: int  # V2V delay theta of the feed-forward [ticks]

    @classmethod
    def from_config(cls, config: PlatoonConfig) -> Controller:
        return cls(
            dt=float(config.dt), k_s=float(config.k_s), k_v=float(config.k_v), k_a=float(config.k_a),
            k_f=float(config.k_f), accel_min=float(config.accel_min), accel_max=float(config.accel_max),
            standstill_spacing=float(config.standstill_spacing), vehicle_length=float(config.vehicle_length),
            max_setting_change=float(config.setting_ramp_rate * config.dt), v2v_delay_ticks=config.v2v_delay_ticks,
        )


class FollowerFaults(NamedTuple):
    """Each follower's degradation as the physics sees it. It acts in ticks [start, end) since the env's reset;
    outside that window the follower is nominal."""

    start: Annotated[np.ndarray, PerEnv(np.int64, "followers")]  # first tick it acts [ticks]
    end: Annotated[np.ndarray, PerEnv(np.int64, "followers")]  # first tick it no longer acts; start == end: never
    dynamics: ZOHCoefficients  # the GLVD transition while it acts (its lag and gain)
    k_s: FOLLOWERS  # controller gain on the spacing error while it acts [1/s^2]
    k_v: FOLLOWERS  # controller gain on the speed difference while it acts [1/s]
    accel_max: FOLLOWERS  # highest command while it acts [m/s^2]
    extra_delay: Annotated[np.ndarray, PerEnv(np.int64, "followers")]  # V2V delay added while it acts [ticks]
    packet_loss: FOLLOWERS  # chance per tick that a V2V message is lost while it acts [-]
    radar_bias: FOLLOWERS  # added by the radar to the spacing the controller sees while it acts [m]
    v2v_down: Annotated[np.ndarray, PerEnv(bool, "followers")]  # V2V is down while it acts (the flag shows it)
    keys: Annotated[np.ndarray, PerEnv(np.uint64)]  # keys of the packet-loss draws (counter-based, as the sensors')


class PlatoonParts(NamedTuple):
    """Everything per env a :class:`Platoon` holds."""

    state: PlatoonState
    nominal: ZOHCoefficients  # each follower's GLVD transition when nominal
    faults: FollowerFaults


def platoon_dims(config: PlatoonConfig) -> dict[str, int]:
    """The sizes of :class:`PlatoonParts`' dimensions under ``config``."""
    return {"vehicles": config.n_followers + 1, "followers": config.n_followers,
            "v2v_ring": config.v2v_delay_ticks + config.max_v2v_latency_ticks + 1}


class LeaderTicks(NamedTuple):
    """What drives a block of ticks: row k is the end of tick k."""

    speed: np.ndarray  # (n_ticks, n_envs) the leader's speed [m/s]
    accel: np.ndarray  # (n_ticks, n_envs) the leader's acceleration [m/s^2]
    v2v: np.ndarray  # (n_ticks, n_envs, n_followers) CACC status of each follower during the tick [bool]


class PlatoonTicks(NamedTuple):
    """What :meth:`Platoon.advance` records at the end of each tick, arrays (n_ticks, n_envs, n_followers)."""

    spacing: np.ndarray  # bumper-to-bumper gap to the predecessor [m]
    speed: np.ndarray  # follower speed [m/s]
    accel: np.ndarray  # follower acceleration [m/s^2]
    applied_setting: np.ndarray  # the setting the controller applied during the tick (ramped) [s]
    collisions: np.ndarray  # gap <= 0 reached for the first time this tick [bool]

    @classmethod
    def empty(cls, shape: tuple[int, int, int]) -> PlatoonTicks:
        """Uninitialised arrays of ``shape`` (n_ticks, n_envs, n_followers)."""
        return cls(*(*np.empty((len(cls._fields) - 1, *shape)), np.empty(shape, dtype=bool)))  # collisions last


class Platoon(OnState):
    """``n_envs`` platoons of one leader and ``config.n_followers`` followers, stepped together.

    Its arrays are :attr:`parts` (:class:`PlatoonParts`), views of ``state`` at ``path`` (its own state when
    None), changed in place: the platoons' :attr:`state` (:class:`PlatoonState`, its fields also attributes of
    the platoon: ``x``, ``v``, ``a``, ``u``, ``setting``, ``applied_setting``, ``v2v``, ``collided``, ``ticks``),
    the nominal GLVD transition and :attr:`faults` (:class:`FollowerFaults`, none at first), each follower's
    degradation.
    """

    def __init__(self, config: PlatoonConfig = PlatoonConfig(), n_envs: int = 1, state: State | None = None,
                 path: tuple[str, ...] = ()) -> None:
        if isinstance(n_envs, bool) or not isinstance(n_envs, (int, np.integer)) or n_envs < 1:
            raise ValueError(f"n_envs = {n_envs!r}: must be an integer >= 1")
        self.config = config
        self.n_envs = int(n_envs)
        self.n_followers = config.n_followers
        self._bind(State(PlatoonParts, platoon_dims(config), self.n_envs) if state is None else state, path)
        platoon, faults = self.parts.state, self.parts.faults
        platoon.setting[:] = platoon.applied_setting[:] = config.initial_setting
        platoon.v2v[:] = bool(config.v2v)
        self._controller = Controller.from_config(config)
        self.set_dynamics(config.per_follower("actuation_lag"), config.per_follower("actuation_gain"))
        for degraded, nominal in zip(faults.dynamics, self.parts.nominal):  # no degradation: nominal parameters
            degraded[:] = nominal
        write_nominal_levers(faults, config, SensorConfig())  # the sensors' levers are not the physics'

    # ----------------------------------------------------------------- state
    state = property(lambda self: self.parts.state, doc="The platoons' :class:`PlatoonState` (changed in place).")
    controller = property(lambda self: self._controller, doc="The controller's :class:`Controller` constants.")
    x = property(lambda self: self.parts.state.x, doc="Front-bumper positions (n_envs, n_vehicles) [m].")
    v = property(lambda self: self.parts.state.v, doc="Speeds (n_envs, n_vehicles) [m/s].")
    a = property(lambda self: self.parts.state.a, doc="Accelerations (n_envs, n_vehicles) [m/s^2].")
    u = property(lambda self: self.parts.state.u, doc="Last commands (n_envs, n_vehicles) [m/s^2].")
    setting = property(lambda self: self.parts.state.setting, doc="Settings asked for (n_envs, n_followers) [s].")
    applied_setting = property(
        lambda self: self.parts.state.applied_setting, doc="Settings the controller uses (n_envs, n_followers) [s]."
    )
    v2v = property(lambda self: self.parts.state.v2v, doc="CACC on (n_envs, n_followers) [bool].")
    collided = property(lambda self: self.parts.state.collided, doc="Gap <= 0 was reached (n_envs, n_followers).")
    ticks = property(lambda self: self.parts.state.ticks, doc="Ticks since each env's reset (n_envs,) [-].")
    faults = property(lambda self: self.parts.faults, doc="Each follower's :class:`FollowerFaults` (changed in place).")

    @property
    def spacing(self) -> np.ndarray:
        """Bumper-to-bumper gap of each follower to its predecessor, (n_envs, n_followers) [m]."""
        return self.x[:, :-1] - self.x[:, 1:] - self.config.vehicle_length

    @property
    def actual_time_gap(self) -> np.ndarray:
        """(s - s0) / v of each follower, (n_envs, n_followers) [s]; see :func:`actual_time_gap`."""
        return actual_time_gap(self.spacing, self.v[:, 1:], self.config.standstill_spacing)

    # ----------------------------------------------------------------- setup
    def set_dynamics(self, lag: np.ndarray, gain: np.ndarray) -> None:
        """Set GLVD lag T [s] and gain K [-], each broadcastable to (n_envs, n_followers): the nominal transition's
        arrays change in place."""
        follower_shape = (self.n_envs, self.n_followers)
        for name, values in (("actuation_lag", lag), ("actuation_gain", gain)):
            values = np.asarray(values, dtype=float)
            try:
                np.broadcast_to(values, follower_shape)
            except ValueError:
                raise ValueError(f"{name} has shape {values.shape}: must broadcast to {follower_shape}") from None
            if not np.all(np.isfinite(values)) or np.any(values <= 0):
                raise ValueError(f"{name} = {values}: every value must be finite and > 0")
        zoh = ZOHCoefficients.for_glvd(
            np.broadcast_to(lag, follower_shape), np.broadcast_to(gain, follower_shape), self.config.dt
        )
        for target, values in zip(self.parts.nominal, zoh):
            target[...] = values

    def reset(
        self,
        leader_speed: np.ndarray | float,
        leader_accel: np.ndarray | float = 0.0,
        mask: np.ndarray | None = None,
        setting: np.ndarray | float | None = None,
    ) -> None:
        """Put the platoons in ``mask`` (all if None) in equilibrium behind a leader at ``leader_speed`` [m/s].

        Followers drive at the leader's speed with zero acceleration, each at its
        desired spacing s0 + tau* v; the leader's front bumper is at x = 0. The
        setting, applied at once, becomes ``setting`` [s] (default ``config.initial_setting``,
        broadcast to (n_envs, n_followers)) and V2V returns to ``config.v2v``.
        """
        cfg, state = self.config, self.parts.state
        mask = np.ones(self.n_envs, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        speed = per_env("leader_speed", leader_speed, self.n_envs)[mask]
        accel = per_env("leader_accel", leader_accel, self.n_envs)[mask]
        if np.any(speed < 0):
            raise ValueError(f"leader_speed = {speed}: must be >= 0")
        self.request_setting(cfg.initial_setting if setting is None else setting, mask=mask[:, None])
        state.applied_setting[mask] = state.setting[mask]
        gaps = cfg.standstill_spacing + state.applied_setting[mask] * speed[:, None]  # (n_reset, n_followers)
        offsets = np.cumsum(cfg.vehicle_length + gaps, axis=1)
        state.x[mask, 0] = 0.0
        state.x[mask, 1:] = -offsets
        state.v[mask] = speed[:, None]
        state.a[mask] = 0.0
        state.a[mask, 0] = accel
        state.u[mask] = 0.0
        state.u[mask, 0] = accel
        state.v2v[mask] = bool(cfg.v2v)
        state.collided[mask] = False
        state.predecessor_accel[mask] = state.a[mask, None, :-1]
        state.received_accel[mask] = state.a[mask, :-1]
        state.ticks[mask] = 0

    def request_setting(self, setting: np.ndarray | float, mask: np.ndarray | None = None) -> None:
        """Ask for a new time gap setting [s] (broadcast to (n_envs, n_followers)); the controller ramps to it."""
        current = self.parts.state.setting
        setting = np.asarray(setting, dtype=float)
        if setting.shape != current.shape:
            setting = np.broadcast_to(setting, current.shape)
        if not ((setting > 0) & (setting < np.inf)).all():  # NaN fails both
            raise ValueError(f"setting = {setting}: every value must be finite and > 0 [s]")
        np.copyto(current, setting, where=True if mask is None else np.asarray(mask, dtype=bool))

    def ramp_ticks(self, setting: np.ndarray) -> np.ndarray:
        """Ticks the applied setting needs to reach ``setting`` [s] (n_envs, n_followers) from where it is now."""
        return np.ceil(np.abs(setting - self.parts.state.applied_setting) / self._controller.max_setting_change)

    def set_v2v(self, enabled: np.ndarray | bool, mask: np.ndarray | None = None) -> None:
        """Switch CACC (True) or ACC (False) per follower, broadcast to (n_envs, n_followers), for the envs
        in ``mask`` ((n_envs,) bool, None = all)."""
        enabled = np.broadcast_to(np.asarray(enabled, dtype=bool), self.parts.state.v2v.shape)
        np.copyto(self.parts.state.v2v, enabled, where=True if mask is None else np.asarray(mask, dtype=bool)[:, None])

    # ----------------------------------------------------------------- physics
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
            v2v = np.broadcast_to(self.parts.state.v2v, follower_shape)
        elif np.shape(v2v) != follower_shape:
            raise ValueError(f"v2v has shape {np.shape(v2v)}: expected {follower_shape} (n_ticks, n_envs, n_followers)")
        ticks = PlatoonTicks.empty(follower_shape)
        inputs = tuple(LeaderTicks(speed=leader_speed, accel=leader_accel, v2v=np.ascontiguousarray(v2v, dtype=bool)))
        parts = self.parts
        _advance(tuple(parts.state), inputs, tuple(parts.nominal), tuple(self._controller), _plain(parts.faults),
                 tuple(ticks))
        parts.state.v2v[:] = v2v[-1]
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


def _plain(faults: FollowerFaults) -> tuple:
    """``faults`` as the plain nested tuple a kernel is handed from Python (numba types a NamedTuple slowly)."""
    return (*faults[:2], tuple(faults.dynamics), *faults[3:])


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


@numba.njit(cache=True, error_model="numpy")
def _ring_back(slot, ticks, length):  # noqa: ANN001, ANN202
    """The ring slot ``ticks`` (0 <= ticks < ``length``) before ``slot``: (slot - ticks) % length without a division
    (an integer division per follower and tick was a third of the physics' time)."""
    back = slot - ticks
    return back + length if back < 0 else back


@numba.njit(cache=True, error_model="numpy")
def _advance(state, leader, zoh, controller, faults, out):  # noqa: ANN001, ANN202
    """The physics of :meth:`Platoon.advance`, env by env (:func:`advance_env`), in place.

    ``state`` (:class:`PlatoonState`) is updated, ``out`` (:class:`PlatoonTicks`) filled for the
    ``leader`` (:class:`LeaderTicks`) of each tick, under ``zoh`` (:class:`ZOHCoefficients`),
    ``controller`` (:class:`Controller`) and ``faults`` (:class:`FollowerFaults`), each passed as a
    plain tuple (see the module docstring).
    """
    for e in range(leader[0].shape[1]):
        advance_env(state, leader, zoh, controller, faults, out, e, e)


@numba.njit(**INLINED_STAGE_KERNEL)
def advance_env(state, leader, zoh, controller, faults, out, e, column):  # noqa: ANN001, ANN201, PLR0913
    """Env ``e``'s platoon through the block's ticks, in place; its leader and V2V flags are column ``column`` of
    ``leader``'s arrays and its records go to column ``column`` of ``out``'s (the structures of :func:`_advance`,
    plain tuples). Followers are updated from the last to the first, so each one still sees its predecessor's
    state from the start of the tick, as in the continuous model. The fused env step calls it with one env's
    block (``column`` 0), :meth:`Platoon.advance` for every env."""
    state, leader, zoh = PlatoonState(*state), LeaderTicks(*leader), ZOHCoefficients(*zoh)
    controller, out = Controller(*controller), PlatoonTicks(*out)
    faults = FollowerFaults(*faults)
    degraded_zoh = ZOHCoefficients(*faults.dynamics)
    x, v, a, u = state.x, state.v, state.a, state.u
    n_ticks, n_followers = leader.v2v.shape[0], leader.v2v.shape[2]
    ring = state.predecessor_accel[e]  # (ring length, n_followers)
    buffer_length = ring.shape[0]
    nominal_delay = controller.v2v_delay_ticks
    c = column
    slot = state.ticks[e] % buffer_length - 1  # the ring slot before the block's first tick's, then counted on (a
    for k in range(n_ticks):  # division per tick was a measurable share of the step)
        tick = state.ticks[e] + k
        slot = slot + 1 if slot + 1 < buffer_length else 0  # tick % buffer_length
        nominal_slot = _ring_back(slot, nominal_delay, buffer_length)  # (tick - nominal_delay) % buffer_length
        for i in range(n_followers, 0, -1):  # vehicle i is follower f = i - 1
            f = i - 1
            applied = ramp_toward(state.applied_setting[e, f], state.setting[e, f], controller.max_setting_change)
            state.applied_setting[e, f] = applied
            ring[slot, f] = a[e, i - 1]
            spacing = x[e, i - 1] - x[e, i] - controller.vehicle_length
            active = faults.start[e, f] <= tick < faults.end[e, f]
            if active:
                delay = nominal_delay + faults.extra_delay[e, f]
                lost = leader.v2v[k, c, f] and counter_uniform(
                    faults.keys[e], np.uint64(tick * n_followers + f)) < faults.packet_loss[e, f]
                if not lost:
                    state.received_accel[e, f] = ring[_ring_back(slot, delay, buffer_length), f]
                follower_controller = Controller(
                    controller.dt, faults.k_s[e, f], faults.k_v[e, f], controller.k_a, controller.k_f,
                    controller.accel_min, faults.accel_max[e, f], controller.standstill_spacing,
                    controller.vehicle_length, controller.max_setting_change, controller.v2v_delay_ticks,
                )
                seen_spacing = spacing + faults.radar_bias[e, f]
                dynamics = degraded_zoh
            else:
                state.received_accel[e, f] = ring[nominal_slot, f]
                follower_controller = controller
                seen_spacing = spacing
                dynamics = zoh
            feedforward = 1.0 if leader.v2v[k, c, f] else 0.0, state.received_accel[e, f]
            command = cth_command(seen_spacing, v[e, i], v[e, i - 1], a[e, i], feedforward, applied, follower_controller)
            coefficients = ZOHCoefficients(
                dynamics.a_from_a[e, f], dynamics.a_from_u[e, f], dynamics.v_from_a[e, f], dynamics.v_from_u[e, f],
                dynamics.x_from_a[e, f], dynamics.x_from_u[e, f],
            )
            x_next, v_next, a_next = follower_tick(x[e, i], v[e, i], a[e, i], command, coefficients, controller.dt)
            x[e, i], v[e, i], a[e, i], u[e, i] = x_next, v_next, a_next, command
        x[e, 0] += 0.5 * (v[e, 0] + leader.speed[k, c]) * controller.dt
        v[e, 0] = leader.speed[k, c]
        a[e, 0] = u[e, 0] = leader.accel[k, c]
        for f in range(n_followers):
            spacing = x[e, f] - x[e, f + 1] - controller.vehicle_length
            out.collisions[k, c, f] = spacing <= 0.0 and not state.collided[e, f]
            state.collided[e, f] = state.collided[e, f] or spacing <= 0.0
            out.spacing[k, c, f] = spacing
            out.speed[k, c, f] = v[e, f + 1]
            out.accel[k, c, f] = a[e, f + 1]
            out.applied_setting[k, c, f] = state.applied_setting[e, f]
    state.ticks[e] += n_ticks


follow_sources(__name__)
