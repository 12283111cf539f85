"""``make bench`` of this tree against an earlier commit's, in the same run: did a change cost speed?

    python -m train.bench_against [--ref HEAD] [--rounds 2] [--out runs/bench_against.md]

Checks the commit out into a temporary git worktree and runs ``python -m train.bench`` there (its own package and
harness, imported from the worktree) and here by turns, ``--rounds`` times each, so that both see the same phases of
a shared machine. Each run measures its figures against references in its own process (CartPole-v1, a NumPy
reference, a child process), as ``make bench`` does; the table sets each row's value (the ratio where the row has
one, else the figure) of every run side by side, and the mean change of this tree's against the commit's. Writes
``--out`` (a markdown table) and each run's ``make bench`` table beside it (``<out>.ref1.md``, ``<out>.this1.md``,
...); refuses an existing ``--out``.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from timegap_env import cli

ROOT = Path(__file__).resolve().parents[1]


def rows(table: Path) -> dict[str, str]:
    """A ``make bench`` table's rows: measure -> its ratio to its outer reference (the last of the ratio cell's), else
    its value."""
    found = {}
    for line in table.read_text(encoding="utf-8").splitlines():
        cells = [cell.strip() for cell in line.strip().strip("|").split("|")]
        if line.startswith("| ") and len(cells) >= 4 and cells[0] != "measure" and not cells[0].startswith("---"):
            found[cells[0]] = cells[3].split(" / ")[-1] or cells[1]
    return found


def number(cell: str) -> float | None:
    """The leading number of a cell ("0.53x", "1,350.4x", "9.5 s (...)", "3.71 M"), None if it has none."""
    match = re.match(r"[\d,]*\.?\d+", cell.strip())
    return float(match.group().replace(",", "")) if match else None


def bench(tree: Path, out: Path) -> None:
    """``python -m train.bench --out out`` of the package and harness in ``tree``."""
    command = [sys.executable, "-m", "train.bench", "--out", str(out)]
    print(f"bench_against: {tree}", flush=True)
    subprocess.run(command, cwd=tree, env={**os.environ, "PYTHONPATH": str(tree), "MPLBACKEND": "Agg"}, check=True,
                   stdout=subprocess.DEVNULL)


def compare(ref: str, rounds: int, out: Path) -> str:
    """Run both benches by turns and return the comparison table."""
    runs: dict[str, list[dict[str, str]]] = {"ref": [], "this": []}
    with tempfile.TemporaryDirectory(prefix="bench_against_") as folder:
        worktree = Path(folder) / "ref"
        subprocess.run(["git", "worktree", "add", "--detach", str(worktree), ref], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            for round_ in range(rounds):
                for side, tree in (("ref", worktree), ("this", ROOT)):
                    table = out.with_name(f"{out.stem}.{side}{round_ + 1}.md")
                    bench(tree, table)
                    runs[side].append(rows(table))
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(worktree)], cwd=ROOT, check=False)
    lines = [f"# `make bench` of this tree against {ref}, {rounds} rounds by turns", "",
             "Each cell is the row's ratio to its same-process reference where it has one, else its figure; the last "
             "column is this tree's mean over the commit's mean (above 1: this tree's figure is larger).", "",
             "| measure | " + " | ".join(f"{ref} #{i + 1} | this #{i + 1}" for i in range(rounds)) + " | this / ref |",
             "|---|" + "---|---|" * rounds + "---|"]
    for measure in runs["ref"][0]:
        cells = [run.get(measure, "") for pair in zip(runs["ref"], runs["this"]) for run in pair]
        means = [[number(run.get(measure, "")) for run in runs[side]] for side in ("ref", "this")]
        ratio = ""
        if all(value for side in means for value in side):
            ratio = f"{(sum(means[1]) / rounds) / (sum(means[0]) / rounds):.3f}"  # type: ignore[arg-type]
        lines.append(f"| {measure} | " + " | ".join(cells) + f" | {ratio} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ref", default="HEAD", help="the commit to bench against, any git revision (default HEAD: "
                        "this tree's uncommitted changes against its last commit)")
    parser.add_argument("--rounds", type=cli.count, default=2, help="runs of each, by turns (default 2)")
    parser.add_argument("--out", type=Path, default=Path("runs/bench_against.md"))
    args = parser.parse_args(argv)
    out = cli.output_file(args.out)
    if out.exists():
        raise FileExistsError(f"--out {out}: exists; choose another (a second run overwrites nothing)")
    out.parent.mkdir(parents=True, exist_ok=True)
    table = compare(args.ref, args.rounds, out)
    out.write_text(table, encoding="utf-8")
    print(table)


if __name__ == "__main__":
    cli.run(main, 'python -m train.bench_against')
