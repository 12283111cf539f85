"""Every field of every config refuses bad values with a ValueError naming it (issue 14, careless use 4).

The fields are enumerated from the dataclasses themselves (``ConfigMixin``'s subclasses, and
recursively ``EnvConfig``'s nested configs), and each gets bad values chosen by its type: a
string, a bool for a number, NaN, infinities, negatives, values far beyond any upper bound,
pairs of the wrong shape, non-mappings for nested configs. A new field or config is tested
without touching this file; a field of a type this file does not know fails
``test_every_field_has_bad_values``.
"""

import dataclasses
import math
import tracemalloc
import types
import typing

import gymnasium as gym
import numpy as np
import pytest

import timegap_env  # noqa: F401  registers TimeGapMonitor-v0 and imports every config
from timegap_env.config import (
    MAX_DECISION_TICKS,
    MAX_EPISODE_TICKS,
    MAX_FOLLOWERS,
    MAX_SETTING_LEVELS,
    MAX_TIME_GAP,
    MAX_WINDOW_TICKS,
    MIN_DT,
    NESTED_CONFIGS,
    ConfigMixin,
    EnvConfig,
    MonitorConfig,
    PlatoonConfig,
)

NAN, INF = float("nan"), float("inf")
HUGE = 1e12  # beyond every upper bound
CONFIG_CLASSES = sorted((cls for cls in ConfigMixin.__subclasses__() if cls.__module__.startswith("timegap_env.")),
                        key=lambda cls: cls.__name__)  # the library's own (a test may define one of its own)


def kind_of(cls: type, field: str) -> typing.Any:
    """The field's type hint, resolved."""
    return typing.get_type_hints(cls)[field]


def number_bad_values(default: typing.Any) -> list[typing.Any]:
    bad = ["1.0", True, np.bool_(False), NAN, INF, -INF, HUGE, -HUGE, {"value": 1.0}]
    return bad + ([-1.0] if default >= 0 else [])  # every field with a default >= 0 is bounded below by 0


def pair_bad_values(default: tuple, integer: bool) -> list[typing.Any]:
    low, high = default
    bad = [0.1, 1, "ab", "12", None, (low,), (low, high, high), {"low": low, "high": high}, (True, high),
           (str(low), str(high)), (NAN, high), (low, INF), (-HUGE, high), (low, HUGE), (high, low), [[low], [high]]]
    return bad + ([(low + 0.5, high + 0.5), (float(low), float(high))] if integer else [])


def bad_values(cls: type, field: str) -> list[typing.Any]:
    """Values the field must refuse, chosen by its type hint and its default."""
    kind, default = kind_of(cls, field), getattr(cls(), field)
    args = typing.get_args(kind)
    if kind is bool:
        return [1, 0, 1.0, "yes", None, np.int64(1)]
    if kind is int:
        return ["3", float(default), 2.5, True, None, NAN, -1, 0, 10**12, 10**400, (default,)]
    if kind is float:
        return number_bad_values(default) + [None, [1.0], (1.0,)]
    if kind is str:
        return ["no_such_option", default.upper(), 3, None, [default], True]
    if isinstance(kind, types.UnionType) and args == (float, type(None)):  # a number or None
        return number_bad_values(default) + [[1.0], (1.0,)]
    if isinstance(kind, types.UnionType) and args == (float, tuple[float, ...]):  # one number or one per follower
        n, rest = cls().n_followers, (0.4,) * (cls().n_followers - 1)
        return number_bad_values(default) + [None, "abc", (), (0.4,) * (n + 1), (True,) * n, ((0.4,),) * n,
                                              rest + (NAN,), rest + (HUGE,), rest + (-0.4,), rest + ("0.4",)]
    if kind == tuple[float, float] or kind == tuple[int, int]:
        return pair_bad_values(default, integer=kind == tuple[int, int])
    if kind == tuple[float, ...]:  # a ladder of settings
        many = tuple(np.linspace(0.1, MAX_TIME_GAP, MAX_SETTING_LEVELS + 1))
        return [1.6, "abc", None, (), (1.6,), (2.0, 1.6), (1.6, 1.6), (True, 1.6), (NAN, 1.6), (1.6, INF), (1.6, HUGE),
                (-1.0, 1.6), (0.0, 1.6), ("1.0", 1.6), many, {"low": 1.0, "high": 1.6}, ((1.0, 1.6),)]
    if kind == tuple[tuple[float, float], tuple[float, float]]:  # a 2x2 matrix
        return [1.0, "ab", None, (1.0, 0.0, 0.0, 1.0), ((1.0, 0.0),), ((1.0, 0.0), (0.0, 1.0), (0.0, 0.0)),
                ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)), ((NAN, 0.0), (0.0, 1.0)), ((1.0, 0.0), (0.0, INF)),
                ((True, 0.0), (0.0, True)), ((HUGE, 0.0), (0.0, 1.0)), ((1.0, "0"), (0.0, 1.0)),
                ((1.0, 2.0), (2.0, 1.0)), ((1.0, 0.5), (0.0, 1.0))]  # the last two: not definite, not symmetric
    if kind == dict[str, float]:  # weights by name
        key = next(iter(default))
        return [1.0, "abc", None, [(key, 1.0)], {}, {1: 1.0}, {key: True}, {key: NAN}, {key: INF}, {key: -1.0},
                {key: HUGE}, {key: "1"}, {name: 0.0 for name in default}]
    if kind == dict[str, dict[str, typing.Any]]:  # leader family -> its parameters (the env checks their names)
        return [1.0, "abc", None, [("sinusoid", {})], {1: {}}, {"sinusoid": 3}, {"sinusoid": "x"}, {"sinusoid": [1]}]
    if isinstance(kind, type) and issubclass(kind, ConfigMixin):  # a nested config, given as a dict of its fields
        return ["abc", 1.0, True, None, [("n_followers", 3)], [1, 2], kind.__name__]
    raise AssertionError(f"{cls.__name__}.{field}: no bad values for a field of type {kind}; add them here")


