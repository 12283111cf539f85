"""Hand-written policies: the paper's rule against the env's own chart, fixed settings, V2V-aware."""

import gymnasium as gym
import numpy as np
import pytest

import timegap_env
from timegap_env.agents.policies import (
    ChartStepPolicy,
    NamedPolicy,
    PaperRulePolicy,
    V2VAwarePolicy,
    fixed_policies,
    level_index,
)
from timegap_env.config import EnvConfig
from timegap_env.envs.observation import FEATURES, decode_observation

# Limits at tau* -/+ 1 sigma instead of 2: the default chart rarely sees 3 exceedances within 35 s,
# this one does within a minute on aggressive_cycles seed 0 (follower 1 first).
BUSY_CHART = {"chart": {"limit_width": 1.0}, "degradation": {"kind_weights": {"none": 1.0}}}
N_FEATURES = len(FEATURES)


def real_observation(config: dict | None = None) -> np.ndarray:
    """A reset observation of the env with ``config`` (N * 9,)."""
    env = gym.make(timegap_env.ENV_ID, config=config)
    obs, _ = env.reset(seed=0)
    return obs


def with_features(obs: np.ndarray, **columns: np.ndarray | float) -> np.ndarray:
    """``obs`` (..., N * 9) with some features replaced, e.g. ``v2v=[1, 1, 0, 1, 1]``."""
    rows = obs.reshape(*obs.shape[:-1], -1, N_FEATURES).copy()
    for feature, value in columns.items():
        rows[..., FEATURES.index(feature)] = value
    return rows.reshape(obs.shape)


def drive_rule(config: dict) -> list[tuple[int, np.ndarray]]:
    """Run the rule in a real env and check every action against the env's chart; return (step, triggered followers)."""
    env = gym.make(timegap_env.ENV_ID, config=config)
    obs, _ = env.reset(seed=0, options={"scenario": "aggressive_cycles"})
    cfg = env.unwrapped.config
    policy = PaperRulePolicy(cfg)
    loop = env.unwrapped.task.loop
    k, switch_index = cfg.chart.switch_exceedances, level_index(cfg, cfg.chart.switch_to)
    triggers = []
    for step in range(cfg.max_episode_steps):
        count = loop.chart.exceedances_in_window[0].copy()
        current = np.array([level_index(cfg, s) for s in loop.platoon.setting[0]])
        triggered = (count >= k) & (current != switch_index)
        action, state = policy.predict(obs)
        assert state is None
        if cfg.action_mode == "platoon":
            expected = switch_index if triggered.any() else current[0]
        else:
            expected = np.where(triggered, switch_index, current)
        np.testing.assert_array_equal(action, expected, err_msg=f"step {step}, counts {count}, settings {current}")
        if triggered.any():
            triggers.append((step, triggered))
            before = loop.platoon.setting[0].copy()
        obs, _, terminated, truncated, _ = env.step(action)
        if triggered.any() and cfg.action_mode == "per_vehicle":
            changed = ~np.isclose(loop.platoon.setting[0], before)
            np.testing.assert_array_equal(changed, triggered, err_msg="only the triggering followers switch")
        if terminated or truncated:
            break
    return triggers


def test_platoon_rule_switches_everyone_exactly_when_a_chart_reaches_k():
    triggers = drive_rule(BUSY_CHART)
    assert triggers, "no chart reached k: the test scenario no longer exercises the rule"
    assert len(triggers) == 1, "after the switch everyone is at switch_to and the rule holds"


def test_per_vehicle_rule_switches_only_the_triggering_follower():
    triggers = drive_rule(BUSY_CHART | {"action_mode": "per_vehicle"})
    assert len(triggers) >= 2, "followers should reach k at different steps in this scenario"
    assert triggers[0][1].sum() == 1, f"one follower first, the others keep their setting: {triggers[0]}"


