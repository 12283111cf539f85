"""Careless inputs to the three leader-file readers (issue 14): each either parses to the clean file's values or
raises an error that names the file and says what is wrong.

Readers: ``read_ngsim``, ``read_openacc`` and ``LeaderProfile.from_csv``; every file is a small synthetic one
written into ``tmp_path``.
"""

from __future__ import annotations

import dataclasses
import gzip
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from timegap_env.leaders import LeaderProfile, ngsim, read_ngsim, read_openacc
from timegap_env.leaders.profile import open_csv


@dataclasses.dataclass(frozen=True)
class Reader:
    """A reader, a clean file for it and where its header and a numeric value sit (0-based lines and fields)."""

    read: Callable[[Path], Any]
    values: Callable[[Any], dict[str, Any]]  # what must not change between a clean file and a legitimate variant
    clean: str
    header_line: int
    value_line: int
    value_field: int
    value_column: str
    missing_column: tuple[str, str]  # (header name, its replacement) that makes a required column missing
    nan_is_a_gap: bool = False  # OpenACC records a gap as an empty or NaN value


NGSIM = Reader(
    read=read_ngsim,
    values=lambda table: {name: getattr(table, name) for name in ("vehicle_id", "frame", "v_vel", "v_acc")},
    clean="Vehicle_ID,Frame_ID,Local_X,v_Vel,v_Acc\n1,10,5.0,20.0,0.5\n1,11,5.1,20.05,0.5\n2,10,7.0,30.0,-1.0\n",
    header_line=0, value_line=2, value_field=3, value_column="v_Vel",
    missing_column=("v_Acc", "v_Accel"),
)
OPENACC = Reader(
    read=read_openacc,
    values=lambda run: {name: getattr(run, name) for name in (
        "date", "vehicles", "acc", "distance_setting", "t", "speed", "spacing", "absent_positions",
        "absent_spacings", "name")},
    clean=(
        "Date,8,10,2019\nVehicle_order,LEAD,CAR_A,CAR_B,\nNumber_of_vehicles,3\nACC,1\nDistance_setting,S\n"
        "Time,Speed1,E1,IVS1,Speed2,E2,IVS2,Speed3,E3\n"
        "10.0,8.0,1.0,12.5,8.1,1.0,13.0,8.2,1.0\n10.1,8.1,1.0,12.6,,1.0,13.1,8.3,1.0\n"
        "10.2,8.2,1.0,,8.3,1.0,13.2,8.4,1.0\n"
    ),
    header_line=5, value_line=7, value_field=1, value_column="Speed1",
    missing_column=("Time", "Clock"), nan_is_a_gap=True,
)
PROFILE = Reader(
    read=LeaderProfile.from_csv,
    values=lambda profile: {"speed": profile.speed, "accel": profile.accel, "dt": profile.dt, "name": profile.name},
    clean="time,speed\n0.0,20.0\n0.2,21.0\n0.4,22.5\n0.6,23.0\n",  # dt 0.2 s, not the default 0.1 s
    header_line=0, value_line=2, value_field=1, value_column="speed",
    missing_column=("speed", "velocity"),
)
READERS = {"ngsim": NGSIM, "openacc": OPENACC, "profile": PROFILE}


def write(path: Path, content: str | bytes, compress: bool = False) -> Path:
    """Write ``content`` (text as UTF-8) to ``path``, gzip-compressed when ``compress``."""
    data = content.encode() if isinstance(content, str) else content
    path.write_bytes(gzip.compress(data, mtime=0) if compress else data)
    return path


def replace_value(reader: Reader, text: str) -> str:
    """``reader.clean`` with its chosen numeric value replaced by ``text``."""
    lines = reader.clean.split("\n")
    fields = lines[reader.value_line].split(",")
    fields[reader.value_field] = text
    lines[reader.value_line] = ",".join(fields)
    return "\n".join(lines)


def spaced_header(reader: Reader) -> str:
    """``reader.clean`` with a space after every comma of its column header, as in ``time, speed``."""
    lines = reader.clean.split("\n")
    lines[reader.header_line] = lines[reader.header_line].replace(",", ", ")
    return "\n".join(lines)


def header_only(reader: Reader) -> str:
    return "\n".join(reader.clean.split("\n")[: reader.header_line + 1]) + "\n"


def missing_column(reader: Reader) -> str:
    old, new = reader.missing_column
    lines = reader.clean.split("\n")
    lines[reader.header_line] = lines[reader.header_line].replace(old, new, 1)
    return "\n".join(lines)


def assert_same_values(reader: Reader, variant: Any, clean: Any) -> None:
    expected, found = reader.values(clean), reader.values(variant)
    for name, value in expected.items():
        np.testing.assert_array_equal(found[name], value, err_msg=name)


# --- legitimate variants: parsed to the clean file's values ------------------------------------------------------

