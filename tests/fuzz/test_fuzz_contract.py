"""Fuzz of the env's contract (issue 22): calls in the wrong order, actions outside the space, copies mid-episode,
reset options of every wrong type.

- ``step()`` before ``reset()``, after the episode ended, and after a ``reset()`` that raised: gymnasium's
  ``ResetNeeded`` (single and native vector env, full and masked resets); a failed reset leaves nothing behind
  (the next good reset runs as a fresh env's would).
- Actions: what the action space holds steps (as the same action as int64 would); anything outside it raises
  ``ValueError`` naming the action and leaves the env as it was.
- ``copy.deepcopy`` and ``pickle`` mid-episode give envs that go on with the same bits.
- Reset options (``scenario``, ``leader_speed``, ``degradation``, ``reset_mask``) of right and wrong types: the env
  runs clean, or raises ``ValueError`` naming the option (and for a degradation its key); a value outside the
  documented ones is refused, a documented one is not. ``num_envs`` the machine cannot hold is refused by name.
"""

from __future__ import annotations

import copy
import math
import pickle
from decimal import Decimal
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.error import ResetNeeded
from hypothesis import given
from hypothesis import strategies as st

import timegap_env  # noqa: F401 - registers the env
from timegap_env.config import DEGRADATION_KINDS, DEGRADATIONS, MAX_SPEED
from timegap_env.envs.env import TimeGapMonitorEnv
from timegap_env.sim.presets import acc_presets
from tests.fuzz.fuzzing import (
    DATA_PRESENT, ENV_ID, NO_DATA, PLAYABLE, Defects, Digest, bad_step, bad_values, call, fuzz_settings, short,
)

N_FOLLOWERS = 3
SHORT = {"episode_duration": 2.0}  # episodes of two steps
CARS = sorted(acc_presets())
MAX_TIME = 1e6  # latest onset or end of a degradation [s] (timegap_env.sim.degradation.MAX_TIME)


def make(mode: str = "platoon", **config: Any) -> gym.Env:
    return gym.make(ENV_ID, config={"action_mode": mode, "platoon": {"n_followers": N_FOLLOWERS}, **config},
                    truth_info=True)  # every info key: the true state and the ground truth too


def make_vector(num_envs: int = 3, autoreset_mode: str = "same_step", mode: str = "platoon", **config: Any):
    return gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        config={"action_mode": mode, "platoon": {"n_followers": N_FOLLOWERS}, **config},
                        autoreset_mode=autoreset_mode, truth_info=True)


def run(env: Any, seed: int, steps: int, actions_seed: int = 0, options: dict | None = None) -> str:
    """The digest of ``reset(seed)`` and ``steps`` steps with fixed random actions."""
    digest = Digest()
    digest.add(*env.reset(seed=seed, options=options))
    rng = np.random.default_rng(actions_seed)
    space = env.action_space
    for _ in range(steps):
        action = rng.integers(0, space.nvec) if isinstance(space, gym.spaces.MultiDiscrete) else \
            int(rng.integers(space.n))
        out = env.step(action)
        digest.add(*out)
        if not isinstance(env, gym.vector.VectorEnv) and (out[2] or out[3]):
            digest.add(*env.reset())
    return digest.hexdigest()


# ----------------------------------------------------------------------------------------------- call order

@pytest.mark.parametrize("build", ["gym.make", "class"])
def test_step_before_reset_and_after_the_end_raise_reset_needed(build):
    env = make(**SHORT) if build == "gym.make" else TimeGapMonitorEnv(config=SHORT, truth_info=True, task_id=ENV_ID)
    with pytest.raises(ResetNeeded):
        env.step(0)
    env.reset(seed=0)
    for _ in range(2):
        *_, terminated, truncated, _ = env.step(0)
    assert terminated or truncated
    for _ in range(2):
        with pytest.raises(ResetNeeded):
            env.step(0)
    env.reset()
    env.step(0)


def test_vector_step_before_reset_raises_reset_needed():
    envs = make_vector()
    with pytest.raises(ResetNeeded):
        envs.step(np.zeros(3, dtype=np.int64))