def test_rule_reads_counts_exactly_and_holds_below_k():
    config = EnvConfig()
    obs = real_observation()
    k, levels = config.chart.switch_exceedances, np.asarray(config.setting_levels)
    for count in range(2 * k + 1):
        crafted = with_features(obs, exceedances=np.float32(count / (2 * k)))
        assert np.all(decode_observation(crafted[None], config).exceedances == count)
        action, _ = PaperRulePolicy(config).predict(crafted)
        expected = level_index(config, 1.0) if count >= k else level_index(config, 1.6)
        assert action == expected, count
    for index, level in enumerate(levels):
        setting = np.float32((level - levels[0]) / (levels[-1] - levels[0]))
        assert np.all(decode_observation(with_features(obs, setting=setting)[None], config).setting_index == index)


def test_rule_parameters_and_their_limits():
    obs = with_features(real_observation(), exceedances=np.float32(2 / 6))
    assert PaperRulePolicy(switch_exceedances=2).predict(obs)[0] == level_index(EnvConfig(), 1.0)
    assert PaperRulePolicy(switch_exceedances=3).predict(obs)[0] == level_index(EnvConfig(), 1.6)
    assert PaperRulePolicy(switch_to=0.8, switch_exceedances=2).predict(obs)[0] == level_index(EnvConfig(), 0.8)
    with pytest.raises(ValueError, match="exceedance_window = 20.0"):
        PaperRulePolicy(exceedance_window=20.0)
    with pytest.raises(ValueError, match="switch_exceedances = 7"):
        PaperRulePolicy(switch_exceedances=7)
    with pytest.raises(ValueError, match="switch_to = 1.1"):
        PaperRulePolicy(switch_to=1.1)
    # an env whose chart counts over 20 s: the rule takes its window from there
    assert PaperRulePolicy({"chart": {"exceedance_window": 20.0}}, exceedance_window=20.0).exceedance_window == 20.0


def test_rule_is_not_re_triggered_at_switch_to():
    config = EnvConfig()
    levels = np.asarray(config.setting_levels)
    at_switch_to = np.float32((1.0 - levels[0]) / (levels[-1] - levels[0]))
    obs = with_features(real_observation(), exceedances=1.0, setting=at_switch_to)
    assert PaperRulePolicy(config).predict(obs)[0] == level_index(config, 1.0)


def test_fixed_baselines_return_their_level_single_and_batched():
    obs = real_observation()
    batch = np.stack([obs, with_features(obs, v2v=0.0, exceedances=1.0)])
    config = EnvConfig()
    policies = fixed_policies(config)
    assert [p.setting for p in policies] == list(config.setting_levels)
    for index, policy in enumerate(policies):
        action, _ = policy.predict(obs)
        assert action.shape == () and action == index
        np.testing.assert_array_equal(policy.predict(batch)[0], [index, index])
    per_vehicle = fixed_policies({"action_mode": "per_vehicle"})[2]
    assert per_vehicle.predict(obs)[0].tolist() == [2] * 5
    assert per_vehicle.predict(batch)[0].shape == (2, 5)


def test_v2v_aware_policy():
    obs = real_observation()
    one_lost = with_features(obs, v2v=np.array([1, 1, 0, 1, 1], dtype=np.float32))
    connected, acc = level_index(EnvConfig(), 1.0), level_index(EnvConfig(), 1.6)
    assert V2VAwarePolicy().predict(obs)[0] == connected
    np.testing.assert_array_equal(V2VAwarePolicy().predict(np.stack([obs, one_lost]))[0], [connected, acc])
    per_vehicle = V2VAwarePolicy({"action_mode": "per_vehicle"})
    np.testing.assert_array_equal(per_vehicle.predict(one_lost)[0], [connected] * 2 + [acc] + [connected] * 2)


