"""What goes wrong with a follower: a description, its draw per episode, its physics and its ground truth.

A :class:`Degradation` names a kind, a size, the followers it hits (1 = right behind the leader),
when it starts and whether it ends. Only a V2V outage shows in the car's V2V flag; the rest is
hidden, and spotting it from spacing and speed is what the monitor is for.

The kinds are the records of :data:`~timegap_env.config.DEGRADATIONS`, each with what it does, what
its size is and the bounds of a size, the config field of its drawn range and the parameter (the
``lever``) it sets: this module draws, writes and reports every kind from those records alone
(``commercial_acc``, which swaps the whole car model for a calibrated one, is the one kind handled by
name).

A commercial ACC keeps the platoon's s0, so its actual time gap and the monitor's prior mean the
same thing as for the others. :class:`DegradationTable` holds every follower's degradation of
``n_envs`` platoons as arrays: it writes the physics' :class:`~timegap_env.sim.platoon.FollowerFaults`,
says when the V2V flag is down, and gives the ground truth of each tick: the active degradation,
the true parameters and the smallest string-stable setting for them (:func:`smallest_stable_setting`).
"""

from __future__ import annotations

import bisect
import dataclasses
import functools
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np

from timegap_env.config import (
    DEGRADATION_KINDS, DEGRADATIONS, LEVERS, MAX_DT, MAX_EPISODE_TICKS, DegradationConfig, PlatoonConfig,
    SensorConfig, is_finite, is_real, shown,
)
from timegap_env.sim.platoon import Platoon, ZOHCoefficients
from timegap_env.sim.stability import SettingSweep

KINDS = ("none", *DEGRADATION_KINDS)  # kind codes: the index in this tuple
MAX_TIME = MAX_EPISODE_TICKS * MAX_DT  # latest onset or end of a degradation, the longest episode there can be [s]
DESCRIPTION_KEYS = ("kind", "size", "followers", "onset", "end", "car")  # what a degradation dict may hold
NEVER = np.iinfo(np.int64).max // 4  # the end tick of a degradation that does not end
SETTING_SEARCH = (0.05, 6.0)  # smallest_stable_setting searches tau* in this range [s]
REPORTED_LEVERS = tuple(lever for lever in LEVERS.values() if lever.truth is not None)
# the true parameters the ground truth reports, nominal while no degradation acts (LEVERS' records give their units)
TRUE_PARAMETERS = tuple(lever.truth for lever in LEVERS.values() if lever.truth is not None)


