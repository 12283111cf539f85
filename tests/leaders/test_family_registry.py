"""A leader family is one record (issue 23, item 3): ``register_family`` adds it, and every way to a leader reaches
it (``scenario_weights``, ``reset(options={"scenario": ...})``, ``leader_params``, ``simulate``, a vector env); bad
records are refused naming the field; the built-in families build what their functions build."""

import dataclasses
import os
import subprocess
import sys
import textwrap

import gymnasium as gym
import numpy as np
import pytest

import timegap_env
from timegap_env.config import (
    AggressiveCyclesConfig, ConfigMixin, HardBrakingConfig, LeaderConfig, SinusoidConfig, StochasticHumanConfig,
)
from timegap_env.leaders import idm, scenarios, synthetic
from timegap_env.leaders.profile import LeaderProfile, LeaderProfiles
from timegap_env.leaders.scenarios import LEADER_FAMILIES, SCENARIOS, LeaderFamily, make_leader, register_family


@dataclasses.dataclass(frozen=True)
class WavesConfig(ConfigMixin):
    mean_speed: float = 22.0  # [m/s]
    amplitude: float = 3.0  # [m/s]


def waves(seed: int | None, params: WavesConfig, leader: LeaderConfig) -> LeaderProfile:
    period = np.random.default_rng(seed).uniform(40.0, 80.0)  # [s]
    t = np.arange(leader.n_samples) * leader.dt
    return LeaderProfile.from_speed(params.mean_speed + params.amplitude * np.sin(2 * np.pi * t / period),
                                    dt=leader.dt, name="waves")


def waves_batch(seeds: list[int | None], params: WavesConfig, leader: LeaderConfig) -> LeaderProfiles:
    profiles = [waves(seed, params, leader) for seed in seeds]
    return LeaderProfiles(speed=np.stack([p.speed for p in profiles]), accel=np.stack([p.accel for p in profiles]),
                          dt=leader.dt, name="waves")


def constant(seed: int | None, params: None, leader: LeaderConfig) -> LeaderProfile:
    return LeaderProfile.from_speed(np.full(leader.n_samples, 20.0), dt=leader.dt, name="constant")


@pytest.fixture(autouse=True)
def registry():
    """Each test registers what it needs; the registry is put back afterwards."""
    saved = dict(LEADER_FAMILIES)
    yield
    LEADER_FAMILIES.clear()
    LEADER_FAMILIES.update(saved)


def episode_speed(env: gym.Env) -> np.ndarray:
    episodes = env.unwrapped.task.episodes
    return episodes.leader_speed[0, : episodes.episode_ticks[0] + 1].copy()


def leader_seed(reset_seed: int) -> int:
    """The leader's seed a reset with ``options={"scenario": ...}`` draws (nothing drawn before it)."""
    return int(np.random.default_rng(reset_seed).integers(2**31))


def test_a_registered_family_is_drawn_picked_parametrised_and_simulated():
    register_family(LeaderFamily("waves", waves, "Slow speed waves.", WavesConfig))
    assert SCENARIOS["waves"] == scenarios.Scenario("waves", "waves", "Slow speed waves.")
    drawn = gym.make("TimeGapMonitor-v0", config={"scenario_weights": {"waves": 1.0}, "episode_duration": 30})
    drawn.reset(seed=1)
    assert drawn.unwrapped.scenario == "waves"

    env = gym.make("TimeGapMonitor-v0", config={"episode_duration": 30})
    env.reset(seed=2, options={"scenario": "waves"})
    leader = env.unwrapped.config.leader
    assert np.array_equal(episode_speed(env), waves(leader_seed(2), WavesConfig(), leader).speed)

    faster = gym.make("TimeGapMonitor-v0", config={"episode_duration": 30,
                                                   "leader_params": {"waves": {"mean_speed": 30.0}}})
    faster.reset(seed=2, options={"scenario": "waves"})
    assert np.array_equal(episode_speed(faster), waves(leader_seed(2), WavesConfig(mean_speed=30.0), leader).speed)

    trajectory = timegap_env.simulate("waves", seed=3)
    assert trajectory.leader_name == "waves" and trajectory.collision is None
    np.testing.assert_array_equal(trajectory.v[:, 0], waves(3, WavesConfig(), LeaderConfig()).speed)


