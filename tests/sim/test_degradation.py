"""Degradations: described and checked, drawn, acting in the physics exactly as the equivalent nominal platoon, and
reported as ground truth."""

import copy
import pickle

import gymnasium as gym
import numpy as np
import pytest

import timegap_env
from timegap_env.config import LEVERS, LeaderConfig, PlatoonConfig, SensorConfig
from timegap_env.envs.info import truth_of
from timegap_env.monitoring.sensors import Readings, SensorFaults, Sensors
from timegap_env.sim.degradation import (
    TRUE_PARAMETERS, Degradation, DegradationTable, parse_degradations, smallest_stable_setting,
)
from timegap_env.sim.platoon import FollowerFaults
from timegap_env.sim.presets import COMMERCIAL_ACC, acc_presets
from timegap_env.sim.stability import string_stability

LEADER = timegap_env.aggressive_cycles(0, leader=LeaderConfig(duration=120.0))


def run(config: PlatoonConfig = PlatoonConfig(), degradation: object = None, setting: float = 1.0, **kwargs):
    return timegap_env.simulate(LEADER, config, setting=setting, degradation=degradation, **kwargs)


@pytest.mark.parametrize(
    "description, message",
    [
        ({"kind": "brake_fade", "size": 2.0}, "degradation kind = 'brake_fade'"),
        ({"kind": "gain"}, "degradation size = None: a gain degradation needs a finite size"),
        ({"kind": "packet_loss", "size": 1.0}, "degradation size = 1.0: out of range for packet_loss"),
        ({"kind": "v2v_outage", "size": 1.0}, "a v2v_outage degradation has no size"),
        ({"kind": "gain", "size": 0.7, "followers": [0]}, r"degradation followers = \(0,\)"),
        ({"kind": "gain", "size": 0.7, "followers": [6]}, r"degradation followers = \(6,\): the platoon has 5"),
        ({"kind": "gain", "size": 0.7, "onset": 20.0, "end": 10.0}, "degradation end = 10.0"),
        ({"kind": "gain", "size": 0.7, "onset": -1.0}, "degradation onset = -1.0"),
        ({"kind": "gain", "size": 0.7, "car": "BMW_I3"}, "only a commercial_acc degradation names a car"),
        ({"kind": "gain", "size": 0.7, "when": 3}, r"degradation keys \['when'\] unknown"),
        ({"size": 0.7}, "needs a 'kind'"),
        ([{"kind": "gain", "size": 0.7, "followers": [1, 2]}, {"kind": "lag", "size": 2.0, "followers": [2]}],
         r"degradation followers \[2\]: hit by more than one"),
        ("gain", "must be a dict"),
    ],
)
def test_bad_descriptions_are_named(description, message):
    with pytest.raises(ValueError, match=message):
        parse_degradations(description, n_followers=5)


def test_a_latency_off_the_tick_or_beyond_the_buffer_is_named():
    table = DegradationTable(PlatoonConfig(), n_envs=1)
    for size, rule in ((0.25, "must be a multiple of dt = 0.1 s"), (1.2, "must be at most max_v2v_latency = 1.0 s")):
        with pytest.raises(ValueError, match=f"degradation size = {size}: a v2v_latency {rule}"):
            table.set(0, parse_degradations({"kind": "v2v_latency", "size": size}, 5))


def test_a_degradation_that_never_starts_changes_nothing():
    nominal = run()
    later = run(degradation={"kind": "lag", "size": 2.5, "onset": 500.0})
    np.testing.assert_array_equal(nominal.x, later.x)


@pytest.mark.parametrize(
    "degradation, equivalent",
    [
        ({"kind": "lag", "size": 2.0}, {"actuation_lag": 0.9}),
        ({"kind": "gain", "size": 0.7}, {"actuation_gain": 0.7}),
        ({"kind": "v2v_latency", "size": 0.4}, {"v2v_delay": 0.5}),
        ({"kind": "gain", "size": 0.7, "followers": [2, 4]}, {"actuation_gain": (1.0, 0.7, 1.0, 0.7, 1.0)}),
    ],
)
def test_a_degradation_from_the_start_is_the_platoon_with_those_parameters(degradation, equivalent):
    degraded = run(degradation=degradation)
    np.testing.assert_allclose(degraded.x, run(PlatoonConfig(**equivalent)).x, rtol=0, atol=1e-9)
    assert not np.allclose(degraded.x, run().x)


