"""Fuzz of a trained run's files (issue 22, items 1-2): the committed run (``results/v0/ppo``: ``model.zip``,
``vecnormalize.pkl``, ``env.json``) copied to a temporary directory and corrupted.

``timegap_env.agents.learned.LearnedPolicy.load`` must raise ``timegap_env.agents.learned.RunFileError`` (or ``FileNotFoundError`` for a
missing file) whose message names the file at fault, never load silently: a missing or inconsistent ``env.json``
(another action mode, another platoon, another frame stack, not JSON, not the run's format), a missing, corrupt or
non-finite ``vecnormalize.pkl`` (NaN mean, inf or negative variance, statistics of another shape), a truncated,
empty or foreign ``model.zip``, a directory where a file should be. A model whose bytes were flipped may load only
if it predicts exactly as the intact one (the flip hit nothing that matters).
"""

from __future__ import annotations

import io
import json
import pickle
import shutil
import tempfile
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import timegap_env  # noqa: F401 - registers the env
from tests.fuzz.fuzzing import ENV_ID, Defects, call, fuzz_settings, short

torch = pytest.importorskip("torch")
learned = pytest.importorskip("timegap_env.agents.learned")
LearnedPolicy, RunFileError = learned.LearnedPolicy, learned.RunFileError

RUN = Path(__file__).resolve().parents[2] / "results" / "v0" / "ppo"
MODEL, STATS, ENV = "model.zip", "vecnormalize.pkl", "env.json"


@pytest.fixture(scope="module", autouse=True)
def one_thread():
    """Torch on one thread while these tests run (a shared 2-core machine)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture(scope="module")
def observations() -> np.ndarray:
    """Observations of the env the committed run was trained in, a few steps of an episode."""
    if not (RUN / MODEL).is_file():
        pytest.skip(f"no committed run at {RUN}")
    kwargs = json.loads((RUN / ENV).read_text())["env_kwargs"]
    env = gym.make(ENV_ID, **kwargs)
    obs, _ = env.reset(seed=0)
    rows = [obs]
    for action in [0, 1, 2, 1, 0]:
        rows.append(env.step(action)[0])
    return np.stack(rows)


def copy_run(directory: Path) -> Path:
    run = directory / "run"
    shutil.copytree(RUN, run)
    return run


def env_json(run: Path) -> dict[str, Any]:
    return json.loads((run / ENV).read_text())


def write_json(run: Path, content: Any) -> None:
    (run / ENV).write_text(json.dumps(content))


def with_config(**changes: Any) -> Callable[[Path], tuple[str, bool]]:
    def change(run: Path) -> tuple[str, bool]:
        content = env_json(run)
        content["env_kwargs"].setdefault("config", {}).update(changes)
        write_json(run, content)
        return ENV, True
    return change


def with_field(name: str, value: Any) -> Callable[[Path], tuple[str, bool]]:
    def change(run: Path) -> tuple[str, bool]:
        content = env_json(run)
        content[name] = value
        write_json(run, content)
        return ENV, True
    return change


def raw(name: str, content: bytes | str | None) -> Callable[[Path], tuple[str, bool]]:
    """Replace file ``name`` by ``content`` (None: remove it; "directory": a directory in its place)."""
    def change(run: Path) -> tuple[str, bool]:
        path = run / name
        path.unlink()
        if content == "directory":
            path.mkdir()
        elif content is not None:
            path.write_bytes(content if isinstance(content, bytes) else content.encode())
        return name, True
    return change


def stats(edit: Callable[[Any], None]) -> Callable[[Path], tuple[str, bool]]:
    """Load the VecNormalize pickle, ``edit`` it, save it back."""
    def change(run: Path) -> tuple[str, bool]:
        with open(run / STATS, "rb") as file:
            saved = pickle.load(file)
        edit(saved)
        for name, value in (("venv", None), ("class_attributes", {}), ("returns", np.zeros(1))):
            saved.__dict__.setdefault(name, value)  # what VecNormalize.__getstate__ deletes and expects to find
        with open(run / STATS, "wb") as file:
            pickle.dump(saved, file)
        return STATS, True
    return change


def set_rms(field: str, value: Any) -> Callable[[Any], None]:
    def edit(saved: Any) -> None:
        array = np.array(getattr(saved.obs_rms, field), dtype=np.float64)
        if callable(value):
            array = value(array)
        else:
            array[0] = value
        setattr(saved.obs_rms, field, array)
    return edit


def foreign_model(run: Path) -> tuple[str, bool]:
    """A PPO model of another platoon (3 followers: 27 observations, not 45) in place of the run's."""
    from stable_baselines3 import PPO

    env = gym.make(ENV_ID, config={"action_mode": "relative", "platoon": {"n_followers": 3}})
    PPO("MlpPolicy", env, n_steps=64, batch_size=32, seed=0, device="cpu").save(run / MODEL)
    return MODEL, True


