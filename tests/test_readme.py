"""Every Python block of the README runs as pasted, each alone (with fewer training steps, to stay fast)."""

import re
from pathlib import Path

import pytest

import timegap_env

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)


def python_block_after(heading: str) -> str:
    """The first ```python block after ``heading`` in the README."""
    text = README.read_text(encoding="utf-8")
    match = re.search(r"```python\n(.*?)```", text[text.index(heading):], flags=re.S)
    assert match, f"no python block after {heading!r}"
    return match.group(1)


def run(code: str) -> dict:
    namespace: dict = {}
    exec(compile(code, str(README), "exec"), namespace)
    return namespace


def test_the_readme_has_its_blocks():
    assert len(BLOCKS) >= 3


def test_the_readme_is_short_and_keeps_the_quick_start():
    """At most 200 lines (the rest is in docs/), the two commands, and every figure it shows committed."""
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200
    assert "make demo" in text and "make test" in text
    figures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert figures
    for figure in figures:
        assert (README.parent / figure).is_file(), f"the README shows {figure}, which is not there"


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_every_python_block_runs_alone_as_pasted(index):
    code = BLOCKS[index]
    if "openacc" in code and not timegap_env.default_openacc_dir().is_dir():
        pytest.skip(f"the OpenACC data are not at {timegap_env.default_openacc_dir()} (set TIMEGAP_OPENACC_PATH)")
    namespace = run(code.replace("total_timesteps=20_000", "total_timesteps=256"))
    for name in ("env", "envs", "workers"):
        if hasattr(namespace.get(name), "close"):
            namespace[name].close()


def test_train_your_own_policy_gives_an_action():
    code = python_block_after("### Train your own policy")
    assert "total_timesteps=20_000" in code
    namespace = run(code.replace("total_timesteps=20_000", "total_timesteps=256"))
    assert namespace["env"].action_space.contains(namespace["action"])


def test_the_environment_example_makes_what_it_says():
    namespace = run(python_block_after("## The environment: `TimeGapMonitor-v1`"))
    assert namespace["envs"].num_envs == 256
    assert namespace["workers"].num_envs == 2
    namespace["workers"].close()