@dataclasses.dataclass(frozen=True)
class Degradation:
    """One degradation of some followers; see the module docstring for the kinds and their sizes."""

    kind: str
    followers: tuple[int, ...]  # which followers, 1 = right behind the leader
    size: float | None = None  # the kind's size, None for v2v_outage and commercial_acc
    onset: float = 0.0  # when it starts, since reset [s]
    end: float | None = None  # when it stops [s]; None: never
    car: str | None = None  # commercial_acc only: the car model (default the median car, COMMERCIAL_ACC)

    def __post_init__(self) -> None:
        if not isinstance(self.kind, str) or self.kind not in DEGRADATION_KINDS:
            self._fail("kind", self.kind, f"must be one of {DEGRADATION_KINDS}")
        followers = self.followers
        if (not isinstance(followers, tuple) or not followers
                or any(isinstance(f, (bool, np.bool_)) or not isinstance(f, (int, np.integer)) or f < 1 for f in followers)
                or len(set(followers)) != len(followers)):
            self._fail("followers", followers, "must be distinct follower numbers >= 1 (1 = right behind the leader)")
        object.__setattr__(self, "followers", tuple(int(f) for f in followers))
        record = DEGRADATIONS[self.kind]
        if record.size_bounds is not None:
            self._time_or_size("size", f"a {self.kind} degradation needs a finite size: {record.size}")
            if self.size not in record.size_bounds:
                self._fail("size", self.size, f"out of range for {self.kind}: {record.size} in {record.size_bounds}")
        elif self.size is not None:
            self._fail("size", self.size, f"a {self.kind} degradation has no size")
        if self.car is not None and (self.kind != "commercial_acc" or not isinstance(self.car, str)):
            self._fail("car", self.car, "only a commercial_acc degradation names a car (by its name)")
        self._time_or_size("onset", f"must be a time in [0, {MAX_TIME:g}] [s]")
        if not 0 <= self.onset <= MAX_TIME:
            self._fail("onset", self.onset, f"must be a time in [0, {MAX_TIME:g}] [s]")
        if self.end is not None:
            self._time_or_size("end", f"must be None (never) or a time after onset = {self.onset}, at most {MAX_TIME:g} [s]")
            if not self.onset < self.end <= MAX_TIME:
                self._fail("end", self.end, f"must be None (never) or a time after onset = {self.onset}, "
                           f"at most {MAX_TIME:g} [s]")

    @classmethod
    def drawn(cls, kind: str, followers: tuple[int, ...], size: float | None = None, onset: float = 0.0,
              end: float | None = None, car: str | None = None) -> Degradation:
        """A degradation as :meth:`DegradationDraw.draw` draws it: valid by construction (a kind of DEGRADATIONS,
        follower numbers as ints, times and size as floats in their ranges), so not checked again (the checks were a
        sixth of a batched reset's time)."""
        degradation = object.__new__(cls)
        degradation.__dict__.update(kind=kind, followers=followers, size=size, onset=onset, end=end, car=car)
        return degradation

    def _time_or_size(self, field: str, rule: str) -> None:
        """Check that ``field`` is a real number (not a bool) that is finite as a float, and store it as a float."""
        value = getattr(self, field)
        if not (is_real(value) and is_finite(value)):
            self._fail(field, value, rule)
        object.__setattr__(self, field, float(value))

    def _fail(self, field: str, value: Any, rule: str) -> NoReturn:
        raise ValueError(f"degradation {field} = {shown(value)}: {rule}")

    @classmethod
    def from_dict(cls, description: Mapping[str, Any], n_followers: int) -> Degradation:
        """A degradation from a dict of DESCRIPTION_KEYS; ``followers`` defaults to all ``n_followers``."""
        if not isinstance(description, Mapping):
            raise ValueError(f"degradation = {description!r}: must be a dict with keys {list(DESCRIPTION_KEYS)}")
        unknown = sorted(set(description) - set(DESCRIPTION_KEYS), key=repr)
        if unknown:
            raise ValueError(f"degradation keys {unknown} unknown; known: {list(DESCRIPTION_KEYS)}")
        if "kind" not in description:
            raise ValueError(f"degradation {dict(description)!r}: needs a 'kind', one of {DEGRADATION_KINDS}")
        fields = dict(description)
        followers = fields.get("followers", range(1, n_followers + 1))
        fields["followers"] = tuple(followers) if isinstance(followers, (list, tuple, range)) else followers
        return cls(**fields)


def parse_degradations(value: Any, n_followers: int) -> tuple[Degradation, ...]:
    """``value`` (None, a :class:`Degradation` or its dict, or a list of them) as degradations of followers
    1..``n_followers``, each follower hit by at most one; ``ValueError`` naming what is wrong."""
    if value is None:
        return ()
    items = list(value) if isinstance(value, (list, tuple)) else [value]
    degradations = tuple(item if isinstance(item, Degradation) else Degradation.from_dict(item, n_followers)
                         for item in items)
    seen: set[int] = set()
    for degradation in degradations:
        beyond = [f for f in degradation.followers if f > n_followers]
        if beyond:
            raise ValueError(f"degradation followers = {degradation.followers}: the platoon has {n_followers} followers")
        twice = seen & set(degradation.followers)
        if twice:
            raise ValueError(f"degradation followers {sorted(twice)}: hit by more than one degradation")
        seen |= set(degradation.followers)
    return degradations


