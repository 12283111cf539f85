"""Tests of the control charts (Shewhart, EWMA, CUSUM) and the paper's switching rule."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from timegap_env.monitoring.charts import CHARTS, CusumChart, EwmaChart, ShewhartChart, make_chart, switch_rule
from timegap_env.config import ChartConfig
from timegap_env.monitoring.monitor import TimeGapMonitor

DT = ChartConfig().dt  # [s]


def run(chart, series) -> list:
    """Feed a 1-D series of estimates to a (1 x 1) chart; return the state after every tick."""
    return [chart.update([[value]]) for value in series]


def excursions(n: int, length: int, gap: int, value: float = 2.0, inside: float = 1.6) -> list[float]:
    """n excursions of `length` ticks at `value`, each followed by `gap` ticks back inside."""
    return ([value] * length + [inside] * gap) * n


# ---- Shewhart limits (the paper's numbers) ---------------------------------------------------


def test_shewhart_limits_paper_numbers():
    chart = ShewhartChart(2, 5, center=1.6)
    np.testing.assert_allclose(chart.lcl, 1.35)
    np.testing.assert_allclose(chart.center, 1.6)
    np.testing.assert_allclose(chart.ucl, 1.85)
    chart.recenter(1.0)
    np.testing.assert_allclose(chart.lcl, 0.75)
    np.testing.assert_allclose(chart.center, 1.0)
    np.testing.assert_allclose(chart.ucl, 1.25)


def test_recenter_only_the_masked_vehicles():
    chart = ShewhartChart(2, 3, center=1.6)
    mask = np.zeros((2, 3), dtype=bool)
    mask[0, 0] = True  # the paper switches vehicle 1 only
    chart.recenter(1.0, mask)
    np.testing.assert_allclose(chart.center, [[1.0, 1.6, 1.6], [1.6, 1.6, 1.6]])
    np.testing.assert_allclose(chart.ucl[0, :2], [1.25, 1.85])


def test_alarm_is_strictly_outside_the_limits():
    chart = ShewhartChart(1, 5, center=1.6)
    state = chart.update([[1.34, 1.36, 1.6, 1.84, 1.86]])
    np.testing.assert_array_equal(state.alarm, [[True, False, False, False, True]])
    np.testing.assert_array_equal(state.side, [[-1, 0, 0, 0, 1]])


# ---- exceedances --------------------------------------------------------------------------------


def test_one_long_excursion_counts_once():
    states = run(ShewhartChart(1, 1, center=1.6), [1.6] * 3 + [1.9] * 50 + [1.6] * 3)
    assert sum(int(s.exceedance[0, 0]) for s in states) == 1
    assert states[-1].exceedances_in_window[0, 0] == 1
    assert all(s.alarm[0, 0] for s in states[3:53])


def test_three_short_excursions_count_three_and_trigger_the_switch():
    config = ChartConfig()
    states = run(ShewhartChart(1, 1, center=1.6, config=config), excursions(3, length=2, gap=20))
    assert [s.exceedances_in_window[0, 0] for s in states][::22] == [1, 2, 3]
    fired = [bool(switch_rule(s.exceedances_in_window, s.center, config)[0, 0]) for s in states]
    assert fired.index(True) == 44  # the tick the third excursion starts
    assert not any(fired[:44])


def test_old_excursions_leave_the_window():
    config = ChartConfig(exceedance_window=3.0)  # 30 ticks
    window = config.exceedance_window_ticks
    states = run(ShewhartChart(1, 1, center=1.6, config=config), [1.2] + [1.6] * (2 * window))
    counts = [s.exceedances_in_window[0, 0] for s in states]
    assert counts[window - 1] == 1  # still within the trailing 3 s (the start tick included)
    assert counts[window] == 0  # one tick later it has left
    assert max(counts[window:]) == 0


def test_jumping_across_the_band_starts_a_new_excursion():
    states = run(ShewhartChart(1, 1, center=1.6), [1.9, 1.2, 1.2, 1.9])
    assert [bool(s.exceedance[0, 0]) for s in states] == [True, True, False, True]


@settings(max_examples=50, deadline=None)
@given(series=st.lists(st.sampled_from([1.0, 1.3, 1.6, 1.9, 2.2]), min_size=1, max_size=120))
def test_window_count_equals_a_brute_force_count(series):
    config = ChartConfig(exceedance_window=2.0)
    window = config.exceedance_window_ticks
    states = run(ShewhartChart(1, 1, center=1.6, config=config), series)
    side = [int(np.sign(v - 1.85) if v > 1.85 else (-1 if v < 1.35 else 0)) for v in series]
    starts = [s != 0 and (t == 0 or side[t - 1] != s) for t, s in enumerate(side)]
    for t, state in enumerate(states):
        assert state.side[0, 0] == side[t]
        assert state.exceedances_in_window[0, 0] == sum(starts[max(0, t - window + 1) : t + 1])


# ---- run length ------------------------------------------------------------------------------


def test_run_length_counts_ticks_since_the_last_alarm():
    states = run(ShewhartChart(1, 1, center=1.6), [1.6, 1.6, 1.9, 1.9, 1.6, 1.6, 1.6])
    assert [s.run_length[0, 0] for s in states] == [1, 2, 0, 0, 1, 2, 3]


def test_recenter_and_reset_restart_the_history():
    chart = ShewhartChart(2, 1, center=1.6)
    for value in excursions(2, length=1, gap=3):
        chart.update([[value], [value]])
    chart.recenter(1.0, np.array([[True], [False]]))
    np.testing.assert_array_equal(chart.exceedances_in_window, [[0], [2]])
    np.testing.assert_array_equal(chart.run_length[0], [0])
    state = chart.update([[1.6], [1.6]])  # 1.6 is an excursion under the new limits 0.75-1.25
    np.testing.assert_array_equal(state.exceedance, [[True], [False]])
    chart.reset(np.array([False, True]), center=1.6)
    np.testing.assert_array_equal(chart.exceedances_in_window, [[1], [0]])
    np.testing.assert_array_equal(chart.run_length, [[0], [0]])


# ---- EWMA and CUSUM -------------------------------------------------------------------------


def test_ewma_limits_and_recursion():
    config = ChartConfig(kind="ewma")
    chart = EwmaChart(1, 1, center=1.6, config=config)
    half_width = 3.0 * 0.125 * np.sqrt(0.2 / 1.8)  # = 0.125
    np.testing.assert_allclose([chart.lcl[0, 0], chart.ucl[0, 0]], [1.6 - half_width, 1.6 + half_width])
    z, series = 1.6, [1.7, 1.8, 1.9, 1.9, 1.9, 1.6]
    for value in series:
        state = chart.update([[value]])
        z = 0.2 * value + 0.8 * z
        assert chart.ewma[0, 0] == pytest.approx(z)
        assert state.alarm[0, 0] == (abs(z - 1.6) > half_width)
    chart.recenter(1.0)
    assert chart.ewma[0, 0] == 1.0


def test_ewma_with_lambda_one_is_a_shewhart_chart():
    config = ChartConfig(ewma_lambda=1.0, ewma_width=2.0)
    series = list(np.random.default_rng(0).normal(1.6, 0.2, 200))
    ewma = [s.side[0, 0] for s in run(EwmaChart(1, 1, 1.6, config), series)]
    shewhart = [s.side[0, 0] for s in run(ShewhartChart(1, 1, 1.6, config), series)]
    assert ewma == shewhart


def test_cusum_detects_a_one_sigma_shift_after_the_textbook_delay():
    chart = CusumChart(1, 1, center=1.6)  # k = 0.5, h = 5 (in sigma_desired = 0.125 s)
    states = run(chart, [1.6 + 0.125] * 12)  # y = 1: C+ grows by 0.5 per tick
    assert [bool(s.alarm[0, 0]) for s in states].index(True) == 10  # C+ = 5.5 > 5 on the 11th tick
    assert chart.upper_sum[0, 0] == pytest.approx(6.0) and chart.lower_sum[0, 0] == 0.0
    assert sum(int(s.exceedance[0, 0]) for s in states) == 1


def test_cusum_matches_its_recursion_on_random_data():
    series = np.random.default_rng(1).normal(1.55, 0.15, 300)
    chart = CusumChart(1, 1, center=1.6)
    upper = lower = 0.0
    for value in series:
        state = chart.update([[value]])
        y = (value - 1.6) / 0.125
        upper, lower = max(0.0, upper + y - 0.5), max(0.0, lower - y - 0.5)
        assert chart.upper_sum[0, 0] == pytest.approx(upper) and chart.lower_sum[0, 0] == pytest.approx(lower)
        assert state.side[0, 0] == (1 if upper > 5 and upper >= lower else -1 if lower > 5 else 0)


@pytest.mark.parametrize("kind", ["shewhart", "ewma", "cusum"])
def test_every_chart_has_the_same_interface(kind):
    config = ChartConfig(kind=kind)
    chart = make_chart(3, 2, center=1.6, config=config)
    assert isinstance(chart, CHARTS[kind])
    for value in [1.6] * 5 + [2.5] * 40 + [1.6] * 60:
        state = chart.update(np.full((3, 2), value))
    assert state.exceedances_in_window.shape == (3, 2)
    assert np.all(state.exceedances_in_window == 1)
    chart.recenter(1.0, np.ones((3, 2), dtype=bool))
    chart.reset(None, 1.6)
    assert np.all(chart.state.exceedances_in_window == 0)


def test_chart_kinds_match_the_config():
    assert set(CHARTS) == {"shewhart", "ewma", "cusum"}
    with pytest.raises(ValueError, match="kind = 'ewmaa'"):
        ChartConfig(kind="ewmaa")


# ---- the paper's rule ------------------------------------------------------------------------


def test_switch_rule_is_pure_and_skips_vehicles_already_switched():
    config = ChartConfig()
    chart = ShewhartChart(1, 2, center=1.6, config=config)
    chart.recenter(1.0, np.array([[False, True]]))
    for value in excursions(3, length=1, gap=5, value=2.2):
        state = chart.update([[value, value - 0.6]])  # the same excursions around either centre
    np.testing.assert_array_equal(state.exceedances_in_window, [[3, 3]])
    before = state.exceedances_in_window.copy()
    np.testing.assert_array_equal(switch_rule(state.exceedances_in_window, state.center, config), [[True, False]])  # vehicle 2 is at 1.0 already
    np.testing.assert_array_equal(state.exceedances_in_window, before)
    assert not switch_rule(state.exceedances_in_window, state.center, ChartConfig(switch_exceedances=4)).any()


def test_monitor_chart_and_rule_together():
    """A vehicle whose time gap swings out of the limits gets the switch, after 3 exits."""
    rng = np.random.default_rng(2)
    config = ChartConfig()
    monitor, chart = TimeGapMonitor(1, 2, setting=1.6), ShewhartChart(1, 2, center=1.6, config=config)
    fired_at = None
    for tick in range(int(80 / DT)):
        swing = 0.4 * np.sin(2 * np.pi * tick * DT / 30.0)  # vehicle 1 swings +-0.4 s, vehicle 2 is steady
        tau = np.array([[1.6 + swing, 1.6]])
        speed = rng.uniform(15, 30, (1, 2))
        monitor.update(speed, 5.0 + tau * speed + rng.normal(0, 0.1, (1, 2)))
        state = chart.update(monitor.tau_mean)
        switch = switch_rule(state.exceedances_in_window, state.center, config)
        if switch.any():
            fired_at = tick
            monitor.recenter(config.switch_to, switch)
            chart.recenter(config.switch_to, switch)
            break
    assert fired_at is not None and switch[0, 0] and not switch[0, 1]
    assert chart.center[0, 0] == 1.0 and monitor.tau_mean[0, 0] == pytest.approx(1.0)


# ---- input checks ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda c: c.update([[np.nan, 1.6]]), r"tau_estimate\[0, 0\] = nan"),
        (lambda c: c.update([1.6, 1.6]), r"tau_estimate has shape \(2,\)"),
        (lambda c: c.recenter(0.0), r"setting\[0, 0\] = 0.0"),
        (lambda c: c.reset(np.array([1]), 1.6), "mask has dtype int"),
    ],
)
def test_charts_reject_bad_arguments(call, message):
    with pytest.raises(ValueError, match=message):
        call(ShewhartChart(1, 2, center=1.6))


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"exceedance_window": 0.25}, "exceedance_window = 0.25"),
        ({"ewma_lambda": 0.0}, "ewma_lambda"),
        ({"cusum_k": -0.5}, "cusum_k"),
        ({"switch_exceedances": 0}, "switch_exceedances"),
    ],
)
def test_chart_config_rejects_bad_values(overrides, message):
    with pytest.raises(ValueError, match=message):
        ChartConfig().with_overrides(overrides)


def test_hold_suppresses_alarms_for_exactly_that_many_ticks():
    chart = ShewhartChart(1, 2, 1.6)
    chart.hold(3, np.array([[True, False]]))
    alarms = [chart.update(np.full((1, 2), 2.5)).alarm.copy() for _ in range(5)]
    assert [a[0, 0] for a in alarms] == [False, False, False, True, True]
    assert all(a[0, 1] for a in alarms)
    assert chart.exceedances_in_window[0, 0] == 1  # the held excursion counts once, from when it shows
