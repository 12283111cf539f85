"""Leader files and speeds that were misread or reported without file or cause (issue 22, items 7 and 11): each is now
an error naming the file (and row, vehicle, column where there is one), the value and what is wrong.

Files are small synthetic ones written into ``tmp_path``; the shared NGSIM and OpenACC data is checked to load as it
did (the tests skip without it).
"""

from __future__ import annotations

import re

import gymnasium as gym
import numpy as np
import pytest

from timegap_env.config import MAX_SPEED, LeaderConfig
from timegap_env.leaders import (
    LeaderProfile,
    default_ngsim_path,
    default_openacc_dir,
    ngsim,
    openacc,
    openacc_paths,
    read_ngsim,
    read_openacc,
    scenarios,
)
from timegap_env.leaders.profile import LeaderProfiles
from tests.leaders.test_malformed_files import OPENACC, READERS, replace_value, write

NGSIM_HEADER = "Vehicle_ID,Frame_ID,v_Vel,v_Acc\n"


def ngsim_text(speeds: dict[int, list[float]]) -> str:
    """An NGSIM file: each vehicle's speeds [ft/s] at frames 0, 1, ... (rows in vehicle order, from line 2)."""
    rows = (f"{vehicle},{frame},{speed},0.0\n" for vehicle, series in speeds.items()
            for frame, speed in enumerate(series))
    return NGSIM_HEADER + "".join(rows)


@pytest.fixture
def ngsim_at(monkeypatch):
    """Point $TIMEGAP_NGSIM_PATH at a path, with the per-process cache of NGSIM tables emptied around the test."""
    def point(path):
        monkeypatch.setenv(ngsim.PATH_VARIABLE, str(path))
        scenarios._ngsim_table.cache_clear()
    yield point
    scenarios._ngsim_table.cache_clear()


# --- item 7: file errors name the file and the cause ---------------------------------------------------------------

@pytest.mark.parametrize("reader_name", READERS)
def test_a_field_over_the_csv_limit_names_the_file_and_row(tmp_path, reader_name):
    # The csv module refuses a field over 131,072 characters with a bare _csv.Error.
    reader = READERS[reader_name]
    path = write(tmp_path / "lead.csv", replace_value(reader, "9" * 140_000))
    row = reader.value_line + 1
    with pytest.raises(ValueError, match=rf"row {row} is not readable as CSV \(field larger than field limit") as error:
        reader.read(path)
    assert str(error.value).startswith(f"{path}: ")


@pytest.mark.parametrize("name", ["lead.csv", "lead.csv.gz"])
@pytest.mark.parametrize("reader_name", READERS)
def test_a_directory_is_named_as_one(tmp_path, reader_name, name):
    path = tmp_path / name
    path.mkdir()
    with pytest.raises(IsADirectoryError, match=rf"^{re.escape(str(path))}: is a directory, not a \.csv or \.csv\.gz"):
        READERS[reader_name].read(path)


def test_ngsim_path_naming_a_directory_says_which_variable(tmp_path, ngsim_at):
    ngsim_at(tmp_path)
    with pytest.raises(IsADirectoryError, match=rf"{re.escape(str(tmp_path))} is a directory: set \$TIMEGAP_NGSIM_PATH"):
        scenarios.make_leader("ngsim", 0)


def test_openacc_path_naming_a_file_says_which_variable(tmp_path):
    path = write(tmp_path / "run.csv", OPENACC.clean)
    with pytest.raises(NotADirectoryError, match=rf"{re.escape(str(path))} is not a directory: set \$TIMEGAP_OPENACC"):
        openacc_paths(path)


@pytest.mark.parametrize("family", ["ngsim", "ngsim_in_band"])
def test_an_ngsim_file_without_a_long_enough_vehicle_says_so(tmp_path, ngsim_at, family):
    # Was numpy's "a cannot be empty unless no samples are taken" from drawing among no vehicles.
    path = write(tmp_path / "short.csv", ngsim_text({1: [30.0] * 50, 2: [30.0]}))  # 4.9 s and one frame
    ngsim_at(path)
    message = (rf"^{re.escape(str(path))}: no vehicle has 30.0 s of usable frames: of its 2 vehicle\(s\), 1 usable "
               r"\(the longest for 4.9 s\), 1 unusable, e.g. Vehicle_ID 2 has 1 frame.*min_recorded_duration = 30.0 s")
    with pytest.raises(ValueError, match=message):
        scenarios.make_leader(family, 0)


@pytest.mark.parametrize("speed", [-1.0, 400.0, 1e300])  # [ft/s]; MAX_SPEED is 328 ft/s
@pytest.mark.parametrize("within_band", [False, True])
def test_an_ngsim_speed_outside_the_bounds_names_file_vehicle_and_row(tmp_path, speed, within_band):
    # A negative speed was "LeaderProfile.speed[7] = -0.3048: must be >= 0" (no file, no vehicle); a speed of
    # 1e300 ft/s ran, and in band neither was noticed.
    speeds = [30.0] * 10
    speeds[7] = speed
    path = write(tmp_path / "ngsim.csv", ngsim_text({4: [30.0] * 10, 9: speeds}))
    table = read_ngsim(path)
    assert ngsim.vehicle_ids(table) == [4]  # vehicle 9 is never drawn
    band = LeaderConfig() if within_band else None
    message = rf"^{re.escape(str(path))}: Vehicle_ID 9, row 19 \(Frame_ID 7\): v_Vel = {re.escape(str(speed))} ft/s"
    with pytest.raises(ValueError, match=message + r" \(.* m/s\) is outside \[0, MAX_SPEED = 100\] m/s"):
        ngsim.vehicle_profile(table, 9, within_band=band)
    ngsim.vehicle_profile(table, 4, within_band=band)


