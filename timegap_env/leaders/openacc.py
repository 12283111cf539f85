"""Real commercial ACC platoons: the OpenACC AstaZero runs (10 Hz, SI units).

The OpenACC database (Makridis, Mattas, Anesiadou & Ciuffo, Transportation Research Part C
125:103047, 2021) recorded platoons of up to 11 production cars behind a human-driven car on a
test track, with their factory ACC engaged at a known distance setting, or driven by people.
Each file holds five metadata lines and a table::

    Date,d,m,yyyy
    Vehicle_order,NAME1,NAME2,...        the cars from the front (position 1) backwards
    Number_of_vehicles,n
    ACC,1 (or 0: people drove)
    Distance_setting,S | M | L | SL (a mix), empty when ACC is off
    Time,Speed1,E1,N1,...,IVS1,...       [s], [m/s], [m]; IVS<k> the gap behind car k

:func:`read_openacc` turns a file into an :class:`OpenAccRun`: speeds and bumper-to-bumper
spacings per position, NaN where a record has a gap or a position has no columns at all (those
are listed, never invented). :func:`openacc_leader` replays a run's human-driven lead car as a
:class:`LeaderProfile`. The data never lives in this repository: :func:`default_openacc_dir` is
``$TIMEGAP_OPENACC_PATH`` or the shared copy next to the repository.
"""

from __future__ import annotations

import csv
import dataclasses
import datetime
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from timegap_env.config import MAX_SPEED, LeaderConfig
from timegap_env.leaders.profile import LeaderProfile, csv_errors, open_csv, recorded_part

PATH_VARIABLE = "TIMEGAP_OPENACC_PATH"  # a directory of OpenACC files
SHARED_DIR = Path("shared", "data", "openacc")
TICK = 0.1  # time between two records [s]
STANDSTILL_SPEED = 0.1  # a car slower than this stands still; a recorded speed may dip this far below 0 (the data
# holds -0.07 m/s), a lead car's is then read as 0 [m/s]
MIN_STANDSTILL_TIME = 2.0  # a follower's standstill spacing needs at least this much standing still [s]
TICK_TOLERANCE = 1e-6  # a time step farther than this from TICK is an error [s]
METADATA = ("Date", "Vehicle_order", "Number_of_vehicles", "ACC", "Distance_setting")
DISTANCE_SETTINGS = ("S", "M", "L", "SL")  # shortest, medium, longest, a mix of short and long


@dataclasses.dataclass(frozen=True)
class OpenAccRun:
    """One OpenACC run: a platoon of ``n_vehicles`` cars, position 1 (index 0) the human-driven lead car.

    ``spacing[:, j]`` is the bumper-to-bumper gap from car j + 1 to the car ahead of it, car j
    (0-based; the file's ``IVS<j + 1>``), so follower j + 1's own spacing.
    """

    path: Path
    date: datetime.date
    vehicles: tuple[str, ...]  # car names, from the front backwards
    acc: bool  # the followers drove on ACC (else people drove)
    distance_setting: str | None  # one of DISTANCE_SETTINGS, None when ACC is off
    t: np.ndarray  # (n_ticks,) [s]
    speed: np.ndarray  # (n_ticks, n_vehicles) [m/s], NaN where there is no record
    spacing: np.ndarray  # (n_ticks, n_vehicles - 1) [m], NaN where there is no record
    absent_positions: tuple[int, ...]  # 1-based positions whose speed columns the file lacks
    absent_spacings: tuple[int, ...]  # k whose IVS<k> column (the gap behind car k) the file lacks

    @property
    def n_vehicles(self) -> int:
        return len(self.vehicles)

    @property
    def name(self) -> str:
        """The file's name without its suffixes, e.g. ``astazero_dynamic_part1``."""
        return self.path.name.split(".")[0]


