"""The package's modules import along the data flow only, never upward, and never in a cycle (issue 40):
ground floor (compiled, state, config, tasks, generators, _extras) -> leaders -> sim -> monitoring -> envs ->
agents, experiments -> the package's front (its __init__, cli, precompile) and what the scripts of train/ share: its
studies and speed measures. Imports inside functions count too."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "timegap_env"
GROUND = {"compiled", "state", "config", "tasks", "generators", "_extras"}
LAYERS = {"leaders": 1, "sim": 2, "monitoring": 3, "envs": 4, "agents": 5, "experiments": 5, "studies": 6, "speed": 6}
FRONT = 6  # timegap_env/__init__.py, cli.py, precompile.py


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(path): path for path in PACKAGE.rglob("*.py")}


def layer(module: str) -> int:
    parts = module.split(".")
    if len(parts) == 1:
        return FRONT
    return 0 if parts[1] in GROUND else LAYERS.get(parts[1], FRONT)


def imports(module: str) -> set[str]:
    """The package's modules (or packages) ``module`` imports, anywhere in its file."""
    path, found = MODULES[module], set()
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[:len(package) - node.level + 1] + ([base] if base else []))
            for alias in node.names:
                name = f"{base}.{alias.name}"
                found.add(name if name in MODULES else base)
        elif isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
    return {name for name in found if name in MODULES and name != module}


def test_no_module_imports_a_later_layer():
    upward = [f"{module} -> {other}" for module in sorted(MODULES) for other in sorted(imports(module))
              if layer(other) > layer(module)]
    assert not upward


def test_no_import_cycles():
    edges = {module: imports(module) for module in MODULES}
    state: dict[str, int] = {}  # 1 on the path, 2 done
    cycles: list[str] = []

    def visit(module: str, path: list[str]) -> None:
        state[module] = 1
        for other in sorted(edges[module]):
            if state.get(other) == 1:
                cycles.append(" -> ".join([*path[path.index(other):], other]))
            elif other not in state:
                visit(other, [*path, other])
        state[module] = 2

    for module in sorted(MODULES):
        if module not in state:
            visit(module, [module])
    assert not cycles


def test_the_layers_name_every_module():
    """A new top-level module or subpackage gets its layer here (else it counts as the front)."""
    top = {path.stem if path.is_file() else path.name for path in PACKAGE.iterdir()
           if (path.suffix == ".py" or (path / "__init__.py").is_file())}
    assert top - {"__init__", "cli", "precompile"} <= GROUND | set(LAYERS)


def test_the_parser_sees_imports_of_every_kind():
    """Relative, absolute and function-level imports are all found (else the tests above would pass vacuously)."""
    assert "timegap_env.monitoring.loop" in imports("timegap_env.envs.task")
    assert "timegap_env.sim.sumo" in imports("timegap_env.envs.task")  # imported inside a function
    assert "timegap_env.state" in imports("timegap_env.sim.platoon")
    assert layer("timegap_env.state") < layer("timegap_env.leaders.profile") < layer("timegap_env.sim.platoon") \
        < layer("timegap_env.monitoring.loop") < layer("timegap_env.envs.task") < layer("timegap_env.agents.policies")