class Categorical:
    """Draws an index of ``weights`` (non-negative, not all 0) with chance proportional to its weight: exactly what
    ``rng.choice(len(weights), p=weights / weights.sum())`` draws, and from the same one uniform number, without
    checking ``p`` again at every draw.

    numpy's ``Generator.choice`` with ``p`` takes the cumulative sum of ``p``, divides it by its last entry, draws
    one ``random()`` and returns the first index whose cumulative probability exceeds it (a right-sided search).
    """

    def __init__(self, weights: Sequence[float]) -> None:
        array = np.array(weights, dtype=float)
        cumulative = (array / array.sum()).cumsum()
        cumulative /= cumulative[-1]
        self._cumulative = cumulative.tolist()

    def draw(self, rng: np.random.Generator) -> int:
        """An index drawn from ``rng`` (one ``random()``)."""
        return bisect.bisect_right(self._cumulative, rng.random())


class DegradationDraw:
    """The degradations of an episode of a platoon of ``n_followers`` at tick ``dt`` [s], drawn as ``config`` says
    (:class:`~timegap_env.config.DegradationConfig`): :meth:`draw` draws one episode's. What is the same for every
    episode (the kinds' chances, the drawn kinds' ranges) is worked out once, here."""

    def __init__(self, config: DegradationConfig, n_followers: int, dt: float) -> None:
        self.config, self.n_followers, self.dt = config, n_followers, dt
        self._kinds = tuple(config.kind_weights)
        self._kind_draw = Categorical(list(config.kind_weights.values()))
        drawn = [DEGRADATIONS[kind] for kind in self._kinds if kind != "none"]
        self._sizes = {kind.name: config.size_range(kind.name) for kind in drawn
                       if kind.range_field is not None}  # kind -> the (low, high) its size is drawn from
        self._durations = {kind.name: getattr(config, kind.duration_field) for kind in drawn
                           if kind.duration_field is not None}  # kind -> the (low, high) its length is drawn from [s]

    def draw(self, rng: np.random.Generator, duration: float) -> tuple[Degradation, ...]:
        """The degradations of one episode of ``duration`` [s], drawn from ``rng``; () when it draws none."""
        config, dt, n_followers = self.config, self.dt, self.n_followers
        kind = self._kinds[self._kind_draw.draw(rng)]
        hit = rng.random(n_followers).tolist()
        forced = int(rng.integers(n_followers))  # at least one follower
        followers = tuple(f + 1 for f in range(n_followers) if hit[f] < config.follower_probability or f == forced)
        midway, recovers = rng.random() < config.midway_onset_probability, rng.random() < config.recovery_probability
        onset = round_to_tick(_uniform(rng, 0.25, 0.75) * duration, dt) if midway else 0.0
        end = round_to_tick(onset + _uniform(rng, 0.2, 0.5) * duration, dt) if recovers else None
        end = end if end is not None and onset < end < duration else None  # (in a one-tick episode both round to 0)
        if kind == "none":
            return ()
        if kind in self._durations:
            length = max(round_to_tick(_uniform(rng, *self._durations[kind]), dt), dt)  # at least a tick
            onset = round_to_tick(_uniform(rng, 0.0, max(duration - length, 0.0)), dt)
            end = onset + length
        if kind == "commercial_acc":
            from timegap_env.sim.presets import COMMERCIAL_ACC, acc_presets  # scipy-backed: imported when used

            cars = sorted(car for car in acc_presets() if car != COMMERCIAL_ACC)
            return tuple(Degradation.drawn(kind, (f,), car=cars[rng.integers(len(cars))]) for f in followers)
        if kind not in self._sizes:
            return (Degradation.drawn(kind, followers, onset=float(onset), end=end),)
        record = DEGRADATIONS[kind]
        size = _uniform(rng, *self._sizes[kind])
        if record.whole_ticks:
            size = round_to_tick(size, dt)
        if record.signed and rng.random() < 0.5:
            size = -size
        return (Degradation.drawn(kind, followers, size=size, onset=float(onset), end=end),)


def _uniform(rng: np.random.Generator, low: float, high: float) -> float:
    """What ``rng.uniform(low, high)`` draws (low + (high - low) u, u = ``rng.random()``), without its checks."""
    return low + (high - low) * rng.random()


