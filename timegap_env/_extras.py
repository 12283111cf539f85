"""The optional dependencies (pyproject's extras): a clear ImportError naming the extra to install."""

from __future__ import annotations

import importlib.util

__all__ = ["MissingExtra", "require"]


class MissingExtra(ImportError):
    """An optional dependency is not installed; the message names the extra (the scripts print it as one line)."""

    missing_extra = True


def require(extra: str, *modules: str, needed_for: str) -> None:
    """Raise ImportError, naming ``pip install 'timegap_env[<extra>]'``, unless every one of ``modules`` is importable."""
    missing = [module for module in modules if not _importable(module)]
    if missing:
        raise MissingExtra(
            f"{needed_for} needs {', '.join(missing)}, which the core install leaves out: "
            f"pip install 'timegap_env[{extra}]'",
            name=missing[0],
        )


def _importable(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # ValueError: sys.modules[module] is None, i.e. blocked
        return False
