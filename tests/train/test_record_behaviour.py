"""train/record_behaviour.py: what it compares, and that it finds a changed bit, a renamed key and a new one."""

import numpy as np

from train.record_behaviour import canonical, differences


def test_identical_recordings_have_no_difference_and_one_ulp_is_one():
    before = canonical({"steps": [{"obs": np.array([1.0, 2.0]), "reward": 0.5, "info": {"alarm": True}}]})
    after = canonical({"steps": [{"obs": np.array([1.0, 2.0]), "reward": 0.5, "info": {"alarm": True}}]})
    assert list(differences(before, after, {})) == []
    after["steps"][0]["reward"] = np.asarray(np.nextafter(0.5, 1.0))
    assert [line.split(":")[0] for line in differences(before, after, {})] == ["/steps[0]/reward"]


def test_nan_compares_by_its_bits_and_dtypes_and_keys_count():
    before = canonical({"a": np.array([np.nan, 1.0]), "b": np.float64(1.0), "time_gap": 1.0})
    after = canonical({"a": np.array([np.nan, 1.0]), "b": np.float32(1.0), "actual_time_gap": 1.0})
    found = list(differences(before, after, {}))
    assert any("keys" in line for line in found) and any(line.startswith("/b:") for line in found)
    assert not any(line.startswith("/a") for line in found)
    renamed = list(differences(before, after, {"time_gap": "actual_time_gap"}))
    assert [line.split(":")[0] for line in renamed] == ["/b"]
