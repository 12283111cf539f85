"""TimeGapMonitor-v1 and mo-TimeGapMonitor-v1 (issue 24): the objectives as a vector, the cost, the regime, the
presets; v0 keeps its task and its info keys."""

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import timegap_env
from timegap_env.config import REWARD_PRESETS, EnvConfig, RewardWeights
from timegap_env.envs.env import TimeGapMonitorEnv
from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv
from timegap_env.tasks import TASKS, get_task
from timegap_env.envs.info import COST, OBJECTIVES_KEY, VECTOR_REWARD, objectives_of, rewards_of, truth_of
from timegap_env.envs.reward import COST_TERMS, OBJECTIVES, REWARD_TERMS
from timegap_env.leaders.regimes import REGIMES
from timegap_env.leaders.scenarios import USER, regime_names

V1_KEYS = {VECTOR_REWARD, COST, OBJECTIVES_KEY, "truth_regime"}  # with truth_info=True; without it no truth_regime


def weights_vector(config: EnvConfig) -> np.ndarray:
    return np.array([getattr(config.reward_weights, name) for name in REWARD_TERMS])


def test_v1_is_v0_with_the_tasks_overrides():
    v0, v1 = gym.make("TimeGapMonitor-v0").unwrapped.config, gym.make("TimeGapMonitor-v1").unwrapped.config
    assert v0 == EnvConfig() and v1 == EnvConfig.from_dict(dict(TASKS["TimeGapMonitor-v1"].overrides))
    assert v1 == get_task("TimeGapMonitor-v1").config()
    assert v1.reward_weights == REWARD_PRESETS["variation_first"].weights and v1.scenario_weights["regimes"] == 1.0
    assert v1.with_overrides({"reward_weights": v0.reward_weights, "scenario_weights": v0.scenario_weights}) == v0
    # a user's overrides go over the version's defaults, nested ones field by field
    tuned = gym.make("TimeGapMonitor-v1", config={"reward_weights": {"comfort": 0.1}}).unwrapped.config
    assert tuned.reward_weights == RewardWeights(**{**vars(REWARD_PRESETS["variation_first"].weights), "comfort": 0.1})


@pytest.mark.parametrize("truth_info", [False, True])
def test_v0_info_keeps_its_keys_and_v1_adds_the_objectives(truth_info):
    env0, env1 = (gym.make(env_id, truth_info=truth_info) for env_id in ("TimeGapMonitor-v0", "TimeGapMonitor-v1"))
    _, info0 = env0.reset(seed=3)
    _, info1 = env1.reset(seed=3)
    v1_keys = V1_KEYS if truth_info else V1_KEYS - {"truth_regime"}
    assert not V1_KEYS & set(info0) and set(info1) == set(info0) | v1_keys
    assert any(key.startswith("truth_") for key in info1) == truth_info
    assert np.all(info1[VECTOR_REWARD] == 0) and info1[COST] == 0
    _, _, _, _, step0 = env0.step(4)
    _, _, _, _, step1 = env1.step(4)
    assert set(step0) == set(info0) and set(step1) == set(info1)


@pytest.mark.parametrize("scenario", ["regimes", "aggressive_cycles"])
def test_the_scalar_reward_is_the_weights_times_the_vector(scenario):
    env = gym.make("TimeGapMonitor-v1")
    _, info = env.reset(seed=11, options={"scenario": scenario, "degradation": {"kind": "lag", "size": 0.8}})
    weights = weights_vector(env.unwrapped.config)
    rng = np.random.default_rng(0)
    costs = []
    for _ in range(120):
        _, reward, terminated, truncated, info = env.step(int(rng.integers(9)))
        vector = info[VECTOR_REWARD]
        assert vector.shape == (len(REWARD_TERMS),)
        assert reward == pytest.approx(float(weights @ vector), abs=1e-12)
        terms = rewards_of(info)
        assert np.array_equal(vector, [terms[name] for name in REWARD_TERMS])
        clipped = {name: max(-1.0, float(terms[name])) for name in COST_TERMS}
        assert info[COST] == pytest.approx(-sum(clipped.values())) and 0 <= info[COST] <= 3
        costs.append(info[COST])
        if terminated or truncated:
            break
    assert max(costs) > 0  # not a key that is always 0


