"""timegap_env.compiled's Stacked: a structure handed to a kernel as a few stacks, made again inside, and kept
stacked through copies and pickles."""

from __future__ import annotations

import copy
import pickle
from typing import NamedTuple

import numba
import numpy as np
import pytest

from timegap_env.compiled import Stacked, restack
from timegap_env.envs.step_kernel import StepState
from timegap_env.envs.vector_env import TimeGapMonitorVectorEnv


class Inner(NamedTuple):
    p: np.ndarray
    q: np.ndarray
    scale: float


class Outer(NamedTuple):
    a: np.ndarray
    flags: np.ndarray
    inner: Inner
    b: np.ndarray
    count: np.ndarray


INNER = Stacked(Inner, (("p", "q"),))
OUTER = Stacked(Outer, (("a", "b"),), nested={"inner": INNER})
unstack_outer, prefetch_outer = OUTER.unstack, OUTER.prefetch  # a kernel calls them by global names (numba types no
# other object's attributes)


@numba.njit
def _write_through(form):  # noqa: ANN001, ANN202
    prefetch_outer(form, 1)  # a hint for env 1's rows, the nested layout's and past a scalar field: changes nothing
    a, flags, inner, b, count = unstack_outer(form)
    a[0, 1], b[1, 0], inner[1][0] = 1.5, 2.5, 3.5
    count[0] += 1
    return inner[2]


def outer() -> Outer:
    ab, pq = np.zeros((2, 2, 3)), np.zeros((2, 4))
    return Outer(a=ab[0], flags=np.zeros(3, dtype=bool), inner=Inner(*pq, scale=0.5), b=ab[1],
                 count=np.zeros(1, dtype=np.int64))


def test_the_form_holds_each_group_as_its_stack_and_the_kernel_writes_through_the_rows():
    value = outer()
    form = OUTER.form(value)
    assert len(form) == 4 and form[0].shape == (2, 2, 3) and form[2][0].shape == (2, 4)  # a+b, flags, inner, count
    assert _write_through(form) == 0.5
    assert value.a[0, 1] == 1.5 and value.b[1, 0] == 2.5 and value.inner.q[0] == 3.5 and value.count[0] == 1


def test_fields_that_are_not_the_rows_of_one_stack_are_refused_by_name():
    value = outer()._replace(b=np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"Outer fields \('a', 'b'\): must be the rows"):
        OUTER.form(value)
    swapped = outer()
    with pytest.raises(ValueError, match="in this order"):
        OUTER.form(swapped._replace(a=swapped.b, b=swapped.a))


def test_a_layout_naming_an_unknown_or_repeated_field_is_refused():
    with pytest.raises(ValueError, match="distinct fields"):
        Stacked(Inner, (("p", "r"),))
    with pytest.raises(ValueError, match="distinct fields"):
        Stacked(Inner, (("p", "q"), ("q",)))


def test_restack_makes_a_copys_rows_one_stack_again_and_every_reference_follows():
    class Holder:  # an owner keeping the structure and a plain tuple of the same arrays, as the components do
        __module__ = "timegap_env.tests"

        def __init__(self) -> None:
            self.value = outer()
            self.args = tuple(self.value)

    twin = copy.deepcopy(Holder())
    with pytest.raises(ValueError):
        OUTER.form(twin.value)  # deepcopy copied each row apart
    restack(twin)
    form = OUTER.form(twin.value)
    _write_through(form)
    assert twin.args[0] is twin.value.a and twin.args[3] is twin.value.b and twin.args[0][0, 1] == 1.5


@pytest.mark.parametrize("how", ["deepcopy", "pickle"])
def test_a_copied_vector_env_steps_like_the_original(how):
    """A copy's fused step writes into the copy's stacks, which its observations and the staged path read."""
    env = TimeGapMonitorVectorEnv(3, autoreset_mode="same_step")
    env.reset(seed=4)
    action = np.array([5, 2, 7])
    for _ in range(3):
        env.step(action)
    twin = copy.deepcopy(env) if how == "deepcopy" else pickle.loads(pickle.dumps(env))
    staged = copy.deepcopy(env)
    staged.task.fused = False
    for _ in range(4):
        results = [e.step(action) for e in (env, twin, staged)]
        for other in results[1:]:
            np.testing.assert_array_equal(other[0], results[0][0])
            np.testing.assert_array_equal(other[1], results[0][1])


def test_the_fused_step_follows_dynamics_set_after_the_first_reset():
    """The fused state is built once; set_dynamics changes the arrays it holds, as the staged path reads them."""
    envs = [TimeGapMonitorVectorEnv(2, autoreset_mode="same_step") for _ in range(2)]
    envs[1].task.fused = False
    for env in envs:
        env.reset(seed=1)
        env.task.loop.platoon.set_dynamics(np.array([[0.9], [0.3]]), 0.7)
    for _ in range(5):
        (fused, *_), (staged, *_) = (env.step(np.array([2, 6])) for env in envs)
        np.testing.assert_array_equal(fused, staged)


def test_the_fused_step_is_handed_about_fifty_arrays():
    env = TimeGapMonitorVectorEnv(2)
    env.reset(seed=0)

    def arrays(value: object) -> int:
        if isinstance(value, np.ndarray):
            return 1
        return sum(arrays(part) for part in value) if isinstance(value, tuple) else 0

    assert arrays(StepState(*env.task._state)) <= 60  # about 120 before the structures came stacked


