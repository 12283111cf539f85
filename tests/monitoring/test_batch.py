"""Argument checks of the monitor and the charts: each names the argument and the value at fault."""

import numpy as np
import pytest

from timegap_env.monitoring.batch import batch_array, batch_shape, check_finite, env_mask, setting_array, vehicle_mask


def test_good_arguments_pass_through():
    assert batch_shape(np.int64(2), 3) == (2, 3)
    np.testing.assert_array_equal(batch_array("speed", [[1, 2, 3], [4, 5, 6]], (2, 3)), [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(setting_array(1.6, (2, 3)), np.full((2, 3), 1.6))
    np.testing.assert_array_equal(vehicle_mask(np.array([True, False])[:, None], (2, 3)), [[True] * 3, [False] * 3])
    assert vehicle_mask(None, (2, 3)).all() and env_mask(None, 2).tolist() == [True, True]
    check_finite(estimates=np.ones((2, 3)), centers=np.full((4, 1, 2), 1.6))


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: batch_shape(0, 3), "n_envs = 0"),
        (lambda: batch_shape(2, True), "n_vehicles = True"),
        (lambda: batch_array("speed", [[1, 2]], (2, 3)), r"speed has shape \(1, 2\): expected \(2, 3\)"),
        (lambda: batch_array("speed", "fast", (2, 3)), "speed = 'fast': must be numbers"),
        (lambda: setting_array([[1.6, np.nan, 1.6]], (2, 3)), r"setting\[0, 1\] = nan: must be finite and > 0"),
        (lambda: setting_array([1.0, 2.0], (2, 3)), r"setting has shape \(2,\): not broadcastable"),
        (lambda: vehicle_mask(np.ones((2, 3)), (2, 3)), "mask has dtype float64: must be bool"),
        (lambda: vehicle_mask(np.ones(4, dtype=bool), (2, 3)), r"mask has shape \(4,\): not broadcastable"),
        (lambda: env_mask(np.ones(3, dtype=bool), 2), r"must be bool of shape \(2,\)"),
        (lambda: check_finite(estimates=np.ones(3), centers=np.array([[1.0, np.inf]])), r"centers\[0, 1\] = inf"),
    ],
)
def test_bad_arguments_are_named(call, message):
    with pytest.raises(ValueError, match=message):
        call()
