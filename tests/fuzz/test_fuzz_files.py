"""Fuzz of the leader-file readers (issue 22): malformed NGSIM, OpenACC and leader-profile CSV files through the
public readers and through the env.

Each NGSIM and OpenACC case starts from a valid base, the first lines of a real file of ``../shared/data`` read at
test time (never copied into the repository; the tests skip, saying where they looked, when the data is absent),
and mutates it: truncated (plain and gzip), empty, header only, a field over csv's 131,072 characters, a column
renamed or dropped, a cell replaced (NaN, inf, text, negative and absurd speeds, 1e300, 10^400), non-UTF-8 or NUL
bytes, rows too short or too long, broken metadata lines, a directory or nothing where the file should be.

Allowed outcomes: the reader returns data that is finite where it must be (NaN only where OpenACC records a gap)
with speeds within [0, MAX_SPEED] (OpenACC: |speed| <= MAX_SPEED; its records dip a little below 0 at a stop);
or it raises ``ValueError`` (``FileNotFoundError``, ``IsADirectoryError`` for a missing file or a directory)
whose message names the file. A mutation that breaks the file for sure (a huge field in a numeric column, an
absurd speed, bytes that are not text, a truncated gzip stream, ...) must be refused. Through the env
(``$TIMEGAP_NGSIM_PATH`` / ``$TIMEGAP_OPENACC_PATH`` pointing at the bad file, ``reset(options={"scenario": ...})``)
the same, and a refused reset leaves the env refusing to step.
"""

from __future__ import annotations

import gzip
import math
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from hypothesis import given
from hypothesis import strategies as st

import timegap_env  # noqa: F401 - registers the env
from timegap_env.config import MAX_SPEED, LeaderConfig
from timegap_env.leaders import LeaderProfile, read_ngsim, read_openacc, vehicle_ids, vehicle_profile
from timegap_env.leaders import ngsim, openacc
from tests.fuzz.fuzzing import ENV_ID, Defects, call, fuzz_settings, short

DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
NGSIM_FILE = DATA / "ngsim" / "i80_0400_0415_pairs.csv.gz"
OPENACC_FILE = DATA / "openacc" / "astazero_dynamic_part1.csv.gz"
FIELD_LIMIT = 131_072  # csv's default field size limit [characters]
FILE_ERRORS = (ValueError, FileNotFoundError, IsADirectoryError, NotADirectoryError)


def first_lines(path: Path, n: int) -> list[str]:
    """The first ``n`` lines of a (gzip) text file, newlines kept."""
    if not path.exists():
        pytest.skip(f"real data not found at {path} (../shared/data beside the repository): the file fuzz builds its "
                    "base from a few of its lines")
    with gzip.open(path, "rt", encoding="utf-8", newline="") as file:
        return [line for _, line in zip(range(n), file)]


# ----------------------------------------------------------------------------------------------- the readers

def read_ngsim_through(path: Path) -> list[str]:
    """NGSIM through every public reader: the table, then each vehicle's profile as recorded and within the band
    (a vehicle ``vehicle_ids`` leaves out may be refused, with a ValueError naming the file; one it lists must
    not); what in the results breaks the standard (empty when clean)."""
    table = read_ngsim(path)
    problems = []
    for name in ("vehicle_id", "frame", "v_vel", "v_acc"):
        if not np.isfinite(getattr(table, name)).all():
            problems.append(f"table.{name} not finite")
    usable = set(vehicle_ids(table))
    for vehicle in np.unique(table.vehicle_id)[:10].tolist():
        for band in (None, LeaderConfig()):
            profile, error = call(lambda: vehicle_profile(table, vehicle, within_band=band))
            if error is None:
                problems += bad_profile(profile, f"vehicle {vehicle}")
            elif vehicle in usable:
                problems.append(f"vehicle {vehicle}, listed by vehicle_ids, refused: {type(error).__name__}: "
                                f"{short(str(error), 200)}")
            elif not isinstance(error, ValueError) or path.name not in str(error):
                problems.append(f"vehicle {vehicle}: {type(error).__name__} not naming the file: "
                                f"{short(str(error), 200)}")
    return problems


def read_openacc_through(path: Path) -> list[str]:
    run = read_openacc(path)
    problems = []
    if not np.isfinite(run.t).all():
        problems.append("t not finite")
    speed = run.speed[np.isfinite(run.speed)]
    if np.isinf(run.speed).any() or np.isinf(run.spacing).any():
        problems.append("inf in speed or spacing")
    if speed.size and np.abs(speed).max() > MAX_SPEED:
        problems.append(f"|speed| up to {np.abs(speed).max():g} m/s, beyond MAX_SPEED = {MAX_SPEED}")
    return problems


