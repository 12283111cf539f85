"""The documentation in docs/: every ```python block of its pages runs as pasted, each alone; its links into results/
lead to committed files; and the site builds with ``mkdocs build --strict`` where mkdocs is installed.

A block right after a ``<!-- not run: ... -->`` line is not run (its libraries live in ``.venv-clients``: Tianshou,
TorchRL, RLlib); the tests for those libraries are ``tests/clients``. Blocks that read the OpenACC or NGSIM data
skip, saying where they looked, when the data are absent.

A block right after ``<!-- edit: <file>, after the line ending `<text>` -->`` (or ``before the line starting
`<text>```) is an insertion into the library's own file; the block after ``<!-- run with the edits above -->``
runs in a fresh process on a copy of the package with its page's edits applied.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
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
BLOCK = re.compile(r"(<!-- (?P<marker>[^>]*?) -->\n)?```python\n(?P<code>.*?)```", flags=re.S)
BLOCKS = [
    pytest.param(page, match["code"], match["marker"], id=f"{page.stem}-{index}")
    for page in PAGES
    for index, match in enumerate(BLOCK.finditer(page.read_text(encoding="utf-8")))
]
EDIT = re.compile(r'edit: (?P<file>\S+), (?P<where>after the line ending|before the line starting) `(?P<anchor>.*)`')
RUN_EDITED = "run with the edits above"
FAST = {"total_timesteps=20_000": "total_timesteps=256"}  # training as the pages say it, cut short
LINK = re.compile(r"\]\((?P<target>[^)#\s]+)(#[^)]*)?\)")
MKDOCS_PACKAGES = ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python")


def skip_without_data(code: str) -> None:
    if "openacc" in code and not timegap_env.default_openacc_dir().is_dir():
        pytest.skip(f"the OpenACC data are not at {timegap_env.default_openacc_dir()} (set TIMEGAP_OPENACC_PATH)")
    if "ngsim" in code and not timegap_env.default_ngsim_path().exists():
        pytest.skip(f"the NGSIM data are not at {timegap_env.default_ngsim_path()} (set TIMEGAP_NGSIM_PATH)")
    if '"simulator": "sumo"' in code and importlib.util.find_spec("libsumo") is None:
        pytest.skip("libsumo is not installed (the sumo extra: pip install -e '.[sumo]')")


@pytest.fixture
def scenario_tables():
    """A block may register a leader family (docs/extending.md): put the registry back afterwards."""
    saved = dict(scenarios.LEADER_FAMILIES)
    yield
    scenarios.LEADER_FAMILIES.clear()
    scenarios.LEADER_FAMILIES.update(saved)


def test_the_docs_have_their_pages_and_blocks():
    names = {page.name for page in PAGES}
    assert {"index.md", "environment.md", "benchmark.md", "extending.md", "api.md"} <= names
    assert len(BLOCKS) >= 15


@pytest.mark.parametrize(("page", "code", "marker"), BLOCKS)
def test_every_python_block_runs_alone_as_pasted(page: Path, code: str, marker: str | None, scenario_tables):
    if marker and marker.startswith("not run:"):
        pytest.skip(f"{page.name}: marked {marker}")
    if marker and (EDIT.fullmatch(marker) or marker == RUN_EDITED):
        pytest.skip(f"{page.name}: an edit of the library or its example: test_edits_of_the_library_work runs them")
    assert marker is None, f"{page.name}: unknown marker <!-- {marker} --> before a block"
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
    skipped = [code for _, code, marker in (param.values for param in BLOCKS) if marker and marker.startswith("not run:")]
    assert skipped, "docs/libraries.md shows TorchRL, Tianshou and RLlib as text"
    for code in skipped:
        assert re.search(r"^from (torchrl|tianshou|ray|mo_gymnasium|morl_baselines)", code, flags=re.M), code


def apply_edit(package: Path, marker: str, code: str) -> None:
    """Insert ``code`` into the file of the copied ``package`` that ``marker`` (an edit marker) names, at its anchor
    line, which must occur exactly once."""
    edit = EDIT.fullmatch(marker)
    assert edit, marker
    path = package.parent / edit["file"]
    lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
    after = edit["where"].startswith("after")
    hits = [i for i, line in enumerate(lines)
            if (line.rstrip("\n").endswith(edit["anchor"]) if after else line.startswith(edit["anchor"]))]
    assert len(hits) == 1, f"{edit['file']}: {len(hits)} lines match the anchor {edit['anchor']!r}"
    at = hits[0] + (1 if after else 0)
    path.write_text("".join(lines[:at]) + code + "".join(lines[at:]), encoding="utf-8")


EDITED_EXAMPLES = [pytest.param(page, id=page.stem) for page in PAGES
                   if f"<!-- {RUN_EDITED} -->" in page.read_text(encoding="utf-8")]


@pytest.mark.parametrize("page", EDITED_EXAMPLES)
def test_edits_of_the_library_work(page: Path, tmp_path: Path):
    """The page's edits of the library, applied to a copy of the package, make its example run (docs/extending.md:
    a degradation kind in one file). The example runs in a fresh process, importing the copy."""
    package = tmp_path / "timegap_env"
    shutil.copytree(REPO / "timegap_env", package, ignore=shutil.ignore_patterns("__pycache__"))
    examples = []
    for match in BLOCK.finditer(page.read_text(encoding="utf-8")):
        if match["marker"] and EDIT.fullmatch(match["marker"]):
            apply_edit(package, match["marker"], match["code"])
        elif match["marker"] == RUN_EDITED:
            examples.append(match["code"])
    assert examples
    for code in examples:
        check = f"import timegap_env\nassert timegap_env.__file__.startswith({str(tmp_path)!r}), timegap_env.__file__\n"
        run = subprocess.run([sys.executable, "-c", check + code], cwd=tmp_path, capture_output=True, text=True,
                             timeout=600, env={**os.environ, "PYTHONPATH": str(tmp_path)})
        assert run.returncode == 0, f"{page.name}'s edited example failed:\n{run.stdout[-2000:]}{run.stderr[-5000:]}"


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
    assert (site / "index.html").is_file() and (site / "results" / "benchmark" / "leaderboard" / "index.html").is_file()
    assert "Observation Space" in (site / "environment" / "index.html").read_text(encoding="utf-8")
