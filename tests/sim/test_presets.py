"""Presets: the calibrated commercial ACC followers load, make valid platoons, and drive without colliding."""

import numpy as np
import pytest

import timegap_env
from timegap_env.config import PlatoonConfig
from timegap_env.sim.calibration import FollowerFit, FollowerModel
from timegap_env.sim.presets import COMMERCIAL_ACC, acc_platoon, acc_presets, write_presets


def test_every_car_model_and_the_median_car_are_presets():
    presets = acc_presets()
    assert COMMERCIAL_ACC in presets and len(presets) >= 9
    (standstill_spacing,) = {fit.model.standstill_spacing for fit in presets.values()}  # measured once, held for all
    assert 1.0 < standstill_spacing < 5.0
    for car, fit in presets.items():
        assert set(fit.settings) == {"S", "L"} and 0.5 < fit.settings["S"] < fit.settings["L"] < 3.5, car
        assert fit.model.lag > 0 and fit.model.accel_min == PlatoonConfig().accel_min < 0 < fit.model.accel_max, car
        assert fit.spacing_rmse > 0 and fit.n_segments > 0, car


@pytest.mark.parametrize("car", sorted(acc_presets()))
def test_every_preset_at_setting_L_drives_the_papers_leader_without_colliding(car):
    """At S, string-unstable presets collide in five-car platoons behind the paper's hard cycles (README)."""
    config = acc_platoon(car, "L", n_followers=5)
    assert not config.v2v and config.n_followers == 5 and config.initial_setting == acc_presets()[car].settings["L"]
    run = timegap_env.simulate("paper", config)
    assert run.collision is None and np.all(run.spacing > 0)


def test_the_median_car_at_setting_S_drives_the_papers_leader_without_colliding():
    run = timegap_env.simulate("paper", acc_platoon(COMMERCIAL_ACC, "S", n_followers=5))
    assert run.collision is None and np.all(run.spacing > 0)


def test_unknown_cars_and_settings_are_named():
    with pytest.raises(ValueError, match="car = 'TRABANT': no calibrated preset"):
        acc_platoon("TRABANT")
    with pytest.raises(ValueError, match="distance_setting = 'M'"):
        acc_platoon(COMMERCIAL_ACC, "M")


def test_presets_round_trip_through_their_file(tmp_path):
    fit = FollowerFit(FollowerModel(0.7, 0.1, 0.5, 3.0, -3.0, 1.5), {"S": 1.2, "L": 2.2}, 0.5, 3, 600.0)
    path = tmp_path / "presets.json"
    write_presets(path, {"CAR": fit, COMMERCIAL_ACC: fit}, source="a test")
    assert acc_presets(path)["CAR"] == fit
    config = fit.platoon_config("S", PlatoonConfig(), n_followers=2)
    assert (config.k_s, config.k_v, config.standstill_spacing, config.accel_max) == (0.1, 0.5, 3.0, 1.5)
    assert config.per_follower("actuation_lag").tolist() == [0.7, 0.7]
