"""A batched reset draws, bit for bit, what resetting env after env drew.

The digests below were recorded with the per-env reset of commit 156704a (``Episodes.draw`` and
``MonitoredPlatoon.degrade`` env after env, before they were batched): every array a reset writes
(the episodes, the degradation table, the physics' and the sensors' faults), every env's fingerprint
and where each env's generator stands afterwards. The batched calls (``draw_many``, ``degrade_many``)
and the single-env ones (now the batched code with one env) must reproduce them.
"""

import hashlib
import time

import numpy as np
import pytest
from gymnasium.utils import seeding

from timegap_env.config import DEGRADATION_KINDS, EnvConfig, LeaderConfig
from timegap_env.envs.episodes import Episodes, check_reset_options
from timegap_env.envs.task import PlatoonTask
from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv
from timegap_env.leaders import default_ngsim_path, default_openacc_dir, make_leader
from timegap_env.leaders.profile import LeaderProfile
from timegap_env.monitoring.loop import MonitoredPlatoon
from timegap_env.sim.degradation import KINDS, Categorical, Degradation, DegradationTable

EPISODE_DIGESTS = {  # case -> digest after each reset, first 16 hex digits
    "default": ('1b35a2b1d0555301', '57bd67640dcf7e12',),
    "default_followers_half_random_setting": ('46911b9db78a9269', '5e87162654d6044e',),
    "kind_lag": ('1e9a2e182bba1726',),
    "kind_gain": ('3775564253f760e0',),
    "kind_v2v_latency": ('da6aca617a82c9be',),
    "kind_packet_loss": ('644597cfa86e66e4',),
    "kind_v2v_outage": ('5d9ffb404cc34595',),
    "kind_radar_bias": ('f285121ed09971de',),
    "kind_radar_noise": ('624ce37bcafc5947',),
    "kind_commercial_acc": ('f1dbd6fc1f6ad0a9',),
    "scenario_paper": ('bfe21e720fd68867', '3420a9d01f334433',),
    "scenario_aggressive_cycles": ('bfe21e720fd68867', '3420a9d01f334433',),
    "scenario_sinusoid": ('7b0ea3354252154c', 'a98373b1ab4c1c0f',),
    "scenario_hard_braking": ('75bdb9c69279dc6d', 'cc006e1e75157352',),
    "scenario_stochastic_human": ('36dfb5e249f6341a', 'c0bb3c33373103e2',),
    "scenario_stop_and_go": ('13007c965ee66e90', '35acaf45b729955b',),
    "scenario_emergency_braking": ('e9d8ed72605a9d43', '1921624a43c825a2',),
    "all_families_weighted": ('304b1aca808e7915',),
    "scenario_idm": ('f20e2eb907e817af',),
    "scenario_ngsim": ('1bed8c59882ee7f2',),
    "scenario_ngsim_in_band": ('d702d96684273d7b',),
    "scenario_openacc": ('cb87417e17920422',),
    "pinned_leader_speed": ('dba90795e96786d9',),
    "pinned_short_leader_speed": ('271ceeb11c652941',),
    "pinned_degradation_dict": ('4341332faa53a016',),
    "pinned_degradation_list": ('197dc7573f9f0762',),
    "pinned_degradation_none": ('2c11b93a3fd829e6',),
    "pinned_both": ('5080bf5160808a43',),
    "scenario_and_degradation": ('b537f80aaf1277e4',),
}
LEADER_DIGESTS = {  # leader config/family -> digest of seeds 0-39, first 16 hex digits
    "default/aggressive_cycles": "1680dbdc8a96fc5b",
    "default/sinusoid": "253f65f778bdeec4",
    "default/hard_braking": "297ca5a1e6a18a44",
    "default/stochastic_human": "b7dbac5bc15670db",
    "default/stop_and_go": "954faaad3b640f87",
    "default/emergency_braking": "12847afe1754a90b",
    "short/aggressive_cycles": "2bd53b0c60a852e9",
    "short/sinusoid": "4adb3cb95dc9dfd1",
    "short/hard_braking": "52e1cd07c97fc05e",
    "short/stochastic_human": "bab89ef6105e8594",
    "short/stop_and_go": "1bbf4e656412a9ca",
    "short/emergency_braking": "667efe35d07a504b",
    "fine/aggressive_cycles": "d2c7e8f78ac107f6",
    "fine/sinusoid": "20b4fde148345fdb",
    "fine/hard_braking": "0316b4906b1a8f73",
    "fine/stochastic_human": "196075ee3c445867",
    "fine/stop_and_go": "d44e1a9c73ae2f0d",
    "fine/emergency_braking": "8c22f6884a61e4cf",
    "narrow/aggressive_cycles": "8702bb201227184e",
    "narrow/sinusoid": "f563931c38351198",
    "narrow/hard_braking": "cba9dbd442061f56",
    "narrow/stochastic_human": "a57f410ed463ddf5",
    "narrow/stop_and_go": "750bd1b4b4432b0c",
    "narrow/emergency_braking": "fc3db8b63bbcfe1a",
    "from_acceleration": "033cc5475e4ae65c",
}