def test_a_commercial_acc_is_its_calibrated_car_in_acc_with_the_platoons_s0():
    car = acc_presets()["TESLA_MODEL3"]
    degraded = run(degradation={"kind": "commercial_acc", "car": "TESLA_MODEL3"}, setting=1.6)
    as_preset = car.platoon_config("S", standstill_spacing=PlatoonConfig.standstill_spacing,
                                   accel_min=PlatoonConfig.accel_min, v2v=True)  # v2v: dropped by the degradation
    np.testing.assert_allclose(degraded.x, run(as_preset, setting=1.6, v2v=False).x, rtol=0, atol=1e-9)
    assert not degraded.v2v.any()


def test_a_radar_bias_shifts_the_kept_gap_by_bias_over_speed():
    """Behind a leader at constant speed the car keeps s + b = s0 + tau* v: its actual gap is tau* - b / v."""
    bias, speed = 3.0, 20.0
    steady = timegap_env.simulate(np.full(600, speed), setting=1.2, degradation={"kind": "radar_bias", "size": bias})
    np.testing.assert_allclose(steady.actual_time_gap[-1], 1.2 - bias / speed, atol=1e-6)


def test_packet_loss_holds_the_feed_forward_and_draws_from_the_seed():
    lossy = {"kind": "packet_loss", "size": 0.8}
    first, again, other = run(degradation=lossy, seed=1), run(degradation=lossy, seed=1), run(degradation=lossy, seed=2)
    np.testing.assert_array_equal(first.x, again.x)
    assert not np.array_equal(first.x, other.x) and not np.allclose(first.x, run().x)
    np.testing.assert_array_equal(run(degradation={"kind": "packet_loss", "size": 0.0}).x, run().x)


def test_an_onset_and_an_end_bound_the_degradation():
    window = run(degradation={"kind": "gain", "size": 0.6, "onset": 30.0, "end": 60.0})
    nominal = run()
    before = window.t < 30.0
    np.testing.assert_array_equal(window.x[before], nominal.x[before])
    assert not np.allclose(window.x[window.t > 31.0], nominal.x[window.t > 31.0])


def test_a_v2v_outage_drops_the_flag_in_its_window_only():
    outage = run(degradation={"kind": "v2v_outage", "onset": 30.0, "end": 60.0, "followers": [3]})
    down = (outage.t >= 30.0 - 1e-9) & (outage.t < 60.0 - 1e-9)
    np.testing.assert_array_equal(~outage.v2v[:, 2], down)
    assert outage.v2v[:, [0, 1, 3, 4]].all()


def test_a_degraded_radar_biases_and_widens_the_readings_in_its_window():
    sensors = Sensors(SensorConfig(spacing_noise_std=0.1, speed_noise_std=0.0), n_envs=1, seed=0, n_followers=2)
    faults = sensors.faults
    faults.start[0], faults.end[0] = [10, 10], [20, 20]
    faults.radar_bias[0], faults.radar_noise[0] = [2.0, 0.0], [0.1, 1.0]
    true = Readings(np.full((30, 1, 2), 40.0), np.full((30, 1, 2), 20.0))
    spacing = sensors.measure(true, np.zeros(1, dtype=np.int64)).spacing[:, 0]  # reading k follows tick k
    inside = np.arange(30)
    inside = (inside >= 10) & (inside < 20)
    assert abs(spacing[inside, 0].mean() - 42.0) < 0.1 and abs(spacing[~inside, 0].mean() - 40.0) < 0.1
    assert spacing[inside, 1].std() > 0.5 > 0.2 > spacing[~inside, 1].std()


