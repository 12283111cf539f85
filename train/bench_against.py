"""``make bench`` of this tree against an earlier commit's, in the same run: did a change cost speed?

    python -m train.bench_against [--ref HEAD] [--rounds 2] [--first-steps 10] [--out runs/bench_against.md]

Checks the commit out into a temporary git worktree and runs ``python -m train.bench`` there (its own package and
harness, imported from the worktree) and here by turns, ``--rounds`` times each, so that both see the same phases of
a shared machine. Each run measures its figures against references in its own process (CartPole-v1, a NumPy
reference, a child process), as ``make bench`` does; the table sets each row's value (the ratio where the row has
one, else the figure) of every run side by side, and the mean change of this tree's against the commit's. Writes
``--out`` (a markdown table) and each run's ``make bench`` table beside it (``<out>.ref1.md``, ``<out>.this1.md``,
...); refuses an existing ``--out``. ``make bench`` times the first step after ``pip install`` once per run; with
``--first-steps N`` both trees' wheels are built once and N first steps of each, by turns, add their medians.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from timegap_env import cli
from timegap_env.speed import cold

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
    """``python -m train.bench --out out`` of the package and harness in ``tree`` (``out`` relative to here, not to
    ``tree``)."""
    command = [sys.executable, "-m", "train.bench", "--out", str(out.resolve())]
    print(f"bench_against: {tree}", flush=True)
    subprocess.run(command, cwd=tree, env={**os.environ, "PYTHONPATH": str(tree), "MPLBACKEND": "Agg"}, check=True,
                   stdout=subprocess.DEVNULL)


def first_steps(trees: dict[str, Path], work: Path, runs: int) -> dict[str, list[float]]:
    """CPU seconds of ``runs`` first steps after ``pip install`` of each tree's wheel (built once, in ``work``), the
    trees by turns (``timegap_env.speed.cold``'s child, its own copy in each tree building that tree's wheel)."""
    sites = {}
    for side, tree in trees.items():
        folder = work / f"wheel_{side}"  # beside the reference's worktree, which may be work / "ref"
        folder.mkdir()
        build = ("from pathlib import Path\ntry:\n    from timegap_env.speed.cold import install_wheel\n"
                 "except ImportError:  # a tree from before the speed code moved into the package\n"
                 "    from train.speed.cold import install_wheel\n"
                 f"install_wheel(Path({str(folder)!r}))")
        subprocess.run([sys.executable, "-c", build], cwd=tree, env={**os.environ, "PYTHONPATH": str(tree)}, check=True,
                       capture_output=True)
        sites[side] = folder / "site"
    seconds: dict[str, list[float]] = {side: [] for side in trees}
    for _ in range(runs):
        for side, site in sites.items():
            check = f"import timegap_env\nassert timegap_env.__file__.startswith({str(site)!r}), timegap_env.__file__"
            seconds[side].append(cold.first_step("TimeGapMonitor-v0", check, None, site, after=cold.LOADED).cpu_seconds)
    return seconds


def compare(ref: str, rounds: int, out: Path, runs: int = 0) -> str:
    """Run both benches by turns (and ``runs`` first steps after install of each, by turns) and return the
    comparison table."""
    tables: dict[str, list[dict[str, str]]] = {"ref": [], "this": []}
    with tempfile.TemporaryDirectory(prefix="bench_against_") as folder:
        worktree = Path(folder) / "ref"
        subprocess.run(["git", "worktree", "add", "--detach", str(worktree), ref], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            for round_ in range(rounds):
                for side, tree in (("ref", worktree), ("this", ROOT)):
                    table = out.with_name(f"{out.stem}.{side}{round_ + 1}.md")
                    bench(tree, table)
                    tables[side].append(rows(table))
            starts = first_steps({"ref": worktree, "this": ROOT}, Path(folder), runs) if runs else {}
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(worktree)], cwd=ROOT, check=False)
    lines = [f"# `make bench` of this tree against {ref}, {rounds} rounds by turns", "",
             "Each cell is the row's ratio to its same-process reference where it has one, else its figure; the last "
             "column is this tree's mean over the commit's mean (above 1: this tree's figure is larger).", "",
             "| measure | " + " | ".join(f"{ref} #{i + 1} | this #{i + 1}" for i in range(rounds)) + " | this / ref |",
             "|---|" + "---|---|" * rounds + "---|"]
    for measure in tables["ref"][0]:
        cells = [run.get(measure, "") for pair in zip(tables["ref"], tables["this"]) for run in pair]
        means = [[number(run.get(measure, "")) for run in tables[side]] for side in ("ref", "this")]
        ratio = ""
        if all(value for side in means for value in side):
            ratio = f"{(sum(means[1]) / rounds) / (sum(means[0]) / rounds):.3f}"  # type: ignore[arg-type]
        lines.append(f"| {measure} | " + " | ".join(cells) + f" | {ratio} |")
    if starts:
        medians = {side: statistics.median(values) for side, values in starts.items()}
        lines += ["", f"First step after `pip install` of each tree's wheel, {runs} runs each by turns [CPU s]: "
                  f"{ref} median {medians['ref']:.3f} ({', '.join(f'{v:.2f}' for v in starts['ref'])}), this tree "
                  f"median {medians['this']:.3f} ({', '.join(f'{v:.2f}' for v in starts['this'])}): this / ref "
                  f"{medians['this'] / medians['ref']:.3f}."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ref", default="HEAD", help="the commit to bench against, any git revision (default HEAD: "
                        "this tree's uncommitted changes against its last commit)")
    parser.add_argument("--rounds", type=cli.count, default=2, help="runs of each, by turns (default 2)")
    parser.add_argument("--first-steps", type=int, default=0, help="first steps after install of each tree, by turns")
    parser.add_argument("--out", type=Path, default=Path("runs/bench_against.md"))
    args = parser.parse_args(argv)
    out = cli.output_file(args.out)
    if out.exists():
        raise FileExistsError(f"--out {out}: exists; choose another (a second run overwrites nothing)")
    out.parent.mkdir(parents=True, exist_ok=True)
    if args.first_steps < 0:
        parser.error(f"--first-steps {args.first_steps}: must be >= 0")
    table = compare(args.ref, args.rounds, out, args.first_steps)
    out.write_text(table, encoding="utf-8")
    print(table)


if __name__ == "__main__":
    cli.run(main, 'python -m train.bench_against')