def test_vector_env_with_autoreset_disabled_waits_for_masked_resets():
    envs = make_vector(3, "disabled", **SHORT)
    envs.reset(seed=0)
    for _ in range(2):
        *_, terminated, truncated, _ = envs.step(np.zeros(3, dtype=np.int64))
    assert (terminated | truncated).all()
    with pytest.raises(ResetNeeded):
        envs.step(np.zeros(3, dtype=np.int64))
    envs.reset(options={"reset_mask": np.array([True, False, True])})
    with pytest.raises(ResetNeeded, match=r"\[1\]"):
        envs.step(np.zeros(3, dtype=np.int64))
    envs.reset(options={"reset_mask": np.array([False, True, False])})
    envs.step(np.zeros(3, dtype=np.int64))


@pytest.mark.parametrize("mask", [np.array([1, 0, 1]), np.array([False] * 3), np.array([True] * 2),
                                  np.array([[True] * 3]), "all", 1, np.array([True, False, np.nan])],
                         ids=lambda m: short(m, 30))
def test_bad_reset_masks_are_refused_by_name(mask):
    envs = make_vector(3, "disabled")
    envs.reset(seed=0)
    with pytest.raises(ValueError, match="reset_mask"):
        envs.reset(options={"reset_mask": mask})


BAD_OPTIONS = [
    {"degradation": {"kind": "lag", "size": 1e200}},
    {"leader_speed": ["20", "21"]},
    {"degradation": {"kind": "gain", "size": 0.7, "onset": 1e300}},
    {"scenario": "bogus"},
    {"scenario": ["paper"]},
    {"leader_speed": {"a": 1}},
    {"leader_speed": [20.0, math.nan]},
    {"leader_speed": [20.0, 1e300]},
    {"degradation": {"kind": "commercial_acc", "car": "NO_SUCH_CAR"}},
    {"degradation": {"kind": "v2v_latency", "size": 0.55}},
    {"degradation": [{"kind": "lag", "size": 2.0, "followers": [1]}, {"kind": "gain", "size": 0.7, "followers": [1]}]},
]


@pytest.mark.parametrize("options", BAD_OPTIONS, ids=lambda o: short(o, 60))
@pytest.mark.parametrize("build", ["gym.make", "class"])
def test_a_failed_reset_leaves_the_env_refusing_to_step(options, build):
    """After a reset that raised, step() raises ResetNeeded (mid-episode too); the next good reset runs as a fresh
    env's would; the env's scenario is not the failed episode's (issue 22, items 5, 12)."""
    env = make() if build == "gym.make" else TimeGapMonitorEnv(config={"platoon": {"n_followers": N_FOLLOWERS}}, truth_info=True,
                                                                      task_id=ENV_ID)
    env.reset(seed=1, options={"scenario": "sinusoid"})
    env.step(0)
    with pytest.raises(ValueError):
        env.reset(seed=2, options={**options, **({} if "leader_speed" in options or "scenario" in options
                                                    else {"scenario": "hard_braking"})})
    assert env.unwrapped.scenario in ("sinusoid", ""), env.unwrapped.scenario
    with pytest.raises(ResetNeeded):
        env.step(0)
    assert run(env, 5, 6) == run(make(), 5, 6)


@pytest.mark.parametrize("options", BAD_OPTIONS, ids=lambda o: short(o, 60))
@pytest.mark.parametrize("masked", [False, True])
def test_a_failed_vector_reset_leaves_the_vector_env_refusing_to_step(options, masked):
    """Issue 22, item 5: a vector reset that raises (all sub-envs or a masked few) leaves no sub-env half reset
    and stepping: step() raises ResetNeeded until a reset succeeds, which then runs as a fresh env's would."""
    envs = make_vector(3, "disabled" if masked else "same_step")
    envs.reset(seed=1)
    envs.step(np.zeros(3, dtype=np.int64))
    reset_options = dict(options)
    if masked:
        reset_options["reset_mask"] = np.array([True, False, True])
    with pytest.raises(ValueError):
        envs.reset(seed=2, options=reset_options)
    with pytest.raises(ResetNeeded):
        envs.step(np.zeros(3, dtype=np.int64))
    assert run(envs, 5, 6) == run(make_vector(3, "disabled" if masked else "same_step"), 5, 6)


