"""mkdocs hooks: the committed results/ (tables and figures, each written by the command that produces it) become
part of the site as they are, never pasted into a page.

The pages link to them as ``../results/...`` (right when the Markdown is read in the repository); in the site they
sit at ``results/...`` beside the pages, so those links are rewritten while building.
"""

from __future__ import annotations

import re
from pathlib import Path

from mkdocs.structure.files import File, Files

RESULTS = Path(__file__).resolve().parents[1] / "results"
SUFFIXES = (".md", ".png")


def on_files(files: Files, config) -> Files:  # noqa: ANN001
    for path in sorted(RESULTS.rglob("*")):
        if path.suffix in SUFFIXES and path.is_file():
            uri = "results/" + path.relative_to(RESULTS).as_posix()
            files.append(File.generated(config, uri, abs_src_path=str(path)))
    return files


def on_page_markdown(markdown: str, page, config, files) -> str:  # noqa: ANN001
    if page.file.src_uri.startswith("results/"):
        return markdown
    return re.sub(r"\]\(\.\./results/", "](results/", markdown)
