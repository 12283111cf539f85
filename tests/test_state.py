"""timegap_env.state: per-env fields declared once, one allocation in a few blocks, the same views in Python and
inside a kernel, copies and pickles that keep every component on the copied blocks."""

from __future__ import annotations

import copy
import pickle
from typing import Annotated, NamedTuple

import numba
import numpy as np
import pytest

from tests.envs.reference import use_reference
from timegap_env.config import EnvConfig
from timegap_env.envs.reward import REWARD_TERMS
from timegap_env.envs.step_kernel import ENV, EnvState, env_dims
from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv
from timegap_env.state import PerEnv, State, layout_of, padded


class Inner(NamedTuple):
    p: Annotated[np.ndarray, PerEnv(float, "width")]
    count: Annotated[np.ndarray, PerEnv(np.int64, fill=-1)]


class Outer(NamedTuple):
    a: Annotated[np.ndarray, PerEnv(float, "width")]
    flags: Annotated[np.ndarray, PerEnv(bool, "width")]
    inner: Inner
    b: Annotated[np.ndarray, PerEnv(float, "width", fill=np.inf)]


OUTER = layout_of(Outer)
outer_view, outer_prefetch = OUTER.view, OUTER.prefetch  # a kernel calls them by global name


@numba.njit
def _write_through(blocks):  # noqa: ANN001, ANN202
    outer_prefetch(blocks, 1)  # a hint for env 1's rows: changes nothing
    value = outer_view(blocks, 2)
    value.a[0, 1], value.b[1, 0], value.inner.p[1, 0] = 1.5, 2.5, 3.5
    value.inner.count[0] += 1
    return value.inner.count[1]


def test_fields_of_one_dtype_and_dims_are_rows_of_one_block_filled_as_declared():
    state = State(Outer, {"width": 3}, n_envs=2)
    assert [block.shape for block in state.blocks] == [(3, 2, 3), (1, 2, 3), (1, 2)]  # a, p, b; flags; count
    assert OUTER.rows[("inner", "p")] == (0, 1) and OUTER.rows[("b",)] == (0, 2)
    views = state.views
    assert isinstance(views, Outer) and isinstance(views.inner, Inner)
    assert views.b.base is state.blocks[0] and np.all(views.b == np.inf) and np.all(views.inner.count == -1)
    assert not views.flags.any() and not views.a.any()


def test_a_kernel_makes_the_same_views_of_the_blocks_and_writes_through_them():
    state = State(Outer, {"width": 3}, n_envs=2)
    assert _write_through(state.blocks) == -1
    views = state.views
    assert views.a[0, 1] == 1.5 and views.b[1, 0] == 2.5 and views.inner.p[1, 0] == 3.5 and views.inner.count[0] == 0


def test_a_field_without_a_declaration_or_an_unsized_dimension_is_refused_by_name():
    class Loose(NamedTuple):
        a: Annotated[np.ndarray, PerEnv(float)]
        scale: float

    with pytest.raises(TypeError, match=r"Loose\.scale: annotated"):
        layout_of(Loose)
    with pytest.raises(ValueError, match=r"dimensions \['width'\] are not sized"):
        State(Outer, {}, n_envs=2)


def test_rows_of_a_structure_are_one_view_and_refused_when_split():
    with pytest.raises(ValueError, match="not consecutive rows of one block"):
        State(Outer, {"width": 3}, n_envs=2).rows(("inner",))  # p and count lie in two blocks
    env = State(EnvState, env_dims(EnvConfig()), n_envs=3)
    terms = env.rows(("terms",))
    assert terms.shape == (len(REWARD_TERMS), 3)
    terms[1] = 7.0
    assert np.all(getattr(env.views.terms, REWARD_TERMS[1]) == 7.0)


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copy_holds_its_own_blocks_and_its_views_are_of_them(how):
    state = State(Outer, {"width": 3}, n_envs=2)
    twin = copy.deepcopy(state) if how == "deepcopy" else pickle.loads(pickle.dumps(state))
    twin.views.a[0, 0] = 4.0
    assert state.views.a[0, 0] == 0.0 and twin.blocks[0][0, 0, 0] == 4.0
    assert _write_through(twin.blocks) == -1 and twin.views.inner.count[0] == 0


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_vector_env_steps_like_the_original(how):
    """A copy's fused step writes into the copy's blocks, which its components, observations and staged path read."""
    env = TimeGapMonitorVectorEnv(3, autoreset_mode="same_step")
    env.reset(seed=4)
    action = np.array([5, 2, 7])
    for _ in range(3):
        env.step(action)
    twin = copy.deepcopy(env) if how == "deepcopy" else pickle.loads(pickle.dumps(env))
    task = twin.task
    assert task.loop.platoon.x.base is task.state.blocks[ENV.rows[("loop", "platoon", "state", "x")][0]]
    staged = copy.deepcopy(env)
    use_reference(staged.task)
    for _ in range(4):
        results = [e.step(action) for e in (env, twin, staged)]
        for other in results[1:]:
            np.testing.assert_array_equal(other[0], results[0][0])
            np.testing.assert_array_equal(other[1], results[0][1])


def test_the_fused_step_follows_dynamics_set_after_the_first_reset():
    """set_dynamics writes the state's arrays, which both paths read."""
    envs = [TimeGapMonitorVectorEnv(2, autoreset_mode="same_step") for _ in range(2)]
    use_reference(envs[1].task)
    for env in envs:
        env.reset(seed=1)
        env.task.loop.platoon.set_dynamics(np.array([[0.9], [0.3]]), 0.7)
    for _ in range(5):
        (fused, *_), (staged, *_) = (env.step(np.array([2, 6])) for env in envs)
        np.testing.assert_array_equal(fused, staged)


def test_the_fused_step_is_handed_a_handful_of_arrays():
    env = TimeGapMonitorVectorEnv(2)
    env.reset(seed=0)
    assert len(env.task.state.blocks) <= 16  # about 120 arrays before the state was one allocation, 50 stacked


def test_rows_of_4_kib_or_more_start_in_distinct_cache_sets():
    """A block's rows hold a few padding envs when a row spans 4 KiB or more, so that one env's rows do not all fall
    in the same cache sets; the views stay the envs' (n_envs rows), C-contiguous."""
    assert padded(3, 40) == 3 and padded(1, 20_000) == 1  # small rows, or a single env: no padding
    for n_envs, env_bytes in ((1024, 40), (4096, 8), (65536, 1), (300, 20_008)):
        count = padded(n_envs, env_bytes)
        assert n_envs <= count <= n_envs + n_envs // 16 and count * env_bytes % 128 == 64
    state = State(Outer, {"width": 5}, n_envs=1024)
    block = state.blocks[0]
    sets = {(row.__array_interface__["data"][0] // 64) % 64 for row in block}
    assert block.shape[1] > 1024 and len(sets) == len(block)
    assert state.views.a.shape == (1024, 5) and state.views.a.flags.c_contiguous