FIELDS = [(cls, field.name) for cls in CONFIG_CLASSES for field in dataclasses.fields(cls)]
NESTED_FIELDS = [(name, field.name) for name, cls in NESTED_CONFIGS.items() for field in dataclasses.fields(cls)]


def test_every_config_and_field_is_enumerated():
    names = {cls.__name__ for cls in CONFIG_CLASSES}
    assert names >= {"PlatoonConfig", "LeaderConfig", "AggressiveCyclesConfig", "SinusoidConfig", "HardBrakingConfig",
                     "StochasticHumanConfig", "HumanLeaderConfig", "SensorConfig", "MonitorConfig", "ChartConfig",
                     "RewardWeights", "DegradationConfig", "EnvConfig", "StopAndGoConfig", "EmergencyBrakingConfig"}
    assert len(FIELDS) == sum(len(dataclasses.fields(cls)) for cls in CONFIG_CLASSES)
    hints = typing.get_type_hints(EnvConfig)
    nested = {name for name, kind in hints.items() if isinstance(kind, type) and issubclass(kind, ConfigMixin)}
    assert nested == set(NESTED_CONFIGS)


@pytest.mark.parametrize(("cls", "field"), FIELDS, ids=[f"{cls.__name__}.{field}" for cls, field in FIELDS])
def test_every_field_has_bad_values(cls, field):
    assert len(bad_values(cls, field)) >= 5


@pytest.mark.parametrize(("cls", "field"), FIELDS, ids=[f"{cls.__name__}.{field}" for cls, field in FIELDS])
def test_every_field_refuses_bad_values_naming_itself(cls, field):
    for bad in bad_values(cls, field):
        with pytest.raises(ValueError) as error:
            cls().with_overrides({field: bad})
        assert f"{cls.__name__}.{field}" in str(error.value), (bad, str(error.value))


@pytest.mark.parametrize(("nested", "field"), NESTED_FIELDS, ids=[f"{n}.{f}" for n, f in NESTED_FIELDS])
def test_every_nested_field_refuses_bad_values_naming_its_path(nested, field):
    cls = NESTED_CONFIGS[nested]
    for bad in bad_values(cls, field):
        with pytest.raises(ValueError) as error:
            EnvConfig.from_dict({nested: {field: bad}})
        assert f"EnvConfig.{nested}: {cls.__name__}.{field} = " in str(error.value), (bad, str(error.value))


