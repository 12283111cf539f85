"""Lean packaging (issue 23): the core dependencies, the extras, the version, the package data, the citation.

The clean-venv install (pip install ., the wheel, the sdist: the env steps without torch) needs pip and the network,
so it runs in .ci/package (from .ci/run), not here.
"""

import importlib.metadata
import importlib.resources
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import timegap_env

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
CORE = {"numpy", "numba", "gymnasium", "scipy"}


def _name(requirement: str) -> str:
    return re.split(r"[<>=!~\[; ]", requirement, maxsplit=1)[0].lower()


def test_the_core_dependencies_are_numpy_numba_gymnasium_scipy():
    assert {_name(requirement) for requirement in PYPROJECT["project"]["dependencies"]} == CORE


def test_the_extras_hold_the_rest_and_pin_torch_to_the_release_on_disk():
    extras = {extra: {_name(r): r for r in requirements}
              for extra, requirements in PYPROJECT["project"]["optional-dependencies"].items()}
    assert {"torch", "stable-baselines3", "tensorboard", "tqdm", "rich", "pyyaml", "matplotlib"} <= set(extras["train"])
    assert {"highway-env", "pygame-ce"} <= set(extras["render"]) and "highway-env" in extras["idm"]
    assert {"mkdocs-material", "mkdocstrings"} <= set(extras["docs"])
    assert {"pytest", "hypothesis", "mypy", "build"} <= set(extras["dev"])
    assert "ray" in extras["ray"]
    # any looser torch spec makes pip fetch a multi-GB CUDA build on this project's machines
    torch_specs = [requirements["torch"] for requirements in extras.values() if "torch" in requirements]
    assert torch_specs == ["torch==2.13.0"]
    makefile = (ROOT / "Makefile").read_text()
    assert re.search(r"^EXTRAS := dev,train,render,docs$", makefile, re.M), "make test/demo install every extra they use"


def test_the_version_is_the_installed_metadata():
    assert timegap_env.__version__ == importlib.metadata.version("timegap_env") == PYPROJECT["project"]["version"]
    assert "__version__" in timegap_env.__all__


def test_py_typed_and_the_presets_are_package_data():
    assert set(PYPROJECT["tool"]["setuptools"]["package-data"]["timegap_env"]) == {"py.typed", "sim/acc_presets.json"}
    package = importlib.resources.files("timegap_env")
    assert package.joinpath("py.typed").is_file() and package.joinpath("sim/acc_presets.json").is_file()


def test_importing_and_stepping_imports_no_extra():
    """What `import timegap_env` and a reset and a step load: none of the extras' packages (all are installed here)."""
    code = (
        "import sys, gymnasium as gym, timegap_env\n"
        "env = gym.make('TimeGapMonitor-v0'); env.reset(seed=0); env.step(env.action_space.sample())\n"
        "print(' '.join(sorted(m for m in ('torch', 'stable_baselines3', 'highway_env', 'pygame', 'matplotlib',"
        " 'tensorboard', 'tqdm', 'rich', 'ray') if m in sys.modules)))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT).stdout
    assert out.strip() == ""


@pytest.mark.parametrize("what, code, extra", [
    ("rendering", "env = gym.make('TimeGapMonitor-v0', render_mode='rgb_array'); env.reset(seed=0); env.render()",
     "render"),
    ("the IDM leader", "env = gym.make('TimeGapMonitor-v0'); env.reset(seed=0, options={'scenario': 'idm'})", "idm"),
])
def test_without_highway_env_the_error_names_the_extra(what, code, extra):
    blocked = "import sys; sys.modules['highway_env'] = sys.modules['pygame'] = None\nimport gymnasium as gym, timegap_env\n"
    run = subprocess.run([sys.executable, "-c", blocked + code], capture_output=True, text=True, cwd=ROOT)
    assert run.returncode != 0, what
    assert "MissingExtra" in run.stderr and f"pip install 'timegap_env[{extra}]'" in run.stderr, run.stderr[-2000:]


def test_the_citation_cites_the_paper_and_the_project():
    yaml = pytest.importorskip("yaml")
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert citation["cff-version"] == "1.2.0" and citation["type"] == "software"
    assert citation["version"] == PYPROJECT["project"]["version"]
    paper = citation["preferred-citation"]
    assert paper["title"] == "Real-time Monitoring of Autonomous Vehicle's Time Gap Variations: A Bayesian Framework"
    assert [(a["given-names"], a["family-names"]) for a in paper["authors"]] == [("Wissam", "Kontar"), ("Soyoung", "Ahn")]


def test_the_changelog_has_the_current_version():
    changelog = (ROOT / "CHANGELOG.md").read_text()
    assert re.search(rf"^## \[?{re.escape(PYPROJECT['project']['version'])}\]?", changelog, re.M)