def test_a_vector_env_builds_a_registered_family_by_its_batch_or_seed_by_seed():
    register_family(LeaderFamily("waves", waves, "Slow speed waves.", WavesConfig, waves_batch))
    register_family(LeaderFamily("waves_one_by_one", waves, "The same, without a batch builder.", WavesConfig))
    speeds = []
    for name in ("waves", "waves_one_by_one"):
        envs = gym.make_vec("TimeGapMonitor-v0", num_envs=3, vectorization_mode="vector_entry_point",
                            config={"scenario_weights": {name: 1.0}, "episode_duration": 30})
        envs.reset(seed=4)
        episodes = envs.unwrapped.task.episodes
        assert list(episodes.scenario) == ["waves"] * 3  # the profiles' name
        speeds.append(episodes.leader_speed.copy())
        envs.close()
    assert np.array_equal(*speeds)


def test_a_family_registered_again_is_built_with_its_own_defaults():
    register_family(LeaderFamily("waves", waves, "Slow speed waves.", WavesConfig))
    env = gym.make("TimeGapMonitor-v0", config={"episode_duration": 30})
    env.reset(seed=2, options={"scenario": "waves"})

    @dataclasses.dataclass(frozen=True)
    class FasterWaves(WavesConfig):
        mean_speed: float = 28.0  # [m/s]

    register_family(LeaderFamily("waves", waves, "Faster waves.", FasterWaves), replace=True)
    env.reset(seed=2, options={"scenario": "waves"})
    leader = env.unwrapped.config.leader
    assert np.array_equal(episode_speed(env), waves(leader_seed(2), FasterWaves(), leader).speed)
    register_family(LeaderFamily("waves", constant, "20 m/s, without parameters."), replace=True)
    env.reset(seed=2, options={"scenario": "waves"})
    assert np.all(episode_speed(env) == 20.0)


def test_a_family_without_parameters_takes_none():
    register_family(LeaderFamily("constant", constant, "20 m/s throughout."))
    assert make_leader("constant", 0).speed.max() == 20.0
    with pytest.raises(ValueError, match="EnvConfig.leader_params has family 'constant': the families with parameters"):
        gym.make("TimeGapMonitor-v0", config={"leader_params": {"constant": {}}})
    with pytest.raises(ValueError, match=r"params = SinusoidConfig\(.*\): scenario 'constant' takes no parameters"):
        make_leader("constant", 0, params=SinusoidConfig())
    with pytest.raises(ValueError, match=r"params = SinusoidConfig\(.*\): scenario 'paper' takes a AggressiveCycles"):
        make_leader("paper", 0, params=SinusoidConfig())


def test_an_unregistered_family_is_unknown_to_the_env():
    with pytest.raises(ValueError, match=r"EnvConfig.scenario_weights has unknown families \['waves'\]"):
        gym.make("TimeGapMonitor-v0", config={"scenario_weights": {"waves": 1.0}})


@pytest.mark.parametrize(
    "fields, message",
    [
        ({"name": ""}, "LeaderFamily.name = '': must be a non-empty str"),
        ({"name": 3}, "LeaderFamily.name = 3: must be a non-empty str"),
        ({"build": "waves"}, "LeaderFamily.build = 'waves': must be callable"),
        ({"description": None}, "LeaderFamily.description = None: must be a str"),
        ({"params": WavesConfig()}, r"LeaderFamily.params = WavesConfig\(mean_speed=22.0, amplitude=3.0\): must be"),
        ({"params": dict}, "LeaderFamily.params = <class 'dict'>: must be None .* subclassing .*ConfigMixin"),
        ({"params": dataclasses.make_dataclass("Plain", [("x", float, 1.0)])}, "LeaderFamily.params = <class "),
        ({"batch": 3}, "LeaderFamily.batch = 3: must be None or callable"),
    ],
)
def test_an_invalid_record_is_refused_naming_its_field(fields, message):
    record = {"name": "waves", "build": waves, "description": "Slow speed waves.", "params": WavesConfig} | fields
    with pytest.raises(ValueError, match=message):
        LeaderFamily(**record)