def read_profile_through(path: Path) -> list[str]:
    return bad_profile(LeaderProfile.from_csv(path), "profile")


def bad_profile(profile: LeaderProfile, what: str) -> list[str]:
    if not (np.isfinite(profile.speed).all() and np.isfinite(profile.accel).all()):
        return [f"{what}: not finite"]
    if profile.speed.min() < 0 or profile.speed.max() > MAX_SPEED:
        return [f"{what}: speed {profile.speed.min():g} .. {profile.speed.max():g} m/s outside [0, {MAX_SPEED}]"]
    return []


READERS: dict[str, Callable[[Path], list[str]]] = {
    "ngsim": read_ngsim_through, "openacc": read_openacc_through, "profile": read_profile_through,
}


def judge(reader: str, path: Path, must_fail: bool, defects: Defects, case: str) -> str:
    """Read ``path`` with ``reader``; the outcome as the module docstring allows."""
    problems, error = call(lambda: READERS[reader](path))
    if error is None:
        for problem in problems:
            defects.add("bad data read from a file", problem, case)
        if must_fail:
            defects.add("bad file accepted", f"{reader} read it", case)
        return "read"
    if not isinstance(error, FILE_ERRORS):
        defects.exception(f"{reader} reader", error, case)
        return type(error).__name__
    if path.name not in str(error):
        defects.add(f"{type(error).__name__} not naming the file", str(error)[:300], case)
    return type(error).__name__


# ----------------------------------------------------------------------------------------------- mutations

class Base:
    """A valid file as lines, and where its header, first data row and numeric columns are."""

    def __init__(self, lines: list[str], header_line: int, numeric: list[str], speed: str, speed_scale: float) -> None:
        self.lines = lines
        self.header_line = header_line
        self.header = lines[header_line].rstrip("\r\n").split(",")
        self.numeric = numeric  # columns the reader parses as numbers
        self.speed = speed  # the speed column
        self.speed_scale = speed_scale  # file units per m/s


def ngsim_base() -> Base:
    return Base(first_lines(NGSIM_FILE, 400), 0, list(ngsim.REQUIRED_COLUMNS), "v_Vel", 1 / ngsim.FOOT)


def openacc_base() -> Base:
    return Base(first_lines(OPENACC_FILE, 306), 5, ["Time", "Speed1", "Speed2", "IVS1"], "Speed1", 1.0)


def profile_base() -> Base:
    rows = [f"{0.1 * i:.1f},{20.0 + 2.0 * math.sin(i / 10):.4f}\n" for i in range(200)]
    return Base(["time,speed\n", *rows], 0, ["time", "speed"], "speed", 1.0)


BASES: dict[str, Callable[[], Base]] = {"ngsim": ngsim_base, "openacc": openacc_base, "profile": profile_base}

# Cell values: (text, whether it breaks each reader for sure). OpenACC records a gap as an empty or NaN value.
CELLS: list[tuple[str, set[str]]] = [
    ("nan", {"ngsim", "profile"}), ("NaN", {"ngsim", "profile"}), ("", {"ngsim", "profile"}),
    ("inf", {"ngsim", "openacc", "profile"}), ("-inf", {"ngsim", "openacc", "profile"}),
    ("abc", {"ngsim", "openacc", "profile"}), ("1e300", set()), ("-1e300", set()),  # (speeds: see speeds())
    ("1e400", {"ngsim", "openacc", "profile"}),
    ("1" + "0" * 400, {"ngsim", "openacc", "profile"}), ("0x10", {"ngsim", "openacc", "profile"}),
    (" 12 ", set()), ("1_000", set()), ("\u0661\u0662", set()), ("\u221e", {"ngsim", "openacc", "profile"}),
    ("1e-400", set()), ("-0", set()), ("12,5", set()), ('"12"', set()), ("None", {"ngsim", "openacc", "profile"}),
]


def speeds(reader: str) -> list[tuple[float, bool]]:
    """Speeds [m/s] for the speed column and whether the file must be refused. NGSIM: the table may be read (its
    vehicle is then refused, by the file's name, or left out by vehicle_ids), so the profile checks judge it.
    OpenACC: its own records dip a little below 0 at a stop; beyond MAX_SPEED either way is an error."""
    must = {"ngsim": False, "openacc": True, "profile": True}[reader]
    return [(-1.0, must and reader != "openacc"), (-50.0, must and reader != "openacc"), (MAX_SPEED * 1.01, must),
            (1000.0, must), (1e300, must), (0.0, False), (MAX_SPEED * 0.99, False)]