def _distinct(values: np.ndarray) -> bool:
    """Whether no two of ``values`` (ints, any shape) are equal: sorted, no neighbours equal (numpy's unique hashes
    them, slower for a reset's tens of thousands of envs)."""
    ordered = np.sort(values, axis=None)
    return not (ordered[1:] == ordered[:-1]).any()


def round_to_tick(time: float, dt: float) -> float:
    """``time`` [s] rounded to a whole number of ticks of ``dt`` [s]."""
    return round(time / dt) * dt


@functools.lru_cache(maxsize=4096)
def smallest_stable_setting(lag: float, gain: float, k_s: float, k_v: float, k_a: float, k_f: float,
                            delay: float, packet_loss: float = 0.0, dt: float = PlatoonConfig.dt) -> float:
    """The smallest tau* [s] at which a follower of these parameters is string and locally stable by
    :func:`~timegap_env.sim.stability.string_stability` (to 0.01 s, searched over SETTING_SEARCH; inf if none
    there). ``k_f = 0`` is ACC; ``delay`` is the V2V delay [s], ``packet_loss`` the chance [-] that a V2V message
    (one every ``dt`` [s]) is lost."""

    sweep = SettingSweep(k_s=k_s, k_v=k_v, k_a=k_a, k_f=k_f, lag=lag, gain=gain, delay=delay, packet_loss=packet_loss,
                         dt=dt)

    def stable(setting: float) -> bool:
        report = sweep.report(setting)
        return report.string_stable and report.locally_stable

    low, high = SETTING_SEARCH
    if stable(low):
        return low
    if not stable(high):
        return math.inf
    while high - low > 0.001:  # stability grows with tau*: bisect the boundary
        middle = 0.5 * (low + high)
        low, high = (low, middle) if stable(middle) else (middle, high)
    candidate = math.ceil(low * 100) / 100  # the first hundredth above the last unstable setting found
    return candidate if stable(candidate) else round(candidate + 0.01, 2)