@pytest.mark.parametrize("action_mode", ["platoon", "per_vehicle"])
def test_batched_equals_one_by_one_and_actions_fit_the_env(action_mode):
    config = {"action_mode": action_mode}
    env = gym.make(timegap_env.ENV_ID, config=config)
    obs = real_observation(config)
    batch = np.stack([obs, with_features(obs, exceedances=1.0), with_features(obs, v2v=0.0),
                      with_features(obs, time_since_alarm=np.array([1, 0, 1, 1, 1], dtype=np.float32)),
                      with_features(obs, time_since_alarm=1.0)])
    policies = [PaperRulePolicy(config), ChartStepPolicy(config), ChartStepPolicy(config, min_setting=1.0),
                V2VAwarePolicy(config), *fixed_policies(config)]
    for policy in policies:
        assert isinstance(policy, NamedPolicy) and policy.action_mode == action_mode
        actions, _ = policy.predict(batch)
        for row, action in zip(batch, actions):
            single, _ = policy.predict(row)
            np.testing.assert_array_equal(single, action)
            assert env.action_space.contains(single), (policy, single)


def test_observation_shape_and_config_mismatches_are_errors():
    obs = real_observation()
    with pytest.raises(ValueError, match=r"observation shape \(44,\)"):
        PaperRulePolicy().predict(obs[:-1])
    with pytest.raises(ValueError, match="not on setting_levels"):
        PaperRulePolicy({"setting_levels": (0.6, 1.0, 1.6, 3.0)}).predict(with_features(obs, setting=0.3))


# ---------------------------------------------------------------- the chart step rule
LEVELS = np.asarray(EnvConfig().setting_levels)


def at_setting(obs: np.ndarray, setting: float | np.ndarray) -> np.ndarray:
    """``obs`` with the followers' setting feature at ``setting`` [s], one level or one per follower."""
    return with_features(obs, setting=((np.asarray(setting) - LEVELS[0]) / (LEVELS[-1] - LEVELS[0])).astype(np.float32))


def counts(count: int | np.ndarray) -> np.ndarray:
    """The exceedance feature for ``count`` exceedances under the default chart (saturating at 6)."""
    return (np.asarray(count) / 6).astype(np.float32)


def quiet(seconds: float | np.ndarray) -> np.ndarray:
    """The time-since-alarm feature for ``seconds`` without an alarm under the default 35 s window."""
    return np.minimum(np.asarray(seconds) / 35.0, 1.0).astype(np.float32)


def test_chart_steps_go_up_on_excursions_and_down_when_quiet():
    config = EnvConfig()
    obs, at = real_observation(), lambda setting: level_index(config, setting)
    policy = ChartStepPolicy(config, k_up=2, quiet_time=20.0, min_setting=1.0)
    assert policy.predict(with_features(obs, exceedances=counts(1), time_since_alarm=quiet(5)))[0] == at(1.6)
    assert policy.predict(with_features(obs, exceedances=counts(2), time_since_alarm=quiet(5)))[0] == at(1.8)
    assert policy.predict(with_features(obs, exceedances=counts(0), time_since_alarm=quiet(19)))[0] == at(1.6)
    assert policy.predict(with_features(obs, exceedances=counts(0), time_since_alarm=quiet(20)))[0] == at(1.4)
    # excursions in the window outvote a quiet spell since them
    assert policy.predict(with_features(obs, exceedances=counts(2), time_since_alarm=quiet(20)))[0] == at(1.8)


def test_chart_steps_stay_within_the_floor_and_the_ladder_top():
    config = EnvConfig()
    obs, at = real_observation(), lambda setting: level_index(config, setting)
    policy = ChartStepPolicy(config, k_up=1, quiet_time=10.0, min_setting=1.2)
    calm, busy = with_features(obs, time_since_alarm=quiet(35)), with_features(obs, exceedances=counts(6))
    assert policy.predict(at_setting(calm, 1.4))[0] == at(1.2)
    assert policy.predict(at_setting(calm, 1.2))[0] == at(1.2)
    assert policy.predict(at_setting(calm, 0.6))[0] == at(1.2), "below the floor: back to it"
    assert policy.predict(at_setting(busy, 2.0))[0] == at(2.2)
    assert policy.predict(at_setting(busy, 2.2))[0] == at(2.2)


