"""EpisodeTotals: add_step of a step's read-outs against NumPy references, restart of some envs, the episode summary."""

from __future__ import annotations

import numpy as np
import pytest

from timegap_env.config import EnvConfig
from timegap_env.envs.reward import RewardConstants, StepReadouts
from timegap_env.envs.totals import EpisodeTotals

CONFIG = EnvConfig()
GAP = RewardConstants.from_config(CONFIG).gap_per_vehicle
LEVELS = np.array(CONFIG.setting_levels)
N_TICKS, N_ENVS, N_FOLLOWERS = 10, 4, CONFIG.platoon.n_followers
COLLIDING_ENV = 2  # collides in the first step only
NEVER_CLOSING_ENV = 1  # no follower ever closes in: min TTC stays inf
ADDITIVE = ("steps", "gap_deviation", "alarm_ticks", "exceedances", "jerk_squared", "switches", "setting", "capacity")


def random_step(rng: np.random.Generator, collide: bool):
    """A step's read-outs, the settings at its end and which changed."""
    per_follower = (N_ENVS, N_FOLLOWERS)
    min_ttc = rng.uniform(0.5, 30.0, per_follower)
    min_ttc[rng.random(per_follower) < 0.3] = np.inf
    min_ttc[NEVER_CLOSING_ENV] = np.inf
    readouts = StepReadouts(
        min_ttc=min_ttc,
        jerk_squared=rng.uniform(0.0, 500.0, per_follower),
        final_speed=rng.uniform(0.0, 35.0, per_follower),
        accel_growth=rng.uniform(0.0, 2.0, N_ENVS),
        gap_deviation_sum=rng.uniform(0.0, 10.0, N_ENVS),
        deviation_sum=rng.uniform(0.0, 20.0, N_ENVS),
        max_deviation=rng.uniform(0.0, 1.0, N_ENVS),
        alarm_ticks=rng.integers(0, N_TICKS * N_FOLLOWERS, N_ENVS).astype(float),
        exceedances=rng.integers(0, 5, N_ENVS).astype(float),
        collided=(np.arange(N_ENVS) == COLLIDING_ENV) & collide,
    )
    setting = rng.choice(LEVELS, per_follower)
    changed = rng.random(per_follower) < 0.4
    return readouts, setting, changed


def reference_step(readouts: StepReadouts, setting, changed, gap: float) -> dict[str, np.ndarray]:
    """One step's contribution to each total, the field comments of EpisodeTotals as NumPy."""
    v = readouts.final_speed
    return {
        "steps": np.ones(N_ENVS),
        "gap_deviation": readouts.gap_deviation_sum,
        "alarm_ticks": readouts.alarm_ticks,
        "exceedances": readouts.exceedances,
        "max_deviation": readouts.max_deviation,
        "jerk_squared": readouts.jerk_squared.mean(axis=1),
        "switches": changed.sum(axis=1).astype(float),
        "setting": setting.mean(axis=1),
        "capacity": (3600.0 * v / (v * setting + gap)).mean(axis=1),
        "collision": readouts.collided.astype(float),
        "min_ttc": readouts.min_ttc.min(axis=1),
    }


def two_steps(seed: int) -> tuple[EpisodeTotals, dict[str, np.ndarray]]:
    """Totals after two steps (a collision in the first) and their reference."""
    rng = np.random.default_rng(seed)
    totals = EpisodeTotals.zeros(N_ENVS)
    steps = [random_step(rng, collide=True), random_step(rng, collide=False)]
    for step in steps:
        totals.add_step(*step, GAP)
    first, second = (reference_step(*step, GAP) for step in steps)
    expected = {name: first[name] + second[name] for name in ADDITIVE}
    expected["max_deviation"] = np.maximum(first["max_deviation"], second["max_deviation"])
    expected["collision"] = np.maximum(first["collision"], second["collision"])
    expected["min_ttc"] = np.minimum(first["min_ttc"], second["min_ttc"])
    return totals, expected


