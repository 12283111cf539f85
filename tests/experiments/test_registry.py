"""The policy registry builds what evaluate's and sweep's own registries built, and takes new policies."""

from __future__ import annotations

import pytest

from timegap_env.agents.policies import ChartStepPolicy, FixedPolicy, PaperRulePolicy, V2VAwarePolicy, as_config, fixed_policies, seconds
from timegap_env.config import EnvConfig
from timegap_env.experiments import registry


def test_the_registered_names_are_evaluates_and_sweeps():
    assert set(registry.POLICIES) == {"rule_platoon", "rule_per_vehicle", "chart_step", "chart_step_per_vehicle",
                                      "v2v_aware", "v2v_aware_per_vehicle"}
    assert registry.fixed_names() == [f"fixed_{seconds(p.setting)}" for p in fixed_policies(EnvConfig())]
    assert all(registry.is_known(name) for name in ["oracle", "ppo", "fixed_1.6", *registry.POLICIES])
    assert not registry.is_known("greedy")


@pytest.mark.parametrize("overrides", [{}, {"preferred_setting": 1.0, "platoon": {"n_followers": 3}}])
def test_make_builds_the_old_policies(overrides):
    config = as_config(overrides)
    old = {  # as train/evaluate.py and train/sweep.py built them
        "rule_platoon": PaperRulePolicy(config),
        "rule_per_vehicle": PaperRulePolicy(config.with_overrides({"action_mode": "per_vehicle"})),
        "chart_step": ChartStepPolicy(config),
        "chart_step_per_vehicle": ChartStepPolicy(as_config({**overrides, "action_mode": "per_vehicle"})),
        "v2v_aware": V2VAwarePolicy(config),
        "v2v_aware_per_vehicle": V2VAwarePolicy(as_config({**overrides, "action_mode": "per_vehicle"})),
        "fixed_1.6": FixedPolicy(1.6, config),
    }
    for name, policy in old.items():
        for given in (config, overrides):  # an EnvConfig or gym.make's overrides
            made = registry.make(name, given)
            assert type(made) is type(policy) and made.config == policy.config and made.name == policy.name
            assert made.action_mode == policy.action_mode


def test_parameters_and_errors():
    tuned = registry.make("chart_step", None, k_up=2, quiet_time=20.0, min_setting=1.2)
    assert (tuned.k_up, tuned.quiet_time, tuned.min_setting) == (2, 20.0, 1.2)
    with pytest.raises(ValueError, match="greedy"):
        registry.make("greedy")
    with pytest.raises(ValueError, match="not a number"):
        registry.make("fixed_x")
    with pytest.raises(ValueError, match="reserved"):
        registry.register("fixed_2", FixedPolicy)


def test_a_new_policy_is_one_register_call(monkeypatch):
    monkeypatch.setattr(registry, "POLICIES", dict(registry.POLICIES))
    spec = registry.register("cautious", FixedPolicy.__new__, "per_vehicle", "a test entry")
    assert registry.POLICIES["cautious"] is spec and registry.is_known("cautious")
    calls = []
    registry.register("recorder", lambda config, **kwargs: calls.append((config.action_mode, kwargs)) or "made",
                      "per_vehicle", "records its arguments", level=3)
    assert registry.make("recorder", {}, level=4) == "made" and calls == [("per_vehicle", {"level": 4})]