def test_a_name_is_registered_once_unless_replaced():
    with pytest.raises(ValueError, match="LeaderFamily.name = 'sinusoid': a leader family already; .*replace=True"):
        register_family(LeaderFamily("sinusoid", waves, "Slow speed waves.", WavesConfig))
    with pytest.raises(ValueError, match="LeaderFamily.name = 'paper': a scenario name already"):
        register_family(LeaderFamily("paper", waves, "Slow speed waves.", WavesConfig), replace=True)
    with pytest.raises(ValueError, match="register_family: family = <function waves .*> must be a LeaderFamily"):
        register_family(waves)
    register_family(LeaderFamily("sinusoid", constant, "Constant now."), replace=True)
    assert make_leader("sinusoid", 0).name == "constant" and SCENARIOS["sinusoid"].description == "Constant now."
    assert sorted(SCENARIOS) == sorted(["paper", *LEADER_FAMILIES])


def test_a_registration_lives_in_its_process_and_a_module_prefix_imports_it(tmp_path):
    (tmp_path / "my_leaders.py").write_text(textwrap.dedent("""
        import numpy as np
        from timegap_env.config import LeaderConfig
        from timegap_env.leaders import LeaderFamily, LeaderProfile, register_family

        def constant(seed: int | None, params: None, leader: LeaderConfig) -> LeaderProfile:
            return LeaderProfile.from_speed(np.full(leader.n_samples, 20.0), dt=leader.dt, name="constant")

        register_family(LeaderFamily("constant", constant, "20 m/s throughout."))
    """))
    code = ("import gymnasium as gym; env = gym.make('my_leaders:TimeGapMonitor-v0', "
            "config={'scenario_weights': {'constant': 1.0}}); env.reset(seed=0); print(env.unwrapped.scenario)")
    environ = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), *sys.path])}
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=environ, timeout=300)
    assert run.returncode == 0 and run.stdout.strip() == "constant", run.stderr[-2000:]
    assert "constant" not in SCENARIOS


SYNTHETIC = {  # family -> its function, batch function and parameter dataclass in timegap_env.leaders.synthetic
    "aggressive_cycles": (synthetic.aggressive_cycles, synthetic.aggressive_cycles_batch, AggressiveCyclesConfig),
    "sinusoid": (synthetic.sinusoid, synthetic.sinusoid_batch, SinusoidConfig),
    "hard_braking": (synthetic.hard_braking, synthetic.hard_braking_batch, HardBrakingConfig),
    "stochastic_human": (synthetic.stochastic_human, synthetic.stochastic_human_batch, StochasticHumanConfig),
    "stop_and_go": (synthetic.stop_and_go, synthetic.stop_and_go_batch, synthetic.StopAndGoConfig),
    "emergency_braking": (synthetic.emergency_braking, synthetic.emergency_braking_batch,
                          synthetic.EmergencyBrakingConfig),
}
SEEDS = [0, 1, 7, 2**31 - 1]
LEADERS = [LeaderConfig(), LeaderConfig(duration=3.3), LeaderConfig(dt=0.5, duration=40.0)]


@pytest.mark.parametrize("leader", LEADERS, ids=lambda leader: f"{leader.duration:g}s@{leader.dt:g}s")
@pytest.mark.parametrize("family", SYNTHETIC)
def test_a_built_in_family_builds_what_its_functions_build(family, leader):
    single, batch, params = SYNTHETIC[family]
    assert LEADER_FAMILIES[family].params is params
    for seed in SEEDS:
        expected = single(seed, params(), leader)
        profile = make_leader(family, seed, leader)
        assert np.array_equal(profile.speed, expected.speed) and np.array_equal(profile.accel, expected.accel)
    [profiles] = scenarios.make_leaders(family, SEEDS, leader)
    expected_batch = batch(SEEDS, params(), leader)
    assert np.array_equal(profiles.speed, expected_batch.speed) and np.array_equal(profiles.accel, expected_batch.accel)


def test_paper_and_idm_build_what_their_functions_build():
    for seed in SEEDS[:2]:
        assert np.array_equal(make_leader("paper", seed).speed, synthetic.aggressive_cycles(seed).speed)
        expected = idm.idm_leader(synthetic.hard_braking(seed), seed=seed)
        assert np.array_equal(make_leader("idm", seed).speed, expected.speed)
    assert scenarios.get_scenario("paper").leader_family == "aggressive_cycles"