def test_zeros_are_the_totals_of_no_step():
    totals = EpisodeTotals.zeros(N_ENVS)
    for name, total in zip(totals._fields, totals):
        assert total.shape == (N_ENVS,)
        np.testing.assert_array_equal(total, np.inf if name == "min_ttc" else 0.0, err_msg=name)


@pytest.mark.parametrize("seed", range(3))
def test_two_steps_add_up_to_the_numpy_reference(seed):
    totals, expected = two_steps(seed)
    assert set(totals._fields) == set(expected)
    for name in totals._fields:
        np.testing.assert_allclose(getattr(totals, name), expected[name], rtol=1e-12, err_msg=name)
    np.testing.assert_array_equal(totals.collision, np.arange(N_ENVS) == COLLIDING_ENV)  # kept after the step
    assert totals.min_ttc[NEVER_CLOSING_ENV] == np.inf
    assert np.all(np.isfinite(np.delete(totals.min_ttc, NEVER_CLOSING_ENV)))


def test_restart_zeroes_only_the_masked_envs():
    totals, _ = two_steps(4)
    before = [total.copy() for total in totals]
    mask = np.array([True, False, True, False])
    totals.restart(mask)
    for name, total, old in zip(totals._fields, totals, before):
        np.testing.assert_array_equal(total[mask], np.inf if name == "min_ttc" else 0.0, err_msg=name)
        np.testing.assert_array_equal(total[~mask], old[~mask], err_msg=name)
    np.testing.assert_array_equal(before[totals._fields.index("steps")], 2.0)  # there was something to zero


@pytest.mark.parametrize("seed", range(2))
def test_summary_keys_and_formulas(seed):
    totals, expected = two_steps(seed)
    summary = totals.summary(CONFIG)
    assert set(summary) == {"mean_gap_deviation", "time_out_of_control", "exceedances", "max_deviation", "min_ttc", "rms_jerk", "switches",
                            "mean_setting", "mean_capacity", "collision", "duration"}
    dt, n_followers = CONFIG.platoon.dt, CONFIG.platoon.n_followers
    formulas = {
        "mean_gap_deviation": expected["gap_deviation"] / (2 * CONFIG.ticks_per_decision * n_followers),
        "time_out_of_control": expected["alarm_ticks"] * dt / n_followers,
        "exceedances": expected["exceedances"],
        "max_deviation": expected["max_deviation"],
        "min_ttc": expected["min_ttc"],
        "rms_jerk": np.sqrt(expected["jerk_squared"] / 2),
        "switches": expected["switches"],
        "mean_setting": expected["setting"] / 2,
        "mean_capacity": expected["capacity"] / 2,
        "duration": np.full(N_ENVS, 2 * CONFIG.decision_interval),
    }
    for name, value in formulas.items():
        np.testing.assert_allclose(summary[name], value, rtol=1e-12, err_msg=name)
    assert summary["collision"].dtype == bool
    np.testing.assert_array_equal(summary["collision"], np.arange(N_ENVS) == COLLIDING_ENV)
    assert np.all((LEVELS[0] <= summary["mean_setting"]) & (summary["mean_setting"] <= LEVELS[-1]))


def test_summary_of_no_step_divides_by_one_step_not_zero():
    summary = EpisodeTotals.zeros(N_ENVS).summary(CONFIG)
    for name in ("mean_gap_deviation", "time_out_of_control", "rms_jerk", "mean_setting", "mean_capacity", "duration"):
        np.testing.assert_array_equal(summary[name], 0.0, err_msg=name)
    assert np.all(summary["min_ttc"] == np.inf) and not summary["collision"].any()


def test_an_env_totals_the_same_alone_as_in_a_batch():
    rng = np.random.default_rng(6)
    readouts, setting, changed = random_step(rng, collide=True)
    batch, alone = EpisodeTotals.zeros(N_ENVS), EpisodeTotals.zeros(1)
    batch.add_step(readouts, setting, changed, GAP)
    env = [COLLIDING_ENV]
    alone.add_step(StepReadouts(*(field[env] for field in readouts)), setting[env], changed[env], GAP)
    for name, batch_total, alone_total in zip(batch._fields, batch, alone):
        np.testing.assert_array_equal(alone_total, batch_total[env], err_msg=name)