class DegradationTable:
    """Every follower's degradation in ``n_envs`` platoons of ``config``, arrays (n_envs, n_followers).

    Per follower: ``kind`` (int8 code, an index of KINDS), ``size`` (NaN without one), ``start`` and
    ``end`` (ticks since reset, [start, end); start == end: none; NEVER: no end), and in ``levers`` the value of
    each lever of :data:`~timegap_env.config.LEVERS` while it acts (nominal where no degradation sets it; each also
    an attribute: ``table.lag`` [s], ``table.extra_delay`` [ticks], ...); ``nominal`` holds the levers' nominal
    values under ``config`` and ``sensors`` (the radar's noise). :meth:`write_levers` copies them into the
    physics' and the sensors' faults.
    """

    def __init__(self, config: PlatoonConfig, n_envs: int, sensors: SensorConfig = SensorConfig()) -> None:
        self.config = config
        shape = (n_envs, config.n_followers)
        self.kind = np.zeros(shape, dtype=np.int8)
        self.size = np.full(shape, np.nan)
        self.start = np.zeros(shape, dtype=np.int64)
        self.end = np.zeros(shape, dtype=np.int64)
        self.nominal = {name: lever.nominal(config, sensors) for name, lever in LEVERS.items()}  # while nothing acts
        self.levers: dict[str, np.ndarray] = {name: np.zeros(shape, dtype=lever.dtype)
                                              for name, lever in LEVERS.items()}
        clash = sorted(set(self.levers) & set(vars(self)))
        if clash:
            raise ValueError(f"config.LEVERS: lever {clash[0]!r} has the name of a DegradationTable attribute")
        vars(self).update(self.levers)  # table.lag is table.levers["lag"]
        # the smallest string-stable setting [s], nominal / degraded parameters, V2V up / down (found when truth() asks)
        self.stable = {(degraded, up): np.zeros(shape) for degraded in (False, True) for up in (False, True)}
        # what truth() reports: fixed per episode, and the true parameters while it acts / otherwise
        self._reported = {name: np.zeros(shape) for name in ("size", "onset", "end")}
        self._while_active, self._otherwise = np.zeros((2, len(TRUE_PARAMETERS), *shape))
        self._stale = np.ones(n_envs, dtype=bool)  # envs whose stable settings and ground truth's fixed parts (the
        #                                            three above) are not worked out yet: truth() does it
        self.descriptions: list[tuple[Degradation, ...]] = [() for _ in range(n_envs)]
        self.set_many(np.arange(n_envs), [()] * n_envs)

    if TYPE_CHECKING:  # each lever is also an attribute (set in __init__: a plain attribute reads fastest)
        def __getattr__(self, name: str) -> np.ndarray: ...

    def set(self, env: int, degradations: Sequence[Degradation]) -> None:
        """Env ``env``'s followers take ``degradations`` (from :func:`parse_degradations`); the others are nominal."""
        self.set_many(np.array([env]), [degradations])

    def set_many(self, envs: np.ndarray, degradations: Sequence[Sequence[Degradation]]) -> None:
        """Each env of ``envs`` (distinct indices) takes its entry of ``degradations`` (as :meth:`set` does), all
        in a few array operations: the envs' rows are made nominal, then every hit follower takes its
        degradation's schedule and parameters."""
        envs = np.asarray(envs, dtype=np.intp)
        if not _distinct(envs):
            raise ValueError(f"envs = {envs.tolist()}: each env may be set once")
        self.kind[envs], self.size[envs], self.start[envs], self.end[envs] = 0, np.nan, 0, 0
        for name, values in self.levers.items():
            values[envs] = self.nominal[name]
        hits = _Hits()
        for env, items in zip(envs.tolist(), degradations, strict=True):
            for degradation in items:
                hits.add(env, degradation, self)
            self.descriptions[env] = tuple(items)
        hits.write(self)
        self._stale[envs] = True  # their ground truth's fixed parts are worked out when it is first asked for

    def _prepare_truth(self, envs: np.ndarray) -> None:
        """The parts of :meth:`truth` fixed for the episode of each env of ``envs``."""
        cfg = self.config
        hit = self.kind[envs] > 0
        start, end = self.start[envs], self.end[envs]
        self._reported["size"][envs] = np.nan_to_num(self.size[envs])
        self._reported["onset"][envs] = np.where(hit, start * cfg.dt, np.inf)
        self._reported["end"][envs] = np.where(hit & (end < NEVER), end * cfg.dt, np.inf)
        for i, lever in enumerate(REPORTED_LEVERS):  # in TRUE_PARAMETERS order
            self._while_active[i, envs] = lever.reported(self.levers[lever.name][envs], cfg)
            self._otherwise[i, envs] = lever.reported(self.nominal[lever.name], cfg)

    def _find_stable_settings(self, envs: np.ndarray) -> None:
        """The smallest string-stable settings (``stable``) of the envs ``envs`` for their nominal and degraded
        parameters, with the link up and down: the nominal ones once for all; a follower whose degraded parameters
        are its nominal ones (not hit, or hit in the radar or the link only) copies them, the others are searched."""
        cfg = self.config
        nominal_lag, nominal_gain = np.asarray(self.nominal["lag"]), np.asarray(self.nominal["gain"])
        for up in (False, True):
            nominal = [self._stable_setting(nominal_lag[f], nominal_gain[f], cfg.k_s, cfg.k_v, 0.0, 0.0, up)
                       for f in range(cfg.n_followers)]
            self.stable[False, up][envs] = self.stable[True, up][envs] = nominal
        own = ((self.lag[envs] != nominal_lag) | (self.gain[envs] != nominal_gain)
               | (self.k_s[envs] != cfg.k_s) | (self.k_v[envs] != cfg.k_v) | (self.extra_delay[envs] != 0)
               | (self.packet_loss[envs] != 0.0))
        for env, f in zip(*np.nonzero(own)):
            env = envs[env]
            for up in (False, True):
                self.stable[True, up][env, f] = self._stable_setting(
                    self.lag[env, f], self.gain[env, f], self.k_s[env, f], self.k_v[env, f],
                    self.extra_delay[env, f] * cfg.dt, self.packet_loss[env, f], up)
        self._stale[envs] = False

    def _stable_setting(self, lag: float, gain: float, k_s: float, k_v: float, extra_delay: float, loss: float,
                        up: bool) -> float:
        """:func:`smallest_stable_setting` of one follower's parameters (``extra_delay`` [s] beyond the V2V delay),
        with the link up or down."""
        cfg = self.config
        return smallest_stable_setting(float(lag), float(gain), float(k_s), float(k_v), cfg.k_a, cfg.k_f if up else 0.0,
                                       round(float(cfg.v2v_delay + extra_delay), 9), float(loss), cfg.dt)

    def write_faults(self, platoon: Platoon, env: int, key: int | np.unsignedinteger) -> None:
        """Write env ``env``'s degradations into ``platoon.faults``; ``key`` (uint64) seeds its packet losses."""
        self.write_faults_many(platoon, np.array([env]), np.array([key], dtype=np.uint64))

    def write_faults_many(self, platoon: Platoon, envs: np.ndarray, keys: np.ndarray) -> None:
        """:meth:`write_faults` for each env of ``envs`` with its key of ``keys`` (uint64), at once: the levers
        (:meth:`write_levers`), the GLVD transition of the lag and gain, the keys."""
        faults = platoon.faults
        self.write_levers(faults, envs)
        degraded = ZOHCoefficients.for_glvd(self.levers["lag"][envs], self.levers["gain"][envs], self.config.dt)
        for target, values in zip(faults.dynamics, degraded):
            target[envs] = values
        faults.keys[envs] = np.asarray(keys, dtype=np.uint64)

    def write_levers(self, faults: tuple, envs: np.ndarray) -> None:
        """Copy the envs ``envs``' schedule (``start``, ``end``) and every lever that ``faults`` (a NamedTuple of
        arrays (n_envs, n_followers): FollowerFaults, SensorFaults) has a field of, by name, into it."""
        for name, target in zip(faults._fields, faults):  # type: ignore[attr-defined]
            if name in ("start", "end") or name in LEVERS:
                target[envs] = getattr(self, name)[envs]

    def active(self, ticks: np.ndarray) -> np.ndarray:
        """Which degradations act during tick ``ticks`` since reset, (..., n_envs) -> (..., n_envs, n_followers)."""
        ticks = np.asarray(ticks)[..., None]
        return (self.start <= ticks) & (ticks < self.end)

    def v2v_up(self, ticks: np.ndarray) -> np.ndarray:
        """The V2V flag during tick ``ticks``, (..., n_envs) -> (..., n_envs, n_followers): down while a V2V
        outage or a commercial ACC acts."""
        return ~(self.active(ticks) & self.v2v_down)

    def truth(self, ticks: np.ndarray, v2v: np.ndarray) -> dict[str, np.ndarray]:
        """The ground truth for the next tick, ``ticks`` (n_envs,) since reset, with the V2V flag ``v2v`` (n_envs,
        n_followers) it will have, arrays (n_envs, n_followers) without NaN (so that equal episodes give equal
        infos): never in the observation.

        ``kind`` (the follower's degradation, an int8 index of KINDS, 0 = "none": not hit), ``size`` (0 without one), ``onset`` and ``end``
        [s] (inf: not hit / never): the episode's schedule, what has not started included (an oracle that reads
        it sees the future; ours read ``active`` and the true parameters only); ``active`` (it acts in the next
        tick), ``v2v`` (the link is up, what the flag shows),
        ``smallest_stable_setting`` [s] for the true parameters and link, and the true parameters of
        TRUE_PARAMETERS.
        """
        if self._stale.any():
            stale = np.flatnonzero(self._stale)
            self._prepare_truth(stale)
            self._find_stable_settings(stale)
        active = self.active(ticks)
        parameters = np.where(active, self._while_active, self._otherwise)
        stable = np.where(active, np.where(v2v, self.stable[True, True], self.stable[True, False]),
                          np.where(v2v, self.stable[False, True], self.stable[False, False]))
        return {"kind": self.kind.copy(), **{name: value.copy() for name, value in self._reported.items()},
                "active": active, **dict(zip(TRUE_PARAMETERS, parameters)), "v2v": v2v.copy(),
                "smallest_stable_setting": stable}


