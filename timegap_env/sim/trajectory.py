"""Run a whole scenario without the Gymnasium environment: ``simulate(...) -> Trajectory``."""

from __future__ import annotations

import dataclasses

import numpy as np

from timegap_env.config import TIME_GAP_MIN_SPEED, PlatoonConfig
from timegap_env.leaders.profile import LeaderProfile
from timegap_env.leaders.scenarios import make_leader
from timegap_env.sim.degradation import Degradation, DegradationTable, parse_degradations
from timegap_env.sim.platoon import Platoon, actual_time_gap


@dataclasses.dataclass(frozen=True)
class Collision:
    """The first gap <= 0 of a run."""

    time: float  # [s]
    follower: int  # 1 = the first follower (behind the leader) [-]
    gap: float  # bumper-to-bumper gap when detected [m]


@dataclasses.dataclass(frozen=True)
class Trajectory:
    """A simulated run; vehicle arrays are (n_ticks, n_vehicles) with column 0 the leader."""

    t: np.ndarray  # (n_ticks,) [s]
    x: np.ndarray  # front-bumper position [m]
    v: np.ndarray  # speed [m/s]
    a: np.ndarray  # acceleration [m/s^2]
    u: np.ndarray  # commanded acceleration [m/s^2]; the leader's is its acceleration
    setting: np.ndarray  # (n_ticks, n_followers) time gap setting asked for [s]
    applied_setting: np.ndarray  # (n_ticks, n_followers) ramped setting the controller used [s]
    v2v: np.ndarray  # (n_ticks, n_followers) CACC on [bool]
    config: PlatoonConfig
    leader_name: str
    collision: Collision | None  # the run stops at the first collision
    degradations: tuple[Degradation, ...] = ()  # what degraded the followers (timegap_env.sim.degradation)

    @property
    def spacing(self) -> np.ndarray:
        """Bumper-to-bumper gap of each follower, (n_ticks, n_followers) [m]."""
        return self.x[:, :-1] - self.x[:, 1:] - self.config.vehicle_length

    @property
    def actual_time_gap(self) -> np.ndarray:
        """Actual time gap (s - s0) / v of each follower, NaN below ``TIME_GAP_MIN_SPEED`` [s]."""
        speed = self.v[:, 1:]
        gap = actual_time_gap(self.spacing, speed, self.config.standstill_spacing)
        return np.where(speed >= TIME_GAP_MIN_SPEED, gap, np.nan)

    @property
    def spacing_error(self) -> np.ndarray:
        """Controller spacing error s - s0 - tau* v of each follower, (n_ticks, n_followers) [m]."""
        return self.spacing - self.config.standstill_spacing - self.applied_setting * self.v[:, 1:]


def _schedule(name: str, value: object, n_ticks: int, n_followers: int, dtype: type) -> np.ndarray:
    """``value`` (scalar, per follower, or per tick and follower) as an (n_ticks, n_followers) array."""
    array: np.ndarray = np.asarray(value, dtype=dtype)
    if array.ndim == 0 or array.shape == (n_followers,):
        return np.broadcast_to(array, (n_ticks, n_followers))
    if array.shape == (n_ticks, n_followers):
        return array
    raise ValueError(
        f"{name} has shape {array.shape}: must be a scalar, ({n_followers},) or ({n_ticks}, {n_followers})"
    )


def simulate(
    scenario: str | LeaderProfile | np.ndarray = "paper",
    config: PlatoonConfig | None = None,
    *,
    seed: int | None = 0,
    setting: float | np.ndarray | None = None,
    v2v: bool | np.ndarray | None = None,
    degradation: object = None,
) -> Trajectory:
    """Simulate one platoon behind a leader and return its trajectory.

    ``scenario``: a scenario name (see ``timegap_env.SCENARIOS``; its leader is built with the
    default :class:`~timegap_env.config.LeaderConfig`), a :class:`LeaderProfile`, or a leader
    speed series [m/s] at ``config.dt``.
    ``config``: the platoon, default ``PlatoonConfig()`` (the paper's).
    ``setting`` (the time gap setting tau* [s]) and ``v2v`` may be a scalar, one value per
    follower, or an (n_ticks, n_followers) schedule, so that a setting can
    change (it is ramped) and V2V can drop out during the run.
    ``degradation``: what goes wrong with the followers, as the env's ``reset(options={"degradation": ...})``
    takes it (a dict, a list of dicts or :class:`~timegap_env.sim.degradation.Degradation`; a V2V outage or
    a commercial ACC also drops ``v2v``; a noisy radar changes nothing here, there is no monitor);
    its packet losses are drawn from ``seed``.
    The run stops at the first collision, which ``Trajectory.collision`` reports.
    """
    config = config or PlatoonConfig()
    if isinstance(scenario, str):
        leader = make_leader(scenario, seed)
    elif isinstance(scenario, LeaderProfile):
        leader = scenario
    else:
        leader = LeaderProfile.from_speed(scenario, dt=config.dt)
    if not np.isclose(leader.dt, config.dt):
        raise ValueError(f"leader dt = {leader.dt} s differs from PlatoonConfig.dt = {config.dt} s")

    n_ticks, n_followers = leader.speed.size, config.n_followers
    settings = _schedule("setting", config.initial_setting if setting is None else setting, n_ticks, n_followers, float)
    if not np.all(np.isfinite(settings)) or np.any(settings <= 0):
        raise ValueError(f"setting = {setting!r}: every value must be finite and > 0 [s]")
    degradations = parse_degradations(degradation, n_followers)
    table = DegradationTable(config, n_envs=1)
    table.set(0, degradations)
    v2v_schedule = _schedule("v2v", config.v2v if v2v is None else v2v, n_ticks, n_followers, bool)
    v2v_schedule = v2v_schedule & table.v2v_up(np.arange(n_ticks)[:, None])[:, 0]

    platoon = Platoon(config)
    table.write_faults(platoon, 0, key=np.random.default_rng(seed).integers(0, 2**63, dtype=np.uint64))
    platoon.reset(leader.speed[0], leader.accel[0], setting=settings[0])
    shape = (n_ticks, n_followers + 1)
    record = {name: np.empty(shape) for name in ("x", "v", "a", "u")}
    applied = np.empty((n_ticks, n_followers))
    collision = None
    last = n_ticks - 1
    for k in range(n_ticks):
        for name, array in record.items():
            array[k] = getattr(platoon, name)[0]
        applied[k] = platoon.applied_setting[0]
        if k == last:
            break
        platoon.request_setting(settings[k])  # row k is in force from t_k to t_{k+1}
        platoon.set_v2v(v2v_schedule[k])
        collided = platoon.step(leader.speed[k + 1], leader.accel[k + 1])[0]
        if collided.any():
            follower = int(np.flatnonzero(collided)[0])
            collision = Collision(time=(k + 1) * config.dt, follower=follower + 1,
                                  gap=float(platoon.spacing[0, follower]))
            last = k + 1
    n = last + 1
    return Trajectory(
        t=np.arange(n) * config.dt,
        **{name: array[:n] for name, array in record.items()},
        setting=np.array(settings[:n]),
        applied_setting=applied[:n],
        v2v=np.array(v2v_schedule[:n]),
        config=config,
        leader_name=leader.name,
        collision=collision,
        degradations=degradations,
    )
