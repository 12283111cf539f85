"""OpenACC: every shared file reads, absent positions are reported, bad files are named, lead cars replay."""

import gzip
from collections import Counter

import numpy as np
import pytest

from timegap_env.config import LeaderConfig
from timegap_env.leaders import default_openacc_dir, make_leader, openacc_paths, read_openacc
from timegap_env.leaders.openacc import repeated_runs

GOOD = """Date,8,10,2019
Vehicle_order,LEAD,CAR_A,CAR_B,SPARE,
Number_of_vehicles,3
ACC,1
Distance_setting,S
Time,Speed1,E1,IVS1,Speed2,E2,IVS2,Speed3,E3
10.0,8.0,1.0,12.5,8.1,1.0,13.0,8.2,1.0
10.1,8.1,1.0,12.6,,1.0,13.1,8.3,1.0
10.2,8.2,1.0,,8.3,1.0,13.2,8.4,1.0
"""


def write(tmp_path, text: str, name: str = "run.csv"):
    path = tmp_path / name
    if name.endswith(".gz"):
        with gzip.open(path, "wt") as handle:
            handle.write(text)
    else:
        path.write_text(text)
    return path


def shared_runs():
    directory = default_openacc_dir()
    if not directory.exists():
        pytest.skip(f"OpenACC data absent at {directory} (set $TIMEGAP_OPENACC_PATH)")
    return [read_openacc(path) for path in openacc_paths(directory)]


def test_a_file_becomes_speeds_and_spacings_per_position(tmp_path):
    for name in ("run.csv", "run.csv.gz"):
        run = read_openacc(write(tmp_path, GOOD, name))
        assert run.vehicles == ("LEAD", "CAR_A", "CAR_B") and run.acc and run.distance_setting == "S"
        assert run.date.isoformat() == "2019-10-08" and run.name == "run"
        np.testing.assert_allclose(run.t, [10.0, 10.1, 10.2])
        np.testing.assert_array_equal(run.speed, [[8.0, 8.1, 8.2], [8.1, np.nan, 8.3], [8.2, 8.3, 8.4]])
        np.testing.assert_array_equal(run.spacing, [[12.5, 13.0], [12.6, 13.1], [np.nan, 13.2]])
        assert run.absent_positions == () and run.absent_spacings == ()


def test_absent_columns_are_reported_not_invented(tmp_path):
    text = GOOD.replace("Time,Speed1,E1,IVS1,Speed2,E2,IVS2,Speed3,E3", "Time,X1,E1,Y1,Speed2,E2,IVS2,Speed3,E3")
    run = read_openacc(write(tmp_path, text))
    assert run.absent_positions == (1,) and run.absent_spacings == (1,)
    assert np.isnan(run.speed[:, 0]).all() and np.isnan(run.spacing[:, 0]).all()


def test_people_driving_have_no_distance_setting(tmp_path):
    run = read_openacc(write(tmp_path, GOOD.replace("ACC,1\nDistance_setting,S", "ACC,0\nDistance_setting,")))
    assert not run.acc and run.distance_setting is None