def default_openacc_dir() -> Path:
    """``$TIMEGAP_OPENACC_PATH`` if set, else the shared OpenACC copy beside the repository."""
    if os.environ.get(PATH_VARIABLE):
        return Path(os.environ[PATH_VARIABLE])
    repo_root = Path(__file__).resolve().parents[2]  # timegap_env/leaders/openacc.py -> the repository
    return repo_root.parent / SHARED_DIR


def openacc_paths(directory: str | Path | None = None) -> list[Path]:
    """The ``.csv`` and ``.csv.gz`` files of ``directory`` (default :func:`default_openacc_dir`), sorted by name."""
    directory = default_openacc_dir() if directory is None else Path(directory)
    if directory.exists() and not directory.is_dir():
        raise NotADirectoryError(f"OpenACC data at {directory} is not a directory: set ${PATH_VARIABLE} to a directory "
                                 "of OpenACC files")
    return sorted(path for path in directory.iterdir() if path.name.endswith((".csv", ".csv.gz")))


def read_openacc(path: str | Path) -> OpenAccRun:
    """Read one OpenACC ``.csv`` or ``.csv.gz`` file.

    Raises ``ValueError`` naming the file and what is wrong: the file itself (see :func:`open_csv`), a
    missing or malformed metadata line, a missing column, a value that is neither a number nor empty
    (an empty or NaN value is a gap in the record; ``inf`` is an error), a speed outside [-STANDSTILL_SPEED,
    ``MAX_SPEED``], a time step that is not 0.1 s, an empty table. Rows are numbered as lines of the file.
    Trailing blank lines are ignored.
    """
    path = Path(path)
    metadata = {}
    with open_csv(path) as lines:
        for line_number, expected in enumerate(METADATA, start=1):
            line = next(lines, "")
            if not line:
                raise ValueError(
                    f"{path}: ends after line {line_number - 1}: expected the metadata line {expected!r}"
                )
            fields = [field.strip() for field in line.rstrip("\r\n").split(",")]
            if fields[0] != expected:
                raise ValueError(f"{path}: line {line_number} is {fields[0]!r}: expected the metadata line {expected!r}")
            metadata[expected] = [field for field in fields[1:] if field]
        reader = csv.reader(lines)
        with csv_errors(path, reader, first_line=len(METADATA) + 1):
            header = [name.strip() for name in next(reader, [])]
            rows = list(reader)
    date, acc, setting, vehicles = _parse_metadata(path, metadata)
    if "Time" not in header:
        raise ValueError(f"{path}: missing column 'Time' (found columns {header[:8]}...)")
    if not rows:
        raise ValueError(f"{path}: no data rows after the header")
    columns = {name: j for j, name in enumerate(header)}
    first_data_line = len(METADATA) + 2
    short = next((i for i, row in enumerate(rows) if len(row) < len(header)), None)
    if short is not None:
        raise ValueError(f"{path}: row {first_data_line + short} has {len(rows[short])} fields, the header {len(header)}")

    def column(name: str) -> np.ndarray:
        return _parse_column(path, name, [row[columns[name]] for row in rows], first_data_line)

    t = column("Time")
    if np.isnan(t).any():
        i = int(np.flatnonzero(np.isnan(t))[0])
        text = rows[i][columns["Time"]]
        what = f"= {text!r} is not a finite number" if text.strip() else "is empty"
        raise ValueError(f"{path}: row {first_data_line + i}, column 'Time' {what}")
    steps = np.diff(t)
    wrong = np.flatnonzero(np.abs(steps - TICK) > TICK_TOLERANCE)
    if wrong.size:
        k = int(wrong[0])
        raise ValueError(f"{path}: time steps must be {TICK} s; rows {first_data_line + k} and {first_data_line + k + 1} "
                         f"are {steps[k]:.6g} s apart (t = {t[k]:.6g}, {t[k + 1]:.6g})")
    n = len(vehicles)
    speed, spacing = np.full((t.size, n), np.nan), np.full((t.size, n - 1), np.nan)
    absent_positions, absent_spacings = [], []
    for k in range(1, n + 1):
        if f"Speed{k}" in columns:
            speed[:, k - 1] = column(f"Speed{k}")
            with np.errstate(invalid="ignore"):
                wrong = np.flatnonzero((speed[:, k - 1] < -STANDSTILL_SPEED) | (speed[:, k - 1] > MAX_SPEED))
            if wrong.size:
                i = int(wrong[0])
                raise ValueError(
                    f"{path}: row {first_data_line + i}, column 'Speed{k}' (car {vehicles[k - 1]}) = "
                    f"{rows[i][columns[f'Speed{k}']]!r} m/s is outside [-{STANDSTILL_SPEED}, MAX_SPEED = "
                    f"{MAX_SPEED:g}] m/s"
                )
        else:
            absent_positions.append(k)
        if k < n:
            if f"IVS{k}" in columns:
                spacing[:, k - 1] = column(f"IVS{k}")
            else:
                absent_spacings.append(k)
    return OpenAccRun(path, date, vehicles, acc, setting, t, speed, spacing, tuple(absent_positions),
                      tuple(absent_spacings))


