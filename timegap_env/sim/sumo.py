"""SUMO as a second simulator of the platoon (issue 26): :class:`SumoPlatoon` is a
:class:`~timegap_env.sim.platoon.Platoon` whose ticks SUMO computes.

The platoon drives on a straight single-lane road at the platoon's tick (0.1 s), through libsumo (the ``sumo``
extra). The leader follows the episode's speed profile (``setSpeed`` with every safety check off, so SUMO applies
it as given); the followers are SUMO's own car-following models, not this package's controller:

- ``SumoConfig.model = "cc"``: Plexe's ``CC`` model. Its engine is a first-order lag; each follower's lag T (a
  degradation's while it acts) is mapped to the engine constant that gives the same one-tick response as the
  native exact transition (``tauEngine = dt / (1 - exp(-dt/T)) - dt``). Without V2V it runs Plexe's ACC, the
  constant-time-headway law u = -(v - v_pred + lambda (h v + 2 m - gap)) / h with headway h = the applied setting and
  lambda = k_s / k_v (the native gains' ratio; the native law's overall gain k_v is 1/h there); with V2V it runs
  Ploeg's CACC, headway h = the applied setting, its gains kp = k_s and kd = k_v (the native ones), fed the
  predecessor's speed and controller output (its desired acceleration, as Ploeg's design sends; the native
  feed-forward reads the predecessor's actual acceleration) after each tick: one tick old, the native default
  delay theta = 0.1 s (other ``v2v_delay`` values do not map). The standstill gap of
  both laws is 2 m; the vType's ``minGap`` adds the rest of s0.
- ``SumoConfig.model = "cacc"``: SUMO's ``CACC`` model (Milanés & Shladover; Xiao, Wang & van Arem) with its
  default gains: time gap = the vehicle's ``tau`` (the applied setting), standstill gap = ``minGap`` = s0; its CACC
  mode while V2V is up and its ACC mode (same time gap) while it is down, each forced through
  ``caccCommunicationsOverrideMode`` (the leader is a plain Krauss car on the profile). It has no actuation lag.

What does not map, and is therefore absent from a SUMO episode: the actuation gain K (neither model has one), the
V2V delay (always one tick), V2V latency and packet loss (SUMO has no communication model; a degradation that takes
V2V down switches the follower to ACC), a degradation's controller gains, command limit or radar bias in the controller (the sensors still add the
radar's bias and noise to what the monitor measures, as in the native simulator). Settings ramp as in the native
platoon: the applied setting moves ``setting_ramp_rate`` per second and is pushed to SUMO each tick it moves.

libsumo runs one simulation per process: a second platoon that starts while another runs raises
:class:`SumoBusyError` (run many episodes one after the other, or one per worker process; a platoon dropped without
:meth:`SumoPlatoon.close` frees the process when it is collected). Any failure while SUMO runs closes the
simulation; SUMO's own becomes a :class:`SumoError` naming the tick.
"""

from __future__ import annotations

import tempfile
import weakref
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from timegap_env.config import MAX_TIME_GAP, PlatoonConfig, SumoConfig
from timegap_env.sim.platoon import Platoon, PlatoonTicks
from timegap_env.state import State

SUMO_EXTRA = "pip install 'timegap-env[sumo]'"  # what installs libsumo
TOP_SPEED = 60.0  # the road's speed limit and every vType's top speed, above any leader profile [m/s]
START_MARGIN = 50.0  # road behind the last follower at reset [m]
END_MARGIN = 500.0  # road ahead of the leader at the episode's end [m]
INSERTION_STEPS = 50  # SUMO steps allowed to insert the vehicles before an episode [-]
WARM_UP = 10.0  # SUMO runs the placed platoon this long at the leader's initial speed before the episode, for its
# models' memories to settle (the CACC model's, otherwise jolted for ~2 s) [s]
PLEXE_STANDSTILL_GAP = 2.0  # the standstill gap Plexe's ACC and Ploeg laws hold, hard-coded in SUMO [m]
ACC, PLOEG = 1, 4  # Plexe's active-controller codes (carFollowModel.ccac)
FORCE_ACC, FORCE_CACC = 2, 3  # the CACC model's caccCommunicationsOverrideMode: its ACC mode, its CACC mode
CRUISE_SPEED = TOP_SPEED  # Plexe's cruise-control speed, above the leader's so that ACC/CACC govern [m/s]
_running: weakref.ref[SumoPlatoon] | None = None  # the platoon whose simulation runs in this process