def replace_cell(base: Base, column: str, row: int, text: str) -> list[str]:
    lines = list(base.lines)
    j = base.header.index(column)
    at = base.header_line + 1 + row
    fields = lines[at].rstrip("\r\n").split(",")
    fields[j] = text
    lines[at] = ",".join(fields) + "\n"
    return lines


def to_bytes(lines: list[str]) -> bytes:
    return "".join(lines).encode()


@st.composite
def mutations(draw: st.DrawFn, reader: str) -> tuple[str, Any, bool, str]:
    """(description, content: bytes, a callable making the path, or None for no file; must fail, file suffix)."""
    base = BASES[reader]()
    rnd = draw(st.randoms(use_true_random=True))
    data_rows = len(base.lines) - base.header_line - 1
    row = rnd.randrange(data_rows)
    kind = rnd.choice(["cell", "cell", "speed", "speed", "truncate", "truncate gzip", "empty", "header only", "huge",
                       "column", "bytes", "row length", "directory", "missing", "metadata", "time", "garbage",
                       "gzip name", "valid variant"])
    data = to_bytes(base.lines)
    if kind == "cell":
        column = rnd.choice(base.numeric)
        text, breaks = rnd.choice(CELLS)
        if reader == "openacc" and column == "Time" and text in ("nan", "NaN", ""):
            breaks = {"openacc"}  # a gap in time is no gap
        return (f"{column} row {row} = {text!r}", to_bytes(replace_cell(base, column, row, text)), reader in breaks,
                ".csv")
    if kind == "speed":
        speed, breaks = rnd.choice(speeds(reader))
        text = repr(speed * base.speed_scale)
        return f"{base.speed} row {row} = {text} ({speed:g} m/s)", to_bytes(replace_cell(base, base.speed, row, text)), \
            breaks, ".csv"
    if kind == "truncate":
        cut = rnd.randrange(1, len(data))
        return f"truncated at byte {cut} of {len(data)}", data[:cut], cut <= len(to_bytes(
            base.lines[: base.header_line + 1])), ".csv"
    if kind == "truncate gzip":
        packed = gzip.compress(data, mtime=0)
        cut = rnd.randrange(0, len(packed) - 8)  # the last 8 bytes are the trailer: any cut before it breaks
        return f"gzip truncated at byte {cut} of {len(packed)}", packed[:cut], True, ".csv.gz"
    if kind == "empty":
        content, suffix = rnd.choice([(b"", ".csv"), (b"", ".csv.gz"), (gzip.compress(b"", mtime=0), ".csv.gz"),
                                      (b"\n\n  \n", ".csv"), (b"\xef\xbb\xbf", ".csv")])
        return f"empty ({content!r}, {suffix})", content, True, suffix
    if kind == "header only":
        return "header only", to_bytes(base.lines[: base.header_line + 1]), True, ".csv"
    if kind == "huge":
        size = rnd.choice([FIELD_LIMIT + 1, 3 * FIELD_LIMIT])
        where = rnd.choice(["numeric", "other", "header"])
        if where == "numeric":
            column = rnd.choice(base.numeric)
            return f"{column} row {row}: a {size}-character number", to_bytes(
                replace_cell(base, column, row, "1" * size)), True, ".csv"
        if where == "other" and reader != "profile":
            other = [c for c in base.header if c not in base.numeric and c]
            column = rnd.choice(other)
            return f"{column} row {row}: a {size}-character field", to_bytes(
                replace_cell(base, column, row, "x" * size)), False, ".csv"
        lines = list(base.lines)
        lines[base.header_line] = lines[base.header_line].rstrip("\r\n") + "," + "h" * size + "\n"
        return f"a {size}-character header name", to_bytes(lines), False, ".csv"
    if kind == "column":
        column = rnd.choice(base.numeric if reader != "openacc" else ["Time"])
        how = rnd.choice(["rename", "drop name", "duplicate"])
        lines = list(base.lines)
        header = list(base.header)
        j = header.index(column)
        if how == "rename":
            header[j] = column + "_x"
        elif how == "drop name":
            header[j] = ""
        else:
            header[j - 1 if j else j + 1] = column
        lines[base.header_line] = ",".join(header) + "\n"
        required = not (reader == "profile" and column == "time")  # a profile's time column is optional
        return f"column {column}: {how}", to_bytes(lines), how != "duplicate" and required, ".csv"
    if kind == "bytes":
        bad = rnd.choice([b"\xff", b"\xe9", b"\x80\x81", b"\x00", b"\xc3(", b"\xed\xa0\x80"])
        at = len(to_bytes(base.lines[: base.header_line + 1 + row])) + rnd.randrange(3)
        return f"bytes {bad!r} at {at}", data[:at] + bad + data[at:], True, rnd.choice([".csv", ".csv.gz"])
    if kind == "row length":
        lines = list(base.lines)
        at = base.header_line + 1 + row
        fields = lines[at].rstrip("\r\n").split(",")
        short_row = rnd.random() < 0.5
        cut = rnd.randrange(1, len(fields)) if short_row else 0
        lines[at] = ",".join(fields[:cut] if short_row else fields + ["1", "2"]) + "\n"
        needed = max(base.header.index(c) for c in base.numeric)
        return (f"row {row} with {cut if short_row else len(fields) + 2} fields", to_bytes(lines),
                short_row and (cut <= needed or reader == "openacc"), ".csv")
    if kind == "directory":
        return "a directory in place of the file", "directory", True, rnd.choice([".csv", ".csv.gz"])
    if kind == "missing":
        return "no file", None, True, ".csv"
    if kind == "metadata" and reader == "openacc":
        lines = list(base.lines)
        line = rnd.randrange(5)
        replacement = rnd.choice(["", "Date,32,13,2019\n", "Number_of_vehicles,0\n", "Number_of_vehicles,x\n",
                                  "Number_of_vehicles,99\n", "ACC,2\n", "Distance_setting,XL\n", "Vehicle_order\n",
                                  "Bogus,1\n", "Number_of_vehicles,1e9\n", "Number_of_vehicles,\u0663\n"])
        lines[line] = replacement
        # the Arabic-Indic digit three is a count of 3 to Python: read as 3 cars, or refused, either is fine
        must = not (line == 2 and "\u0663" in replacement)
        return f"metadata line {line + 1} = {replacement!r}", to_bytes(lines), must, ".csv"
    if kind == "time" and reader != "ngsim":
        column = "Time" if reader == "openacc" else "time"
        how = rnd.choice(["back", "repeat", "jump"])
        value = {"back": "-5", "repeat": None, "jump": "1e6"}[how]
        lines = list(base.lines)
        at = base.header_line + 1 + max(row, 1)
        fields = lines[at].rstrip("\r\n").split(",")
        j = base.header.index(column)
        fields[j] = value if value is not None else lines[at - 1].split(",")[j].strip()
        lines[at] = ",".join(fields) + "\n"
        return f"time row {max(row, 1)}: {how}", to_bytes(lines), True, ".csv"
    if kind == "garbage":
        content = rnd.randbytes(rnd.choice([1, 100, 5000]))
        return f"{len(content)} random bytes", content, True, rnd.choice([".csv", ".csv.gz"])
    if kind == "gzip name":
        if rnd.random() < 0.5:
            return "plain text named .csv.gz", data, True, ".csv.gz"
        return "gzip data named .csv", gzip.compress(data, mtime=0), True, ".csv"
    variant = rnd.choice(["bom", "crlf", "blank tail", "gzip", "no final newline"])
    content = {"bom": b"\xef\xbb\xbf" + data, "crlf": data.replace(b"\n", b"\r\n"), "blank tail": data + b"\n\n",
               "gzip": gzip.compress(data, mtime=0), "no final newline": data.rstrip(b"\n")}[variant]
    return f"valid variant: {variant}", content, False, ".csv.gz" if variant == "gzip" else ".csv"