def zip_without(member: str) -> Callable[[Path], tuple[str, bool]]:
    def change(run: Path) -> tuple[str, bool]:
        source = zipfile.ZipFile(run / MODEL)
        buffer = io.BytesIO()
        with zipfile.ZipFile(buffer, "w") as target:
            for item in source.infolist():
                if item.filename != member:
                    target.writestr(item, source.read(item.filename))
        source.close()
        (run / MODEL).write_bytes(buffer.getvalue())
        return MODEL, True
    return change


CORRUPTIONS: dict[str, Callable[[Path], tuple[str, bool]]] = {
    # env.json: missing, another meaning of the actions, another env, not the run's format
    "env.json missing": raw(ENV, None),
    "env.json: action_mode platoon": with_config(action_mode="platoon"),
    "env.json: action_mode per_vehicle": with_config(action_mode="per_vehicle"),
    "env.json: 3 followers": with_config(platoon={"n_followers": 3}),
    "env.json: unknown config field": with_config(bogus=1),
    "env.json: bad config value": with_config(episode_duration=-1),
    "env.json: frame_stack 3": with_field("frame_stack", 3),
    "env.json: frame_stack 0": with_field("frame_stack", 0),
    "env.json: frame_stack '1'": with_field("frame_stack", "1"),
    "env.json: frame_stack true": with_field("frame_stack", True),
    "env.json: frame_stack 1.5": with_field("frame_stack", 1.5),
    "env.json: no frame_stack": lambda run: (write_json(run, {"env_kwargs": env_json(run)["env_kwargs"]}), (ENV, True))[1],
    "env.json: no env_kwargs": lambda run: (write_json(run, {"frame_stack": 1}), (ENV, True))[1],
    "env.json: env_kwargs a list": with_field("env_kwargs", []),
    "env.json: config a string": lambda run: (write_json(run, {**env_json(run), "env_kwargs": {"config": "relative"}}),
                                              (ENV, True))[1],
    "env.json: not JSON": raw(ENV, "{env_kwargs: "),
    "env.json: empty": raw(ENV, b""),
    "env.json: a list": raw(ENV, "[1, 2]"),
    "env.json: null": raw(ENV, "null"),
    "env.json: not UTF-8": raw(ENV, b"\xff\xfe{}"),
    "env.json: a directory": raw(ENV, "directory"),
    # vecnormalize.pkl: missing, unreadable, statistics that cannot be used
    "vecnormalize.pkl missing": raw(STATS, None),
    "vecnormalize.pkl: empty": raw(STATS, b""),
    "vecnormalize.pkl: garbage": raw(STATS, b"\x80\x04garbage" * 10),
    "vecnormalize.pkl: a pickled dict": raw(STATS, pickle.dumps({"obs_rms": None})),
    "vecnormalize.pkl: a directory": raw(STATS, "directory"),
    "vecnormalize.pkl: NaN mean": stats(set_rms("mean", np.nan)),
    "vecnormalize.pkl: inf mean": stats(set_rms("mean", np.inf)),
    "vecnormalize.pkl: NaN variance": stats(set_rms("var", np.nan)),
    "vecnormalize.pkl: inf variance": stats(set_rms("var", np.inf)),
    "vecnormalize.pkl: negative variance": stats(set_rms("var", -1.0)),
    "vecnormalize.pkl: mean of 27": stats(set_rms("mean", lambda a: a[:27])),
    "vecnormalize.pkl: var of 27": stats(set_rms("var", lambda a: a[:27])),
    "vecnormalize.pkl: NaN clip_obs": stats(lambda saved: setattr(saved, "clip_obs", float("nan"))),
    "vecnormalize.pkl: NaN epsilon": stats(lambda saved: setattr(saved, "epsilon", float("nan"))),
    "vecnormalize.pkl: 2-D mean": stats(set_rms("mean", lambda a: a[None, :])),
    # model.zip: missing, unreadable, another model
    "model.zip missing": raw(MODEL, None),
    "model.zip: empty": raw(MODEL, b""),
    "model.zip: garbage": raw(MODEL, b"PK\x03\x04" + b"\x00" * 100),
    "model.zip: a directory": raw(MODEL, "directory"),
    "model.zip: no data member": zip_without("data"),
    "model.zip: no policy.pth": zip_without("policy.pth"),
    "model.zip: another platoon's model": foreign_model,
}