def test_objectives_are_the_terms_in_natural_units():
    env = gym.make("TimeGapMonitor-v1")
    config = env.unwrapped.config
    scales, levels = config.reward_scales, config.setting_levels
    env.reset(seed=5, options={"scenario": "sinusoid"})
    for action in [0, 0, 8, 8, 4] * 10:
        _, _, _, _, info = env.step(action)
        terms, objectives = rewards_of(info), objectives_of(info)
        assert set(objectives) == {o.name for o in OBJECTIVES.values()}
        assert terms["tracking"] == pytest.approx(-objectives["time_gap_variation"] / scales.tracking_reference)
        assert terms["string_stability"] == pytest.approx(-min(1.0, objectives["acceleration_growth"]
                                                                / scales.accel_growth_reference))
        assert terms["safety"] == pytest.approx(-objectives["ttc_shortfall"] / scales.ttc_threshold)
        assert terms["comfort"] == pytest.approx(-objectives["jerk_squared"] / scales.jerk_reference**2)
        assert terms["preference"] == pytest.approx(-objectives["preference_deviation"] / (levels[-1] - levels[0]))
        assert terms["switching"] == -objectives["switching"] and terms["collision"] == -objectives["collision"]
        speed = info["estimate"] * 0 + env.unwrapped.task._readouts.final_speed[0]  # the step's final speeds [m/s]
        gap = config.platoon.standstill_spacing + config.platoon.vehicle_length
        capacity = 3600 * speed / (speed * info["setting"] + gap)
        assert objectives["capacity"] == pytest.approx(capacity.mean())
        smallest = 3600 * speed / (speed * levels[0] + gap)
        assert terms["efficiency"] == pytest.approx(-np.mean(1 - capacity / smallest))


def test_the_regime_is_the_leaders_own():
    env = gym.make("TimeGapMonitor-v1", truth_info=True)
    names = regime_names()
    assert names[-1] == USER and {f"regimes:{r}" for r in REGIMES} <= set(names)
    _, info = env.reset(seed=2, options={"scenario": "regimes"})
    seen = {truth_of(info)["regime"]}
    for _ in range(250):
        _, _, terminated, truncated, info = env.step(5)
        seen.add(truth_of(info)["regime"])
        if terminated or truncated:
            break
    assert len(seen) >= 2 and all(name.startswith("regimes:") for name in seen)
    _, info = env.reset(seed=2, options={"scenario": "sinusoid"})
    assert truth_of(info)["regime"] == "sinusoid"
    _, info = env.reset(seed=2, options={"leader_speed": np.full(300, 20.0)})
    assert truth_of(info)["regime"] == USER


def test_the_vector_env_carries_the_objectives_through_autoresets():
    venv = gym.make_vec("TimeGapMonitor-v1", num_envs=3, vectorization_mode="vector_entry_point",
                        config={"episode_duration": 20.0}, autoreset_mode="same_step", truth_info=True)
    _, infos = venv.reset(seed=0)
    weights = weights_vector(venv.unwrapped.config)
    assert infos[VECTOR_REWARD].shape == (3, len(REWARD_TERMS)) and infos["truth_regime"].shape == (3,)
    for _ in range(20):
        _, reward, terminated, truncated, infos = venv.step(np.full(3, 4))
    assert (terminated | truncated).all()
    final = infos["final_info"]
    np.testing.assert_allclose(final[VECTOR_REWARD] @ weights, reward, atol=1e-12)
    assert np.all(infos[VECTOR_REWARD] == 0) and np.all(infos[COST] == 0)  # the new episodes' (reset's)


def test_mo_env_returns_the_terms_as_a_vector():
    env = gym.make(timegap_env.MO_ENV_ID, objectives=["efficiency", "string_stability", "tracking"])
    mo = env.unwrapped
    assert mo.reward_dim == 3 and mo.reward_space.shape == (3,) and mo.reward_space.dtype == np.float32
    assert mo.config == gym.make("TimeGapMonitor-v1").unwrapped.config
    scalar = gym.make("TimeGapMonitor-v1")
    env.reset(seed=4)
    scalar.reset(seed=4)
    for action in [0, 3, 8, 8, 2]:
        _, vector, _, _, info = env.step(action)
        _, _, _, _, scalar_info = scalar.step(action)
        assert vector.dtype == np.float32 and vector in mo.reward_space
        assert np.array_equal(vector, np.float32([scalar_info["reward_efficiency"], scalar_info["reward_string_stability"],
                                                  scalar_info["reward_tracking"]]))
    full = gym.make(timegap_env.MO_ENV_ID)
    assert full.unwrapped.reward_dim == len(REWARD_TERMS)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", ".*step.*must be a float", UserWarning)  # a vector reward, by design
        check_env(full.unwrapped, skip_render_check=True)