@pytest.mark.parametrize("num_envs", [0, -1, True, 1.5, "4", None, 10**12, 10**400])
def test_num_envs_the_machine_cannot_hold_or_that_is_not_a_count_is_refused_by_name(num_envs):
    """Issue 22, item 13: not an integer >= 1, or more sub-envs than fit in memory: ValueError naming num_envs (not
    a MemoryError from NumPy)."""
    with pytest.raises(ValueError, match="num_envs"):
        gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point")


def test_num_envs_as_numpy_integer_works():
    envs = gym.make_vec(ENV_ID, num_envs=np.int8(2), vectorization_mode="vector_entry_point")
    obs, _ = envs.reset(seed=0)
    assert obs.shape[0] == 2


# ----------------------------------------------------------------------------------------------- actions

def make_array(shape: tuple[int, ...], dtype: type, values: list[int]) -> np.ndarray:
    """``values`` repeated to ``shape`` as ``dtype`` (negative values made positive for an unsigned dtype)."""
    if np.dtype(dtype).kind == "u":
        values = [abs(v) for v in values]
    return np.resize(np.asarray(values, dtype=object), shape).astype(dtype)


def action_values() -> st.SearchStrategy:
    """Actions of every type and shape: in and out of range, ints, NumPy integers, bools, floats, strings, arrays."""
    ints = st.one_of(st.integers(-3, 12), st.integers(-(10**30), 10**30), st.sampled_from([10**400, 2**63, 2**64]))
    np_ints = st.builds(lambda x, t: t(x), st.integers(0, 8), st.sampled_from([np.int8, np.int16, np.int32, np.int64,
                                                                               np.uint8, np.uint64, np.intp]))
    floats = st.one_of(st.floats(), st.integers(-2, 10).map(float), st.integers(0, 8).map(np.float32))
    bools = st.sampled_from([True, False, np.True_, np.False_])
    scalars = st.one_of(ints, np_ints, floats, bools)
    shapes = st.sampled_from([(), (1,), (2,), (3,), (4,), (3, 1), (1, 3), (0,)])
    dtypes = st.sampled_from([np.int64, np.int8, np.uint8, np.int32, np.float64, np.float32, np.bool_, object])
    arrays = st.builds(make_array, shapes, dtypes, st.lists(st.integers(-2, 10), min_size=1, max_size=4))
    arrays_nan = st.builds(lambda shape: np.full(shape, np.nan), shapes)
    sequences = st.one_of(st.lists(scalars, max_size=4), st.lists(st.integers(0, 8), min_size=3, max_size=3),
                          st.lists(st.integers(0, 8), min_size=3, max_size=3).map(tuple))
    odd = st.sampled_from([None, "1", b"1", "", {"a": 1}, complex(1, 0), Decimal(1), [[1, 2, 3]], [None, 1, 2],
                           range(3), object()])
    return st.one_of(scalars, scalars, arrays, arrays, arrays_nan, sequences, odd)


def classify(action: Any, space: gym.Space) -> str:
    """What the env must do with ``action``, by gymnasium's ``space.contains``: "valid" (integers of the right shape
    in range that the space holds: must step, as their int64 form would), "odd" (a bool the space holds, or an
    in-range integer of a dtype the space will not cast, such as np.uint64: may step as the integer or raise
    ValueError), "invalid" (everything else, floats and out-of-range values included: must raise ValueError)."""
    try:
        contained = bool(space.contains(action))
    except Exception:  # noqa: BLE001 - what the space cannot even look at is outside it
        contained = False
    if isinstance(space, gym.spaces.Discrete):
        if isinstance(action, (bool, np.bool_)) or (isinstance(action, np.ndarray) and action.dtype == np.bool_):
            return "odd" if contained else "invalid"
        if isinstance(action, (int, np.integer)) or (
                isinstance(action, np.ndarray) and action.shape == () and action.dtype.kind in "iu"):
            return ("valid" if contained else "odd") if 0 <= int(action) < space.n else "invalid"
        return "invalid"
    if isinstance(action, (str, bytes)):
        return "invalid"
    if isinstance(action, np.ndarray):
        array = action
    elif isinstance(action, Sequence):
        try:
            array = np.array(action)
        except Exception:  # noqa: BLE001 - ragged, or items NumPy cannot hold
            return "invalid"
    else:
        return "invalid"
    if array.shape != space.shape:
        return "invalid"
    items = array.ravel().tolist() if array.dtype != object else list(array.ravel())
    if array.dtype == np.bool_ or any(isinstance(x, (bool, np.bool_)) for x in
                                      (action if isinstance(action, Sequence) else items)):
        return "odd" if contained else "invalid"
    if array.dtype.kind in "iu" or (array.dtype == object and all(isinstance(x, (int, np.integer)) for x in items)):
        in_range = all(0 <= int(x) < int(n) for x, n in zip(items, space.nvec.ravel()))
        return ("valid" if contained else "odd") if in_range else "invalid"
    return "invalid"


