"""simulate(): the whole-scenario entry point, its inputs and its determinism."""

import numpy as np
import pytest

import timegap_env
from timegap_env.config import PlatoonConfig


def test_paper_scenario_trajectory():
    trajectory = timegap_env.simulate("paper", seed=0)
    assert trajectory.t.shape == (2501,) and trajectory.t[-1] == pytest.approx(250.0)
    for name in ("x", "v", "a", "u"):
        assert getattr(trajectory, name).shape == (2501, 6)
    assert trajectory.setting.shape == (2501, 5)
    assert trajectory.collision is None
    gap = trajectory.actual_time_gap
    # The paper's shape: the first followers swing most, the swing shrinks down the platoon (string stable).
    swing = np.nanmax(gap, axis=0) - np.nanmin(gap, axis=0)
    assert np.all(np.diff(swing) < 0)
    assert swing[0] > 0.3


def test_same_seed_gives_identical_arrays():
    first, again = timegap_env.simulate("stochastic_human", seed=5), timegap_env.simulate("stochastic_human", seed=5)
    for name in ("x", "v", "a", "u", "applied_setting"):
        np.testing.assert_array_equal(getattr(first, name), getattr(again, name))
    other = timegap_env.simulate("stochastic_human", seed=6)
    assert not np.array_equal(first.v, other.v)


def test_user_speed_array_runs():
    trajectory = timegap_env.simulate(20 + np.sin(np.arange(600) * 0.05))
    assert trajectory.leader_name == "custom" and trajectory.v.shape == (600, 6)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"scenario": "rush_hour"}, "scenario = 'rush_hour'"),
        ({"setting": np.ones((3, 5))}, r"setting has shape \(3, 5\)"),
        ({"setting": np.ones(4)}, r"setting has shape \(4,\)"),
        ({"setting": -1.0}, "setting = -1.0"),
        ({"v2v": np.ones((2, 2), dtype=bool)}, r"v2v has shape \(2, 2\)"),
        ({"scenario": np.ones((10, 2))}, r"speed has shape \(10, 2\)"),
        ({"scenario": np.r_[20.0, np.nan, 20.0]}, r"speed\[1\] = nan"),
        ({"scenario": timegap_env.LeaderProfile.from_speed(np.ones(20), dt=0.2)}, "differs from PlatoonConfig.dt"),
    ],
)
def test_simulate_rejects_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        timegap_env.simulate(**kwargs)


def test_heterogeneous_followers_run():
    config = PlatoonConfig(actuation_lag=(0.3, 0.45, 0.6, 0.45, 0.3), actuation_gain=(1.0, 0.9, 1.1, 1.0, 1.0))
    trajectory = timegap_env.simulate("sinusoid", config, seed=1)
    assert trajectory.collision is None and np.all(np.isfinite(trajectory.x))