def test_the_smallest_stable_setting_is_where_string_stability_begins():
    config = PlatoonConfig()
    for lag, gain, k_f in ((0.45, 1.0, 0.6), (1.0, 1.0, 0.6), (0.45, 0.7, 0.6), (0.45, 0.7, 0.0)):
        found = smallest_stable_setting(lag, gain, config.k_s, config.k_v, config.k_a, k_f, config.v2v_delay)

        def stable(setting: float) -> bool:
            return string_stability(k_s=config.k_s, k_v=config.k_v, k_a=config.k_a, k_f=k_f, setting=setting,
                                    lag=lag, gain=gain, delay=config.v2v_delay).string_stable

        assert stable(found) and not stable(found - 0.01), (lag, gain, k_f)
    nominal = smallest_stable_setting(0.45, 1.0, config.k_s, config.k_v, config.k_a, config.k_f, config.v2v_delay)
    assert 0.8 < nominal < 1.0  # the "1.0 s nominally", on the ladder


def test_the_env_reports_the_ground_truth_and_never_observes_it():
    env = gym.make("TimeGapMonitor-v0", truth_info=True)
    pinned = {"degradation": {"kind": "gain", "size": 0.7, "followers": [1, 2], "onset": 5.0}}
    obs, info = env.reset(seed=0, options=pinned)
    truth = truth_of(info)
    assert truth["kind"].tolist() == ["gain", "gain", "none", "none", "none"] and not truth["active"].any()
    assert truth["onset"].tolist()[:2] == [5.0, 5.0] and np.isinf(truth["onset"][2:]).all()
    unpinned_obs, _ = env.reset(seed=0, options={"degradation": None})
    np.testing.assert_array_equal(obs, unpinned_obs)  # nothing of the degradation shows before it acts
    env.reset(seed=0, options=pinned)
    for _ in range(6):
        _, _, _, _, info = env.step(2)
    truth = truth_of(info)
    assert truth["active"].tolist() == [True, True, False, False, False]
    assert truth["gain"].tolist() == [0.7, 0.7, 1.0, 1.0, 1.0]
    assert truth["smallest_stable_setting"][0] > truth["smallest_stable_setting"][2]
    assert not np.isnan(np.concatenate([np.asarray(v, dtype=float).ravel() for k, v in truth.items() if k != "kind"])).any()


def test_drawn_commercial_acc_followers_are_calibrated_cars():
    env = gym.make("TimeGapMonitor-v0", config={"degradation": {"kind_weights": {"commercial_acc": 1.0}}},
                   truth_info=True)
    _, info = env.reset(seed=1)
    truth = truth_of(info)
    assert set(truth["kind"]) == {"commercial_acc"} and not truth["v2v"].any()
    lags = {fit.model.lag for car, fit in acc_presets().items() if car != COMMERCIAL_ACC}
    assert set(truth["lag"]) <= lags


def test_a_degradation_kind_alone_is_a_valid_description():
    assert parse_degradations(Degradation("v2v_outage", (1,), onset=1.0, end=2.0), 3)[0].followers == (1,)


@pytest.mark.parametrize("degradation", [{"kind": "gain", "size": 0.7}, {"kind": "lag", "size": 2.5},
                                         {"kind": "packet_loss", "size": 0.9}])
def test_the_ground_truths_stable_setting_splits_growing_from_shrinking_platoons(degradation):
    """Behind a slow braking pulse, 8 degraded followers: the peak acceleration grows down the platoon 0.2 s below
    the smallest stable setting of the ground truth and does not grow by 2 % 0.2 s above it (the analytic check is
    continuous in time; the simulator holds each command over a tick, so the split is checked with a margin)."""
    config = PlatoonConfig(n_followers=8)
    table = DegradationTable(config, n_envs=1)
    table.set(0, parse_degradations(degradation, 8))
    boundary = table.truth(np.array([0]), np.ones((1, 8), dtype=bool))["smallest_stable_setting"][0, 0]
    pulse = np.r_[np.zeros(50), np.full(100, -1.0), np.full(100, 1.0), np.zeros(700)]
    leader = timegap_env.LeaderProfile.from_acceleration(pulse)
    peaks = {}
    for setting in (boundary - 0.2, boundary + 0.2):
        trajectory = timegap_env.simulate(leader, config, setting=setting, degradation=degradation)
        peaks[setting] = np.abs(trajectory.a[:, 1:]).max(axis=0)
    assert peaks[boundary - 0.2][-1] > 1.02 * peaks[boundary - 0.2][0], peaks
    assert peaks[boundary + 0.2][-1] < 1.02 * peaks[boundary + 0.2][0], peaks


