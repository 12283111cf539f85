"""The package's build backend (pyproject.toml's ``build-backend``): setuptools', and a wheel that carries the numba
cache of the kernels a first step needs, compiled while the wheel is built (:mod:`timegap_env.precompile`).

A wheel cannot run code when it is installed, so the compiling happens when it is built: ``pip install .`` (which
builds a wheel here, then installs it), ``pip wheel`` and ``python -m build``. Building one therefore needs the
core dependencies (numpy, numba, gymnasium, scipy, read from pyproject.toml's ``[project] dependencies``) and takes
about 15 s longer. ``TIMEGAP_ENV_PRECOMPILE=0`` builds a wheel without the cache; an editable install
(``pip install -e .``) never has one: its kernels are cached in the source tree at their first use.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

from setuptools import build_meta as _setuptools
from setuptools.build_meta import *  # noqa: F403  the hooks this module does not change are setuptools' own
from setuptools.command.build_py import build_py

PACKAGE = "timegap_env"
SWITCH = "TIMEGAP_ENV_PRECOMPILE"  # "0": no cache in the wheel


def get_requires_for_build_wheel(config_settings: dict[str, Any] | None = None) -> list[str]:
    """setuptools' requirements and, unless the switch is off, the package's own (the precompile imports it)."""
    required = list(_setuptools.get_requires_for_build_wheel(config_settings))
    if os.environ.get(SWITCH) != "0":
        required += tomllib.loads(Path("pyproject.toml").read_text())["project"]["dependencies"]
    return required


class BuildPy(build_py):
    """setuptools' ``build_py``, then the numba cache compiled into the built package's ``__pycache__`` folders
    (not for an editable install, nor with ``TIMEGAP_ENV_PRECOMPILE=0``)."""

    def run(self) -> None:
        built = Path(self.build_lib)
        if not getattr(self, "editable_mode", False):  # what an earlier build left (its cache, modules since
            shutil.rmtree(built / PACKAGE, ignore_errors=True)  # deleted) is not this source's
        super().run()
        if getattr(self, "editable_mode", False) or os.environ.get(SWITCH) == "0":
            return
        # numba's settings (NUMBA_CACHE_DIR, NUMBA_OPT, NUMBA_DISABLE_JIT, ...) are the user's, not the wheel's
        environment = {name: value for name, value in os.environ.items() if not name.startswith("NUMBA_")}
        inherited = [os.environ["PYTHONPATH"]] if os.environ.get("PYTHONPATH") else []  # pip's isolated build's
        environment["PYTHONPATH"] = os.pathsep.join([str(built.resolve()), *inherited])
        done = subprocess.run([sys.executable, "-m", f"{PACKAGE}.precompile"], cwd=built, env=environment,
                              capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise RuntimeError(f"{PACKAGE}: compiling the kernels into the wheel failed ({SWITCH}=0 builds one without "
                               f"them):\n{done.stdout}{done.stderr[-4000:]}")
        print(done.stdout.strip())
        for compiled in (built / PACKAGE).rglob("__pycache__/*.pyc"):  # pip byte-compiles what it installs
            compiled.unlink()