def canonical(action: Any, space: gym.Space) -> Any:
    """The int64 action a "valid" or "odd" one stands for."""
    if isinstance(space, gym.spaces.Discrete):
        return int(action)
    return np.array(action).astype(np.int64)


def check_action(env: Any, action: Any, defects: Defects, where: str) -> str:
    """Step a copy of ``env`` with ``action`` and another copy with its integer form (or, for an action the env
    refuses, both with a valid one after it); the outcome must be as :func:`classify` says."""
    space = env.action_space
    kind = classify(action, space)
    mine, reference = copy.deepcopy(env), copy.deepcopy(env)
    case = f"{where}: action {short(action, 200)} ({type(action).__name__}), {kind}"
    result, error = call(lambda: mine.step(action))
    if error is None:
        if kind == "invalid":
            defects.add("action outside the space accepted", f"{short(action, 100)} stepped", case)
            return "accepted"
        want = reference.step(canonical(action, space))
        if Digest_of(result) != Digest_of(want):
            defects.add("action stepped differently from its integer form", short(action, 100), case)
        return "stepped"
    if not isinstance(error, ValueError):
        defects.exception("step with a bad action", error, case)
        return type(error).__name__
    if kind == "valid":
        defects.add("valid action refused", str(error)[:200], case)
    elif "action" not in str(error):
        defects.add("ValueError not naming the action", str(error)[:200], case)
    valid = space.sample()
    if Digest_of(mine.step(valid)) != Digest_of(reference.step(valid)):
        defects.add("a refused action changed the env", str(error)[:100], case)
    return "ValueError"


def Digest_of(result: tuple) -> str:  # noqa: N802
    digest = Digest()
    digest.add(*result)
    return digest.hexdigest()


def fuzz_actions(max_examples: int) -> None:
    defects = Defects("contract/actions")
    envs = {}
    for mode in ("platoon", "per_vehicle", "relative"):
        env = make(mode)
        env.reset(seed=0)
        env.action_space.seed(0)
        envs[mode] = env
        vector = make_vector(3, "same_step", mode)
        vector.reset(seed=0)
        vector.action_space.seed(0)
        envs[f"{mode}, vector"] = vector
    names = sorted(envs)

    @fuzz_settings(max_examples)
    @given(index=st.integers(0, len(names) - 1), action=action_values())
    def example(index: int, action: Any) -> None:
        name = names[index]
        defects.case(check_action(envs[name], action, defects, name))

    example()
    defects.check()


def test_fuzz_actions():
    """Single and vector env in each action mode against actions of every type and shape."""
    fuzz_actions(max_examples=300)


@pytest.mark.slow
def test_fuzz_actions_long():
    fuzz_actions(max_examples=3000)


def test_a_discrete_env_steps_every_action_its_space_contains():
    """Issue 22, item 12: ``Discrete(9).contains(True)`` holds (gymnasium counts a bool as an int), so ``step(True)``
    must step as ``step(1)`` (a wrapper or library that samples, checks with ``contains`` and steps relies on it)."""
    env, reference = make(), make()
    env.reset(seed=0)
    reference.reset(seed=0)
    assert env.action_space.contains(True)
    assert Digest_of(env.step(True)) == Digest_of(reference.step(1))
    assert Digest_of(env.step(False)) == Digest_of(reference.step(0))


