"""Scripts import the library, nothing of train/; the library imports nothing from train/; one
rollout loop in the code base (issues 23 and 38)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


SCRIPTS = {path.stem for path in (ROOT / "train").glob("*.py")} - {"__init__"}  # train/'s packages are not scripts


def imported_train(path: Path) -> set[str]:
    """The train/ modules and packages ``path`` imports (their first name below ``train``; ``train`` for the package
    itself)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and (node.module == "train" or node.module.startswith("train.")):
            found |= {alias.name for alias in node.names} if node.module == "train" else {node.module.split(".")[1]}
        elif isinstance(node, ast.Import):
            found |= {(alias.name + ".").split(".")[1] or "train" for alias in node.names
                      if alias.name == "train" or alias.name.startswith("train.")}  # "train": the package itself
    return found


def test_no_script_imports_anything_of_train():
    """A script imports the library only, never another module of train/ (what scripts share is in the library:
    timegap_env.studies, timegap_env.speed)."""
    for path in sorted((ROOT / "train").rglob("*.py")):
        assert not imported_train(path), path.relative_to(ROOT)


def test_the_library_imports_nothing_from_train():
    for path in sorted((ROOT / "timegap_env").rglob("*.py")):
        assert not imported_train(path), path


def test_one_rollout_loop():
    """Only the harness steps a vector env until its episodes end (``while active.any()``)."""
    loops = [path.relative_to(ROOT).as_posix() for folder in ("train", "timegap_env")
             for path in sorted((ROOT / folder).rglob("*.py")) if "while active.any()" in path.read_text()]
    assert loops == ["timegap_env/experiments/rollout.py"]
