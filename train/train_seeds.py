"""Train one recipe over several training seeds: one after another by default, side by side in worker processes or
on a Ray cluster with the harness's ``--backend`` (issue 39, item 4).

    python -m train.train_seeds --seeds 0 1 2 3 4 --out 'results/recipes/ppo_real_seed{seed}' \\
        -- --env-config "$(cat hyperparams/real_traffic.json)" --curve-freq 0
    python -m train.train_seeds --seeds 0 1 2 3 4 --out 'runs/real/seed{seed}' --backend ray --address auto -- ...

Each seed is ``python -m train.train_ppo ARGS --seed K --out OUT`` (everything after ``--`` is ``train_ppo``'s, seed
and out excepted), run in a child process where the piece runs, from the repository's root, so the run's
``training.md`` records the same command ``make train`` gives. ``--out`` holds ``{seed}``; relative to the
repository's root. On a Ray cluster a seed trains on whichever node takes it; its run directory comes back to this
machine and is written beside the others (through a partial directory, like train_ppo's own). A seed that fails
stops no other seed: the command ends with the failed seeds' errors after every seed has run, the others' runs
written.
"""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

from timegap_env import cli
from timegap_env.experiments import backends

OWN_FLAGS = ("--seed", "--out")  # train_ppo's arguments this script sets per seed


class Trained(NamedTuple):
    """What one seed's piece gives back."""

    where: str  # host:repository root it trained in
    files: dict[str, bytes]  # the run directory's files by relative path (none if it failed)
    error: str = ""  # why it failed ("": it did not)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    argv = list(sys.argv[1:] if argv is None else argv)
    mine, rest = (argv[:argv.index("--")], argv[argv.index("--") + 1:]) if "--" in argv else (argv, [])
    parser = argparse.ArgumentParser(prog="python -m train.train_seeds", description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", required=True, help="training seeds (train_ppo --seed)")
    parser.add_argument("--out", required=True,
                        help="each seed's run directory, with {seed} in it (relative: to the repository's root)")
    backends.add_arguments(parser)
    args = parser.parse_args(mine)
    if "{seed}" not in args.out or "{" in args.out.replace("{seed}", "") or "}" in args.out.replace("{seed}", ""):
        parser.error(f"--out {args.out!r}: must hold {{seed}} and no other braces, e.g. 'runs/recipe/seed{{seed}}'")
    if args.address is not None and Path(args.out).is_absolute():
        parser.error(f"--out {args.out!r}: relative with --address (a node writes it inside its copy of the repository)")
    if bad := [seed for seed in args.seeds if seed < 0]:
        parser.error(f"--seeds {bad}: must be >= 0")
    if len(set(args.seeds)) != len(args.seeds):
        parser.error(f"--seeds {args.seeds}: each seed once")
    if given := [flag for flag in rest if flag.split("=")[0] in OWN_FLAGS]:
        parser.error(f"train_ppo's {given}: set per seed by --seeds and --out")
    args.train_ppo = rest
    return args


def train_one(arguments: list[str], seed: int, out: str) -> Trained:
    """One seed's ``train_ppo`` in a child process, from the root of the repository this piece runs in."""
    where = backends.REPO  # the repository this piece runs in (a Ray worker: its copy of it)
    command = [sys.executable, "-m", "train.train_ppo", *arguments, "--seed", str(seed), "--out", out,
               "--no-progress-bar"]
    done = subprocess.run(command, cwd=where, stderr=subprocess.PIPE, text=True)  # its progress shown as it goes
    if done.returncode != 0:
        return Trained(f"{socket.gethostname()}:{where}", {}, f"train_ppo exited with {done.returncode}: "
                       + "\n".join(done.stderr.strip().splitlines()[-5:]))
    run = where / out
    files = {str(path.relative_to(run)): path.read_bytes() for path in sorted(run.rglob("*")) if path.is_file()}
    return Trained(f"{socket.gethostname()}:{where}", files)


def bring_back(run: Path, files: dict[str, bytes]) -> None:
    """A run trained elsewhere written to ``run`` on this machine: into a partial directory, then moved there."""
    work = cli.work_directory(run)
    for name, data in files.items():
        (work / name).parent.mkdir(parents=True, exist_ok=True)
        (work / name).write_bytes(data)
    cli.publish(work, run)


def main(argv: list[str] | None = None) -> None:
    args = parse_args(argv)
    backend = backends.Backend.from_args(args)
    outs = [args.out.replace("{seed}", str(seed)) for seed in args.seeds]
    for out in outs:
        cli.output_dir(backends.REPO / out)
    here = f"{socket.gethostname()}:{backends.REPO}"
    results = backend.map(train_one, [(args.train_ppo, seed, out) for seed, out in zip(args.seeds, outs)])
    for seed, out, trained in zip(args.seeds, outs, results):
        if trained.error:
            print(f"seed {seed}: failed at {trained.where}: {trained.error}", flush=True)
            continue
        if trained.where != here:
            bring_back(backends.REPO / out, trained.files)
        print(f"seed {seed}: {out} ({len(trained.files)} files, trained at {trained.where})", flush=True)
    if failed := [seed for seed, trained in zip(args.seeds, results) if trained.error]:
        raise RuntimeError(f"--seeds {failed}: train_ppo failed (above); the other seeds' runs are written")
    print(f"{len(outs)} seeds trained; {backend.describe()}")


if __name__ == "__main__":
    cli.run(main, "python -m train.train_seeds")