# ----------------------------------------------------------------------------------------------- copies

@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
@pytest.mark.parametrize("mode", ["platoon", "per_vehicle", "relative"])
def test_copies_mid_episode_go_on_with_the_same_bits(how, mode):
    env = make(mode, episode_duration=6.0)
    env.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(4):
        env.step(env.action_space.sample())
    clone = copy.deepcopy(env) if how == "deepcopy" else pickle.loads(pickle.dumps(env))
    for _ in range(10):  # across the episode's end and a reset without a seed
        action = rng.integers(0, env.action_space.nvec) if mode == "per_vehicle" else int(rng.integers(env.action_space.n))
        a, b = env.step(action), clone.step(action)
        assert Digest_of(a) == Digest_of(b)
        if a[2] or a[3]:
            assert Digest_of(env.reset()) == Digest_of(clone.reset())


@pytest.mark.parametrize("autoreset_mode", ["same_step", "next_step", "disabled"])
@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_vector_copies_mid_episode_go_on_with_the_same_bits(how, autoreset_mode):
    envs = make_vector(3, autoreset_mode, episode_duration=4.0)
    envs.reset(seed=3)
    envs.step(np.ones(3, dtype=np.int64))
    clone = copy.deepcopy(envs) if how == "deepcopy" else pickle.loads(pickle.dumps(envs))
    rng = np.random.default_rng(0)
    for _ in range(10):
        actions = rng.integers(0, 9, size=3)
        a, b = envs.step(actions), clone.step(actions)
        assert Digest_of(a) == Digest_of(b)
        if autoreset_mode == "disabled" and (a[2] | a[3]).any():
            mask = a[2] | a[3]
            assert Digest_of(envs.reset(options={"reset_mask": mask})) == Digest_of(
                clone.reset(options={"reset_mask": mask.copy()}))


def test_a_rendering_env_pickles_mid_episode():
    env = gym.make(ENV_ID, render_mode="rgb_array")
    env.reset(seed=0)
    env.step(3)
    env.render()
    clone = pickle.loads(pickle.dumps(env))
    assert Digest_of(env.step(4)) == Digest_of(clone.step(4))
    assert clone.render().shape == env.render().shape


# ----------------------------------------------------------------------------------------------- reset options

VALID, INVALID, EITHER = "valid", "invalid", "either"


def tagged(pairs: list[tuple[Any, str]]) -> st.SearchStrategy:
    return st.sampled_from(pairs)


SCENARIO_VALUES = [(name, VALID) for name in PLAYABLE] + [
    (None, VALID), (np.str_("paper"), EITHER),
    ("", INVALID), (" paper", INVALID), ("PAPER", INVALID), ("bogus", INVALID), (["paper"], INVALID), (1, INVALID),
    (b"paper", INVALID), ({"paper": 1}, INVALID), (True, INVALID), ("x" * 100_000, INVALID), (math.nan, INVALID),
]


def leader_speed_values() -> st.SearchStrategy:
    valid = st.lists(st.floats(0.0, MAX_SPEED), min_size=2, max_size=300)
    return st.one_of(
        valid.map(lambda xs: (xs, VALID)),
        valid.map(lambda xs: (np.asarray(xs), VALID)),
        valid.map(lambda xs: (tuple(xs), VALID)),
        st.lists(st.integers(0, 100), min_size=2, max_size=50).map(lambda xs: (xs, VALID)),
        st.lists(st.integers(0, 100), min_size=2, max_size=50).map(lambda xs: (np.asarray(xs, dtype=np.int8), VALID)),
        tagged([
            ([], INVALID), ([5.0], INVALID), ([[20.0, 21.0], [22.0, 23.0]], INVALID), ("fast", INVALID),
            (["20", "21"], INVALID), ({"a": 1}, INVALID), ([math.nan, 20.0], INVALID), ([20.0, math.inf], INVALID),
            ([-1.0, 20.0], INVALID), ([20.0, 1000.0], INVALID), ([20.0, 1e300], INVALID), ([20.0, 10**400], INVALID),
            (None, INVALID), (25.0, INVALID), ([1 + 2j, 20.0], INVALID), (np.array([20.0, None]), INVALID),
            ([20.0, MAX_SPEED + 1e-9], INVALID), ([True, False, True], EITHER), (np.zeros(2), VALID),
            (np.full(10, MAX_SPEED), VALID), (np.zeros(0), INVALID), (np.zeros((2, 1)), INVALID),
        ]),
    )