LEGITIMATE: dict[str, tuple[str, Callable[[Reader], str | bytes], bool]] = {
    # case: (file name, content from the reader, gzip-compressed)
    "utf8-bom": ("lead.csv", lambda reader: "\ufeff" + reader.clean, False),
    "utf8-bom-gzip": ("lead.csv.gz", lambda reader: "\ufeff" + reader.clean, True),
    "crlf": ("lead.csv", lambda reader: reader.clean.replace("\n", "\r\n"), False),
    "spaces-in-header": ("lead.csv", spaced_header, False),
    "trailing-blank-line": ("lead.csv", lambda reader: reader.clean + "\n", False),
    "trailing-blank-line-crlf": ("lead.csv", lambda reader: (reader.clean + "\n").replace("\n", "\r\n"), False),
    "no-final-newline": ("lead.csv", lambda reader: reader.clean.rstrip("\n"), False),
    "gzip": ("lead.csv.gz", lambda reader: reader.clean, True),
}


@pytest.mark.parametrize("case", LEGITIMATE)
@pytest.mark.parametrize("reader_name", READERS)
def test_legitimate_variant_parses_like_the_clean_file(tmp_path, reader_name, case):
    reader = READERS[reader_name]
    name, make, compress = LEGITIMATE[case]
    (tmp_path / "clean").mkdir()
    clean = reader.read(write(tmp_path / "clean" / "lead.csv", reader.clean))
    assert_same_values(reader, reader.read(write(tmp_path / name, make(reader), compress)), clean)


# --- malformed files: a ValueError naming the file and what is wrong ---------------------------------------------