def test_chart_steps_platoon_takes_the_largest_level_asked_per_vehicle_each_its_own():
    config = EnvConfig()
    obs, at = real_observation(), lambda setting: level_index(config, setting)
    one_busy = with_features(obs, exceedances=counts([0, 0, 3, 0, 0]), time_since_alarm=quiet([35, 35, 0, 35, 35]))
    one_calm = with_features(obs, time_since_alarm=quiet([35, 5, 5, 5, 5]))
    all_calm = with_features(obs, time_since_alarm=quiet(35))
    platoon = ChartStepPolicy(config, k_up=3, quiet_time=35.0, min_setting=1.0)
    np.testing.assert_array_equal(platoon.predict(np.stack([one_busy, one_calm, all_calm]))[0],
                                  [at(1.8), at(1.6), at(1.4)])
    per_vehicle = ChartStepPolicy({"action_mode": "per_vehicle"}, k_up=3, quiet_time=35.0, min_setting=1.0)
    assert per_vehicle.name.endswith("per vehicle") and not platoon.name.endswith("per vehicle")
    np.testing.assert_array_equal(per_vehicle.predict(one_busy)[0], [at(1.4), at(1.4), at(1.8), at(1.4), at(1.4)])
    np.testing.assert_array_equal(per_vehicle.predict(one_calm)[0], [at(1.4)] + [at(1.6)] * 4)
    mixed = at_setting(one_busy, np.array([1.0, 1.2, 2.2, 1.6, 0.8]))
    np.testing.assert_array_equal(per_vehicle.predict(mixed)[0], [at(1.0), at(1.0), at(2.2), at(1.4), at(1.0)])


def test_chart_step_parameters_and_their_limits():
    for bad, message in [({"k_up": 7}, "k_up = 7"), ({"k_up": 1.5}, "k_up = 1.5"), ({"k_up": True}, "k_up = True"),
                         ({"quiet_time": 40.0}, "quiet_time = 40.0 s"), ({"quiet_time": 0.0}, "quiet_time = 0.0 s"),
                         ({"min_setting": 1.1}, "min_setting = 1.1")]:
        with pytest.raises(ValueError, match=message):
            ChartStepPolicy(**bad)
    # an env whose chart counts over 60 s lets the rule wait that long
    assert ChartStepPolicy({"chart": {"exceedance_window": 60.0}}, quiet_time=60.0).quiet_time == 60.0


@pytest.mark.parametrize("action_mode", ["platoon", "per_vehicle"])
def test_chart_steps_follow_the_env_s_chart_up_and_down(action_mode):
    """In a real env, every action is the rule applied to the chart's own count and run length."""
    env = gym.make(timegap_env.ENV_ID, config=BUSY_CHART | {"action_mode": action_mode})
    obs, _ = env.reset(seed=0, options={"scenario": "aggressive_cycles"})
    cfg, loop = env.unwrapped.config, env.unwrapped.task.loop
    policy = ChartStepPolicy(cfg, k_up=2, quiet_time=20.0, min_setting=1.2)
    moves = set()
    for step in range(cfg.max_episode_steps):
        current = np.array([level_index(cfg, s) for s in loop.platoon.setting[0]])
        up = loop.chart.exceedances_in_window[0] >= 2
        down = ~up & (loop.chart.run_length[0] * cfg.platoon.dt >= 20.0 - 1e-9)
        asked = np.clip(current + up - down, level_index(cfg, 1.2), len(cfg.setting_levels) - 1)
        expected = asked.max() if action_mode == "platoon" else asked
        action, _ = policy.predict(obs)
        np.testing.assert_array_equal(action, expected, err_msg=f"step {step}")
        moves |= set(np.sign(np.atleast_1d(action) - (current[0] if action_mode == "platoon" else current)).tolist())
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            break
    assert {-1, 1} <= moves, f"the scenario should send the rule both ways: {moves}"
