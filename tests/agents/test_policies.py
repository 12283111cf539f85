"""Hand-written policies: the paper's rule against the env's own chart, fixed settings, V2V-aware."""

import gymnasium as gym
import numpy as np
import pytest

import timegap_env
from agents.policies import NamedPolicy, PaperRulePolicy, V2VAwarePolicy, fixed_policies, level_index
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
    batch = np.stack([obs, with_features(obs, exceedances=1.0), with_features(obs, v2v=0.0)])
    for policy in [PaperRulePolicy(config), V2VAwarePolicy(config), *fixed_policies(config)]:
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
