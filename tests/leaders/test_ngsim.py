"""NGSIM loader: the real I-80 subset (skipped when absent) and small crafted files."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

import timegap_env
from timegap_env.config import MPH, LeaderConfig
from timegap_env.leaders.ngsim import (
    FOOT,
    PATH_VARIABLE,
    default_ngsim_path,
    read_ngsim,
    vehicle_ids,
    vehicle_profile,
)

HEADER = "Vehicle_ID,Frame_ID,Local_X,v_Vel,v_Acc,Preceding"


def write_ngsim(path: Path, rows: list[tuple], header: str = HEADER) -> Path:
    """Write ``rows`` of (Vehicle_ID, Frame_ID, v_Vel, v_Acc) under ``header``, gzipped for ``.gz``."""
    lines = [header] + [f"{vid},{frame},,{vel},{acc},0" for vid, frame, vel, acc in rows]
    write_text(path, "\n".join(lines) + "\n")
    return path


def write_text(path: Path, text: str) -> Path:
    if path.suffix == ".gz":
        path.write_bytes(gzip.compress(text.encode()))
    else:
        path.write_text(text)
    return path


# --- the real file -------------------------------------------------------------


@pytest.fixture(scope="module")
def real_table():
    path = default_ngsim_path()
    if not path.exists():
        pytest.skip(f"NGSIM data not found at {path} (set ${PATH_VARIABLE} to the file)")
    return read_ngsim(path)


def test_real_file_loads_with_readme_counts(real_table):
    assert real_table.vehicle_id.size == 110_905
    assert np.unique(real_table.vehicle_id).size == 222
    usable = vehicle_ids(real_table)
    assert len(usable) == 217  # 5 vehicles have a gap in their frames
    assert 398 not in usable and 39 in usable


def test_real_profiles_have_readme_speeds_and_matching_accel(real_table):
    for vid in vehicle_ids(real_table):
        profile = vehicle_profile(real_table, vid)
        assert profile.dt == 0.1
        assert profile.name == f"ngsim-{vid}"
        assert 1.5 <= profile.speed.min() and profile.speed.max() <= 22.5  # README: 2-22 m/s, rounded
        mismatch = np.abs(profile.accel - np.gradient(profile.speed, profile.dt)).mean()
        assert mismatch < 0.25, f"vehicle {vid}: mean |v_Acc - dv/dt| = {mismatch:.3f} m/s^2"


def test_real_vehicle_with_gap_is_rejected(real_table):
    with pytest.raises(ValueError, match="Vehicle_ID 398 has a gap in Frame_ID between 1632 and 1719"):
        vehicle_profile(real_table, 398)


def test_min_duration_selects_long_vehicles(real_table):
    long = vehicle_ids(real_table, min_duration=60.0)
    assert 0 < len(long) < len(vehicle_ids(real_table))
    assert all(vehicle_profile(real_table, vid).duration >= 60.0 for vid in long)


@pytest.mark.parametrize(
    "band",
    [LeaderConfig(), LeaderConfig(speed_band=(20 * MPH, 25 * MPH), initial_speed=10.0)],
    ids=["paper-20-80mph", "narrow-20-25mph"],
)
def test_real_accel_within_band(real_table, band):
    vid = vehicle_ids(real_table, min_duration=60.0)[0]
    raw = vehicle_profile(real_table, vid)
    banded = vehicle_profile(real_table, vid, within_band=band)
    low, high = band.speed_band
    assert banded.speed.size == raw.speed.size
    assert banded.speed[0] == band.initial_speed
    assert np.all((banded.speed >= low) & (banded.speed <= high))
    strictly_inside = (banded.speed > low) & (banded.speed < high)
    inside = strictly_inside[:-1] & strictly_inside[1:]  # steps the band did not clip
    assert inside.any()
    np.testing.assert_allclose(np.diff(banded.speed)[inside] / band.dt, raw.accel[:-1][inside], atol=1e-9)
    if band.speed_band != LeaderConfig().speed_band:  # the narrow band must actually clip
        assert np.isclose(banded.speed, low).any() or np.isclose(banded.speed, high).any()


# --- crafted files ---------------------------------------------------------------


@pytest.mark.parametrize("suffix", [".csv", ".csv.gz"])
def test_units_converted_exactly(tmp_path, suffix):
    path = write_ngsim(tmp_path / f"t{suffix}", [(1, 10, 10.0, 1.0), (1, 11, 20.0, -2.0), (1, 12, 30.0, 0.0)])
    profile = vehicle_profile(read_ngsim(path), 1)
    assert profile.name == "ngsim-1" and profile.dt == 0.1
    np.testing.assert_allclose(profile.speed, [3.048, 6.096, 9.144], rtol=1e-15)
    np.testing.assert_allclose(profile.accel, [0.3048, -0.6096, 0.0], rtol=1e-15)


def test_columns_found_by_name_in_any_order(tmp_path):
    text = "v_Acc, Lane_ID ,Frame_ID,v_Vel,Vehicle_ID\n1.0,2,11,20.0,5\n0.5,2,10,10.0,5\n"
    profile = vehicle_profile(read_ngsim(write_text(tmp_path / "t.csv", text)), 5)
    np.testing.assert_allclose(profile.speed, [10 * FOOT, 20 * FOOT])
    np.testing.assert_allclose(profile.accel, [0.5 * FOOT, 1.0 * FOOT])


def test_frames_sorted_and_identical_duplicates_collapse(tmp_path):
    rows = [(7, 12, 30.0, 3.0), (7, 10, 10.0, 1.0), (7, 11, 20.0, 2.0), (7, 10, 10.0, 1.0)]
    table = read_ngsim(write_ngsim(tmp_path / "t.csv", rows))
    profile = vehicle_profile(table, 7)
    np.testing.assert_allclose(profile.speed, np.array([10.0, 20.0, 30.0]) * FOOT)
    assert vehicle_ids(table) == [7]


def test_vehicle_ids_skip_faulty_vehicles_and_respect_min_duration(tmp_path):
    rows = (
        [(1, f, 10.0, 0.0) for f in range(3)]  # 0.2 s
        + [(2, 0, 10.0, 0.0), (2, 2, 10.0, 0.0)]  # gap
        + [(3, 0, 10.0, 0.0), (3, 1, 10.0, 0.0), (3, 1, 11.0, 0.0)]  # conflicting duplicate
        + [(4, 0, 10.0, 0.0)]  # a single frame
        + [(5, f, 10.0, 0.0) for f in range(11)]  # 1.0 s
    )
    table = read_ngsim(write_ngsim(tmp_path / "t.csv", rows))
    assert vehicle_ids(table) == [1, 5]
    assert vehicle_ids(table, min_duration=0.5) == [5]
    assert vehicle_ids(table, min_duration=1.0) == [5]
    assert vehicle_ids(table, min_duration=1.5) == []
    with pytest.raises(ValueError, match="Vehicle_ID 4 has 1 frame"):
        vehicle_profile(table, 4)


def test_missing_column_is_named(tmp_path):
    path = write_text(tmp_path / "t.csv", "Vehicle_ID,Frame_ID,v_Vel\n1,10,20.0\n")
    message = r"t\.csv: missing column\(s\) \['v_Acc'\] \(found columns \['Vehicle_ID'"
    with pytest.raises(ValueError, match=message):
        read_ngsim(path)


@pytest.mark.parametrize(
    "column, value, expected",
    [
        ("v_Vel", "fast", "a finite number"),
        ("v_Acc", "", "a finite number"),
        ("v_Acc", "nan", "a finite number"),
        ("Frame_ID", "11.5", "an integer"),
        ("Vehicle_ID", "car", "an integer"),
    ],
)
def test_bad_value_names_row_column_and_value(tmp_path, column, value, expected):
    rows = [{"Vehicle_ID": "1", "Frame_ID": "10", "v_Vel": "20.0", "v_Acc": "0.0"} for _ in range(3)]
    rows[1][column] = value
    text = "Vehicle_ID,Frame_ID,v_Vel,v_Acc\n" + "".join(",".join(row.values()) + "\n" for row in rows)
    with pytest.raises(ValueError, match=rf"t\.csv: row 3, column '{column}' = '{value}' is not {expected}"):
        read_ngsim(write_text(tmp_path / "t.csv", text))


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "empty file"),
        (HEADER + "\n", "no data rows"),
        (HEADER + "\n1,10,,20.0,0.0,0\n1,11,,20.0\n", "row 3 has fewer fields"),
    ],
    ids=["empty", "header-only", "short-row"],
)
def test_malformed_file_is_rejected(tmp_path, text, message):
    with pytest.raises(ValueError, match=rf"t\.csv\.gz: {message}"):
        read_ngsim(write_text(tmp_path / "t.csv.gz", text))


def test_gap_in_frames_names_vehicle_and_frames(tmp_path):
    rows = [(7, 10, 1.0, 0.0), (7, 11, 1.0, 0.0), (7, 14, 1.0, 0.0)]
    table = read_ngsim(write_ngsim(tmp_path / "t.csv", rows))
    with pytest.raises(ValueError, match="Vehicle_ID 7 has a gap in Frame_ID between 11 and 14"):
        vehicle_profile(table, 7)


def test_unknown_vehicle_names_it_and_known_ids(tmp_path):
    table = read_ngsim(write_ngsim(tmp_path / "t.csv", [(7, 10, 1.0, 0.0), (8, 10, 1.0, 0.0)]))
    with pytest.raises(ValueError, match=r"no rows for Vehicle_ID 99; known ids include \[7, 8\]"):
        vehicle_profile(table, 99)


def test_conflicting_duplicate_frame_names_vehicle_and_frame(tmp_path):
    rows = [(7, 10, 1.0, 0.0), (7, 11, 1.0, 0.0), (7, 11, 2.0, 0.0), (7, 12, 1.0, 0.0)]
    table = read_ngsim(write_ngsim(tmp_path / "t.csv", rows))
    message = r"Vehicle_ID 7, Frame_ID 11 appears in rows 3 and 4 with different values"
    with pytest.raises(ValueError, match=message):
        vehicle_profile(table, 7)


def test_band_with_another_tick_is_rejected(tmp_path):
    table = read_ngsim(write_ngsim(tmp_path / "t.csv", [(7, 10, 1.0, 0.0), (7, 11, 1.0, 0.0)]))
    with pytest.raises(ValueError, match=r"within_band\.dt = 0\.2"):
        vehicle_profile(table, 7, within_band=LeaderConfig(dt=0.2))


def test_default_path_is_outside_the_repository(monkeypatch, tmp_path):
    monkeypatch.setenv(PATH_VARIABLE, str(tmp_path / "mine.csv"))
    assert default_ngsim_path() == tmp_path / "mine.csv"
    monkeypatch.delenv(PATH_VARIABLE)
    repo_root = Path(timegap_env.__file__).resolve().parent.parent
    path = default_ngsim_path()
    assert path == repo_root.parent / "shared" / "data" / "ngsim" / "i80_0400_0415_pairs.csv.gz"
    assert not path.is_relative_to(repo_root)
