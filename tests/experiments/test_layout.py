"""Scripts import the library, not each other; one rollout loop in the code base (issue 23)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def imported_scripts(path: Path) -> set[str]:
    """The train/ modules ``path`` imports."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and (node.module == "train" or node.module.startswith("train.")):
            found |= {alias.name for alias in node.names} if node.module == "train" else {node.module.split(".")[1]}
        elif isinstance(node, ast.Import):
            found |= {alias.name.split(".")[1] for alias in node.names if alias.name.startswith("train.")}
    return found


def test_no_script_imports_another():
    for path in sorted((ROOT / "train").glob("*.py")):
        assert not imported_scripts(path), path.name


def test_the_library_imports_no_script():
    for path in sorted((ROOT / "timegap_env").rglob("*.py")):
        assert not imported_scripts(path), path


def test_one_rollout_loop():
    """Only the harness steps a vector env until its episodes end (``while active.any()``)."""
    loops = [path.relative_to(ROOT).as_posix() for folder in ("train", "timegap_env")
             for path in sorted((ROOT / folder).rglob("*.py")) if "while active.any()" in path.read_text()]
    assert loops == ["timegap_env/experiments/rollout.py"]