def test_a_cache_index_naming_a_class_that_is_gone_is_compiled_anew(tmp_path):
    """numba unpickles a cache's index before it checks the stamp; an index written before a NamedTuple of a cached
    signature was renamed would raise at the kernel's first call. Under ``follow_sources`` it counts as stale."""
    import subprocess
    import sys

    module = tmp_path / "renamed.py"
    source = ("from typing import NamedTuple\nimport numba\nfrom timegap_env.compiled import follow_sources\n"
              "class {name}(NamedTuple):\n    x: float\n"
              "@numba.njit(cache=True)\ndef kernel(p):\n    return p.x + 1.0\n"
              "follow_sources(('renamed',))\nprint(kernel({name}(1.0)))\n")
    environment = {**__import__("os").environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(tmp_path)}
    for name in ("Before", "After"):
        module.write_text(source.format(name=name))
        out = subprocess.run([sys.executable, "-c", "import renamed"], capture_output=True, text=True, env=environment,
                             cwd=tmp_path)
        assert out.returncode == 0 and out.stdout.strip() == "2.0", out.stderr[-2000:]


def test_a_cache_is_fresh_by_content_not_by_modification_time(tmp_path):
    """A cached kernel is loaded from its module with a new modification time (what installing a wheel does to its
    files; numba before 0.68 read that as stale), compiled again when a module it reaches changes, and
    ``precompile.compiled_not_loaded`` tells the two apart."""
    import os
    import subprocess
    import sys

    source = ("import numba\nfrom timegap_env.compiled import follow_sources\nimport helper\n"
              "@numba.njit(cache=True)\ndef kernel(x):\n    return x + helper.OFFSET\n"
              "follow_sources(('stamped',), reached=('helper',))\nprint(kernel(1.0))\n"
              "from timegap_env.precompile import compiled_not_loaded\nprint(compiled_not_loaded())\n")

    def run(folder, offset):
        folder.mkdir(exist_ok=True)
        (folder / "stamped.py").write_text(source)
        (folder / "helper.py").write_text(f"OFFSET = {offset}\n")
        environment = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(folder)}
        out = subprocess.run([sys.executable, "-c", "import stamped"], capture_output=True, text=True, env=environment,
                             cwd=folder)
        assert out.returncode == 0, out.stderr[-2000:]
        return out.stdout.split()

    assert run(tmp_path / "a", 1.0) == ["2.0", "[]"]  # kernels outside the package are not counted
    first = next((tmp_path / "cache").rglob("stamped.kernel-*.nbi"))
    written = first.stat().st_mtime_ns
    os.utime(tmp_path / "a" / "stamped.py", ns=(0, 0))  # a new modification time, the same content: loaded
    assert run(tmp_path / "a", 1.0) == ["2.0", "[]"] and first.stat().st_mtime_ns == written
    assert run(tmp_path / "a", 2.0) == ["3.0", "[]"] and first.stat().st_mtime_ns != written  # helper changed


def test_precompile_names_the_package_kernels_a_process_compiled(tmp_path):
    import os
    import subprocess
    import sys

    code = ("import numpy as np\nimport timegap_env\nfrom timegap_env.monitoring.batch import _all_finite\n"
            "_all_finite(np.ones(2))\nfrom timegap_env.precompile import compiled_not_loaded\n"
            "print(compiled_not_loaded())\n")
    environment = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=environment)
            for _ in range(2)]
    assert [run.stdout.strip() for run in runs] == ["['timegap_env.monitoring.batch._all_finite']", "[]"], runs


def test_a_kernel_is_stamped_by_one_call_only(tmp_path, monkeypatch):
    """Two different calls may not stamp one kernel; the same call again (a module reloaded after an edit) may."""
    import importlib

    from timegap_env.compiled import follow_sources

    (tmp_path / "stamped_twice.py").write_text("import numba\n@numba.njit(cache=True)\ndef kernel(x):\n"
                                               "    return x\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cache"))
    importlib.import_module("stamped_twice")
    follow_sources(("stamped_twice",))
    follow_sources(("stamped_twice",))
    with pytest.raises(ValueError, match="stamped by two calls"):
        follow_sources(("stamped_twice",), reached=("timegap_env.config",))
    with pytest.raises(ValueError, match="stamped by two calls"):
        follow_sources(("timegap_env.sim.platoon",))  # the step's call stamps its kernels with the step's modules


def test_prefetch_item_hints_any_element_and_changes_nothing():
    from numba.core.errors import TypingError

    from timegap_env.compiled import prefetch_item

    @numba.njit
    def hinted(values, ring):  # noqa: ANN001, ANN202
        prefetch_item(values, (1, 3))  # a row's middle
        prefetch_item(ring, (0, 1))  # the remaining index 0
        prefetch_item(ring, (5, 100, 7))  # far past the end: a hint never faults
        return values.sum() + ring.sum()

    values, ring = np.arange(12.0).reshape(2, 6), np.arange(24, dtype=np.int64).reshape(2, 3, 4)
    assert hinted(values, ring) == values.sum() + ring.sum()

    @numba.njit
    def too_many(values):  # noqa: ANN001, ANN202
        prefetch_item(values, (0, 0, 0))

    with pytest.raises(TypingError):
        too_many(values)