def test_an_ngsim_file_whose_vehicles_are_all_faulty_names_one_fault(tmp_path, ngsim_at):
    path = write(tmp_path / "ngsim.csv", ngsim_text({9: [30.0] * 200 + [-1.0] + [30.0] * 200}))
    ngsim_at(path)
    with pytest.raises(ValueError, match=r"0 usable, 1 unusable, e.g. Vehicle_ID 9, row 202 \(Frame_ID 200\): v_Vel"):
        scenarios.make_leader("ngsim", 0)


# --- item 11: speeds beyond MAX_SPEED (or negative, or not finite) are refused wherever a profile is built -------

@pytest.mark.parametrize("value", [1000.0, 1e300, MAX_SPEED + 1e-9, -0.5])
def test_a_profile_refuses_a_speed_outside_the_bounds(value):
    speed = np.array([20.0, 21.0, value, 22.0])
    message = rf"LeaderProfile 'user': speed\[2\] = {re.escape(repr(value))} m/s: every speed must lie in \[0, MAX_SPEED"
    with pytest.raises(ValueError, match=message):
        LeaderProfile.from_speed(speed, 0.1, "user")
    with pytest.raises(ValueError, match=message):
        LeaderProfile(speed=speed, accel=np.zeros(4), dt=0.1, name="user")
    with pytest.raises(ValueError, match=rf"LeaderProfiles 'user': speed\[1, 2\] = {re.escape(repr(value))} m/s"):
        LeaderProfiles(speed=np.stack([np.full(4, 20.0), speed]), accel=np.zeros((2, 4)), dt=0.1, name="user")


def test_a_profile_names_itself_for_a_speed_that_is_not_finite():
    with pytest.raises(ValueError, match=r"LeaderProfile 'user': speed\[1\] = nan: every sample must be finite"):
        LeaderProfile.from_speed(np.array([20.0, np.nan]), 0.1, "user")


def test_a_profile_accepts_the_bounds_themselves():
    profile = LeaderProfile.from_speed(np.array([0.0, MAX_SPEED, 0.0]), 0.1, "user")
    assert profile.speed.max() == MAX_SPEED


@pytest.mark.parametrize("value", [{"a": 1}, "fast", [1.0, "x"], object()])
def test_a_speed_series_that_is_not_numbers_is_a_value_error(value):
    # Was a TypeError (or numpy's "could not convert string to float") from np.asarray.
    with pytest.raises(ValueError, match=r"LeaderProfile 'user': speed = .*: must be a 1-D array of numbers"):
        LeaderProfile.from_speed(value, 0.1, "user")


def test_the_env_refuses_an_absurd_leader_speed():
    env = gym.make("TimeGapMonitor-v0", config={"episode_duration": 10.0})
    for value in (1000.0, 1e300):
        speed = np.full(101, 20.0)
        speed[50] = value
        with pytest.raises(ValueError, match=rf"speed\[50\] = {re.escape(repr(value))} m/s"):
            env.reset(seed=0, options={"leader_speed": speed})
    env.close()


def test_a_csv_profile_names_the_row_of_a_speed_outside_the_bounds(tmp_path):
    path = write(tmp_path / "lead.csv", "time,speed\n0.0,20.0\n0.1,1000\n0.2,-3\n")
    with pytest.raises(ValueError, match=rf"^{re.escape(str(path))}: row 3, column 'speed' = '1000' m/s is outside"):
        LeaderProfile.from_csv(path)


@pytest.mark.parametrize(("text", "column"), [("1000", "Speed1"), ("1e300", "Speed1"), ("-0.5", "Speed1")])
def test_an_openacc_speed_outside_the_bounds_names_file_row_column_and_car(tmp_path, text, column):
    path = write(tmp_path / "run.csv", replace_value(OPENACC, text))
    message = rf"^{re.escape(str(path))}: row 8, column '{column}' \(car LEAD\) = '{re.escape(text)}' m/s is outside"
    with pytest.raises(ValueError, match=message):
        read_openacc(path)


def test_an_openacc_speed_slightly_below_zero_is_standing_still(tmp_path):
    # The shared data holds lead-car speeds down to -0.07 m/s; the lead car's leader reads them as 0.
    run = read_openacc(write(tmp_path / "run.csv", replace_value(OPENACC, "-0.07")))
    assert run.speed[OPENACC.value_line - OPENACC.header_line - 1, 0] == -0.07


# --- the shared data still loads -------------------------------------------------------------------------------

def test_every_shared_ngsim_vehicle_with_clean_frames_loads():
    path = default_ngsim_path()
    if not path.exists():
        pytest.skip(f"NGSIM data not found at {path} (set $TIMEGAP_NGSIM_PATH)")
    table = read_ngsim(path)
    ids = ngsim.vehicle_ids(table)
    assert len(ids) == 217  # of 222: five have gaps in their frames, none a speed outside [0, MAX_SPEED]
    for vehicle in ids:
        assert ngsim.vehicle_profile(table, vehicle).speed.max() <= MAX_SPEED


def test_every_shared_openacc_file_loads():
    directory = default_openacc_dir()
    if not directory.exists():
        pytest.skip(f"OpenACC data not found at {directory} (set $TIMEGAP_OPENACC_PATH)")
    paths = openacc_paths(directory)
    assert len(paths) == 44
    for path in paths:
        read_openacc(path)
    assert len(openacc.lead_car_speeds(directory)) > 0