TABLE_FIELDS = ("kind", "size", "start", "end", "lag", "gain", "k_s", "k_v", "accel_max", "extra_delay",
                "packet_loss", "radar_bias", "radar_noise", "v2v_down")
FAULT_FIELDS = ("start", "end", "k_s", "k_v", "accel_max", "extra_delay", "packet_loss", "radar_bias", "keys")
SPEED = 20.0 + 3.0 * np.sin(np.arange(1234) * 0.01)  # a user's leader [m/s]


def one_kind(kind: str, **overrides: float) -> EnvConfig:
    """A config whose degradation is always ``kind``."""
    weights = {"none": 0.0, **{k: float(k == kind) for k in DEGRADATION_KINDS}}
    return EnvConfig.from_dict({"degradation": {"kind_weights": weights, **overrides}})


def cases() -> dict[str, tuple[EnvConfig, int, int, dict | None, int]]:
    """name -> (config, n_envs, first seed, reset options, resets)."""
    default = EnvConfig()
    found = {
        "default": (default, 64, 0, None, 2),
        "default_followers_half_random_setting": (EnvConfig.from_dict(
            {"degradation": {"follower_probability": 0.5}, "random_initial_setting": True}), 48, 100, None, 2),
        **{f"kind_{kind}": (one_kind(kind, follower_probability=0.4), 24, 1000, None, 1) for kind in DEGRADATION_KINDS},
        **{f"scenario_{name}": (default, 24, 2000, {"scenario": name}, 2) for name in (
            "paper", "aggressive_cycles", "sinusoid", "hard_braking", "stochastic_human", "stop_and_go",
            "emergency_braking")},
        "all_families_weighted": (EnvConfig.from_dict({"scenario_weights": {
            "aggressive_cycles": 1.0, "sinusoid": 2.0, "hard_braking": 1.0, "stochastic_human": 3.0,
            "stop_and_go": 1.0, "emergency_braking": 1.0}}), 40, 3000, None, 1),
        "scenario_idm": (default, 2, 4000, {"scenario": "idm"}, 1),
        "scenario_ngsim": (default, 3, 4100, {"scenario": "ngsim"}, 1),
        "scenario_ngsim_in_band": (default, 3, 4200, {"scenario": "ngsim_in_band"}, 1),
        "scenario_openacc": (default, 3, 4300, {"scenario": "openacc"}, 1),
        "pinned_leader_speed": (default, 8, 5000, {"leader_speed": SPEED}, 1),
        "pinned_short_leader_speed": (default, 4, 5100, {"leader_speed": SPEED[:77]}, 1),
        "pinned_degradation_dict": (default, 8, 6000, {"degradation": {
            "kind": "gain", "size": 0.7, "followers": [2, 4], "onset": 12.3, "end": 50.0}}, 1),
        "pinned_degradation_list": (default, 8, 6100, {"degradation": [
            {"kind": "lag", "size": 2.0, "followers": [1]}, {"kind": "commercial_acc", "followers": [3]},
            {"kind": "v2v_latency", "size": 0.3, "followers": [5]}]}, 1),
        "pinned_degradation_none": (default, 8, 6200, {"degradation": None}, 1),
        "pinned_both": (default, 4, 6300, {"leader_speed": SPEED, "degradation": {"kind": "radar_bias", "size": -2.0}}, 1),
        "scenario_and_degradation": (default, 6, 6400, {
            "scenario": "stochastic_human", "degradation": {"kind": "packet_loss", "size": 0.5}}, 1),
    }
    assert set(found) == set(EPISODE_DIGESTS)
    return found


def batched_reset(episodes: Episodes, loop: MonitoredPlatoon, envs: np.ndarray, rngs: list, options: dict) -> None:
    episodes.draw_many(envs, rngs, options)
    loop.degrade_many(envs, [episodes.degradations[env] for env in envs], episodes.packet_loss_keys[envs])


def per_env_reset(episodes: Episodes, loop: MonitoredPlatoon, envs: np.ndarray, rngs: list, options: dict) -> None:
    for env in envs:
        episodes.draw(env, rngs[env], options)
        loop.degrade(env, episodes.degradations[env], episodes.packet_loss_keys[env])


