"""A run is loaded as it was trained or not at all (issue 22, items 2, 8 and 14): env.json and vecnormalize.pkl must be
there and agree with the model, statistics must be finite, and loading puts torch on one thread."""

from __future__ import annotations

import json
import pickle
import shutil
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import torch
from gymnasium import spaces

from timegap_env.agents.learned import LearnedPolicy, RunFileError, load_vecnormalize
from timegap_env.agents.protocol import ENV_FILE, MODEL_FILE, VECNORMALIZE_FILE, read_env_file
from timegap_env.agents.rllib_policy import CHECKPOINT_MARKER, MODULE_PATH, RLlibPolicy

COMMITTED = Path(__file__).resolve().parents[2] / "results" / "v0" / "ppo"  # relative mode: Discrete(3), normalised


@pytest.fixture
def run(tmp_path: Path) -> Path:
    """A copy of the committed run's model, statistics and env.json."""
    for name in (MODEL_FILE, VECNORMALIZE_FILE, ENV_FILE):
        shutil.copy(COMMITTED / name, tmp_path / name)
    return tmp_path


def env_file(run: Path, **changes: object) -> None:
    """Rewrite ``run``'s env.json with ``changes`` (None: the key removed)."""
    content = json.loads((run / ENV_FILE).read_text())
    content.update(changes)
    (run / ENV_FILE).write_text(json.dumps({key: value for key, value in content.items() if value is not None}))


def test_the_committed_run_loads_as_it_was_trained(run: Path) -> None:
    policy = LearnedPolicy.load(run)
    assert policy.action_mode == "relative" and policy.normalizer is not None and policy.frame_stack == 1
    # written before train_ppo recorded normalize (left so, as the committed sweep's piece keys hash its bytes):
    # the statistics beside it say the run normalised
    assert read_env_file(COMMITTED / ENV_FILE).normalize is None


def test_a_run_trained_on_the_raw_gap_reads_it_again(run: Path) -> None:
    assert LearnedPolicy.load(run).monitor_estimator == "bayes"
    env_file(run, env_kwargs={"config": {"action_mode": "relative", "monitor": {"estimator": "raw_gap"}}})
    policy = LearnedPolicy.load(run)
    assert policy.monitor_estimator == "raw_gap" and "monitor_estimator='raw_gap'" in repr(policy)


def test_a_run_without_env_json_is_refused_not_read_as_platoon_mode(run: Path) -> None:
    (run / ENV_FILE).unlink()
    with pytest.raises(RunFileError, match=f"{run / ENV_FILE}: missing"):
        LearnedPolicy.load(run)


def test_env_json_naming_another_discrete_mode_is_refused(run: Path) -> None:
    # the relative model's actions 0-2 would be read as the ladder's 0.6-1.0 s
    env_file(run, env_kwargs={"config": {"action_mode": "platoon"}})
    with pytest.raises(RunFileError, match=r"env.json does not fit the model .*model.zip: its env \(action_mode = "
                                           r"'platoon'\) has actions Discrete\(9\), the model Discrete\(3\)"):
        LearnedPolicy.load(run)
    env_file(run, env_kwargs={})  # the default config is platoon mode too
    with pytest.raises(RunFileError, match="Discrete"):
        LearnedPolicy.load(run)
    env_file(run, env_kwargs={"config": {"action_mode": "relative", "platoon": {"n_followers": 4}}})
    with pytest.raises(RunFileError, match=r"observations of shape \(36,\)"):
        LearnedPolicy.load(run)
    env_file(run, env_kwargs={"config": {"action_mode": "relative", "bogus": 1}})
    with pytest.raises(RunFileError, match="env.json: env_kwargs.config is not a config of this env: .*bogus"):
        LearnedPolicy.load(run)


def test_missing_statistics_are_an_error_unless_the_run_says_it_did_not_normalise(run: Path) -> None:
    (run / VECNORMALIZE_FILE).rename(run / "elsewhere.pkl")
    with pytest.raises(RunFileError, match=f"{run / VECNORMALIZE_FILE}: missing; .*env.json does not say whether"):
        LearnedPolicy.load(run)  # the committed env.json, as train_ppo wrote it before the field
    env_file(run, normalize=True)
    with pytest.raises(RunFileError, match=f"{run / VECNORMALIZE_FILE}: missing; .*says the run normalised"):
        LearnedPolicy.load(run)
    assert LearnedPolicy.load(run, vecnormalize=run / "elsewhere.pkl").normalizer is not None  # given explicitly
    env_file(run, normalize=False)
    assert LearnedPolicy.load(run).normalizer is None  # a run trained without VecNormalize
    (run / "elsewhere.pkl").rename(run / VECNORMALIZE_FILE)
    with pytest.raises(RunFileError, match=f"{run / VECNORMALIZE_FILE}: present, but .*normalize: false"):
        LearnedPolicy.load(run)
    env_file(run, normalize="yes")
    with pytest.raises(RunFileError, match="env.json: normalize = 'yes'"):
        LearnedPolicy.load(run)


