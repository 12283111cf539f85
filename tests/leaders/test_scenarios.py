"""Named scenarios: the paper's leader, real NGSIM drivers, highway-env's IDM driver."""

import numpy as np
import pytest

from timegap_env.config import LeaderConfig
from timegap_env.leaders import SCENARIOS, default_ngsim_path, make_leader


def test_paper_scenario_is_250_s_at_10_hz():
    profile = make_leader("paper", 0)
    assert profile.duration == pytest.approx(250.0) and profile.dt == pytest.approx(0.1)
    assert SCENARIOS["paper"].leader_family == "aggressive_cycles"
    np.testing.assert_array_equal(profile.speed, make_leader("aggressive_cycles", 0).speed)


@pytest.mark.parametrize("family", ["ngsim", "ngsim_in_band"])
def test_ngsim_families_draw_real_vehicles_by_seed(family):
    if not default_ngsim_path().exists():
        pytest.skip(f"NGSIM data absent at {default_ngsim_path()}")
    first, again = make_leader(family, 4), make_leader(family, 4)
    np.testing.assert_array_equal(first.speed, again.speed)
    assert first.name.startswith("ngsim-") and first.duration >= LeaderConfig().min_recorded_duration
    names = {make_leader(family, seed).name for seed in range(6)}
    assert len(names) > 1
    if family == "ngsim_in_band":
        low, high = LeaderConfig().speed_band
        assert low - 1e-9 <= first.speed.min() and first.speed.max() <= high + 1e-9


def test_idm_family_is_a_human_driver_behind_scripted_braking():
    first, again = make_leader("idm", 2), make_leader("idm", 2)
    np.testing.assert_array_equal(first.speed, again.speed)
    disturbance = make_leader("hard_braking", 2)
    assert first.name == "idm" and first.speed.size == disturbance.speed.size
    assert first.accel.min() < -1.0  # it brakes in answer to the disturbance ...
    assert first.accel.min() > disturbance.accel.min()  # ... more gently than the scripted braking


def test_missing_recorded_data_is_named_with_its_variable(tmp_path, monkeypatch):
    from timegap_env.leaders.scenarios import missing_data

    monkeypatch.setenv("TIMEGAP_NGSIM_PATH", str(tmp_path / "absent.csv"))
    monkeypatch.setenv("TIMEGAP_OPENACC_PATH", str(tmp_path))
    assert missing_data("ngsim_in_band") == f"no NGSIM data at {tmp_path / 'absent.csv'} ($TIMEGAP_NGSIM_PATH)"
    assert missing_data("openacc") == f"no OpenACC data in {tmp_path} ($TIMEGAP_OPENACC_PATH)"
    assert missing_data("paper") == ""