def arrays(episodes: Episodes, loop: MonitoredPlatoon, rngs: list) -> list:
    """Everything a reset writes, in a fixed order: arrays, and reprs of what is not one."""
    table, faults = loop.degradation, loop.platoon.faults
    table.truth(np.zeros(len(rngs), dtype=np.int64), np.ones(table.kind.shape, dtype=bool))  # works out the fixed
    # parts of the ground truth, which a reset leaves until it is asked for
    return [
        *(episodes.fingerprint(env) for env in range(len(rngs))),
        episodes.leader_speed, episodes.leader_accel, episodes.episode_ticks, episodes.dropout_probability,
        episodes.initial_setting, episodes.noise_keys, episodes.packet_loss_keys,
        repr(list(episodes.scenario)), repr(episodes.degradations),
        *(recorded_form(table, name) for name in TABLE_FIELDS), repr(table.descriptions),
        *(table._reported[name] for name in ("size", "onset", "end")), table._while_active, table._otherwise,
        *(getattr(faults, name) for name in FAULT_FIELDS), *faults.dynamics, *loop.sensors.faults,
        *(repr(rng.bit_generator.state) for rng in rngs),  # an unseeded reset carries on from there
    ]


def recorded_form(table: DegradationTable, name: str) -> np.ndarray:
    """The table's array ``name`` as 156704a held it: its radar noise was NaN where no radar_noise degradation set it
    (the table now holds the sensors' nominal noise there, as every lever holds its nominal value)."""
    if name != "radar_noise":
        return getattr(table, name)
    return np.where(table.kind == KINDS.index("radar_noise"), table.radar_noise, np.nan)


def digest(items: list) -> str:
    sha = hashlib.sha256()
    for item in items:
        sha.update(item.encode() if isinstance(item, str) else np.ascontiguousarray(item).tobytes())
    return sha.hexdigest()[:16]


def run(reset, config: EnvConfig, n_envs: int, seed: int, options: dict | None, resets: int) -> list[list]:
    """``resets`` resets (every env, then every other one, their generators carrying on): the arrays after each."""
    episodes = Episodes(config, n_envs)
    loop = MonitoredPlatoon(config.platoon, config.monitor, config.chart, config.sensors, n_envs)
    rngs = [np.random.default_rng(seed + i) for i in range(n_envs)]
    envs = np.arange(n_envs)
    after = []
    for r in range(resets):
        reset(episodes, loop, envs if r == 0 else envs[::2], rngs, check_reset_options(options))
        after.append([np.copy(item) if isinstance(item, np.ndarray) else item for item in arrays(episodes, loop, rngs)])
    return after


def needs_data(name: str) -> list:
    """Marks of a golden case: slow, or skipped without its data."""
    if name in ("scenario_ngsim", "scenario_ngsim_in_band") and not default_ngsim_path().exists():
        return [pytest.mark.skip(reason=f"NGSIM data absent at {default_ngsim_path()}")]
    if name == "scenario_openacc":
        absent = not default_openacc_dir().exists()
        return [pytest.mark.slow] + ([pytest.mark.skip(reason="OpenACC data absent")] if absent else [])
    return [pytest.mark.slow] if name == "scenario_idm" else []


@pytest.mark.parametrize("name", [pytest.param(name, marks=needs_data(name)) for name in EPISODE_DIGESTS])
@pytest.mark.parametrize("reset", [batched_reset, per_env_reset])
def test_a_reset_draws_what_the_per_env_reset_drew(name, reset):
    after = run(reset, *cases()[name])
    assert tuple(digest(items) for items in after) == EPISODE_DIGESTS[name]


def test_batched_and_per_env_resets_agree_array_by_array():
    for config in (EnvConfig.from_dict({"degradation": {"kind_weights": {k: 1.0 for k in ("none", *DEGRADATION_KINDS)},
                                                        "follower_probability": 0.5}, "random_initial_setting": True}),
                   one_kind("commercial_acc"), one_kind("v2v_outage", midway_onset_probability=1.0)):
        batched, per_env = run(batched_reset, config, 150, 77, None, 2), run(per_env_reset, config, 150, 77, None, 2)
        for after_batched, after_per_env in zip(batched, per_env, strict=True):
            for a, b in zip(after_batched, after_per_env, strict=True):
                np.testing.assert_array_equal(a, b)


