"""Analytic string stability, and the simulator agreeing with it."""

import numpy as np
import pytest

from timegap_env.config import PlatoonConfig
from timegap_env.leaders import LeaderProfile
from timegap_env.sim import simulate
from timegap_env.sim.stability import platoon_string_stability, string_stability, transfer_gain

DEFAULT = PlatoonConfig()
GAINS = dict(k_s=DEFAULT.k_s, k_v=DEFAULT.k_v, k_a=DEFAULT.k_a, lag=0.45, gain=1.0)


@pytest.mark.parametrize("setting", [1.0, 1.6])
@pytest.mark.parametrize("delay", [0.1, 0.2])
def test_default_gains_are_string_stable_with_v2v(setting, delay):
    report = string_stability(**GAINS, k_f=DEFAULT.k_f, setting=setting, delay=delay)
    assert report.string_stable and report.locally_stable
    assert report.peak_gain <= 1 + 1e-9


def test_default_gains_without_v2v_are_unstable_at_1_0_and_stable_at_1_6():
    unstable = string_stability(**GAINS, k_f=0.0, setting=1.0, delay=0.1)
    stable = string_stability(**GAINS, k_f=0.0, setting=1.6, delay=0.1)
    assert not unstable.string_stable and unstable.peak_gain > 1.05
    assert 0.1 < unstable.peak_frequency < 1.0
    assert stable.string_stable
    assert unstable.locally_stable


def test_gain_is_one_at_zero_frequency():
    assert transfer_gain(np.array([0.0]), **GAINS, k_f=0.6, setting=1.6, delay=0.1)[0] == pytest.approx(1.0)


def test_hurwitz_check_flags_an_unstable_loop():
    report = string_stability(k_s=0.2, k_v=0.01, k_a=0.9, k_f=0.0, setting=0.1, lag=2.0, gain=1.0, delay=0.0)
    assert not report.locally_stable


@pytest.mark.parametrize("field, value", [("setting", 0.0), ("lag", -0.45), ("gain", 0.0), ("delay", -0.1)])
def test_bad_arguments_are_named(field, value):
    arguments = dict(**GAINS, k_f=0.6, setting=1.6, delay=0.1)
    arguments[field] = value
    with pytest.raises(ValueError, match=field):
        string_stability(**arguments)


def _peak_spacing_errors(setting: float, v2v: bool) -> np.ndarray:
    """Peak |spacing error| of each of 8 followers after one slow braking-and-recovery pulse of the leader.

    10 s each way puts the pulse's energy near the unstable band (peak near 0.3 rad/s);
    a short pulse lives at frequencies every setting attenuates.
    """
    pulse = np.r_[np.zeros(50), np.full(100, -1.0), np.full(100, 1.0), np.zeros(700)]
    leader = LeaderProfile.from_acceleration(pulse)
    config = PlatoonConfig(n_followers=8, initial_setting=setting, v2v=v2v)
    trajectory = simulate(leader, config)
    assert trajectory.collision is None
    return np.abs(trajectory.spacing_error).max(axis=0)


@pytest.mark.parametrize("setting, v2v", [(1.0, True), (1.6, True), (1.0, False), (1.6, False), (0.6, True)])
def test_simulator_agrees_with_the_analytic_check(setting, v2v):
    """Where the check says unstable the peak spacing error grows down the platoon; where stable it shrinks."""
    report = platoon_string_stability(PlatoonConfig(n_followers=8, initial_setting=setting, v2v=v2v))[0]
    peaks = _peak_spacing_errors(setting, v2v)
    if report.string_stable:
        assert np.all(np.diff(peaks) < 0), peaks
    else:
        assert np.all(np.diff(peaks) > 0), peaks
        assert peaks[-1] > 1.1 * peaks[0]


def test_a_setting_sweep_gives_the_transfer_function_bit_for_bit():
    """SettingSweep computes the setting-free parts of G once; the gains equal G written out whole, in the same
    order of operations, at every setting (smallest_stable_setting's bisection relies on it)."""
    from timegap_env.sim.stability import FREQUENCY_GRID, SettingSweep

    parameters = dict(k_s=0.2, k_v=0.7, k_a=0.0, k_f=1.0, lag=0.9, gain=0.7, delay=0.4, packet_loss=0.5, dt=0.1)
    sweep = SettingSweep(**parameters)
    s = 1j * FREQUENCY_GRID
    held = (1.0 - 0.5) / (1.0 - 0.5 * np.exp(-0.1 * s))
    numerator = 0.7 * (1.0 * s**2 * np.exp(-0.4 * s) * held + 0.7 * s + 0.2)
    for setting in (0.6, 1.0, 1.37, 2.2):
        denominator = 0.9 * s**3 + (1 - 0.7 * 0.0) * s**2 + 0.7 * (0.7 + 0.2 * setting) * s + 0.7 * 0.2
        assert sweep.gains(setting).tobytes() == np.abs(numerator / denominator).tobytes()
        assert sweep.report(setting) == string_stability(setting=setting, **parameters)
