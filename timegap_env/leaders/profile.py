"""Leader speed profiles: the disturbance every platoon follows.

A :class:`LeaderProfile` is a speed series [m/s] with its acceleration [m/s^2]
sampled every ``dt`` [s]. Sources:

- ``LeaderProfile.from_acceleration``: integrate an acceleration profile from an
  initial speed, kept within a speed band (the paper's method); :class:`LeaderProfiles` does it for
  many profiles of one length at once (a batched reset);
- ``LeaderProfile.from_speed`` / ``LeaderProfile.from_csv``: the user's own data;
- the seeded synthetic families of :mod:`timegap_env.leaders.synthetic`, real NGSIM
  I-80 vehicles (:mod:`timegap_env.leaders.ngsim`) and highway-env's IDM driver
  (:mod:`timegap_env.leaders.idm`), named in :mod:`timegap_env.leaders.scenarios`.

Every leader file (the user's CSV, NGSIM, OpenACC) is read through :func:`open_csv`, which
checks it (a file, gzip, UTF-8 text, not empty) and names the file in its errors, and parsed inside
:func:`csv_errors`, which names the file and row of an error of the :mod:`csv` module.

Every profile's speeds lie in [0, ``MAX_SPEED``]: a speed outside (or not finite) is a ``ValueError``
naming the profile, the sample and the value, whatever the source.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import gzip
import io
import math
import zlib
from collections.abc import Iterator, Sequence
from typing import Any, TypeVar, cast
from pathlib import Path

import numba
import numpy as np

from timegap_env.compiled import follow_sources
from timegap_env.config import HELD_OUT_EVERY, MAX_SPEED, RECORDED_PARTS, LeaderConfig, shown

T = TypeVar("T")


GZIP_MAGIC = b"\x1f\x8b"  # the first two bytes of every gzip file


@contextlib.contextmanager
def open_csv(path: Path) -> Iterator[Iterator[str]]:
    """Open a ``.csv`` or gzip-compressed ``.csv.gz`` file for :mod:`csv`: ``with open_csv(path) as lines: ...``.

    ``lines`` reads the file a line at a time and checks it: the text is UTF-8 (a leading byte-order mark
    is dropped) and blank lines at the end are dropped. Raises ``FileNotFoundError`` for a missing file and
    ``ValueError`` naming the file when it is named ``.gz`` but not gzip (on opening), or, as ``lines`` is
    read, a truncated or corrupt gzip stream, binary (not UTF-8, or NUL bytes), or empty (no line with text).
    A directory raises ``IsADirectoryError`` saying so.
    """
    if path.is_dir():
        raise IsADirectoryError(f"{path}: is a directory, not a .csv or .csv.gz file")
    if path.suffix == ".gz":
        with path.open("rb") as raw:
            start = raw.read(8)
        if not start.startswith(GZIP_MAGIC):
            what = "an empty file" if not start else f"its first bytes are {start!r}"
            raise ValueError(f"{path}: not gzip-compressed although named .gz ({what})")
        binary: gzip.GzipFile | io.BufferedReader = gzip.open(path, "rb")
    else:
        binary = path.open("rb")
    with io.TextIOWrapper(binary, encoding="utf-8-sig", errors="strict", newline="") as text:
        yield _checked_lines(path, text)


def _checked_lines(path: Path, text: io.TextIOWrapper) -> Iterator[str]:
    """The lines of ``text`` (``path``'s), checked as :func:`open_csv` says; blank lines are held back until a
    line with text follows, so the blank lines at the end are never yielded."""
    blank: list[str] = []
    has_text = False
    try:
        for number, line in enumerate(text, start=1):
            if "\0" in line:
                raise ValueError(f"{path}: NUL byte on line {number}: binary data, not CSV text")
            if line.isspace():
                blank.append(line)
                continue
            yield from blank
            blank.clear()
            has_text = True
            yield line
    except (EOFError, zlib.error, gzip.BadGzipFile) as err:
        raise ValueError(f"{path}: truncated or corrupt gzip data ({err})") from err
    except UnicodeDecodeError as err:
        # err.object holds the bytes decoded last, which end where the binary stream stands.
        offset = cast(io.BufferedIOBase, text.buffer).tell() - len(err.object) + err.start  # what open_csv wraps
        where = "of the decompressed data " if path.suffix == ".gz" else ""
        raise ValueError(
            f"{path}: not UTF-8 text (byte {offset} {where}is {err.object[err.start]:#04x}): "
            "binary data or another encoding"
        ) from err
    if not has_text:
        raise ValueError(f"{path}: empty file (no text)")


@contextlib.contextmanager
def csv_errors(path: Path, reader: csv.DictReader | Iterator[list[str]], first_line: int = 1) -> Iterator[None]:
    """Turn an error of the :mod:`csv` module while ``reader`` (a reader of ``path``) is read into a ``ValueError``
    naming the file, the row (a line of the file; the reader's first line is line ``first_line``) and the cause,
    e.g. a field longer than the module's limit of 131,072 characters."""
    try:
        yield
    except csv.Error as err:
        # A DictReader's own line_num lags behind its csv reader's until a row is read whole.
        source: Any = getattr(reader, "reader", reader)  # a csv reader: has line_num
        row = first_line - 1 + max(source.line_num, 1)
        raise ValueError(f"{path}: row {row} is not readable as CSV ({err})") from err


def _series(name: str, values: np.ndarray) -> np.ndarray:
    """``values`` as a finite 1-D float array of at least 2 samples; ValueError naming ``name`` otherwise."""
    try:
        array = np.asarray(values, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} = {shown(values)}: must be a 1-D array of numbers") from None
    if array.ndim != 1 or array.size < 2:
        raise ValueError(f"{name} has shape {array.shape}: must be 1-D with at least 2 samples")
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise ValueError(f"{name}[{bad[0]}] = {array[bad[0]]}: every sample must be finite ({bad.size} are not)")
    return array


def check_speeds(speed: np.ndarray, where: str) -> None:
    """ValueError unless every speed [m/s] of ``speed`` (any shape, finite) lies in [0, MAX_SPEED], naming the first
    that does not as ``where`` followed by its index, e.g. ``LeaderProfile 'user': speed[3] = 1000.0 m/s ...``."""
    if speed.min() >= 0 and speed.max() <= MAX_SPEED:  # the usual case, in two passes
        return
    bad = (speed < 0) | (speed > MAX_SPEED)
    if bad.any():
        index = tuple(int(i) for i in np.argwhere(bad)[0])
        at = ", ".join(map(str, index))
        raise ValueError(f"{where}speed[{at}] = {float(speed[index])!r} m/s: every speed must lie in [0, MAX_SPEED = "
                         f"{MAX_SPEED:g}] m/s ({np.count_nonzero(bad)} do not)")


def recorded_part(items: Sequence[T], part: str) -> list[T]:
    """The ``part`` (a :data:`~timegap_env.config.RECORDED_PARTS` name) of recorded leaders ``items``, given in a
    fixed order (NGSIM vehicles by id, OpenACC runs by name): all of them; the held-out part, every
    :data:`~timegap_env.config.HELD_OUT_EVERY`-th from the first; or the training part, the others."""
    if part == "all":
        return list(items)
    if part not in RECORDED_PARTS:
        raise ValueError(f"LeaderConfig.recorded_part = {part!r}: must be one of {RECORDED_PARTS}")
    held_out = part == "held_out"
    return [item for i, item in enumerate(items) if (i % HELD_OUT_EVERY == 0) == held_out]


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
            values = _series(f"LeaderProfile {self.name!r}: {field}", getattr(self, field)).copy()
            values.setflags(write=False)
            object.__setattr__(self, field, values)
            if field == "speed":
                check_speeds(values, f"LeaderProfile {self.name!r}: ")
        if self.speed.shape != self.accel.shape:
            raise ValueError(
                f"LeaderProfile {self.name!r}: accel has shape {self.accel.shape}, speed has {self.speed.shape}: "
                "must match"
            )

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
        speed = _series(f"LeaderProfile {name!r}: speed", speed)
        check_speeds(speed, f"LeaderProfile {name!r}: ")  # before the difference, which 1e308 m/s would overflow
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
        return LeaderProfiles.from_acceleration(_series("accel", accel)[None], leader, name).profile(0)

    @classmethod
    def from_csv(cls, path: str | Path, dt: float = LeaderConfig.dt, name: str | None = None) -> LeaderProfile:
        """Read a profile from a ``.csv`` or gzip-compressed ``.csv.gz`` file with a header.

        Columns: ``speed`` [m/s] (required); ``time`` [s] (optional, evenly
        spaced, sets ``dt``); ``accel`` [m/s^2] (optional, else differentiated).
        Names may be padded with spaces (``time, speed``); blank lines are skipped.
        Raises ``ValueError`` naming the file and what is wrong (see :func:`open_csv`), e.g. a speed outside
        [0, ``MAX_SPEED``];
        rows are numbered as lines of the file, the header being row 1.
        """
        path = Path(path)
        with open_csv(path) as lines:
            reader = csv.DictReader(lines)
            with csv_errors(path, reader):
                fieldnames = reader.fieldnames
                assert fieldnames is not None  # open_csv's lines include a header: the file has text
                columns = [column.strip() for column in fieldnames]
                if "speed" not in columns:
                    raise ValueError(f"{path}: missing column 'speed' (found columns {columns})")
                reader.fieldnames = columns
                rows = [(reader.line_num, row) for row in reader]
        if len(rows) < 2:
            found = "one data row" if rows else "no data rows"
            raise ValueError(f"{path}: {found} after the header; a profile needs at least 2")
        data = {}
        for column in ("time", "speed", "accel"):
            if column not in columns:
                continue
            values = np.empty(len(rows))
            for i, (line, row) in enumerate(rows):
                if row[column] is None:
                    raise ValueError(f"{path}: row {line} has fewer fields than the header ({len(columns)})")
                try:
                    values[i] = float(row[column])
                except ValueError:
                    values[i] = math.nan  # not a number: reported just below, as NaN or inf text is
                if not math.isfinite(values[i]):
                    raise ValueError(f"{path}: row {line}, column '{column}' = {row[column]!r} is not a finite number")
                if column == "speed" and not 0 <= values[i] <= MAX_SPEED:
                    raise ValueError(f"{path}: row {line}, column 'speed' = {row[column]!r} m/s is outside "
                                     f"[0, MAX_SPEED = {MAX_SPEED:g}] m/s")
            data[column] = values
        if "time" in data:
            steps = np.diff(data["time"])
            if not np.allclose(steps, steps[0], rtol=1e-6, atol=1e-9) or steps[0] <= 0:
                raise ValueError(f"{path}: column 'time' must increase in even steps")
            dt = float(steps[0])
        name = name or (Path(path.stem).stem if path.suffix == ".gz" else path.stem)
        if "accel" in data:
            return cls(speed=data["speed"], accel=data["accel"], dt=dt, name=name)
        return cls.from_speed(data["speed"], dt=dt, name=name)


@dataclasses.dataclass(frozen=True)
class LeaderProfiles:
    """Leader profiles of one length, a row each: what a batched reset draws and loads at once.

    Checked as :class:`LeaderProfile` checks one (finite, speeds in [0, MAX_SPEED]), for all rows in one pass;
    ``profile(i)`` is row i as a :class:`LeaderProfile`.
    """

    speed: np.ndarray  # (n_profiles, n) [m/s]
    accel: np.ndarray  # (n_profiles, n) [m/s^2]
    dt: float  # [s]
    name: str = "custom"
    regime: np.ndarray | None = None  # (n_profiles, n) int8 the regime of each sample, an index into its family's
    # ``regimes`` (:class:`~timegap_env.leaders.scenarios.LeaderFamily`), from the plan the profile comes from;
    # None: not given

    def __post_init__(self) -> None:
        if not (isinstance(self.dt, (int, float)) and math.isfinite(self.dt) and self.dt > 0):
            raise ValueError(f"LeaderProfiles.dt = {self.dt!r}: must be a finite number > 0")
        for field in ("speed", "accel"):
            values = np.asarray(getattr(self, field), dtype=float)
            if values.ndim != 2 or values.shape[1] < 2:
                raise ValueError(f"LeaderProfiles.{field} has shape {values.shape}: must be (n_profiles, n >= 2)")
            if not np.isfinite(values).all():
                row, k = np.argwhere(~np.isfinite(values))[0]
                raise ValueError(f"LeaderProfiles.{field}[{row}, {k}] = {values[row, k]}: every sample must be finite")
            object.__setattr__(self, field, values)
        if self.speed.shape != self.accel.shape:
            raise ValueError(
                f"LeaderProfiles.accel has shape {self.accel.shape}, speed has {self.speed.shape}: must match"
            )
        if self.regime is not None and np.shape(self.regime) != self.speed.shape:
            raise ValueError(f"LeaderProfiles.regime has shape {np.shape(self.regime)}, speed has {self.speed.shape}: "
                             "must match")
        check_speeds(self.speed, f"LeaderProfiles {self.name!r}: ")

    def __len__(self) -> int:
        return self.speed.shape[0]

    def profile(self, row: int) -> LeaderProfile:
        """Row ``row`` as a :class:`LeaderProfile` (copies)."""
        return LeaderProfile(speed=self.speed[row], accel=self.accel[row], dt=self.dt, name=self.name)

    @classmethod
    def of(cls, profile: LeaderProfile) -> LeaderProfiles:
        """One profile as a batch of one."""
        return cls(speed=profile.speed[None], accel=profile.accel[None], dt=profile.dt, name=profile.name)

    @classmethod
    def from_acceleration(cls, accel: np.ndarray, leader: LeaderConfig = LeaderConfig(), name: str = "integrated",
                          regime: np.ndarray | None = None) -> LeaderProfiles:
        """:meth:`LeaderProfile.from_acceleration` of each row of ``accel`` (n_profiles, n) [m/s^2], with the
        ``regime`` of each sample if given."""
        accel = np.ascontiguousarray(accel, dtype=float)
        if accel.ndim != 2 or accel.shape[1] < 2:
            raise ValueError(f"accel has shape {accel.shape}: must be (n_profiles, n >= 2)")
        speed, realised = _integrate_in_band(accel, leader.initial_speed, leader.dt, *leader.speed_band)
        return cls(speed=speed, accel=realised, dt=leader.dt, name=name, regime=regime)


# Runs in order: every step depends on the speed reached so far.
@numba.njit(cache=True)
def _integrate_in_band(accel, initial_speed, dt, low, high):  # noqa: ANN001, ANN202
    """Speeds [m/s] integrated from ``initial_speed`` along each row of ``accel`` (n_profiles, n) [m/s^2], each step
    clipped to [low, high] (:func:`_step_in_band`), and the accelerations realised [m/s^2] (the speed's forward
    difference over ``dt``), both (n_profiles, n)."""
    speed, realised = np.empty(accel.shape), np.empty(accel.shape)
    for row in range(accel.shape[0]):
        now = initial_speed
        for k in range(accel.shape[1]):
            speed[row, k] = now
            now, realised[row, k] = _step_in_band(now, accel[row, k], dt, low, high)
    return speed, realised


@numba.njit(cache=True)
def _step_in_band(speed, accel, dt, low, high):  # noqa: ANN001, ANN202
    """One tick of ``dt`` [s] at ``accel`` [m/s^2] from ``speed`` [m/s], the speed held within [low, high]: the speed
    after [m/s] and the acceleration realised [m/s^2]."""
    after = min(max(speed + accel * dt, low), high)
    return after, (after - speed) / dt


follow_sources(__name__)