@pytest.mark.parametrize("bad, message", [
    ({"reward_weights": [1.0, 2.0]}, "reward_weights = [1.0, 2.0]: has 2 weights; needs 8"),
    ({"reward_weights": "operator"}, "reward_weights = 'operator': unknown preset"),
    ({"reward_weights": {"capacity": 1.0}}, "unknown RewardWeights field(s) ['capacity']"),
    ({"reward_weights": [1.0] * 7 + [float("nan")]}, "RewardWeights.switching = nan"),
    ({"info_keys": "v0"}, "unknown EnvConfig field(s) ['info_keys']"),  # the layout is the task's, not a switch
    ({"leader_params": {"regimes": {"free_flow_duration": (0.0, 10.0)}}}, "free_flow_duration = (0.0, 10.0)"),
])
def test_bad_task_input_names_the_field_and_value(bad, message):
    with pytest.raises(ValueError) as error:
        gym.make("TimeGapMonitor-v1", config=bad).reset(seed=0)
    assert message in str(error.value)


def test_an_unknown_objective_or_task_is_refused():
    with pytest.raises(ValueError, match=r"unknown objective\(s\) \[.radar.\]"):
        gym.make(timegap_env.MO_ENV_ID, objectives=["tracking", "radar"])
    with pytest.raises(ValueError, match="each may appear once"):
        gym.make(timegap_env.MO_ENV_ID, objectives=["tracking", "tracking"])
    with pytest.raises(ValueError, match=r"task_id = 'TimeGapMonitor-v7': not a task of this env; known: \[.TimeGap"):
        get_task("TimeGapMonitor-v7")
    with pytest.raises(ValueError, match="task_id = 'TimeGapMonitor-v7'"):
        TimeGapMonitorEnv(task_id="TimeGapMonitor-v7")


@pytest.mark.parametrize("env_id, other", [("TimeGapMonitor-v1", "TimeGapMonitor-v0"),
                                           ("TimeGapMonitor-v0", "TimeGapMonitor-v1"),
                                           (timegap_env.MO_ENV_ID, "TimeGapMonitor-v0")])
def test_the_id_is_the_task_no_switch_behind_it(env_id, other):
    """Every registered id is one task record; a task_id given to make under another id is refused, single and
    vectorised, and each id's env carries its own task."""
    with pytest.raises(ValueError, match=f"task_id = '{other}' under the id '{env_id}': the id is the task"):
        gym.make(env_id, task_id=other)
    if env_id in TASKS:
        with pytest.raises(ValueError, match="the id is the task"):
            gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", task_id=other)
        assert gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point").unwrapped.task_id == env_id
        assert gym.make(env_id).unwrapped.task_id == env_id


def test_a_task_record_holds_its_config_layout_seeds_groups_and_references():
    v0, v1 = TASKS["TimeGapMonitor-v0"], TASKS["TimeGapMonitor-v1"]
    assert list(TASKS) == list(timegap_env.TASKS) and timegap_env.DEFAULT_TASK == v1.id
    assert (v0.info_layout, v1.info_layout) == ("v0", "v1")
    assert len(v0.seeds.check) == 32 and len(v1.seeds.check) == 100 and v1.seeds.check[0] == 9000
    assert v1.seeds.selection_start < v1.seeds.check_start < v1.seeds.held_out_start
    assert [group.name for group in v1.groups][:2] == ["default", "regimes"] and v1.group("sumo").capped
    assert {"full_oracle", "regime_aware"} <= set(v1.references)
    with pytest.raises(ValueError, match="group 'nope': not a held-out group of TimeGapMonitor-v1"):
        v1.group("nope")
    # built directly, the env classes give the default task, or the one named
    assert TimeGapMonitorEnv().config == v1.config() and TimeGapMonitorVectorEnv(2).task_id == v1.id
    assert TimeGapMonitorEnv(task_id=v0.id).config == v0.config()
    with pytest.raises(TypeError):
        v1.overrides["info"] = 1  # a record does not change under its id


def test_presets_by_name_or_vector_equal_their_weights():
    for name, preset in REWARD_PRESETS.items():
        assert EnvConfig.from_dict({"reward_weights": name}).reward_weights == preset.weights
        vector = [getattr(preset.weights, term) for term in REWARD_TERMS]
        assert EnvConfig.from_dict({"reward_weights": vector}).reward_weights == preset.weights


def test_the_cost_stays_in_its_range_through_a_collision():
    env = gym.make("TimeGapMonitor-v1", config={"episode_duration": 60.0})
    env.reset(seed=0, options={"scenario": "emergency_braking", "degradation": {"kind": "lag", "size": 1.2}})
    for _ in range(60):
        _, _, terminated, truncated, info = env.step(0)
        assert 0 <= info[COST] <= 3
        if terminated or truncated:
            break


def test_mo_objectives_by_term_or_objective_name():
    env = gym.make(timegap_env.MO_ENV_ID, objectives=["capacity", "time_gap_variation", "string_stability"])
    assert env.unwrapped.objectives == ("efficiency", "tracking", "string_stability")
    with pytest.raises(ValueError, match="each may appear once"):
        gym.make(timegap_env.MO_ENV_ID, objectives=["capacity", "efficiency"])