def halve(data: bytes) -> bytes:
    return data[: len(data) // 2]


BINARY = b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + bytes(range(256))

MALFORMED: dict[str, tuple[str, Callable[[Reader], str | bytes], bool, str]] = {
    # case: (file name, content from the reader, gzip-compressed, what the message says)
    "truncated-gzip": ("lead.csv.gz", lambda reader: gzip.compress(reader.clean.encode(), mtime=0)[:-12], False,
                       "truncated or corrupt gzip"),
    "gzip-cut-in-half": ("lead.csv.gz", lambda reader: halve(gzip.compress(reader.clean.encode(), mtime=0)), False,
                         "truncated or corrupt gzip"),
    "corrupt-gzip-crc": ("lead.csv.gz", lambda reader: gzip.compress(reader.clean.encode(), mtime=0)[:-8]
                         + b"\0\0\0\0" + gzip.compress(reader.clean.encode(), mtime=0)[-4:], False,
                         "truncated or corrupt gzip"),
    "plain-text-named-gz": ("lead.csv.gz", lambda reader: reader.clean, False, "not gzip-compressed"),
    "empty-named-gz": ("lead.csv.gz", lambda reader: b"", False, "empty file"),
    "binary": ("lead.csv", lambda reader: BINARY, False, "binary"),
    "binary-gzip": ("lead.csv.gz", lambda reader: BINARY, True, "binary"),
    "nul-bytes": ("lead.csv", lambda reader: reader.clean.replace("\n", "\n\0", 1), False, "binary"),
    "latin-1": ("lead.csv", lambda reader: reader.clean.encode() + "caf\xe9\n".encode("latin-1"), False,
                "not UTF-8 text"),
    "utf-16": ("lead.csv", lambda reader: reader.clean.encode("utf-16"), False, "binary"),
    "empty": ("lead.csv", lambda reader: "", False, "empty file"),
    "blank-lines-only": ("lead.csv", lambda reader: "\n\r\n  \n", False, "empty file"),
    "header-only": ("lead.csv", header_only, False, "no data rows"),
    "header-only-gzip": ("lead.csv.gz", header_only, True, "no data rows"),
    "missing-column": ("lead.csv", missing_column, False, "missing column"),
    "non-numeric": ("lead.csv", lambda reader: replace_value(reader, "fast"), False,
                    r"row 3, column '{column}' = 'fast' is not"),
    "infinite": ("lead.csv", lambda reader: replace_value(reader, "inf"), False,
                 r"row 3, column '{column}' = 'inf' is not a finite number"),
    "nan": ("lead.csv", lambda reader: replace_value(reader, "nan"), False,
            r"row 3, column '{column}' = 'nan' is not a finite number"),
}
CHAINED = {"truncated-gzip", "gzip-cut-in-half", "corrupt-gzip-crc", "binary", "binary-gzip", "latin-1", "utf-16"}


@pytest.mark.parametrize("case", MALFORMED)
@pytest.mark.parametrize("reader_name", READERS)
def test_malformed_file_is_a_value_error_naming_it(tmp_path, reader_name, case):
    reader = READERS[reader_name]
    name, make, compress, message = MALFORMED[case]
    if case == "nan" and reader.nan_is_a_gap:
        pytest.skip("an OpenACC NaN is a gap in the record, as an empty value is (test_nan_is_an_openacc_gap)")
    # The row the value sits on, counted as lines of the file from 1.
    message = message.replace("row 3", f"row {reader.value_line + 1}").format(column=reader.value_column)
    path = write(tmp_path / name, make(reader), compress)
    with pytest.raises(ValueError, match=message) as error:
        reader.read(path)
    assert str(error.value).startswith(f"{path}: ")
    if case in CHAINED:
        assert error.value.__cause__ is not None  # the gzip or decoding error is kept as the cause


@pytest.mark.parametrize("reader_name", READERS)
def test_missing_file_is_named(tmp_path, reader_name):
    path = tmp_path / "absent.csv.gz"
    with pytest.raises(FileNotFoundError, match="absent.csv.gz"):
        READERS[reader_name].read(path)


def test_nan_is_an_openacc_gap(tmp_path):
    gap = read_openacc(write(tmp_path / "nan.csv", replace_value(OPENACC, "NaN")))
    empty = read_openacc(write(tmp_path / "empty.csv", replace_value(OPENACC, "")))
    np.testing.assert_array_equal(gap.speed, empty.speed)
    assert np.isnan(gap.speed[OPENACC.value_line - OPENACC.header_line - 1, 0])


@pytest.mark.parametrize("compress", [False, True], ids=["csv", "gzip"])
def test_open_csv_reads_a_line_at_a_time(tmp_path, compress):
    # Reading every line holds a few buffers, not the file: the whole-file reader held 7 times its text.
    rows = 200_000
    text = NGSIM.clean.split("\n")[0] + "\n" + "1,10,5.0,20.0,0.5\n" * rows  # 3.6 MB
    path = write(tmp_path / ("big.csv.gz" if compress else "big.csv"), text, compress)
    tracemalloc.start()
    try:
        with open_csv(path) as lines:
            count = sum(1 for _ in lines)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert count == rows + 1
    assert peak < 2**20, f"peak {peak} bytes while reading {len(text)} characters"


@pytest.mark.parametrize("compress", [False, True], ids=["csv", "gzip"])
def test_non_utf8_byte_past_the_first_chunk_is_located(tmp_path, compress):
    # The reader decodes in chunks of a few kB; the byte offset in the message is still the file's own.
    good = ("\ufeffspeed\n" + "20.5\n" * 10_000).encode()  # 50 kB, BOM included
    path = write(tmp_path / ("lead.csv.gz" if compress else "lead.csv"), good + b"21\xe9\n20\n", compress)
    message = rf"not UTF-8 text \(byte {len(good) + 2} (of the decompressed data )?is 0xe9\)"
    with pytest.raises(ValueError, match=message):
        LeaderProfile.from_csv(path)


def test_read_ngsim_holds_its_columns_not_its_rows(tmp_path, monkeypatch):
    # Rows become arrays a chunk at a time; holding every row's text as Python strings took 11 times the arrays.
    monkeypatch.setattr(ngsim, "CHUNK_ROWS", 1000)
    rows = 50_000
    lines = (f"{k // 500},{k % 500},{k * 0.01:.2f},0.5\n" for k in range(rows))  # 100 vehicles, 500 frames each
    text = "Vehicle_ID,Frame_ID,v_Vel,v_Acc\n" + "".join(lines)
    path = write(tmp_path / "big.csv", text)
    tracemalloc.start()
    try:
        table = read_ngsim(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    arrays = sum(column.nbytes for column in NGSIM.values(table).values())
    assert table.frame.size == rows and table.v_vel[-1] == pytest.approx((rows - 1) * 0.01)
    assert peak < 3 * arrays, f"peak {peak} bytes for {arrays} bytes of arrays"


def test_ngsim_rows_are_numbered_across_chunks(tmp_path, monkeypatch):
    clean = NGSIM.clean + "2,11,7.1,30.5,-1.0\n2,12,7.2,31.0,-1.0\n"  # rows on lines 2-6
    expected = read_ngsim(write(tmp_path / "clean.csv", clean))
    monkeypatch.setattr(ngsim, "CHUNK_ROWS", 2)
    assert_same_values(NGSIM, read_ngsim(write(tmp_path / "chunked.csv", clean)), expected)
    with pytest.raises(ValueError, match=r"row 6, column 'v_Vel' = 'fast' is not a finite number"):
        read_ngsim(write(tmp_path / "bad.csv", clean.replace("31.0", "fast")))
    with pytest.raises(ValueError, match=r"row 5, column 'Frame_ID' = '11.5' is not an integer"):
        read_ngsim(write(tmp_path / "bad.csv", clean.replace("2,11,", "2,11.5,")))
    with pytest.raises(ValueError, match=r"row 6 has fewer fields than the header"):
        read_ngsim(write(tmp_path / "short.csv", clean.replace("2,12,7.2,31.0,-1.0", "2,12,7.2")))