def _parse_metadata(path: Path, metadata: dict[str, list[str]]) -> tuple[datetime.date, bool, str | None, tuple[str, ...]]:
    """(date, ACC on, distance setting, the platoon's cars) from the metadata lines; ValueError naming the line."""
    try:
        day, month, year = (int(value) for value in metadata["Date"])
        date = datetime.date(year, month, day)
    except ValueError:
        raise ValueError(f"{path}: Date = {metadata['Date']}: expected day,month,year") from None
    count = metadata["Number_of_vehicles"]
    if len(count) != 1 or not count[0].isdigit() or int(count[0]) < 2:
        raise ValueError(f"{path}: Number_of_vehicles = {count}: expected one whole number >= 2")
    n_vehicles, order = int(count[0]), metadata["Vehicle_order"]
    if len(order) < n_vehicles:
        raise ValueError(f"{path}: Vehicle_order names {len(order)} cars, Number_of_vehicles is {n_vehicles}")
    if metadata["ACC"] not in (["0"], ["1"]):
        raise ValueError(f"{path}: ACC = {metadata['ACC']}: expected 1 (ACC on) or 0 (people drove)")
    acc = metadata["ACC"] == ["1"]
    setting = metadata["Distance_setting"][0] if metadata["Distance_setting"] else None
    if acc and setting not in DISTANCE_SETTINGS:
        raise ValueError(f"{path}: Distance_setting = {setting!r}: with ACC on, expected one of {DISTANCE_SETTINGS}")
    return date, acc, (setting if acc else None), tuple(order[:n_vehicles])


def _parse_column(path: Path, name: str, texts: list[str], first_data_line: int) -> np.ndarray:
    """One column as floats, NaN where empty or NaN; ValueError naming the row of the first value that is
    not a number, or infinite."""
    try:
        values = np.array([text or "nan" for text in texts], dtype=float)
    except ValueError:
        for i, text in enumerate(texts):
            try:
                float(text or "nan")
            except ValueError:
                raise ValueError(f"{path}: row {first_data_line + i}, column {name!r} = {text!r} is not a number") from None
        raise
    infinite = np.flatnonzero(np.isinf(values))
    if infinite.size:
        i = int(infinite[0])
        raise ValueError(f"{path}: row {first_data_line + i}, column {name!r} = {texts[i]!r} is not a finite number")
    return values


