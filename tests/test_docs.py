"""The documentation in docs/: every ```python block of its pages runs as pasted, each alone; its links into results/
lead to committed files; and the site builds with ``mkdocs build --strict`` where mkdocs is installed.

A block right after a ``<!-- not run: ... -->`` line is not run (its libraries live in ``.venv-clients``: Tianshou,
TorchRL, RLlib); the tests for those libraries are ``tests/clients``. Blocks that read the OpenACC or NGSIM data
skip, saying where they looked, when the data are absent.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from importlib.util import find_spec
from pathlib import Path

import pytest

import timegap_env
from timegap_env.leaders import scenarios

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"
PAGES = sorted(DOCS.glob("*.md"))
BLOCK = re.compile(r"(<!-- not run: (?P<why>[^>]*?) -->\n)?```python\n(?P<code>.*?)```", flags=re.S)
BLOCKS = [
    pytest.param(page, match["code"], match["why"], id=f"{page.stem}-{index}")
    for page in PAGES
    for index, match in enumerate(BLOCK.finditer(page.read_text(encoding="utf-8")))
]
FAST = {"total_timesteps=20_000": "total_timesteps=256"}  # training as the pages say it, cut short
LINK = re.compile(r"\]\((?P<target>[^)#\s]+)(#[^)]*)?\)")
MKDOCS_PACKAGES = ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python")


def skip_without_data(code: str) -> None:
    if "openacc" in code and not timegap_env.default_openacc_dir().is_dir():
        pytest.skip(f"the OpenACC data are not at {timegap_env.default_openacc_dir()} (set TIMEGAP_OPENACC_PATH)")
    if "ngsim" in code and not timegap_env.default_ngsim_path().exists():
        pytest.skip(f"the NGSIM data are not at {timegap_env.default_ngsim_path()} (set TIMEGAP_NGSIM_PATH)")


@pytest.fixture
def scenario_tables():
    """A block may register a leader family (docs/extending.md): put the registry back afterwards."""
    saved = dict(scenarios.LEADER_FAMILIES)
    yield
    scenarios.LEADER_FAMILIES.clear()
    scenarios.LEADER_FAMILIES.update(saved)


def test_the_docs_have_their_pages_and_blocks():
    names = {page.name for page in PAGES}
    assert {"index.md", "environment.md", "evaluation.md", "extending.md", "api.md"} <= names
    assert len(BLOCKS) >= 15


@pytest.mark.parametrize(("page", "code", "not_run"), BLOCKS)
def test_every_python_block_runs_alone_as_pasted(page: Path, code: str, not_run: str | None, scenario_tables):
    if not_run:
        pytest.skip(f"{page.name}: marked not run ({not_run})")
    skip_without_data(code)
    for slow, fast in FAST.items():
        code = code.replace(slow, fast)
    namespace: dict = {"__name__": f"docs.{page.stem}"}
    exec(compile(code, str(page), "exec", dont_inherit=True), namespace)  # not this file's __future__ imports
    for name in ("env", "envs", "workers", "venv"):
        if hasattr(namespace.get(name), "close"):
            namespace[name].close()


def test_the_blocks_not_run_are_the_client_libraries():
    """Only the libraries of .venv-clients are left out, and those pages still show them."""
    skipped = [code for _, code, why in (param.values for param in BLOCKS) if why]
    assert skipped, "docs/libraries.md shows TorchRL, Tianshou and RLlib as text"
    for code in skipped:
        assert re.search(r"^from (torchrl|tianshou|ray)", code, flags=re.M), code


@pytest.mark.parametrize("page", [*PAGES, REPO / "README.md"], ids=lambda page: page.name)
def test_relative_links_lead_to_files(page: Path):
    """Links into results/ and between pages lead to committed files (the site shows results/ as it is)."""
    for match in LINK.finditer(page.read_text(encoding="utf-8")):
        target = match["target"]
        if "://" in target or target.startswith("mailto:"):
            continue
        assert (page.parent / target).resolve().is_file(), f"{page.name} links to {target}, which is not there"


def test_the_feature_table_is_written_once():
    """The observation's feature table lives in the env's docstring (rendered in docs/environment.md), nowhere else."""
    row = re.compile(r"^\|\s*0\s*`?deviation", flags=re.M)
    for page in [*PAGES, REPO / "README.md"]:
        assert not row.search(page.read_text(encoding="utf-8")), f"{page.name} repeats the feature table"
    assert "::: timegap_env.envs.env.TimeGapMonitorEnv" in (DOCS / "environment.md").read_text(encoding="utf-8")


def test_every_page_is_in_the_nav():
    config = (REPO / "mkdocs.yml").read_text(encoding="utf-8")
    for page in PAGES:
        assert f": {page.name}" in config, f"docs/{page.name} is missing from mkdocs.yml's nav"


def test_mkdocs_builds_the_site_strictly(tmp_path: Path):
    missing = [package for package in MKDOCS_PACKAGES if find_spec(package.split(".")[0]) is None
               or find_spec(package) is None]
    if missing:
        pytest.skip(f"mkdocs is not installed ({', '.join(missing)} missing): pip install -e '.[docs]' "
                    "(mkdocs-material, mkdocstrings[python])")
    command = [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(REPO / "mkdocs.yml"),
               "--site-dir", str(tmp_path / "site")]
    run = subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "NO_MKDOCS_2_WARNING": "1"})
    assert run.returncode == 0, f"{' '.join(command)} exited {run.returncode}:\n{run.stdout[-3000:]}{run.stderr[-5000:]}"
    site = tmp_path / "site"
    assert (site / "index.html").is_file() and (site / "results" / "eval" / "table" / "index.html").is_file()
    assert "Observation Space" in (site / "environment" / "index.html").read_text(encoding="utf-8")