def judge(run: Path, culprit: str, observations: np.ndarray, reference: Any, defects: Defects, case: str) -> str:
    """Load ``run``: RunFileError or FileNotFoundError naming ``culprit``; a load that works must predict exactly as
    the intact run (``reference``) does, else it loaded something corrupt silently."""
    policy, error = call(lambda: LearnedPolicy.load(run))
    if error is None:
        predicted, error = call(lambda: policy.predict(observations, deterministic=True)[0])
        if error is not None or reference is None or not np.array_equal(predicted, reference[0]) or \
                policy.action_mode != reference[1] or (policy.normalizer is None) != reference[2]:
            defects.add("corrupt run loaded silently", f"{culprit}: loaded as {policy!r}; predicts "
                        f"{short(predicted, 80)} ({'' if error is None else type(error).__name__})", case)
            return "loaded, differs"
        return "loaded, same predictions"
    if not isinstance(error, (RunFileError, FileNotFoundError)):
        defects.exception("LearnedPolicy.load", error, case)
        return type(error).__name__
    if culprit not in str(error):
        defects.add(f"{type(error).__name__} not naming {culprit}", str(error)[:300], case)
    return type(error).__name__


@pytest.fixture(scope="module")
def reference(observations) -> tuple[np.ndarray, str, bool]:
    """What the intact committed run predicts, its action mode, whether it normalises."""
    policy = LearnedPolicy.load(RUN)
    return policy.predict(observations, deterministic=True)[0], policy.action_mode, policy.normalizer is None


def test_the_intact_copy_loads(tmp_path, observations, reference):
    policy = LearnedPolicy.load(copy_run(tmp_path))
    np.testing.assert_array_equal(policy.predict(observations, deterministic=True)[0], reference[0])
    assert policy.action_mode == "relative" and policy.normalizer is not None


@pytest.mark.parametrize("name", list(CORRUPTIONS))
def test_corrupt_run_files_are_refused_by_name(name, tmp_path, observations, reference):
    run = copy_run(tmp_path)
    culprit, _ = CORRUPTIONS[name](run)
    defects = Defects("run files")
    defects.case(judge(run, culprit, observations, None, defects, name))
    defects.check()


def fuzz_model_bytes(max_examples: int, tmp_path: Path, observations: np.ndarray, reference: Any) -> None:
    defects = Defects("run files/bytes")
    source = {name: (RUN / name).read_bytes() for name in (MODEL, STATS, ENV)}

    @fuzz_settings(max_examples)
    @given(name=st.sampled_from([MODEL, MODEL, STATS, ENV]), how=st.sampled_from(["truncate", "flip", "zero"]),
           where=st.floats(0.0, 1.0, exclude_max=True), value=st.integers(1, 255))
    def example(name: str, how: str, where: float, value: int) -> None:
        if name != MODEL and how != "truncate":
            return  # a flipped byte in a pickle or JSON may be a valid different number: undetectable by design
        run = copy_run(Path(tempfile.mkdtemp(dir=tmp_path)))
        data = bytearray(source[name])
        at = int(where * len(data))
        if how == "truncate":
            data = data[:at]
        elif how == "flip":
            data[at] ^= value
        else:
            data[at : at + 64] = bytes(len(data[at : at + 64]))
        (run / name).write_bytes(bytes(data))
        defects.case(judge(run, name, observations, reference, defects, f"{name} {how} at byte {at} of "
                           f"{len(source[name])}" + (f" (^{value})" if how == "flip" else "")))

    example()
    defects.check()


def test_fuzz_run_file_bytes(tmp_path, observations, reference):
    """Truncations of each run file, byte flips and zeroed stretches of the model zip."""
    fuzz_model_bytes(30, tmp_path, observations, reference)


@pytest.mark.slow
def test_fuzz_run_file_bytes_long(tmp_path, observations, reference):
    fuzz_model_bytes(400, tmp_path, observations, reference)