def sizes_for(kind: str) -> list[tuple[Any, str]]:
    bounds = DEGRADATIONS[kind].size_bounds if kind in DEGRADATIONS else None
    if bounds is None:
        return [(None, VALID), (1.0, INVALID), (0.0, INVALID), ("none", INVALID)]
    low, high, open_low, open_high = bounds
    inside = [low + (high - low) * f for f in (0.0, 0.25, 0.5, 1.0)]
    inside = [x for x in inside if (x > low if open_low else x >= low) and (x < high if open_high else x <= high)]
    if kind == "v2v_latency":  # a multiple of dt = 0.1 s, up to max_v2v_latency = 1 s
        inside = [0.0, 0.1, 0.5, 1.0]
    return [(x, VALID) for x in inside] + [(int(x), VALID) for x in inside if x == int(x) and
                                           (kind != "v2v_latency" or x <= 1.0) and (x > low or not open_low)] + [
        (high + 1.0, INVALID), (low - 1.0, INVALID), (1e200, INVALID), (-1e200, INVALID), (math.nan, INVALID),
        (math.inf, INVALID), (10**400, INVALID), ("1", INVALID), (True, INVALID), (None, INVALID), ([1.0], INVALID),
    ]


FOLLOWERS = [([1], VALID), ([1, 2, 3], VALID), ((2,), VALID), (range(1, 3), VALID), ([3, 1], VALID),
             (np.array([1, 2]), EITHER), (1, EITHER), (np.int8(2), EITHER), ([np.int64(1)], VALID),
             ([], INVALID), ([0], INVALID), ([-1], INVALID), ([N_FOLLOWERS + 1], INVALID), ([True], INVALID),
             ([1.5], INVALID), ("1", INVALID), ([[1]], INVALID), ([1, 1], INVALID), (None, INVALID),
             ([10**400], INVALID), ({1: 1}, INVALID), ([1.0], EITHER)]
ONSETS = [(0.0, VALID), (1.0, VALID), (5, VALID), (MAX_TIME, VALID), (np.float32(2.0), VALID),
          (-1.0, INVALID), (1e300, INVALID), (math.nan, INVALID), (math.inf, INVALID), (10**400, INVALID),
          ("0", INVALID), (None, INVALID), (True, INVALID), (MAX_TIME * 1.0000001, INVALID)]


@st.composite
def degradation_dicts(draw: st.DrawFn) -> tuple[Any, str]:
    kind, status = draw(tagged([(k, VALID) for k in DEGRADATION_KINDS] + [
        ("", INVALID), ("LAG", INVALID), ("none", INVALID), (None, INVALID), (1, INVALID), (["lag"], INVALID)]))
    description: dict[Any, Any] = {} if draw(st.integers(0, 9)) == 0 else {"kind": kind}
    statuses = [status if "kind" in description else INVALID]
    sized = isinstance(kind, str) and kind in DEGRADATIONS and DEGRADATIONS[kind].size_bounds is not None
    if draw(st.booleans()) or sized:
        size, s = draw(tagged(sizes_for(kind if isinstance(kind, str) else "")))
        if size is not None or not sized:
            description["size"] = size
            statuses.append(s)
        else:
            statuses.append(INVALID)  # a sized kind without its size
    if draw(st.booleans()):
        followers, s = draw(tagged(FOLLOWERS))
        description["followers"] = followers
        statuses.append(s)
    if draw(st.booleans()):
        onset, s = draw(tagged(ONSETS))
        description["onset"] = onset
        statuses.append(s)
    if draw(st.booleans()):
        onset = description.get("onset", 0.0)
        end, s = draw(tagged([(None, VALID), (2.0, VALID if _real(onset) and onset < 2.0 else EITHER),
                              (MAX_TIME, VALID if _real(onset) and onset < MAX_TIME else EITHER),
                              (0.0, INVALID if _real(onset) and onset >= 0.0 else EITHER), (1e300, INVALID),
                              (math.nan, INVALID), ("10", INVALID), (True, INVALID)]))
        description["end"] = end
        statuses.append(s)
    if draw(st.integers(0, 4)) == 0:
        car, s = draw(tagged([(name, VALID) for name in CARS] + [("NO_SUCH_CAR", INVALID), (1, INVALID),
                                                                  (None, VALID)]))
        description["car"] = car
        statuses.append(s if kind == "commercial_acc" or car is None else INVALID)
    if draw(st.integers(0, 9)) == 0:
        description[draw(st.sampled_from(["bogus", "Kind", 1, None]))] = 1
        statuses.append(INVALID)
    return description, combine(statuses)