class SumoError(RuntimeError):
    """SUMO failed, or cannot run here; the message says where and what to do."""


class SumoNotInstalled(SumoError):
    """libsumo is not installed (the scripts print it as one line)."""

    missing_extra = True


class SumoBusyError(SumoError):
    """Another SUMO simulation runs in this process (libsumo allows one)."""


def import_libsumo() -> ModuleType:
    """libsumo; :class:`SumoError` naming the extra to install when it is missing."""
    try:
        import libsumo
    except ImportError as error:
        raise SumoNotInstalled(f"simulator = 'sumo' needs libsumo, which is not installed: {SUMO_EXTRA} ({error})") from error
    return libsumo


def _owner() -> SumoPlatoon | None:
    """The platoon whose simulation runs in this process; one dropped without closing is closed here (None)."""
    global _running
    platoon = _running() if _running is not None else None
    if _running is not None and platoon is None:  # collected while its simulation ran
        _running = None
        import_libsumo().close()
    return platoon


def engine_tau(lag: np.ndarray, dt: float) -> np.ndarray:
    """Plexe's ``tauEngine`` [s] whose one-tick response, a += dt / (tauEngine + dt) (u - a), equals the exact
    transition of a first-order lag ``lag`` [s] over ``dt`` [s], a += (1 - exp(-dt/T)) (u - a)."""
    return dt / -np.expm1(-dt / np.asarray(lag, dtype=float)) - dt