@pytest.mark.parametrize(
    "old, new, message",
    [
        ("Date,8,10,2019\n", "", r"line 1 is 'Vehicle_order': expected the metadata line 'Date'"),
        ("Date,8,10,2019", "Date,8,13,2019", r"Date = \['8', '13', '2019'\]"),
        ("Number_of_vehicles,3", "Number_of_vehicles,three", r"Number_of_vehicles = \['three'\]"),
        ("Number_of_vehicles,3", "Number_of_vehicles,5", "Vehicle_order names 4 cars, Number_of_vehicles is 5"),
        ("ACC,1", "ACC,yes", r"ACC = \['yes'\]"),
        ("Distance_setting,S", "Distance_setting,XL", "Distance_setting = 'XL'"),
        ("Time,", "Clock,", "missing column 'Time'"),
        ("10.1,8.1,1.0,12.6", "10.1,8.1,1.0,twelve", r"row 8, column 'IVS1' = 'twelve' is not a number"),
        ("10.2,", "10.25,", r"time steps must be 0.1 s; rows 8 and 9 are 0.15 s apart"),
        ("10.1,8.1", ",8.1", "row 8, column 'Time' is empty"),
        ("10.1,8.1", "NaN,8.1", "row 8, column 'Time' = 'NaN' is not a finite number"),
        ("10.1,8.1,1.0,12.6", "10.1,8.1,1.0,-inf", "row 8, column 'IVS1' = '-inf' is not a finite number"),
        ("10.2,8.2,1.0,,8.3,1.0,13.2,8.4,1.0\n", "10.2,8.2\n", "row 9 has 2 fields, the header 9"),
    ],
)
def test_malformed_files_are_named_with_what_is_wrong(tmp_path, old, new, message):
    path = write(tmp_path, GOOD.replace(old, new, 1))
    with pytest.raises(ValueError, match=message) as error:
        read_openacc(path)
    assert str(path) in str(error.value)


def test_a_file_ending_in_its_metadata_is_named(tmp_path):
    path = write(tmp_path, GOOD.split("ACC,1")[0])
    with pytest.raises(ValueError, match="ends after line 3: expected the metadata line 'ACC'") as error:
        read_openacc(path)
    assert str(error.value).startswith(f"{path}: ")


def test_an_empty_table_is_named(tmp_path):
    path = write(tmp_path, GOOD.split("10.0,")[0])
    with pytest.raises(ValueError, match="no data rows after the header"):
        read_openacc(path)


def test_every_shared_file_reads():
    runs = shared_runs()
    assert len(runs) == 44
    settings = Counter(run.distance_setting if run.acc else "people" for run in runs)
    assert settings == {"S": 22, "L": 11, "M": 1, "SL": 7, "people": 3}
    assert sum(1 in run.absent_positions for run in runs) == 25  # the lead car's columns are absent
    for run in runs:
        assert run.speed.shape == (run.t.size, run.n_vehicles) and run.spacing.shape == (run.t.size, run.n_vehicles - 1)
        np.testing.assert_allclose(np.diff(run.t), 0.1, atol=1e-6)
        for k in run.absent_positions:
            assert np.isnan(run.speed[:, k - 1]).all()
        present = [k for k in range(1, run.n_vehicles) if k not in run.absent_spacings]
        assert all(np.isfinite(run.spacing[:, k - 1]).any() for k in present), run.name
        gaps = run.spacing[np.isfinite(run.spacing)]
        assert gaps.min() > -2.0 and gaps.max() < 1000.0  # bumper-to-bumper [m]; GNSS puts stopped cars up to 1.2 m "into" each other


def test_the_openacc_family_replays_real_lead_cars():
    shared_runs()
    first, again = make_leader("openacc", 5), make_leader("openacc", 5)
    np.testing.assert_array_equal(first.speed, again.speed)
    assert first.name.startswith("openacc-astazero_") and first.dt == 0.1
    assert np.isfinite(first.speed).all() and first.duration >= LeaderConfig().min_recorded_duration
    assert len({make_leader("openacc", seed).name for seed in range(8)}) > 2


def test_a_run_cut_out_of_another_is_found(tmp_path):
    longer = read_openacc(write(tmp_path, GOOD, "long.csv"))
    lines = GOOD.splitlines()
    part = read_openacc(write(tmp_path, "\n".join(lines[:6] + lines[7:9]) + "\n", "part.csv"))  # its 2nd and 3rd records
    other = read_openacc(write(tmp_path, GOOD.replace("8.2,1.0,,8.3", "8.2,1.0,,8.5"), "other.csv"))
    assert repeated_runs([longer, part]) == {"part": "long"}
    assert repeated_runs([other, part]) == {}  # a speed differs
    if default_openacc_dir().exists():
        assert repeated_runs(shared_runs()) == {"astazero_dynamic_part22": "astazero_dynamic_part23"}