class _Hits:
    """Every hit follower of a :meth:`DegradationTable.set_many`, gathered degradation by degradation and written
    into the table's arrays in one go: its kind code, size, start and end ticks, and what the kind changes."""

    def __init__(self) -> None:
        self.rows: list[int] = []  # env of each hit follower
        self.columns: list[int] = []  # follower index, 0 = right behind the leader
        self.kinds: list[int] = []  # KINDS index
        self.sizes: list[float] = []  # NaN without one
        self.starts: list[int] = []  # [ticks]
        self.ends: list[int] = []  # [ticks], NEVER: no end
        self.cars: list[tuple[int, int, str]] = []  # commercial ACC followers: env, follower index, car

    def add(self, env: int, degradation: Degradation, table: DegradationTable) -> None:
        """Env ``env``'s followers that ``degradation`` hits; ``ValueError`` for a V2V latency the table cannot hold or
        an unknown car."""
        cfg, kind, size = table.config, degradation.kind, degradation.size
        record = DEGRADATIONS[kind]
        if record.whole_ticks:
            assert size is not None  # a kind on whole ticks has a size
            if abs(size / cfg.dt - round(size / cfg.dt)) > 1e-9:
                raise ValueError(f"degradation size = {size!r}: a {kind} must be a multiple of dt = {cfg.dt} s")
        if record.lever == "extra_delay" and size is not None and size > cfg.max_v2v_latency + 1e-9:
            raise ValueError(f"degradation size = {size!r}: a {kind} must be at most max_v2v_latency = "
                             f"{cfg.max_v2v_latency} s (the V2V buffer's length)")
        if kind == "commercial_acc":
            from timegap_env.sim.presets import COMMERCIAL_ACC, acc_presets  # scipy-backed: imported when used

            car = degradation.car or COMMERCIAL_ACC
            if car not in acc_presets():
                raise ValueError(f"degradation car = {car!r}: no calibrated preset; known: {sorted(acc_presets())}")
            self.cars.extend((env, follower - 1, car) for follower in degradation.followers)
        count = len(degradation.followers)
        self.rows.extend([env] * count)
        self.columns.extend(follower - 1 for follower in degradation.followers)
        self.kinds.extend([KINDS.index(kind)] * count)
        self.sizes.extend([math.nan if size is None else size] * count)
        self.starts.extend([round(degradation.onset / cfg.dt)] * count)
        self.ends.extend([NEVER if degradation.end is None else round(degradation.end / cfg.dt)] * count)

    def write(self, table: DegradationTable) -> None:
        """Write the hits into ``table``; ``ValueError`` if a follower is hit twice in one env."""
        if not self.rows:
            return
        rows, columns = np.array(self.rows), np.array(self.columns)
        followers = rows * table.kind.shape[1] + columns
        if not _distinct(followers):
            raise ValueError("degradations hit a follower more than once: each follower takes at most one")
        kinds, sizes = np.array(self.kinds, dtype=np.int8), np.array(self.sizes)
        table.kind[rows, columns], table.size[rows, columns] = kinds, sizes
        table.start[rows, columns], table.end[rows, columns] = self.starts, self.ends

        for code, record in enumerate(DEGRADATIONS.values(), start=1):  # each kind sets its lever
            chosen = kinds == code
            if record.lever is None or not chosen.any():
                continue
            at, size, lever = (rows[chosen], columns[chosen]), sizes[chosen], getattr(table, record.lever)
            if record.size is None:
                lever[at] = True  # a flag
            elif record.scales:
                lever[at] *= size
            else:
                lever[at] = np.rint(size / table.config.dt) if record.whole_ticks else size
        if self.cars:
            from timegap_env.sim.presets import acc_presets

            presets = acc_presets()
            for env, f, car in self.cars:
                model = presets[car].model
                table.lag[env, f], table.gain[env, f], table.k_s[env, f], table.k_v[env, f] = model.lag, 1.0, model.k_s, model.k_v
                table.accel_max[env, f], table.v2v_down[env, f] = model.accel_max, True