def test_leaders_are_what_they_were():
    configs = {"default": LeaderConfig(), "short": LeaderConfig(duration=30.0),
               "fine": LeaderConfig(dt=0.05, duration=80.0, initial_speed=30.0),
               "narrow": LeaderConfig(duration=120.0, speed_band=(15.0, 25.0), initial_speed=15.0)}
    for key, expected in LEADER_DIGESTS.items():
        if key == "from_acceleration":
            profiles = [LeaderProfile.from_acceleration(np.random.default_rng(k).normal(0, 3, 500), LeaderConfig(duration=50.0))
                        for k in range(20)]
            found = digest([array for p in profiles for array in (p.speed, p.accel)])
        else:
            config, family = key.split("/")
            profiles = [make_leader(family, seed, configs[config]) for seed in range(40)]
            found = digest([item for p in profiles for item in (p.speed, p.accel, repr((p.dt, p.name)))])
        assert found == expected, key


@pytest.mark.parametrize("weights", [(1.0, 1.0, 1.0, 1.0), (4.0, 1.0, 0.0, 1.0, 4.0, 1e-3), (0.0, 2.0), (3.0,)])
def test_categorical_draws_what_choice_draws(weights):
    categorical, p = Categorical(weights), np.array(weights) / np.sum(weights)
    for seed in range(3000):
        ours, numpy = np.random.default_rng(seed), np.random.default_rng(seed)
        assert categorical.draw(ours) == numpy.choice(len(weights), p=p)
        assert ours.bit_generator.state == numpy.bit_generator.state


def test_a_follower_hit_twice_is_refused():
    table = DegradationTable(EnvConfig().platoon, 2)
    twice = (Degradation("gain", (1, 2), size=0.7), Degradation("lag", (2,), size=2.0))
    with pytest.raises(ValueError, match="more than once"):
        table.set_many(np.array([0, 1]), [(), twice])
    with pytest.raises(ValueError, match="each env may be set once"):
        table.set_many(np.array([1, 1]), [(), ()])


def reset_env_by_env(original):
    """``PlatoonTask.reset`` drawing and degrading one env after another (``Episodes.draw``,
    ``MonitoredPlatoon.degrade``), as it did before its batched calls; the rest of the reset as it is."""

    def reset(task: PlatoonTask, mask: np.ndarray, rngs: list, options: dict | None) -> None:
        episodes, loop = task.episodes, task.loop
        for env in np.flatnonzero(mask):
            episodes.draw(env, rngs[env], check_reset_options(options))
            loop.degrade(env, episodes.degradations[env], episodes.packet_loss_keys[env])
        episodes.draw_many, loop.degrade_many = (lambda *args: None), (lambda *args: None)
        try:
            original(task, mask, rngs, options)
        finally:
            del episodes.draw_many, loop.degrade_many

    return reset


def assert_same(a, b) -> None:
    """``a`` and ``b`` equal all the way down (dicts, sequences, arrays, NaN equal to NaN)."""
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            assert_same(a[key], b[key])
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            assert_same(x, y)
    elif isinstance(a, np.ndarray) and a.dtype == object:
        assert a.shape == b.shape
        for x, y in zip(a.ravel(), b.ravel()):
            assert_same(x, y)
    else:
        np.testing.assert_array_equal(a, b)


def test_the_env_runs_the_same_after_a_batched_reset(monkeypatch):
    def episode(env: TimeGapMonitorVectorEnv) -> list:
        out = [env.reset(seed=11)]
        env.action_space.seed(5)
        for _ in range(3):
            out.append(env.step(env.action_space.sample()))
        out.append(env.reset(options={"reset_mask": np.arange(env.num_envs) % 2 == 0}))  # generators carry on
        out.append(env.step(env.action_space.sample()))
        return out

    config = {"degradation": {"follower_probability": 0.6}, "random_initial_setting": True}
    batched = episode(TimeGapMonitorVectorEnv(num_envs=12, config=config))
    monkeypatch.setattr(PlatoonTask, "reset", reset_env_by_env(PlatoonTask.reset))
    per_env = episode(TimeGapMonitorVectorEnv(num_envs=12, config=config))
    assert_same(batched, per_env)


@pytest.mark.slow
def test_a_batched_reset_is_faster_than_env_by_env():
    n_envs = 2048
    config = EnvConfig()
    episodes, loop = Episodes(config, n_envs), MonitoredPlatoon(config.platoon, n_envs=n_envs)
    envs = np.arange(n_envs)
    times = {}
    for reset in (per_env_reset, batched_reset):
        rngs = [seeding.np_random(i)[0] for i in range(n_envs)]
        start = time.perf_counter()
        reset(episodes, loop, envs, rngs, {})
        times[reset.__name__] = time.perf_counter() - start
    assert times["batched_reset"] < 0.6 * times["per_env_reset"], times