@pytest.mark.parametrize("field, value, message", [
    ("obs_rms.mean", np.nan, r"obs_rms.mean = \[nan\] at entries \[3\]: must be finite"),
    ("obs_rms.var", -1.0, r"obs_rms.var = \[-1.0\] at entries \[3\]: must be finite and >= 0"),
    ("obs_rms.var", np.inf, r"obs_rms.var = \[inf\] at entries \[3\]"),
    ("clip_obs", np.nan, r"clip_obs = nan: must be finite and > 0"),
])
def test_statistics_that_would_turn_observations_into_nan_are_refused_at_load(
        run: Path, field: str, value: float, message: str) -> None:
    with open(run / VECNORMALIZE_FILE, "rb") as file:
        saved = pickle.load(file)
    if field == "clip_obs":
        saved.clip_obs = value
    else:
        getattr(saved.obs_rms, field.split(".")[1])[3] = value
    saved.venv, saved.class_attributes, saved.returns = None, {}, None  # what its pickling drops, absent after a load
    with open(run / VECNORMALIZE_FILE, "wb") as file:
        pickle.dump(saved, file)
    with pytest.raises(RunFileError, match=f"vecnormalize = '{run / VECNORMALIZE_FILE}': {message}"):
        load_vecnormalize(run / VECNORMALIZE_FILE)
    with pytest.raises(RunFileError, match=message):
        LearnedPolicy.load(run)


def test_statistics_whose_mean_and_var_differ_in_shape_are_refused_at_load(run: Path) -> None:
    with open(run / VECNORMALIZE_FILE, "rb") as file:
        saved = pickle.load(file)
    saved.obs_rms.var = saved.obs_rms.var[:27]
    saved.venv, saved.class_attributes, saved.returns = None, {}, None
    with open(run / VECNORMALIZE_FILE, "wb") as file:
        pickle.dump(saved, file)
    with pytest.raises(RunFileError, match=r"obs_rms.mean has shape \(45,\), its var \(27,\): they must match"):
        LearnedPolicy.load(run)


def test_loading_puts_torch_on_one_thread(run: Path) -> None:
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        LearnedPolicy.load(run, threads=None)
        assert torch.get_num_threads() == 2
        LearnedPolicy.load(run)
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)


class FakeModule:
    """What RLlibPolicy reads of an RLModule."""

    def __init__(self, action_space: spaces.Space, width: int = 45) -> None:
        self.action_space = action_space
        self.observation_space = spaces.Box(-1.0, 1.0, (width,), np.float32)

    def eval(self) -> None:
        pass

    def get_inference_action_dist_cls(self) -> None:
        return None

    def get_exploration_action_dist_cls(self) -> None:
        return None


def rllib_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, module: FakeModule, env: dict) -> Path:
    """A checkpoint directory with ``env`` as env.json whose RLModule loads as ``module`` (Ray stubbed out)."""
    checkpoint = tmp_path / "checkpoint"
    checkpoint.joinpath(*MODULE_PATH).mkdir(parents=True)
    (checkpoint / CHECKPOINT_MARKER).write_text("{}")
    (checkpoint / ENV_FILE).write_text(json.dumps(env))
    rl_module = types.ModuleType("ray.rllib.core.rl_module.rl_module")
    rl_module.RLModule = types.SimpleNamespace(from_checkpoint=lambda path: module)
    for name in ("ray", "ray.rllib", "ray.rllib.core", "ray.rllib.core.rl_module"):
        monkeypatch.setitem(sys.modules, name, types.ModuleType(name))
    monkeypatch.setitem(sys.modules, "ray.rllib.core.rl_module.rl_module", rl_module)
    return checkpoint


def test_an_rllib_run_is_checked_against_its_env_json(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    relative = {"env_kwargs": {"config": {"action_mode": "relative"}}, "frame_stack": 1}
    assert RLlibPolicy.load(rllib_run(tmp_path / "a", monkeypatch, FakeModule(spaces.Discrete(3)), relative)
                            ).action_mode == "relative"
    platoon = {"env_kwargs": {"config": {"action_mode": "platoon"}}, "frame_stack": 1}
    checkpoint = rllib_run(tmp_path / "b", monkeypatch, FakeModule(spaces.Discrete(3)), platoon)
    with pytest.raises(RunFileError, match=r"env.json does not fit the model .*has actions Discrete\(9\), the model "
                                           r"Discrete\(3\)"):
        RLlibPolicy.load(checkpoint)
    checkpoint = rllib_run(tmp_path / "c", monkeypatch, FakeModule(spaces.Discrete(3), width=36), relative)
    with pytest.raises(RunFileError, match=r"it takes \(36,\)"):
        RLlibPolicy.load(checkpoint)
    checkpoint = rllib_run(tmp_path / "d", monkeypatch, FakeModule(spaces.Discrete(3)), {**relative, "normalize": True})
    with pytest.raises(RunFileError, match="normalize = True: an RLlib run is read with neither"):
        RLlibPolicy.load(checkpoint)
