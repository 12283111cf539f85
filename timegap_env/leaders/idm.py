"""A human-driven leader: highway-env's IDM driver reacting to a scripted disturbance ahead of it.

The scene is a straight single-lane highway-env road with two vehicles:

- ahead, a scripted *disturbance* vehicle whose speed follows a given
  :class:`~timegap_env.leaders.profile.LeaderProfile` exactly (a braking event, a
  synthetic family, recorded data);
- behind it, a :class:`highway_env.vehicle.behavior.IDMVehicle`, the human
  driver, with lane changes off.

Every tick both vehicles act (the driver computes highway-env's IDM
acceleration from its front vehicle on the road) and step by the profile's
``dt``. The driver's speed and the acceleration it realised become a new
``LeaderProfile`` for the platoon to follow: a disturbance filtered through
a human-like reaction.

Two things highway-env does that this module takes care of:

- ``RoadNetwork.straight_road_network`` gives its lane a 30 m/s speed limit,
  and the IDM clips its desired speed to the lane's limit; the road is built
  without a limit, so ``target_speed`` is the driver's desired speed.
- ``Vehicle.step`` lets a vehicle reverse (its lowest speed is -40 m/s); the
  driver's braking is limited so that it stops at 0 m/s instead. Above
  ``Vehicle.MAX_SPEED`` (40 m/s) ``Vehicle.step`` brakes a vehicle back down,
  so the driver cannot follow a disturbance faster than that.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from timegap_env._extras import require
from timegap_env.config import HumanLeaderConfig
from timegap_env.leaders.profile import LeaderProfile

if TYPE_CHECKING:  # highway-env takes about a second to import: only when an IDM leader is built
    from highway_env.road.road import Road
    from highway_env.vehicle.behavior import IDMVehicle
    from highway_env.vehicle.kinematics import Vehicle

ROAD_MARGIN = 100.0  # road left ahead of the disturbance vehicle at the end of the run [m]
LANE_INDEX = ("0", "1", 0)  # the lane of RoadNetwork.straight_road_network(lanes=1)


def build_scene(
    disturbance: LeaderProfile,
    *,
    seed: int | None = None,
    target_speed: float | None = None,
    initial_gap: float | None = None,
    params: HumanLeaderConfig = HumanLeaderConfig(),
) -> tuple[Road, Vehicle, IDMVehicle]:
    """The road at t = 0 with the disturbance vehicle and the IDM driver behind it.

    ``seed``: ``None`` keeps highway-env's default IDM parameters; an integer
    draws them from a generator private to the road (``IDMVehicle.randomize_behavior``
    for the exponent ``DELTA``, then ``TIME_WANTED`` [s] and ``COMFORT_ACC_MAX``
    [m/s^2] from ``params.time_wanted_range`` and ``params.comfort_accel_range``).
    ``target_speed``: the driver's desired speed [m/s]; default
    ``params.desired_speed_factor`` times the disturbance's top speed.
    ``initial_gap``: bumper-to-bumper gap at t = 0 [m]; default the IDM
    equilibrium gap at the disturbance's initial speed.
    Both vehicles start at the disturbance's initial speed.

    Returns ``(road, disturbance_vehicle, driver)``.
    """
    require("idm", "highway_env", needed_for="The IDM leader (highway-env's IDMVehicle)")
    from highway_env.road.road import Road, RoadNetwork
    from highway_env.vehicle.behavior import IDMVehicle
    from highway_env.vehicle.kinematics import Vehicle

    if target_speed is None:
        target_speed = params.desired_speed_factor * float(disturbance.speed.max())
        if target_speed <= 0:
            raise ValueError(
                f"target_speed = {target_speed!r}: the disturbance never moves, so there is no default; pass target_speed > 0"
            )
    _check_positive("target_speed", target_speed)
    if initial_gap is not None:
        _check_positive("initial_gap", initial_gap)

    travel = float(disturbance.speed.sum()) * disturbance.dt  # distance the disturbance covers [m]
    length = params.max_initial_gap + 2 * Vehicle.LENGTH + travel + ROAD_MARGIN  # [m]
    network = RoadNetwork.straight_road_network(lanes=1, length=length, speed_limit=None)
    road = Road(network=network, np_random=np.random.default_rng(seed))
    lane = network.get_lane(LANE_INDEX)

    initial_speed = float(disturbance.speed[0])
    driver = IDMVehicle(
        road, lane.position(0.0, 0.0), speed=initial_speed, target_speed=target_speed, enable_lane_change=False
    )
    if seed is not None:
        driver.randomize_behavior()
        driver.TIME_WANTED = road.np_random.uniform(*params.time_wanted_range)
        driver.COMFORT_ACC_MAX = road.np_random.uniform(*params.comfort_accel_range)
    if initial_gap is None:
        initial_gap = _equilibrium_gap(driver)
    if initial_gap > params.max_initial_gap:
        raise ValueError(f"initial_gap = {initial_gap!r} m: must be <= max_initial_gap = {params.max_initial_gap} m")

    ahead = initial_gap + Vehicle.LENGTH  # centre-to-centre distance, as highway-env measures it [m]
    scripted = Vehicle(road, lane.position(ahead, 0.0), speed=initial_speed)
    road.vehicles = [scripted, driver]
    return road, scripted, driver


def idm_leader(
    disturbance: LeaderProfile,
    *,
    seed: int | None = None,
    target_speed: float | None = None,
    initial_gap: float | None = None,
    params: HumanLeaderConfig = HumanLeaderConfig(),
) -> LeaderProfile:
    """The speed [m/s] and realised acceleration [m/s^2] of an IDM driver following ``disturbance``.

    Same samples and ``dt`` as ``disturbance``; ``accel[k]`` is the acceleration
    applied over tick k, so ``speed[k + 1] = speed[k] + accel[k] * dt``.
    Arguments as in :func:`build_scene`; the same seed gives identical arrays.
    Raises ``RuntimeError`` if the driver collides with the disturbance vehicle.
    """
    road, scripted, driver = build_scene(
        disturbance, seed=seed, target_speed=target_speed, initial_gap=initial_gap, params=params
    )
    dt = disturbance.dt
    n = disturbance.speed.size
    speed = np.empty(n)
    accel = np.empty(n)
    for k in range(n):
        speed[k] = driver.speed
        road.act()  # the driver's IDM decision; the scripted vehicle keeps its zero action
        driver.action["acceleration"] = max(driver.action["acceleration"], -driver.speed / dt)  # stop, never reverse
        road.step(dt)  # moves both vehicles, then highway-env's collision check
        accel[k] = driver.action["acceleration"]  # as realised: Vehicle.step clips it in place first
        driver.speed = max(driver.speed, 0.0)  # round-off of a stop can leave -1e-17 m/s
        if driver.crashed or driver.impact is not None:
            gap = driver.lane_distance_to(scripted) - scripted.LENGTH
            raise RuntimeError(
                f"the IDM driver collides with the disturbance vehicle at t = {(k + 1) * dt:.1f} s "
                f"(bumper gap {gap:.2f} m, driver speed {driver.speed:.2f} m/s, "
                f"disturbance speed {scripted.speed:.2f} m/s); the disturbance {disturbance.name!r} is too harsh"
            )
        scripted.speed = float(disturbance.speed[min(k + 1, n - 1)])  # scripted: exactly the profile
    return LeaderProfile(speed=speed, accel=accel, dt=dt, name="idm")


def _equilibrium_gap(driver: IDMVehicle) -> float:
    """Bumper-to-bumper gap [m] at which the driver keeps its speed behind a vehicle as fast as itself.

    The IDM acceleration a [1 - (v / v0)^delta - (d* / d)^2] vanishes at
    d = d* / sqrt(1 - (v / v0)^delta), d* being highway-env's desired gap.
    """
    free_road = 1.0 - (driver.speed / driver.target_speed) ** driver.DELTA
    if free_road <= 0:
        raise ValueError(
            f"target_speed = {driver.target_speed!r} m/s: must exceed the disturbance's initial speed "
            f"{driver.speed!r} m/s for an equilibrium initial gap; pass initial_gap instead"
        )
    centre_distance = driver.desired_gap(driver, driver) / math.sqrt(free_road)  # driver as its own front: dv = 0
    return centre_distance - driver.LENGTH


def _check_positive(field: str, value: float) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{field} = {value!r}: must be a number")
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{field} = {value!r}: must be finite and > 0")
