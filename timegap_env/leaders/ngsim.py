"""Real human leaders from the NGSIM vehicle trajectory data (10 Hz, US units).

The official NGSIM CSV gives one row per vehicle and frame (one frame = 0.1 s)
in feet: ``v_Vel`` [ft/s], ``v_Acc`` [ft/s^2]. This module reads the four
columns it needs and turns one vehicle into a :class:`LeaderProfile` in SI
units, either as recorded or, with ``within_band``, as the paper builds its
leader: the vehicle's real acceleration integrated from an initial speed and
kept inside a speed band (e.g. 20-80 mph).

    table = read_ngsim(default_ngsim_path())
    leader = vehicle_profile(table, vehicle_ids(table, min_duration=60.0)[0])

The data never lives in this repository: :func:`default_ngsim_path` points at
``$TIMEGAP_NGSIM_PATH`` or at the shared subset next to the repository.
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import operator
import os
from pathlib import Path

import numpy as np

from timegap_env.config import MAX_SPEED, LeaderConfig
from timegap_env.leaders.profile import LeaderProfile, csv_errors, open_csv

FOOT = 0.3048  # [m per ft]
FRAME_DT = 0.1  # time between two NGSIM frames [s]
REQUIRED_COLUMNS = ("Vehicle_ID", "Frame_ID", "v_Vel", "v_Acc")
COLUMN_TYPES: tuple[type[np.int64] | type[np.float64], ...] = (  # of REQUIRED_COLUMNS
    np.int64, np.int64, np.float64, np.float64)
CHUNK_ROWS = 16_384  # rows parsed at a time, so the text of the whole file is never held
PATH_VARIABLE = "TIMEGAP_NGSIM_PATH"
SHARED_SUBSET = Path("shared", "data", "ngsim", "i80_0400_0415_pairs.csv.gz")


def default_ngsim_path() -> Path:
    """``$TIMEGAP_NGSIM_PATH`` if set, else the shared I-80 subset beside the repository."""
    if os.environ.get(PATH_VARIABLE):
        return Path(os.environ[PATH_VARIABLE])
    repo_root = Path(__file__).resolve().parents[2]  # timegap_env/leaders/ngsim.py -> the repository
    return repo_root.parent / SHARED_SUBSET


@dataclasses.dataclass(frozen=True)
class NgsimTable:
    """The columns of an NGSIM file that a leader needs, one entry per data row, in file order."""

    path: Path
    vehicle_id: np.ndarray  # Vehicle_ID (n,) int64
    frame: np.ndarray  # Frame_ID (n,) int64 [0.1 s]
    v_vel: np.ndarray  # v_Vel (n,) [ft/s]
    v_acc: np.ndarray  # v_Acc (n,) [ft/s^2]


def read_ngsim(path: str | Path) -> NgsimTable:
    """Read ``Vehicle_ID``, ``Frame_ID``, ``v_Vel`` and ``v_Acc`` from an NGSIM ``.csv`` or ``.csv.gz``.

    Raises ``ValueError`` naming the file and what is wrong: the file itself (see :func:`open_csv`), a
    missing column, no data rows, or the row, column and value at fault. Rows are numbered as lines of
    the file, the header being row 1. Names may be padded with spaces; trailing blank lines are ignored.
    """
    path = Path(path)
    parts: list[list[np.ndarray]] = [[] for _ in REQUIRED_COLUMNS]  # each column's arrays, a chunk each
    first_row = 2  # the line of the file the chunk's first row is on
    with open_csv(path) as lines:
        reader = csv.reader(lines)
        with csv_errors(path, reader):
            header = [name.strip() for name in next(reader)]
            missing = [name for name in REQUIRED_COLUMNS if name not in header]
            if missing:
                raise ValueError(f"{path}: missing column(s) {missing} (found columns {header})")
            pick = operator.itemgetter(*(header.index(name) for name in REQUIRED_COLUMNS))
            while True:
                try:
                    chunk = list(map(pick, itertools.islice(reader, CHUNK_ROWS)))
                except IndexError:
                    raise ValueError(
                        f"{path}: row {reader.line_num} has fewer fields than the header ({len(header)})"
                    ) from None
                if not chunk:
                    break
                for j, (name, dtype) in enumerate(zip(REQUIRED_COLUMNS, COLUMN_TYPES)):
                    parts[j].append(_parse(path, name, [row[j] for row in chunk], dtype, first_row))
                first_row += len(chunk)
    if not parts[0]:
        raise ValueError(f"{path}: no data rows after the header")
    vehicle_id, frame, v_vel, v_acc = (np.concatenate(part) for part in parts)
    return NgsimTable(path=path, vehicle_id=vehicle_id, frame=frame, v_vel=v_vel, v_acc=v_acc)


def vehicle_ids(table: NgsimTable, min_duration: float = 0.0) -> list[int]:
    """Sorted ids of the vehicles :func:`vehicle_profile` accepts with at least ``min_duration`` [s] of data.

    A vehicle qualifies when its frames have no gap, no conflicting duplicate,
    its speeds lie in [0, ``MAX_SPEED``] and span at least two samples.
    """
    order = np.lexsort((table.frame, table.vehicle_id))
    vehicle = table.vehicle_id[order]
    repeat, conflict, gap = _adjacent_checks(table, order)
    faulty = np.union1d(vehicle[1:][conflict | gap], table.vehicle_id[_speed_out_of_range(table.v_vel)])
    ids, samples = np.unique(vehicle[np.append(True, ~repeat)], return_counts=True)
    usable = (samples >= 2) & ((samples - 1) * FRAME_DT >= min_duration) & ~np.isin(ids, faulty)
    return ids[usable].tolist()


def no_vehicle_reason(table: NgsimTable, min_duration: float) -> str:
    """Why :func:`vehicle_ids` finds no vehicle of ``table`` with ``min_duration`` [s] of data, for an error message:
    the file, how many vehicles it has, the longest usable one, and what is wrong with the first unusable one."""
    all_ids = np.unique(table.vehicle_id)
    usable = vehicle_ids(table)
    order = np.lexsort((table.frame, table.vehicle_id))
    vehicle, frame = table.vehicle_id[order], table.frame[order]
    first = np.append(True, (np.diff(vehicle) != 0) | (np.diff(frame) != 0))
    ids, samples = np.unique(vehicle[first], return_counts=True)
    longest = ((samples[np.isin(ids, usable)] - 1) * FRAME_DT).max(initial=0.0)
    reason = f"{table.path}: no vehicle has {min_duration} s of usable frames: of its {all_ids.size} vehicle(s), "
    reason += f"{len(usable)} usable" + (f" (the longest for {longest:.1f} s)" if usable else "")
    unusable = np.setdiff1d(all_ids, usable)
    if unusable.size:
        try:
            vehicle_profile(table, int(unusable[0]))
        except ValueError as error:
            reason += f", {unusable.size} unusable, e.g. {str(error).removeprefix(f'{table.path}: ')}"
    return reason


def vehicle_profile(
    table: NgsimTable, vehicle_id: int, *, within_band: LeaderConfig | None = None
) -> LeaderProfile:
    """One vehicle's speed [m/s] and acceleration [m/s^2] in frame order, ``dt`` = 0.1 s.

    Rows repeating a frame with identical ``v_Vel`` and ``v_Acc`` count once. A speed outside [0, ``MAX_SPEED``]
    is a ``ValueError`` naming the file, the vehicle, the row and the value (whether or not ``within_band``).
    With ``within_band``, the vehicle's acceleration is instead integrated from
    ``within_band.initial_speed`` and kept inside ``within_band.speed_band``
    (``LeaderProfile.from_acceleration``); the profile keeps the vehicle's length.
    """
    rows = np.flatnonzero(table.vehicle_id == vehicle_id)
    if rows.size == 0:
        known = np.unique(table.vehicle_id)
        raise ValueError(
            f"{table.path}: no rows for Vehicle_ID {vehicle_id}; "
            f"known ids include {known[:5].tolist()} ({known.size} vehicles)"
        )
    rows = rows[np.argsort(table.frame[rows], kind="stable")]
    frame = table.frame[rows]
    repeat, conflict, gap = _adjacent_checks(table, rows)
    if conflict.any():
        k = np.flatnonzero(conflict)[0]
        first, second = rows[k], rows[k + 1]
        raise ValueError(
            f"{table.path}: Vehicle_ID {vehicle_id}, Frame_ID {frame[k]} appears in rows "
            f"{first + 2} and {second + 2} with different values: "
            f"(v_Vel, v_Acc) = ({table.v_vel[first]}, {table.v_acc[first]}) vs "
            f"({table.v_vel[second]}, {table.v_acc[second]})"
        )
    if gap.any():
        k = np.flatnonzero(gap)[0]
        raise ValueError(
            f"{table.path}: Vehicle_ID {vehicle_id} has a gap in Frame_ID between {frame[k]} and "
            f"{frame[k + 1]} ({gap.sum()} gap(s) in frames {frame[0]}-{frame[-1]})"
        )
    rows = rows[np.append(True, ~repeat)]
    if rows.size < 2:
        raise ValueError(f"{table.path}: Vehicle_ID {vehicle_id} has 1 frame; a profile needs at least 2")
    out_of_range = np.flatnonzero(_speed_out_of_range(table.v_vel[rows]))
    if out_of_range.size:
        row = rows[out_of_range[0]]
        raise ValueError(
            f"{table.path}: Vehicle_ID {vehicle_id}, row {row + 2} (Frame_ID {table.frame[row]}): v_Vel = "
            f"{table.v_vel[row]} ft/s ({table.v_vel[row] * FOOT:.6g} m/s) is outside [0, MAX_SPEED = "
            f"{MAX_SPEED:g}] m/s ({out_of_range.size} of its {rows.size} frames are)"
        )
    speed = table.v_vel[rows] * FOOT
    accel = table.v_acc[rows] * FOOT
    name = f"ngsim-{vehicle_id}"
    if within_band is None:
        return LeaderProfile(speed=speed, accel=accel, dt=FRAME_DT, name=name)
    if not np.isclose(within_band.dt, FRAME_DT):
        raise ValueError(
            f"within_band.dt = {within_band.dt}: must equal the NGSIM frame period {FRAME_DT} s"
        )
    return LeaderProfile.from_acceleration(accel, within_band, name=f"{name}-in-band")


def _speed_out_of_range(v_vel: np.ndarray) -> np.ndarray:
    """Which of the speeds ``v_vel`` [ft/s] lie outside [0, MAX_SPEED] once in m/s [bool]."""
    speed = v_vel * FOOT
    return (speed < 0) | (speed > MAX_SPEED)


def _adjacent_checks(table: NgsimTable, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flags for each pair of neighbours in ``rows``, row indices sorted by (Vehicle_ID, Frame_ID).

    Returns (repeat, conflict, gap), each of shape (len(rows) - 1,): the second
    row repeats the first one's vehicle and frame; it does so with a different
    ``v_Vel`` or ``v_Acc``; it is the same vehicle after missing frames.
    """
    same_vehicle = np.diff(table.vehicle_id[rows]) == 0
    step = np.diff(table.frame[rows])
    repeat = same_vehicle & (step == 0)
    differs = (np.diff(table.v_vel[rows]) != 0) | (np.diff(table.v_acc[rows]) != 0)
    return repeat, repeat & differs, same_vehicle & (step > 1)


def _parse(
    path: Path, column: str, texts: list[str], dtype: type[np.int64] | type[np.float64], first_row: int
) -> np.ndarray:
    """One column of rows ``first_row``, ``first_row`` + 1, ... (lines of the file) as a finite ``dtype`` array;
    the first bad value raises ``ValueError`` naming its row."""
    try:
        values = np.array(texts, dtype=dtype)
    except (ValueError, OverflowError):  # slow path, only to find the first bad value
        i = next(i for i, text in enumerate(texts) if not _converts(text, dtype))
    else:
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size == 0:
            return values
        i = bad[0]
    kind = "an integer" if dtype is np.int64 else "a finite number"
    raise ValueError(f"{path}: row {first_row + i}, column '{column}' = {texts[i]!r} is not {kind}")


def _converts(text: str, dtype: type[np.int64] | type[np.float64]) -> bool:
    """Whether ``text`` converts to ``dtype`` (as ``np.array(..., dtype)`` would)."""
    try:
        dtype(text)
    except (ValueError, OverflowError):
        return False
    return True
