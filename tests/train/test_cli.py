"""The train/ scripts on the command line (issue 22, item 8): bad input is one line naming it and a non-zero exit, no
traceback; an output path that cannot be written is refused before any work, not after it."""

from __future__ import annotations

import ast
import importlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from timegap_env import cli
from timegap_env.leaders import default_openacc_dir

ROOT = Path(__file__).resolve().parents[2]
SCRIPTS = sorted(path.stem for path in (ROOT / "train").glob("*.py") if 'if __name__ == "__main__":' in path.read_text())
DIRECTORY_OUT = ["calibrate_openacc", "choose_degradation_mix", "choose_learner", "choose_recipe", "policy_behaviour", "compare_curves", "demo", "detection_benchmark", "benchmark",
                 "field_validation", "reproduce_paper", "sumo_report", "sweep", "task_map", "train_morl", "train_ppo", "train_rllib", "tune_rule",
                 "value_of_information"]  # --out is a directory
FILE_OUT = ["bench", "bench_against", "bench_ray", "choose_window", "record_behaviour", "render_frame", "results_index"]  # --out is a file
OPENACC_FILE = "astazero_dynamic_part22.csv.gz"  # a small one


def test_run_turns_bad_input_into_one_line_and_keeps_bugs_tracebacks(monkeypatch: pytest.MonkeyPatch,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    def bad(error: BaseException):
        def main() -> None:
            raise error
        return main

    monkeypatch.delenv(cli.TRACEBACK_VARIABLE, raising=False)
    for error in (ValueError("x = 3:\n must be < 2"), FileNotFoundError("data.csv: no such file"),
                  IsADirectoryError("--out d: is a directory"), EOFError("truncated")):
        with pytest.raises(SystemExit) as stopped:
            cli.run(bad(error), "python -m train.x")
        assert stopped.value.code == (f"python -m train.x: error: {' '.join(str(error).split())} "
                                      "(TIMEGAP_TRACEBACK=1 shows the traceback)")  # exit status 1
    with pytest.raises(KeyError):  # a bug: its traceback
        cli.run(bad(KeyError("a")), "python -m train.x")
    with pytest.raises(SystemExit) as stopped:
        cli.run(bad(KeyboardInterrupt()), "python -m train.x")
    assert stopped.value.code == 130 and "python -m train.x: interrupted" in capsys.readouterr().err
    monkeypatch.setenv(cli.TRACEBACK_VARIABLE, "1")
    with pytest.raises(ValueError):
        cli.run(bad(ValueError("x")), "python -m train.x")


def test_output_paths_are_checked_without_creating_anything(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    assert cli.output_dir(tmp_path / "new" / "dir") == tmp_path / "new" / "dir"
    assert cli.output_file(tmp_path / "new" / "file.md") == tmp_path / "new" / "file.md"
    assert sorted(path.name for path in tmp_path.iterdir()) == ["file"]
    with pytest.raises(NotADirectoryError, match=f"--out {tmp_path / 'file'}: is an existing file"):
        cli.output_dir(tmp_path / "file")
    with pytest.raises(NotADirectoryError, match=f"--x {tmp_path / 'file' / 'a' / 'b'}: {tmp_path / 'file'} is a file"):
        cli.output_dir(tmp_path / "file" / "a" / "b", "--x")
    with pytest.raises(IsADirectoryError, match=f"--out {tmp_path}: is a directory"):
        cli.output_file(tmp_path)
    with pytest.raises(NotADirectoryError, match="is a file"):
        cli.output_file(tmp_path / "file" / "out.md")


def test_every_script_runs_its_main_through_the_one_line_handler() -> None:
    # bench_monitor writes no file; train_seeds' --out is a pattern of directories (tests/train/test_train_seeds.py)
    assert set(SCRIPTS) == set(DIRECTORY_OUT) | set(FILE_OUT) | {"bench_monitor", "train_seeds"}
    for name in SCRIPTS:
        tree = ast.parse((ROOT / "train" / f"{name}.py").read_text())
        guard = next(node for node in tree.body if isinstance(node, ast.If) and "__main__" in ast.unparse(node.test))
        assert ast.unparse(guard.body[-1]) == f"cli.run(main, 'python -m train.{name}')", name


def call_main(name: str, arguments: list[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """``train.<name>.main`` with ``arguments``, as its command line (some mains read sys.argv)."""
    module = importlib.import_module(f"train.{name}")
    monkeypatch.setattr(sys, "argv", [f"train/{name}.py", *arguments])
    if module.main.__code__.co_argcount:
        module.main(arguments)
    else:
        module.main()


@pytest.mark.parametrize("name", DIRECTORY_OUT)
def test_out_naming_a_file_is_refused_before_any_work(name: str, tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    target = tmp_path / "results.md"
    target.write_text("keep me")
    arguments = (["train/sweeps/example.yml"] if name == "sweep" else []) + ["--out", str(target)]
    monkeypatch.chdir(ROOT)
    with pytest.raises(NotADirectoryError, match=f"--out {target}: is an existing file"):
        call_main(name, arguments, monkeypatch)
    assert target.read_text() == "keep me" and sorted(path.name for path in tmp_path.iterdir()) == ["results.md"]


@pytest.mark.parametrize("name", FILE_OUT)
def test_out_naming_a_directory_is_refused_before_any_work(name: str, tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    if name == "bench_ray":
        pytest.importorskip("ray", reason="bench_ray needs Ray before it reads --out")
    monkeypatch.chdir(ROOT)
    with pytest.raises(IsADirectoryError, match=f"--out {tmp_path}: is a directory"):
        call_main(name, ["--out", str(tmp_path)], monkeypatch)
    assert not any(tmp_path.iterdir())


def truncated_openacc(tmp_path: Path) -> Path:
    """A directory holding one OpenACC file cut in half."""
    source = default_openacc_dir() / OPENACC_FILE
    if not source.exists():
        pytest.skip(f"OpenACC data absent at {source}")
    directory = tmp_path / "openacc"
    directory.mkdir()
    data = source.read_bytes()
    (directory / OPENACC_FILE).write_bytes(data[:len(data) // 2])
    return directory


@pytest.mark.parametrize("command", [
    ["train.field_validation", "--data", "{data}"],
    ["train.calibrate_openacc", "--presets", "{tmp}/presets.json"],
])
def test_a_truncated_data_file_is_one_line_naming_it(command: list[str], tmp_path: Path) -> None:
    data = truncated_openacc(tmp_path)
    command = [part.format(data=data, tmp=tmp_path) for part in command]
    done = subprocess.run([sys.executable, "-m", *command, "--out", str(tmp_path / "out")], cwd=ROOT,
                          capture_output=True, text=True, timeout=300,
                          env={**os.environ, "TIMEGAP_OPENACC_PATH": str(data), "MPLBACKEND": "Agg"})
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith(f"python -m {command[0]}: error: ") and str(data / OPENACC_FILE) in last, last
    assert not (tmp_path / "out").exists() and not (tmp_path / "presets.json").exists()


def test_a_work_directory_is_published_whole_or_not_at_all(tmp_path: Path) -> None:
    """What train_ppo and train_rllib write through: a run in <out>.partial-*, --out replaced only at the end."""
    from timegap_env import cli

    out = tmp_path / "run"
    out.mkdir()
    (out / "selection.md").write_text("kept")
    (out / "training.md").write_text("old")
    work = cli.work_directory(out, copy=True)
    assert work.parent == tmp_path and work.name.startswith(f"run{cli.PARTIAL_SUFFIX}")
    assert (work / "selection.md").read_text() == "kept"  # a copy: the files the run does not write stay
    (work / "training.md").write_text("new")
    assert (out / "training.md").read_text() == "old"  # --out untouched while the run works
    cli.publish(work, out)
    assert (out / "training.md").read_text() == "new" and (out / "selection.md").read_text() == "kept"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # no work or replaced directory left
    fresh = cli.work_directory(tmp_path / "new", copy=True)  # nothing to copy yet
    assert not any(fresh.iterdir())
    cli.publish(fresh, tmp_path / "new")
    assert (tmp_path / "new").is_dir()


def test_a_missing_extra_is_one_line_and_a_bugs_import_error_keeps_its_traceback(
        monkeypatch: pytest.MonkeyPatch) -> None:
    from timegap_env._extras import MissingExtra
    from timegap_env.sim.sumo import SumoNotInstalled

    monkeypatch.delenv(cli.TRACEBACK_VARIABLE, raising=False)
    for error in (MissingExtra("rendering needs pygame: pip install 'timegap_env[render]'"),
                  SumoNotInstalled("simulator = 'sumo' needs libsumo, which is not installed: pip install x")):
        def main(error: BaseException = error) -> None:
            raise error
        with pytest.raises(SystemExit) as stopped:
            cli.run(main, "python -m train.x")
        assert str(stopped.value.code).startswith(f"python -m train.x: error: {error}")

    def buggy() -> None:
        raise ImportError("cannot import name 'x'")
    with pytest.raises(ImportError):
        cli.run(buggy, "python -m train.x")