def repeated_runs(runs: Sequence[OpenAccRun]) -> dict[str, str]:
    """Runs whose every record repeats part of a longer run of the same day: {repeat: the longer run}.

    Two records are the same when the times match and every car the two files share has identical
    speeds (NaN included); the data's publisher cut the original runs into parts, and some overlap.
    """
    repeats = {}
    for i, short in enumerate(runs):
        for j, long in enumerate(runs):
            if j == i or long.date != short.date or long.t.size < short.t.size or long.name in repeats:
                continue
            if long.t.size == short.t.size and j > i:
                continue  # of two equally long copies, the later one is the repeat
            offset = int(round((short.t[0] - long.t[0]) / TICK))
            if offset < 0 or offset + short.t.size > long.t.size:
                continue
            stretch = slice(offset, offset + short.t.size)
            shared = [name for name in dict.fromkeys(short.vehicles) if name in long.vehicles]
            same = [np.array_equal(short.speed[:, short.vehicles.index(name)],
                                   long.speed[stretch, long.vehicles.index(name)], equal_nan=True) for name in shared]
            if np.allclose(short.t, long.t[stretch]) and shared and all(same):
                repeats[short.name] = long.name
                break
    return repeats


def openacc_leader(seed: int | None, leader: LeaderConfig) -> LeaderProfile:
    """The human-driven lead car of a run drawn by ``seed`` among the runs that recorded it: its longest
    stretch of speeds without a gap, cut to ``leader.duration``."""
    directory = default_openacc_dir()
    if not directory.exists():
        raise FileNotFoundError(f"OpenACC data not found at {directory}: set ${PATH_VARIABLE} to a directory of OpenACC files")
    stretches = recorded_part([stretch for stretch in lead_car_speeds(directory)
                               if stretch[1].size * TICK >= leader.min_recorded_duration], leader.recorded_part)
    if not stretches:
        raise ValueError(f"no OpenACC run in {directory} has {leader.min_recorded_duration} s of lead-car speeds without a "
                         f"gap (LeaderConfig.recorded_part = {leader.recorded_part!r})")
    name, speed = stretches[np.random.default_rng(seed).integers(len(stretches))]
    n = min(speed.size, leader.n_samples)
    return LeaderProfile.from_speed(np.maximum(speed[:n], 0.0), TICK, name=f"openacc-{name}")


_STRETCHES: dict[Path, list[tuple[str, np.ndarray]]] = {}  # per directory, read once per process


def standstill_spacings(run: OpenAccRun) -> list[tuple[str, float]]:
    """(car, median spacing [m]) of every follower of ``run`` that stood still (speed below STANDSTILL_SPEED, its
    spacing recorded) for MIN_STANDSTILL_TIME or more: the standstill spacing s0 the car keeps."""
    with np.errstate(invalid="ignore"):
        still = (np.abs(run.speed[:, 1:]) < STANDSTILL_SPEED) & np.isfinite(run.spacing)
    return [(run.vehicles[j + 1], float(np.median(run.spacing[still[:, j], j])))
            for j in np.flatnonzero(still.sum(axis=0) * TICK >= MIN_STANDSTILL_TIME)]


def valid_stretches(valid: np.ndarray) -> list[tuple[int, int]]:
    """The (start, end) index pairs, end exclusive, of the runs of True in the 1-D mask ``valid``."""
    edges = np.flatnonzero(np.diff(np.r_[0, np.asarray(valid, dtype=np.int8), 0]))
    return [(int(start), int(end)) for start, end in zip(edges[::2], edges[1::2])]


def lead_car_speeds(directory: Path) -> list[tuple[str, np.ndarray]]:
    """(run name, the lead car's longest gap-free speed series [m/s]) of every run in ``directory`` that recorded its
    lead car, sorted by name; read once per process."""
    if directory not in _STRETCHES:
        stretches = []
        for path in openacc_paths(directory):
            run = read_openacc(path)
            if 1 in run.absent_positions:
                continue
            recorded = valid_stretches(np.isfinite(run.speed[:, 0]))
            if recorded:  # the column may be there but empty
                start, end = max(recorded, key=lambda stretch: stretch[1] - stretch[0])
                stretches.append((run.name, run.speed[start:end, 0]))
        _STRETCHES[directory] = stretches
    return _STRETCHES[directory]
