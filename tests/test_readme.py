"""The README's examples run as pasted (with fewer training steps, to stay fast)."""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"


def python_block_after(heading: str) -> str:
    """The first ```python block after ``heading`` in the README."""
    text = README.read_text(encoding="utf-8")
    start = text.index(heading)
    match = re.search(r"```python\n(.*?)```", text[start:], flags=re.S)
    assert match, f"no python block after {heading!r}"
    return match.group(1)


def test_train_your_own_policy_runs_as_pasted():
    code = python_block_after("### Train your own policy")
    assert "total_timesteps=20_000" in code
    namespace: dict = {}
    exec(compile(code.replace("total_timesteps=20_000", "total_timesteps=256"), str(README), "exec"), namespace)
    assert namespace["env"].action_space.contains(namespace["action"])


def test_the_environment_example_runs_as_pasted():
    code = python_block_after("## The environment: `TimeGapMonitor-v0`")
    namespace: dict = {}
    exec(compile(code, str(README), "exec"), namespace)
    assert namespace["envs"].num_envs == 256