class SumoPlatoon(Platoon):
    """One platoon (``n_envs = 1``) whose ticks SUMO computes; the module docstring says how each part maps.

    The state arrays are the :class:`Platoon`'s, written from SUMO after each tick (``x`` counted from the leader's
    position at reset). :meth:`reset` (re)starts SUMO with the platoon in equilibrium; :meth:`close` ends it.
    """

    def __init__(self, config: PlatoonConfig, sumo_config: SumoConfig, episode_duration: float,
                 state: State | None = None, path: tuple[str, ...] = ()) -> None:
        if sumo_config.model == "cc" and config.standstill_spacing < PLEXE_STANDSTILL_GAP:
            raise ValueError(f"platoon.standstill_spacing = {config.standstill_spacing}: Plexe's CC model holds at "
                             f"least {PLEXE_STANDSTILL_GAP} m at a standstill; use >= {PLEXE_STANDSTILL_GAP} m or "
                             "sumo.model = 'cacc'")
        super().__init__(config, 1, state, path)
        self.sumo_config = sumo_config
        self._libsumo = import_libsumo()
        platoon_length = config.n_followers * (config.vehicle_length + config.standstill_spacing
                                               + MAX_TIME_GAP * TOP_SPEED)  # the longest equilibrium
        self._start_position = START_MARGIN + platoon_length  # where the leader is placed at each reset [m]
        self._offset = self._start_position  # the leader's lane position when the episode starts (after warm-up) [m]
        self._road_length = self._start_position + TOP_SPEED * (WARM_UP + episode_duration) + END_MARGIN  # [m]
        self._folder: tempfile.TemporaryDirectory[str] | None = None
        self._ids = [f"v{i}" for i in range(config.n_followers + 1)]  # the leader first
        self._pushed: dict[str, np.ndarray] = {}  # what SUMO was last told per follower: headway, lag, mode

    # ----------------------------------------------------------------- lifecycle
    @property
    def running(self) -> bool:
        """This platoon's simulation runs now."""
        return _owner() is self

    def reset(self, leader_speed: np.ndarray | float, leader_accel: np.ndarray | float = 0.0,
              mask: np.ndarray | None = None, setting: np.ndarray | float | None = None) -> None:
        """The native reset's equilibrium (see :meth:`Platoon.reset`), then SUMO (re)started with it."""
        super().reset(leader_speed, leader_accel, mask, setting)
        if mask is not None and not np.asarray(mask, dtype=bool).all():
            return  # n_envs = 1: a mask without the env resets nothing
        self.close()
        if _owner() is not None:
            raise SumoBusyError("another SUMO simulation runs in this process (libsumo allows one): close its env "
                                "first, or run each env in its own process (the processes or Ray backend)")
        self._start()

    def close(self) -> None:
        """End this platoon's simulation (nothing if none runs) and remove its files."""
        global _running
        if _owner() is self:
            _running = None
            try:
                self._libsumo.close()
            except Exception:  # noqa: BLE001  (closing after a failure: nothing more to lose)
                pass
        if self._folder is not None:
            self._folder.cleanup()
            self._folder = None

    def __getstate__(self) -> Any:
        raise TypeError("a SumoPlatoon cannot be copied or pickled: its simulation lives in libsumo, one per process; "
                        "build a new env (in the worker process, for a parallel run)")

    def _start(self) -> None:
        """Write the road and the vehicle types, start SUMO and put the platoon on the road as the state says."""
        global _running
        api, cfg = self._libsumo, self.config
        self._folder = tempfile.TemporaryDirectory(prefix="timegap_sumo_")
        folder = Path(self._folder.name)
        (folder / "road.net.xml").write_text(_road_xml(self._road_length), encoding="utf-8")
        (folder / "types.rou.xml").write_text(self._types_xml(), encoding="utf-8")
        arguments = ["sumo", "-n", str(folder / "road.net.xml"), "-r", str(folder / "types.rou.xml"),
                     "--step-length", repr(cfg.dt), "--step-method.ballistic", str(self.sumo_config.ballistic).lower(),
                     "--collision.action", "warn", "--collision.mingap-factor", "0", "--time-to-teleport", "-1",
                     "--no-step-log", "true", "--no-warnings", "true", "--duration-log.disable", "true",
                     "--seed", "0"]
        try:
            api.start(arguments)
        except Exception as error:  # libsumo raises its own TraCIException
            self.close()
            raise SumoError(f"SUMO did not start ({type(error).__name__}: {error})") from error
        _running = weakref.ref(self)
        self._guarded("putting the platoon on the road", self._place)

    def _types_xml(self) -> str:
        """The vehicle types: the leader and one type per follower, of the configured model."""
        cfg = self.config
        common = (f'length="{cfg.vehicle_length!r}" maxSpeed="{TOP_SPEED}" speedFactor="1" speedDev="0" '
                  f'accel="{cfg.accel_max!r}" decel="{-cfg.accel_min!r}" emergencyDecel="{-cfg.accel_min + 1.0!r}"')
        if self.sumo_config.model == "cc":
            car_following = ('carFollowModel="CC" lanesCount="1" '
                             f'minGap="{cfg.standstill_spacing - PLEXE_STANDSTILL_GAP!r}" '
                             f'ccAccel="{cfg.accel_max!r}" ccDecel="{-cfg.accel_min!r}" '
                             f'lambda="{cfg.k_s / cfg.k_v!r}" ploegKp="{cfg.k_s!r}" ploegKd="{cfg.k_v!r}"')
        else:
            car_following = (f'carFollowModel="CACC" minGap="{cfg.standstill_spacing!r}" '
                             f'tau="{cfg.initial_setting!r}"')
        return (f'<routes>\n  <vType id="leader" carFollowModel="Krauss" sigma="0" minGap="0" {common}/>\n'
                f'  <vType id="platoon" {car_following} {common}/>\n  <route id="road" edges="e"/>\n</routes>\n')

    def _place(self) -> None:
        """Insert the vehicles at the state's positions and speeds, set them exactly (an insertion may lag), let SUMO
        run them for WARM_UP seconds at the leader's speed, and take the state from there (x from the leader)."""
        api, state = self._libsumo, self.state
        for i, vid in enumerate(self._ids):
            api.vehicle.add(vid, "road", typeID="leader" if i == 0 else "platoon", depart="now", departLane="0",
                             departPos=repr(float(self._start_position + state.x[0, i])),
                             departSpeed=repr(float(state.v[0, i])))
        for _ in range(INSERTION_STEPS):
            api.simulationStep()
            if len(api.vehicle.getIDList()) == len(self._ids):
                break
        else:
            raise SumoError(f"SUMO inserted {len(api.vehicle.getIDList())} of {len(self._ids)} vehicles in "
                            f"{INSERTION_STEPS} steps")
        for i, vid in enumerate(self._ids):
            api.vehicle.moveTo(vid, "e_0", float(self._start_position + state.x[0, i]))
            api.vehicle.setPreviousSpeed(vid, float(state.v[0, i]))
            api.vehicle.setSpeedMode(vid, 0)  # every check of SUMO's off: each car its profile or model alone
        n = self.n_followers
        self._pushed = {"headway": np.full(n, np.nan), "lag": np.full(n, np.nan), "mode": np.full(n, -1)}
        if self.sumo_config.model == "cc":
            for vid in self._ids[1:]:
                _parameter(api, vid, "ccds", CRUISE_SPEED)
                _parameter(api, vid, "ccumin", self.config.accel_min)
                _parameter(api, vid, "ccumax", self.config.accel_max)
        self._push(self.ticks[0], self.v2v[0])
        for _ in range(round(WARM_UP / self.config.dt)):
            api.vehicle.setSpeed(self._ids[0], float(state.v[0, 0]))
            api.simulationStep()
        self._offset = api.vehicle.getLanePosition(self._ids[0])
        self._read(state.x[0], state.v[0], state.a[0])
        state.u[0] = state.a[0]  # the leader's; the followers' controller outputs, for Ploeg's CACC:
        self._read_commands()

    def _read_commands(self) -> None:
        """Each follower's controller output [m/s^2] into ``u`` (Plexe's model only: what Ploeg's CACC sends)."""
        if self.sumo_config.model == "cc":
            for i, vid in enumerate(self._ids[1:], start=1):
                self.state.u[0, i] = float(self._libsumo.vehicle.getParameter(vid, "carFollowModel.ccsa").split(":")[2])

    def _read(self, x: np.ndarray, v: np.ndarray, a: np.ndarray) -> None:
        """Every vehicle's position (from the leader's at reset) [m], speed [m/s] and acceleration [m/s^2], leader
        first, from SUMO into ``x``, ``v``, ``a``."""
        api = self._libsumo
        for i, vid in enumerate(self._ids):
            x[i] = api.vehicle.getLanePosition(vid) - self._offset
            v[i], a[i] = api.vehicle.getSpeed(vid), api.vehicle.getAcceleration(vid)

    # ----------------------------------------------------------------- physics
    def advance(self, leader_speed: np.ndarray, leader_accel: np.ndarray, v2v: np.ndarray | None = None
                ) -> PlatoonTicks:
        """Advance n_ticks ticks in SUMO, as :meth:`Platoon.advance` natively (same arguments and records; SUMO's
        leader drives the speeds, ``leader_accel`` is checked only)."""
        if not self.running:
            raise RuntimeError("SumoPlatoon.advance() before reset(): no simulation runs (or it was closed)")
        leader_speed = self._per_tick("leader_speed", leader_speed)
        n_ticks = leader_speed.shape[0]
        self._per_tick("leader_accel", leader_accel, n_ticks)
        if leader_speed.max() > TOP_SPEED:
            raise ValueError(f"leader_speed = {leader_speed.max()} m/s: above the SUMO road's {TOP_SPEED} m/s")
        shape = (n_ticks, 1, self.n_followers)
        if v2v is None:
            v2v = np.broadcast_to(self.v2v, shape)
        elif np.shape(v2v) != shape:
            raise ValueError(f"v2v has shape {np.shape(v2v)}: expected {shape} (n_ticks, n_envs, n_followers)")
        ticks = PlatoonTicks.empty(shape)
        for k in range(n_ticks):
            self._guarded(f"tick {int(self.ticks[0])} of the episode",
                          lambda k=k: self._tick(float(leader_speed[k, 0]), np.asarray(v2v[k, 0]), ticks, k))
        self.v2v[0] = v2v[-1, 0]
        return ticks

    def _tick(self, leader_speed: float, v2v: np.ndarray, out: PlatoonTicks, k: int) -> None:
        """One tick: the settings ramp, SUMO is told what changed and steps, the state is read back into row k."""
        api, state, cfg = self._libsumo, self.state, self.config
        step = self._controller.max_setting_change
        state.applied_setting[0] += np.clip(state.setting[0] - state.applied_setting[0], -step, step)
        self._push(self.ticks[0], v2v)
        api.vehicle.setSpeed(self._ids[0], leader_speed)
        api.simulationStep()
        self._read(state.x[0], state.v[0], state.a[0])
        state.u[0, 0] = state.a[0, 0]
        self._read_commands()
        state.ticks[0] += 1
        spacing = state.x[0, :-1] - state.x[0, 1:] - cfg.vehicle_length
        new = (spacing <= 0.0) & ~state.collided[0]
        state.collided[0] |= new
        out.spacing[k, 0], out.speed[k, 0], out.accel[k, 0] = spacing, state.v[0, 1:], state.a[0, 1:]
        out.applied_setting[k, 0], out.collisions[k, 0] = state.applied_setting[0], new

    def _push(self, tick: int, v2v: np.ndarray) -> None:
        """Tell SUMO each follower's headway (the applied setting), engine lag and controller where they changed,
        and, in Ploeg's CACC, its predecessor's data after the last tick (the V2V message)."""
        api, state, pushed, cfg = self._libsumo, self.state, self._pushed, self.config
        faults = self.faults
        acting = (faults.start[0] <= tick) & (tick < faults.end[0])
        decay = np.where(acting, faults.dynamics.a_from_a[0], self.parts.nominal.a_from_a[0])  # exp(-dt/T)
        lag = -cfg.dt / np.log(decay)  # T [s]
        for f, vid in enumerate(self._ids[1:]):
            headway = state.applied_setting[0, f]
            if self.sumo_config.model == "cacc":
                if headway != pushed["headway"][f]:
                    api.vehicle.setTau(vid, float(headway))
                mode = FORCE_CACC if v2v[f] else FORCE_ACC
                if mode != pushed["mode"][f]:
                    api.vehicle.setParameter(vid, "carFollowModel.caccCommunicationsOverrideMode", str(mode))
            else:
                mode = PLOEG if v2v[f] else ACC
                if mode != pushed["mode"][f]:
                    _parameter(api, vid, "ccac", mode)
                if headway != pushed["headway"][f] or mode != pushed["mode"][f]:
                    _parameter(api, vid, "ccph" if mode == PLOEG else "ccaht", headway)
                if lag[f] != pushed["lag"][f]:
                    _parameter(api, vid, "cctau", float(engine_tau(lag[f], cfg.dt)))
                    pushed["lag"][f] = lag[f]
                if mode == PLOEG:  # the predecessor's (the vehicle ahead; the leader's: its acceleration) message
                    predecessor = f
                    message = ":".join(repr(float(value)) for value in (
                        state.v[0, predecessor], state.a[0, predecessor], self._offset + state.x[0, predecessor],
                        0.0, tick * cfg.dt, state.u[0, predecessor], state.v[0, predecessor], 0.0, 0.0))
                    api.vehicle.setParameter(vid, "carFollowModel.ccpsa", message)
            pushed["headway"][f], pushed["mode"][f] = headway, mode

    def _guarded(self, doing: str, action: Any) -> None:
        """Run ``action``; any failure closes the simulation, and SUMO's becomes a :class:`SumoError` saying what
        failed."""
        try:
            action()
        except BaseException as error:
            self.close()
            if isinstance(error, SumoError) or type(error).__module__.split(".")[0] != "libsumo":
                raise
            raise SumoError(f"SUMO failed while {doing} ({type(error).__name__}: {error}); the simulation is "
                            "closed: reset the env to start a new episode") from error