def _real(x: Any) -> bool:
    """A finite real number (not a bool) that fits a float."""
    if not isinstance(x, (int, float, np.integer, np.floating)) or isinstance(x, (bool, np.bool_)):
        return False
    try:
        return math.isfinite(float(x))
    except OverflowError:
        return False


def combine(statuses: list[str]) -> str:
    return INVALID if INVALID in statuses else EITHER if EITHER in statuses else VALID


@st.composite
def degradation_values(draw: st.DrawFn) -> tuple[Any, str]:
    how = draw(st.sampled_from(["dict", "dict", "dict", "list", "none", "odd"]))
    if how == "dict":
        return draw(degradation_dicts())
    if how == "list":
        items = draw(st.lists(degradation_dicts(), max_size=3))
        value = [item for item, _ in items]
        statuses = [status for _, status in items]
        hit = [f for item in value if isinstance(item, dict) for f in _followers(item)]
        if len(hit) != len(set(hit)):
            statuses.append(INVALID)  # a follower hit twice
        return (value if draw(st.booleans()) else tuple(value)), combine(statuses)
    if how == "none":
        return None, VALID
    return draw(tagged([("lag", INVALID), (1, INVALID), ({"lag": 2.0}, INVALID), ([None], INVALID),
                        ([[{"kind": "lag", "size": 2.0}]], INVALID), (math.nan, INVALID)]))


def _followers(item: dict) -> list[int]:
    followers = item.get("followers", range(1, N_FOLLOWERS + 1))
    try:
        return [int(f) for f in followers] if isinstance(followers, (list, tuple, range)) else [int(followers)]
    except (TypeError, ValueError, OverflowError):
        return []


@st.composite
def options_values(draw: st.DrawFn) -> tuple[Any, str]:
    """Reset options and whether they are valid, invalid or either (a value the docs leave open)."""
    if draw(st.integers(0, 14)) == 0:
        return draw(tagged([(["scenario"], INVALID), ("scenario", INVALID), (1, INVALID), ({}, VALID), (None, VALID),
                            ({"scenario": "paper", "bogus": 1}, INVALID), ({None: 1}, INVALID),
                            ({"Scenario": "paper"}, INVALID)]))
    options: dict[str, Any] = {}
    statuses = []
    leader = draw(st.sampled_from(["none", "scenario", "speed", "both"]))
    if leader in ("scenario", "both"):
        options["scenario"], s = draw(tagged(SCENARIO_VALUES))
        statuses.append(s)
    if leader in ("speed", "both"):
        options["leader_speed"], s = draw(leader_speed_values())
        statuses.append(s)
    if leader == "both" and options["scenario"] is not None:
        statuses.append(EITHER)  # the README does not say whether both may be given
    if draw(st.booleans()):
        options["degradation"], s = draw(degradation_values())
        statuses.append(s)
    return options, combine(statuses)


def names_option(message: str, options: Any) -> bool:
    """A refusal names the option (or, for options that are not a dict of known keys, says "options")."""
    if not isinstance(options, dict) or any(key not in ("scenario", "leader_speed", "degradation", "reset_mask")
                                            for key in options):
        return "option" in message
    if "degradation" in options and "degradation" in message:
        return True
    return any(key in message for key in options)