@pytest.mark.parametrize("config", ["abc", ["platoon"], [("platoon", {})], 3, 1.5, True, ("episode_duration", 5.0)])
def test_a_whole_config_that_is_not_a_dict_is_refused(config):
    with pytest.raises(ValueError, match=r"EnvConfig config = .*: must be a dict of EnvConfig fields"):
        EnvConfig.from_dict(config)
    with pytest.raises(ValueError, match=r"PlatoonConfig overrides = .*: must be a dict of PlatoonConfig fields"):
        PlatoonConfig().with_overrides(config)


def test_unknown_keys_of_any_type_are_named():
    with pytest.raises(ValueError, match=r"unknown EnvConfig field\(s\) \['warp', 1\]"):
        EnvConfig.from_dict({1: 2, "warp": 3})


@pytest.mark.parametrize(
    ("config", "message"),
    [  # the examples of issue 14
        ({"dropout_probability_range": 0.1}, r"EnvConfig.dropout_probability_range = 0.1: must be a pair"),
        ({"setting_levels": 1.6}, r"EnvConfig.setting_levels = 1.6: must be 2 to 100 finite settings"),
        ({"platoon": {"actuation_gain": "abc"}}, r"EnvConfig.platoon: PlatoonConfig.actuation_gain = 'abc'"),
        ({"episode_duration": 1e9}, rf"EnvConfig.episode_duration = 1000000000.0: must span at most {MAX_EPISODE_TICKS} ticks"),
        ({"monitor": {"window": 1e6}}, r"MonitorConfig.window = 1000000.0: must span at most 6000 ticks"),
        ({"platoon": {"n_followers": 1_000_000}}, r"PlatoonConfig.n_followers = 1000000: must be in \[1, 100\]"),
        ({"preferred_setting": 50}, r"EnvConfig.preferred_setting = 50: must be in \[0.6, 2.2\]"),
        ({"platoon": {"v2v": 1}}, r"PlatoonConfig.v2v = 1: must be True or False"),
        ({"random_initial_setting": 0}, r"EnvConfig.random_initial_setting = 0: must be True or False"),
        ({"platoon": {"k_s": True}}, r"PlatoonConfig.k_s = True: must be a number"),
        ({"scenario_weights": {"sinusoid": True}}, r"EnvConfig.scenario_weights = .*: weights must be finite numbers"),
        ({"degradation": {"gain_range": (True, 0.8)}}, r"DegradationConfig.gain_range = \(True, 0.8\): must be a pair"),
        ({"chart": {"switch_exceedances": 3.0}}, r"ChartConfig.switch_exceedances = 3.0: must be an integer"),
        ({"decision_interval": 1e6}, r"EnvConfig.decision_interval = 1000000.0: must span at most 1000 ticks"),
        ({"decision_interval": 20.0, "episode_duration": 10.0}, r"EnvConfig.decision_interval = 20.0: must be at most"),
        ({"monitor": {"prior_cov": "ab"}}, r"MonitorConfig.prior_cov = 'ab': must be a 2x2 matrix of numbers"),
        ("abc", r"EnvConfig config = 'abc'"),
        ([("platoon", {})], r"EnvConfig config = \[\('platoon', \{\}\)\]"),
        (3, r"EnvConfig config = 3"),
    ],
)
def test_gym_make_names_the_bad_field(config, message):
    with pytest.raises(ValueError, match=message):
        gym.make("TimeGapMonitor-v0", config=config)


def test_the_native_vector_env_refuses_a_bad_config_too():
    with pytest.raises(ValueError, match=r"PlatoonConfig.n_followers = 1000000"):
        gym.make_vec("TimeGapMonitor-v0", num_envs=2, vectorization_mode="vector_entry_point",
                     config={"platoon": {"n_followers": 1_000_000}})


def test_edge_values_and_other_spellings_of_good_values_are_accepted():
    config = EnvConfig.from_dict({
        "dropout_probability_range": [0.0, 0.0],  # low == high: a fixed dropout rate
        "setting_levels": np.array([1.0, 1.6, MAX_TIME_GAP]),
        "preferred_setting": MAX_TIME_GAP,  # the top of the ladder
        "platoon": {"n_followers": np.int64(3), "actuation_lag": [0.3, 0.4, 0.5], "k_f": 0,
                    "accel_max": np.float32(2.5)},
        "monitor": {"window": None, "prior_cov": np.array([[1e-4, 0.0], [0.0, 0.125]])},
        "chart": {"switch_exceedances": 350},  # every tick of the 35 s window
        "reward_weights": {"collision": 0},
        "scenario_weights": {"sinusoid": np.float64(2.0), "hard_braking": 0},
    })
    assert config.setting_levels == (1.0, 1.6, MAX_TIME_GAP)
    assert config.platoon.per_follower("actuation_lag").tolist() == [0.3, 0.4, 0.5]


