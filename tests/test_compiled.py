"""timegap_env.compiled: numba caches stamped by content, kernels stamped once, prefetch hints."""

from __future__ import annotations

import numba
import numpy as np
import pytest


def test_a_cache_index_naming_a_class_that_is_gone_is_compiled_anew(tmp_path):
    """numba unpickles a cache's index before it checks the stamp; an index written before a NamedTuple of a cached
    signature was renamed would raise at the kernel's first call. Under ``follow_sources`` it counts as stale."""
    import subprocess
    import sys

    module = tmp_path / "renamed.py"
    source = ("from typing import NamedTuple\nimport numba\nfrom timegap_env.compiled import follow_sources\n"
              "class {name}(NamedTuple):\n    x: float\n"
              "@numba.njit(cache=True)\ndef kernel(p):\n    return p.x + 1.0\n"
              "follow_sources('renamed')\nprint(kernel({name}(1.0)))\n")
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
              "follow_sources('stamped', reached=('helper',))\nprint(kernel(1.0))\n"
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
    follow_sources("stamped_twice")
    follow_sources("stamped_twice")
    with pytest.raises(ValueError, match="stamped by two calls"):
        follow_sources("stamped_twice", reached=("timegap_env.config",))
    with pytest.raises(ValueError, match="stamped by two calls"):
        follow_sources("timegap_env.sim.platoon", reached=("timegap_env.config",))  # its module's call stamped it


def test_every_cached_kernel_of_the_package_is_stamped_with_the_modules_it_reaches():
    """Each module of kernels stamps them (``follow_sources(__name__)``), with the modules their compiled code and
    constants come from, derived: the fused step's reach every stage's module, the config its constants come from
    and the state module that generates its views."""
    import importlib
    import pkgutil

    from numba.core.dispatcher import Dispatcher

    import timegap_env
    from timegap_env.compiled import reached_modules
    from timegap_env.envs.step_kernel import fused_step

    unstamped = []
    for module in pkgutil.walk_packages(timegap_env.__path__, "timegap_env."):
        if module.name.startswith(("timegap_env.speed.ppo", "timegap_env.studies")):
            continue  # need the train extra; they define no kernel
        for value in vars(importlib.import_module(module.name)).values():
            cache_file = getattr(getattr(value, "_cache", None), "_cache_file", None)
            if isinstance(value, Dispatcher) and cache_file is not None and not hasattr(cache_file, "_followed"):
                unstamped.append(f"{value.py_func.__module__}.{value.py_func.__name__}")
    assert not unstamped
    step = {f"timegap_env.{name}" for name in (
        "compiled", "state", "config", "envs.action", "sim.counter_noise", "sim.platoon", "monitoring.sensors",
        "monitoring.monitor", "monitoring.posterior", "monitoring.charts", "monitoring.loop", "envs.reward",
        "envs.totals", "envs.observation", "envs.info", "envs.episodes", "envs.step_kernel")}  # the list kept by hand
    assert step <= reached_modules(fused_step)
    assert fused_step._cache._cache_file._source_stamp.startswith("sha256 of timegap_env.compiled, timegap_env.config")


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


def test_an_edit_of_a_module_a_kernel_reaches_makes_its_cache_stale(tmp_path):
    """Without naming it: a constant imported from another module of the kernel's package, and one computed at
    import from a third module's (``reached_modules``' one level of imports)."""
    import os
    import subprocess
    import sys

    package = tmp_path / "pkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "kernels.py").write_text(
        "import numba\nfrom timegap_env.compiled import follow_sources\nfrom pkg.offsets import OFFSET, SCALE\n"
        "@numba.njit(cache=True)\ndef kernel(x):\n    return x * SCALE + OFFSET\nfollow_sources(__name__)\n"
        "print(kernel(1.0))\n")
    (package / "offsets.py").write_text("from pkg.base import BASE\nOFFSET = 1.0\nSCALE = 2.0 * BASE\n")

    def run(offset: float, base: float) -> str:
        (package / "base.py").write_text(f"BASE = {base}\n")
        (package / "offsets.py").write_text(f"from pkg.base import BASE\nOFFSET = {offset}\nSCALE = 2.0 * BASE\n")
        environment = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(tmp_path)}
        out = subprocess.run([sys.executable, "-c", "import pkg.kernels"], capture_output=True, text=True,
                             env=environment, cwd=tmp_path)
        assert out.returncode == 0, out.stderr[-2000:]
        return out.stdout.strip()

    assert [run(1.0, 1.0), run(1.0, 1.0), run(5.0, 1.0), run(5.0, 3.0)] == ["3.0", "3.0", "7.0", "11.0"]