def test_a_degradation_that_ends_returns_the_follower_to_nominal():
    """After the end, the follower's parameters are nominal again: its ground truth, and its physics (an ended lag
    degradation leaves the car as it would be nominally, from the state it was in)."""
    table = DegradationTable(PlatoonConfig(), n_envs=1)
    table.set(0, parse_degradations({"kind": "gain", "size": 0.6, "onset": 1.0, "end": 2.0}, 5))
    up = np.ones((1, 5), dtype=bool)
    during, after = table.truth(np.array([15]), up), table.truth(np.array([25]), up)
    assert during["active"].all() and during["gain"].tolist() == [[0.6] * 5]
    assert not after["active"].any() and after["gain"].tolist() == [[1.0] * 5]
    ended = run(degradation={"kind": "gain", "size": 0.6, "onset": 30.0, "end": 40.0})
    nominal = run()
    gap = np.abs(ended.spacing - nominal.spacing)
    assert gap[ended.t > 30.5].max() > 0.5 and gap[-1].max() < 0.1 * gap[ended.t > 30.5].max()  # back to nominal


def test_the_levers_records_drive_the_table_the_faults_and_the_truth():
    """A lever is its LEVERS record: the table holds it at its nominal value, copies it by name into every faults
    structure with a field of its name, and reports it among the true parameters under its truth name."""
    platoon, sensors_config = PlatoonConfig(n_followers=3), SensorConfig(spacing_noise_std=0.2)
    table = DegradationTable(platoon, 2, sensors_config)
    assert TRUE_PARAMETERS == tuple(lever.truth for lever in LEVERS.values() if lever.truth)
    for name, lever in LEVERS.items():
        np.testing.assert_array_equal(getattr(table, name), np.broadcast_to(lever.nominal(platoon, sensors_config),
                                                                            (2, 3)))
    # every faults field is the schedule, a lever or the physics' own (its GLVD transition, its packet-loss keys)
    for faults in (FollowerFaults, SensorFaults):
        assert set(faults._fields) - {"start", "end", "dynamics", "keys"} <= set(LEVERS), faults.__name__
    table.set_many(np.array([1]), [(Degradation("radar_noise", (2,), size=0.9, onset=1.0),
                                   Degradation("v2v_latency", (3,), size=0.3))])
    sensors = Sensors(sensors_config, n_envs=2, n_followers=3)
    table.write_levers(sensors.faults, np.array([1]))
    np.testing.assert_array_equal(sensors.faults.radar_noise, [[0.2, 0.2, 0.2], [0.2, 0.9, 0.2]])
    np.testing.assert_array_equal(sensors.faults.start[1], [0, round(1.0 / platoon.dt), 0])
    truth = table.truth(np.array([0, 20]), np.ones((2, 3), dtype=bool))
    np.testing.assert_array_equal(truth["radar_noise"], [[0.2, 0.2, 0.2], [0.2, 0.9, 0.2]])
    np.testing.assert_allclose(truth["v2v_delay"][1], [platoon.v2v_delay] * 2 + [platoon.v2v_delay + 0.3])
    with pytest.raises(AttributeError, match="no attribute 'brake_fade'"):
        table.brake_fade  # noqa: B018


def test_a_lever_attribute_is_its_array_in_levers_also_in_a_copy():
    table = DegradationTable(PlatoonConfig(), 2)
    for each in (table, copy.deepcopy(table), pickle.loads(pickle.dumps(table))):
        assert all(getattr(each, name) is each.levers[name] for name in LEVERS)