def test_defaults_are_unchanged():
    config = EnvConfig()
    assert config == EnvConfig.from_dict({}) == EnvConfig.from_dict(None)
    assert (config.platoon.n_followers, config.platoon.dt, config.episode_duration, config.monitor.window,
            config.chart.exceedance_window, config.setting_levels, config.preferred_setting) == (
        5, 0.1, 250.0, 2.0, 35.0, (0.6, 0.8, 1.0, 1.2, 1.4, 1.6, 1.8, 2.0, 2.2), 1.6)


def largest_config() -> dict:
    """Every memory-relevant field at its upper bound, at the shortest tick."""
    levels = tuple(np.round(np.linspace(MAX_TIME_GAP / MAX_SETTING_LEVELS, MAX_TIME_GAP, MAX_SETTING_LEVELS), 9))
    return {
        "platoon": {"n_followers": MAX_FOLLOWERS, "dt": MIN_DT, "v2v_delay": 5.0, "max_v2v_latency": MAX_TIME_GAP},
        "leader": {"dt": MIN_DT},
        "monitor": {"dt": MIN_DT, "window": MAX_WINDOW_TICKS * MIN_DT},
        "chart": {"dt": MIN_DT, "exceedance_window": MAX_WINDOW_TICKS * MIN_DT},
        "episode_duration": MAX_EPISODE_TICKS * MIN_DT,
        "decision_interval": MAX_DECISION_TICKS * MIN_DT,
        "setting_levels": levels,
        "action_mode": "per_vehicle",
    }


@pytest.mark.parametrize(
    ("path", "beyond"),
    [
        (("platoon", "n_followers"), MAX_FOLLOWERS + 1),
        (("monitor", "window"), (MAX_WINDOW_TICKS + 1) * MIN_DT),
        (("chart", "exceedance_window"), (MAX_WINDOW_TICKS + 1) * MIN_DT),
        (("episode_duration",), (MAX_EPISODE_TICKS + 1) * MIN_DT),
        (("decision_interval",), (MAX_DECISION_TICKS + 1) * MIN_DT),
        (("setting_levels",), tuple(np.linspace(0.1, 2.0, MAX_SETTING_LEVELS + 1))),
    ],
)
def test_one_past_each_memory_bound_is_refused(path, beyond):
    config = largest_config()
    (config[path[0]] if len(path) == 2 else config)[path[-1]] = beyond
    with pytest.raises(ValueError, match=path[-1]):
        EnvConfig.from_dict(config)


def test_the_largest_allowed_env_builds_and_steps_in_modest_memory():
    config = largest_config()
    tracemalloc.start()
    try:
        env = gym.make("TimeGapMonitor-v0", config=config)
        built = tracemalloc.get_traced_memory()[1]
        env.reset(seed=0)
        env.step(env.action_space.sample())
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    env.close()
    unwrapped = env.unwrapped
    assert unwrapped.config.platoon.n_followers == MAX_FOLLOWERS
    assert unwrapped.config.max_episode_steps * unwrapped.config.ticks_per_decision == MAX_EPISODE_TICKS
    assert built < 100e6 and peak < 300e6, (built, peak)


def test_the_monitor_window_bound_holds_at_every_tick_length():
    for dt in (MIN_DT, 0.1, 1.0):
        assert MonitorConfig(dt=dt, window=MAX_WINDOW_TICKS * dt).window_ticks == MAX_WINDOW_TICKS
        with pytest.raises(ValueError, match=f"at most {MAX_WINDOW_TICKS} ticks"):
            MonitorConfig(dt=dt, window=(MAX_WINDOW_TICKS + 1) * dt)
    assert math.isclose(MonitorConfig(dt=0.1, window=600.0).window, 600.0)