def check_options(env: Any, fresh: Any, options: Any, status: str, seed: int, defects: Defects, where: str) -> str:
    """Reset ``env`` with ``options``: a clean run or a ValueError naming them as their status allows; after a
    refusal, ``step`` raises ResetNeeded and the next good reset runs as ``fresh``'s does."""
    case = f"{where}: options {short(options, 400)} ({status})"
    env.reset(seed=seed)
    result, error = call(lambda: env.reset(seed=seed + 1, options=options))
    vector = isinstance(env, gym.vector.VectorEnv)
    step = (lambda: env.step(np.zeros(env.num_envs, dtype=np.int64))) if vector else (lambda: env.step(0))
    if error is None:
        if status == INVALID:
            defects.add("invalid reset option accepted", "reset ran", case)
        obs, info = result
        problems = bad_step(env.observation_space, obs) + bad_values(info)
        for _ in range(2):
            out, error = call(step)
            if error is not None:
                defects.exception("step after an accepted reset", error, case)
                return "works, then raised"
            problems += bad_step(env.observation_space, out[0], out[1]) + bad_values(out[4])
            if np.any(out[2]) or np.any(out[3]):  # a short leader_speed ends the episode
                break
        for problem in problems:
            defects.add("bad output after a reset with options", problem, case)
        return "works"
    if not isinstance(error, ValueError):
        defects.exception("reset with options", error, case)
        return type(error).__name__
    if status == VALID:
        defects.add("valid reset option refused", str(error)[:300], case)
    if not names_option(str(error), options):
        defects.add("ValueError not naming the option", str(error)[:300], case)
    _, error = call(step)
    if not isinstance(error, ResetNeeded):
        defects.add("stepped after a failed reset" if error is None else f"{type(error).__name__} (not ResetNeeded) "
                    "stepping after a failed reset", "" if error is None else str(error)[:200], case)
    if run(env, seed + 2, 3) != run(fresh, seed + 2, 3):
        defects.add("a failed reset left something behind", "the next good reset runs differently from a fresh env's",
                    case)
    return "ValueError"


def fuzz_options(max_examples: int) -> None:
    defects = Defects("contract/reset options")
    pairs = {"single": (make(), make()), "vector": (make_vector(2), make_vector(2)),
             "vector, masked": (make_vector(2, "disabled"), make_vector(2, "disabled"))}

    @fuzz_settings(max_examples)
    @given(which=st.sampled_from(sorted(pairs)), tagged_options=options_values(), seed=st.integers(0, 2**16))
    def example(which: str, tagged_options: tuple[Any, str], seed: int) -> None:
        options, status = tagged_options
        env, fresh = pairs[which]
        if which == "vector, masked" and isinstance(options, dict):
            options = {**options, "reset_mask": np.array([True, False])}
        defects.case(check_options(env, fresh, options, status, seed, defects, which))

    example()
    defects.check()


def test_fuzz_reset_options():
    """Single env, vector env and masked vector resets against options of every type."""
    fuzz_options(max_examples=250)


@pytest.mark.slow
def test_fuzz_reset_options_long():
    fuzz_options(max_examples=3000)


@pytest.mark.skipif(not DATA_PRESENT, reason=NO_DATA)
def test_a_recorded_leader_at_another_tick_is_refused_by_the_option_or_the_field():
    """A NGSIM leader (0.1 s frames) in an env at dt = 1 s: a ValueError naming the scenario and platoon.dt (then
    what the reader said)."""
    env = gym.make(ENV_ID, config={"platoon": {"dt": 1.0, "v2v_delay": 0.0}, "monitor": {"dt": 1.0},
                                   "chart": {"dt": 1.0}, "leader": {"dt": 1.0}, "episode_duration": 60.0})
    for scenario in ("ngsim", "ngsim_in_band", "openacc"):
        with pytest.raises(ValueError, match=f"scenario '{scenario}' .*(dt = 1.0 s|runs at 1.0 s)"):
            env.reset(seed=0, options={"scenario": scenario})