def write_case(directory: Path, content: Any, suffix: str) -> Path:
    path = directory / f"leader{suffix}"
    if content == "directory":
        path.mkdir()
    elif content is not None:
        path.write_bytes(content)
    return path


def fuzz_files(reader: str, max_examples: int, tmp_path: Path) -> None:
    defects = Defects(f"files/{reader}")
    if reader != "profile":
        BASES[reader]()  # skips when the data is absent

    @fuzz_settings(max_examples)
    @given(mutation=mutations(reader))
    def example(mutation: tuple[str, Any, bool, str]) -> None:
        description, content, must_fail, suffix = mutation
        directory = Path(tempfile.mkdtemp(dir=tmp_path))
        path = write_case(directory, content, suffix)
        defects.case(judge(reader, path, must_fail, defects, f"{reader}: {description} ({path.name})"))

    example()
    defects.check()


@pytest.mark.parametrize("reader", sorted(READERS))
def test_fuzz_leader_files(reader, tmp_path):
    fuzz_files(reader, 100, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("reader", sorted(READERS))
def test_fuzz_leader_files_long(reader, tmp_path):
    fuzz_files(reader, 1500, tmp_path)


def test_the_bases_read_clean():
    """The unmutated bases are valid files: what the fuzz mutates reads clean."""
    with tempfile.TemporaryDirectory() as directory:
        for reader, base in BASES.items():
            path = write_case(Path(directory), to_bytes(base().lines), f"-{reader}.csv")
            assert READERS[reader](path) == []


# ----------------------------------------------------------------------------------------------- through the env

ENV_CASES = {  # (family, what to write) -> content, suffix; each must make the env's reset refuse by the file's name
    "ngsim: truncated gzip": ("ngsim", lambda b: gzip.compress(to_bytes(b.lines), mtime=0)[:500], ".csv.gz"),
    "ngsim: huge field": ("ngsim", lambda b: to_bytes(replace_cell(b, "v_Vel", 3, "9" * (FIELD_LIMIT + 5))), ".csv"),
    "ngsim: no vehicle with two frames": ("ngsim", lambda b: to_bytes(b.lines[:2]), ".csv"),
    "ngsim: negative speed": ("ngsim", lambda b: to_bytes([b.lines[0], *(
        ",".join(f if i != b.header.index("v_Vel") else "-" + f for i, f in enumerate(line.split(",")))
        for line in b.lines[1:])]), ".csv"),
    "ngsim: absurd speed": ("ngsim", lambda b: to_bytes([b.lines[0], *(
        ",".join(f if i != b.header.index("v_Vel") else "1e300" for i, f in enumerate(line.split(",")))
        for line in b.lines[1:])]), ".csv"),
    "ngsim: not UTF-8": ("ngsim", lambda b: to_bytes(b.lines[:50]) + b"\xff\xfe" + to_bytes(b.lines[50:]), ".csv"),
    "ngsim: a directory": ("ngsim", lambda b: "directory", ".csv.gz"),
    "openacc: truncated gzip": ("openacc", lambda b: gzip.compress(to_bytes(b.lines), mtime=0)[:700], ".csv.gz"),
    "openacc: huge field": ("openacc", lambda b: to_bytes(replace_cell(b, "Speed1", 3, "9" * (FIELD_LIMIT + 5))), ".csv"),
    "openacc: absurd lead-car speed": ("openacc", lambda b: to_bytes(replace_cell(b, "Speed1", 40, "1e300")), ".csv"),
    "openacc: 1000 m/s": ("openacc", lambda b: to_bytes(replace_cell(b, "Speed1", 40, "1000")), ".csv"),
    "openacc: not UTF-8": ("openacc", lambda b: to_bytes(b.lines[:50]) + b"\xe9" + to_bytes(b.lines[50:]), ".csv"),
    "openacc: a directory": ("openacc", lambda b: "directory", ".csv"),
}


@pytest.mark.parametrize("name", list(ENV_CASES))
def test_bad_data_files_through_the_env(name, tmp_path, monkeypatch):
    """``$TIMEGAP_NGSIM_PATH`` / ``$TIMEGAP_OPENACC_PATH`` at a bad file: reset(options={"scenario": ...}) raises
    ValueError (IsADirectoryError for a directory) naming the file, and the env then refuses to step."""
    family, make_content, suffix = ENV_CASES[name]
    base = BASES[family]()
    if family == "ngsim":
        path = write_case(tmp_path, make_content(base), suffix)
        monkeypatch.setenv(ngsim.PATH_VARIABLE, str(path))
    else:
        directory = tmp_path / "openacc"
        directory.mkdir()
        path = write_case(directory, make_content(base), suffix)
        monkeypatch.setenv(openacc.PATH_VARIABLE, str(directory))
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    env.step(0)
    scenario = "ngsim" if family == "ngsim" else "openacc"
    _, error = call(lambda: env.reset(seed=1, options={"scenario": scenario}))
    assert error is not None, f"{name}: the env ran a leader from the bad file"
    assert isinstance(error, FILE_ERRORS), f"{type(error).__name__}: {error}"
    assert path.name in str(error), f"{type(error).__name__} not naming {path.name}: {short(str(error), 300)}"
    with pytest.raises(ResetNeeded):
        env.step(0)
