"""What the ``train/`` scripts share on the command line: output paths checked before any work, and bad input
reported as one line and a non-zero exit instead of a traceback.

    from timegap_env.cli import output_dir, run

    def main(argv=None):
        args = parser.parse_args(argv)
        output_dir(args.out)            # before any work: a file there is refused now, not after it
        ...

    if __name__ == "__main__":
        run(main, "python -m train.my_script")

The project's errors for bad input name the field or file and the value (``ValueError``, ``RunFileError`` among
them; ``OSError``: ``FileNotFoundError``, ``IsADirectoryError``, ``NotADirectoryError``, ``PermissionError``, a bad
gzip; ``EOFError``). :func:`run` prints those as ``<prog>: error: <message>`` on stderr and exits with 1; any other
exception is a bug and keeps its traceback. ``TIMEGAP_TRACEBACK=1`` in the environment shows the traceback of bad
input too. Ctrl-C stops with ``<prog>: interrupted`` and exit status 130.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

INPUT_ERRORS: tuple[type[BaseException], ...] = (ValueError, OSError, EOFError)  # bad input, named in the message
TRACEBACK_VARIABLE = "TIMEGAP_TRACEBACK"  # set to 1: bad input raises with its traceback
PARTIAL_SUFFIX = ".partial-"  # a run's work directory beside its --out: <out>.partial-<random>


def run(main: Callable[[], Any], prog: str) -> None:
    """Call ``main()``; bad input (:data:`INPUT_ERRORS`, or an error whose class has ``missing_extra = True``: an
    optional dependency not installed) exits with status 1 and its one-line message, Ctrl-C with 130, other
    exceptions propagate with their traceback."""
    try:
        main()
    except Exception as error:
        if not (isinstance(error, INPUT_ERRORS) or getattr(error, "missing_extra", False)) \
                or os.environ.get(TRACEBACK_VARIABLE, "") not in ("", "0"):
            raise
        message = " ".join(str(error).split()) or type(error).__name__  # one line, whatever the message held
        sys.exit(f"{prog}: error: {message} ({TRACEBACK_VARIABLE}=1 shows the traceback)")
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        sys.exit(130)


def _existing_file_on_the_way(path: Path) -> Path | None:
    """The first of ``path``'s ancestors (not ``path`` itself) that exists and is not a directory, if any."""
    for parent in reversed(path.absolute().parents):
        if parent.exists() and not parent.is_dir():
            return parent
    return None


def output_dir(path: str | Path, option: str = "--out") -> Path:
    """``path`` as a directory to write into, checked before any work: neither it nor a parent may be an existing
    file (``NotADirectoryError`` naming ``option`` and the path). Creates nothing."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(f"{option} {path}: is an existing file, not a directory; give a directory")
    blocking = _existing_file_on_the_way(path)
    if blocking is not None:
        raise NotADirectoryError(f"{option} {path}: {blocking} is a file, not a directory")
    return path


def output_file(path: str | Path, option: str = "--out") -> Path:
    """``path`` as a file to write, checked before any work: it may not be a directory (``IsADirectoryError``) and no
    parent may be an existing file (``NotADirectoryError``), each naming ``option`` and the path. Creates nothing."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"{option} {path}: is a directory; give a file name")
    blocking = _existing_file_on_the_way(path)
    if blocking is not None:
        raise NotADirectoryError(f"{option} {path}: {blocking} is a file, not a directory")
    return path


def count(text: str) -> int:
    """An argparse ``type``: a count, an integer >= 1; anything else is a usage error naming it."""
    import argparse

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: must be an integer >= 1") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: must be an integer >= 1")
    return value


def write_rows(rows: list[dict[str, Any]], path: Path) -> None:
    """``rows`` (dicts with the first row's keys) as a CSV at ``path``, floats to 6 significant digits."""
    import csv

    with open(path, "w", newline="", encoding="utf-8") as file:
        writer = csv.DictWriter(file, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows({key: f"{value:.6g}" if isinstance(value, float) else value for key, value in row.items()}
                         for row in rows)


def json_object(text: str) -> dict[str, Any]:
    """An argparse ``type``: ``text`` as a JSON object; anything else is a usage error saying what was wrong."""
    import argparse

    try:
        value = json.loads(text)
    except (json.JSONDecodeError, RecursionError) as error:  # (nested beyond Python's stack)
        raise argparse.ArgumentTypeError(f"{text!r}: not JSON ({error})") from error
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"{text!r}: must be a JSON object ({{...}}), not {type(value).__name__}")
    return value


def work_directory(out: str | Path, copy: bool = False) -> Path:
    """A new directory beside ``out`` for a run to write into, ``<out>.partial-<random>`` (with ``copy``, holding a
    copy of ``out``'s files, to resume from or to keep the ones the run does not write); :func:`publish` moves it to
    ``out`` when the run has ended, so that a run stopped before leaves ``out`` whole."""
    out = Path(os.path.realpath(out))  # beside the directory itself when out is a symlink to it
    out.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f"{out.name}{PARTIAL_SUFFIX}", dir=out.parent))
    umask = os.umask(0o022)
    os.umask(umask)
    os.chmod(work, 0o777 & ~umask)  # as mkdir would make it (mkdtemp's is private)
    if copy and out.is_dir():
        shutil.copytree(out, work, dirs_exist_ok=True)
    return work


def publish(work: Path, out: str | Path) -> None:
    """Move the finished run ``work`` to ``out``, the previous content of ``out`` deleted only once it is there."""
    out = Path(os.path.realpath(out))  # a symlink out keeps pointing at the run
    if not out.exists():
        os.rename(work, out)
        return
    previous = Path(tempfile.mkdtemp(prefix=f"{out.name}.replaced-", dir=out.parent))
    os.rename(out, previous)  # (rename onto an existing non-empty directory fails)
    try:
        os.rename(work, out)
    except BaseException:  # out back in place: a failed publish changes nothing
        os.rename(previous, out)
        raise
    shutil.rmtree(previous, ignore_errors=True)
