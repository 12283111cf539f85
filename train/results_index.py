"""``results/README.md``: which command wrote each committed result, and whether it is older than its code.

    python -m train.results_index [--out results/README.md]

Each entry of :data:`RESULTS` is a path under ``results/`` and the command that writes it (the Makefile's
``reproduce``, ``benchmark`` and ``train`` targets run them all). "Current" is read from git: the last commit that
changed the path against the last commit that changed the code that writes it (its script, the ``timegap_env``
package and the code the scripts share, timegap_env/studies and timegap_env/speed); a result older than its code says so and
since which commit, and may or may not change when rerun.
"""

from __future__ import annotations

import argparse
import subprocess
from pathlib import Path

from timegap_env import cli

REPO = Path(__file__).resolve().parents[1]
CODE = ("timegap_env", "timegap_env/studies", "timegap_env/speed")  # what every result depends on, besides its own script

# path under results/ -> (the command that writes it, its script under train/)
RESULTS: dict[str, tuple[str, str]] = {
    "benchmark": ("python -m train.benchmark --out results/benchmark --force (make benchmark)", "benchmark"),
    "paper_scenario.md": ("python -m train.demo --out results", "demo"),
    "paper_scenario.png": ("python -m train.demo --out results", "demo"),
    "paper": ("python -m train.reproduce_paper --out results/paper", "reproduce_paper"),
    "field": ("python -m train.field_validation --out results/field; python -m train.calibrate_openacc --out "
              "results/field", "field_validation"),
    "degradation": ("python -m train.choose_degradation_mix --out results/degradation; python -m "
                    "train.value_of_information --out results/degradation", "value_of_information"),
    "monitoring": ("python -m train.detection_benchmark --out results/monitoring", "detection_benchmark"),
    "monitor_window.md": ("python -m train.choose_window --out results/monitor_window.md", "choose_window"),
    "rule": ("python -m train.tune_rule --out results/rule", "tune_rule"),
    "task": ("python -m train.task_map --out results/task", "task_map"),
    "env_frame.png": ("python -m train.render_frame --out results/env_frame.png", "render_frame"),
    "sweep": ("python -m train.sweep train/sweeps/example.yml --out results/sweep/example", "sweep"),
    "sumo": ("python -m train.sumo_report --chart-step-tuning results/rule/tuning.csv --backend processes --out "
             "results/sumo", "sumo_report"),
    "bench.md": ("python -m train.bench --out results/bench.md", "bench"),
    "bench_against": ("python -m train.bench_against --ref 8fffc68 --rounds 2 [--first-steps 10] --out "
                      "results/bench_against/<name>.md (issue40_state: the state's allocation; issue40_at_67c52ab, "
                      "issue40_whole: the whole issue, --first-steps 10; each against the code before issue 40)",
                      "bench_against"),
    "ppo_v1": ("python -m train.train_ppo --out results/ppo_v1 (make train)", "train_ppo"),
    "ppo_v1_nomonitor": ("python -m train.train_ppo --hide-features monitor --out results/ppo_v1_nomonitor (make train)",
                         "train_ppo"),
    "ppo_v1_rawgap": ("python -m train.train_ppo --env-config '{\"monitor\": {\"estimator\": \"raw_gap\"}}' --out "
                      "results/ppo_v1_rawgap (make train)", "train_ppo"),
    "recipes": ("make train (ppo*_seed1-4) and make recipes; curves: python -m train.compare_curves ... --out "
                "results/recipes/curves", "train_ppo"),
    "morl": ("python -m train.train_morl --out results/morl (in .venv-clients: make clients)", "train_morl"),
    "ray": ("python -m train.bench_ray --out results/ray/scaling.md (Ray: make clients)", "bench_ray"),
    "v0/ppo": ("python -m train.train_ppo --env-id TimeGapMonitor-v0 --out results/v0/ppo (make train)", "train_ppo"),
    "v0/rule": ("python -m train.tune_rule --env-id TimeGapMonitor-v0 --out results/v0/rule", "tune_rule"),
    "v0/rllib": ("an earlier train.train_rllib, on TimeGapMonitor-v0 (today's trains the default task)",
                 "train_rllib"),
}


def git(*arguments: str) -> str:
    """git's output in the repository ("" if git fails or is not here)."""
    try:
        return subprocess.run(["git", *arguments], cwd=REPO, capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        return ""


def first_written(path: Path) -> tuple[str, str] | None:
    """(hash, date) of the first commit that held ``path``'s content as it is now (a move keeps it: the same
    blob), or None if no commit holds it yet."""
    blob = git("hash-object", str(path)).strip()
    log = git("log", "--reverse", "--format=%H %cs", f"--find-object={blob}").split() if blob else []
    return (log[0], log[1]) if log else None


def written(path: str) -> tuple[str, str] | None:
    """The newest first-written commit among the files of ``results/<path>`` (None: some is not committed)."""
    files = [REPO / line for line in git("ls-files", f"results/{path}").splitlines()]
    commits = [first_written(file) for file in files]
    if not files or any(commit is None for commit in commits):
        return None
    newest = commits[0]
    for commit in commits[1:]:
        assert commit is not None and newest is not None
        if is_ancestor(newest[0], commit[0]):
            newest = commit
    return newest


def is_ancestor(older: str, newer: str) -> bool:
    """Whether commit ``older`` is an ancestor of (or is) ``newer``."""
    return subprocess.run(["git", "merge-base", "--is-ancestor", older, newer], cwd=REPO).returncode == 0


def state(path: str, script: str) -> str:
    """"current", or since which commit of its code the result is older than that code."""
    if not git("rev-parse", "HEAD"):
        return "unknown (no git history here)"
    result = written(path)
    if result is None:
        return "written, not yet committed"
    code = git("log", "-1", "--format=%H %cs", "--", f"train/{script}.py", *CODE).split()
    if not code or is_ancestor(code[0], result[0]):
        return f"current (written {result[1]})"
    return f"older than its code (written {result[1]}; code changed {code[1]}, {code[0][:8]}): rerun to be sure"


def markdown() -> str:
    """The index."""
    lines = ["# results/", "", "Written by `python -m train.results_index` (make benchmark runs it). Every committed "
             "result, the command that writes it, and whether it is older than the code that writes it (its script "
             "and the `timegap_env` package; from git). `make reproduce` reruns them all; `make train` the models.",
             "", "| path | command | state |", "|---|---|---|"]
    for path, (command, script) in RESULTS.items():
        lines.append(f"| `{path}` | `{command}` | {state(path, script)} |")
    listed = {path.split("/")[0] for path in RESULTS}
    unlisted = sorted(p.name for p in (REPO / "results").iterdir() if p.name not in listed | {"README.md", "v0"})
    if unlisted:
        lines += ["", f"Not listed (no command known): {', '.join(unlisted)}."]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path("runs/results_README.md"),
                        help="the index (default: %(default)s; make benchmark writes results/README.md)")
    args = parser.parse_args()
    cli.output_file(args.out)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(markdown(), encoding="utf-8")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    cli.run(main, "python -m train.results_index")