def _parameter(api: ModuleType, vid: str, key: str, value: float | int) -> None:
    """Set Plexe's run-time parameter ``key`` of vehicle ``vid`` (an int as such: a controller code)."""
    text = str(value) if isinstance(value, int) else repr(float(value))
    api.vehicle.setParameter(vid, f"carFollowModel.{key}", text)


def _road_xml(length: float) -> str:
    """A straight single-lane road ``length`` [m] long, edge ``e``, lane ``e_0``, as SUMO's net file."""
    end = f"{length:.2f}"
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<net version="1.20">
  <location netOffset="0.00,0.00" convBoundary="0.00,0.00,{end},0.00" origBoundary="0.00,0.00,{end},0.00"
            projParameter="!"/>
  <edge id="e" from="start" to="end" priority="-1">
    <lane id="e_0" index="0" speed="{TOP_SPEED:.2f}" length="{end}" shape="0.00,-1.60 {end},-1.60"/>
  </edge>
  <junction id="start" type="dead_end" x="0.00" y="0.00" incLanes="" intLanes="" shape="0.00,0.00 0.00,-3.20"/>
  <junction id="end" type="dead_end" x="{end}" y="0.00" incLanes="e_0" intLanes="" shape="{end},-3.20 {end},0.00"/>
</net>
"""


__all__ = ["SUMO_EXTRA", "SumoBusyError", "SumoError", "SumoNotInstalled", "SumoPlatoon", "engine_tau", "import_libsumo"]
