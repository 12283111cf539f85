"""train_ppo loses nothing (issue 22, items 1, 8 and 14): a run works beside --out and replaces it only when it has
ended; interrupted, fresh or resumed, it leaves the previous run whole; bad --out and --env-config are refused
before any work, on the command line as one line; TensorBoard logs go to the run; training.md says why there is no
share of the oracle gap instead of printing nan."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
import yaml
from stable_baselines3 import PPO

from timegap_env.agents.learned import LearnedPolicy
from timegap_env import DEFAULT_TASK
from train import train_ppo

ROOT = Path(__file__).resolve().parents[2]


def tiny(tmp_path: Path, out: Path, *extra: str) -> list[str]:
    """Arguments of a tiny normalised run into ``out`` (2 platoons, 5 s episodes, no warm-up)."""
    hyperparams = tmp_path / "ppo.yml"
    hyperparams.write_text(yaml.safe_dump({DEFAULT_TASK: {
        "n_envs": 2, "n_timesteps": 32, "policy": "MlpPolicy", "normalize": True, "n_steps": 16, "batch_size": 32,
        "n_epochs": 1, "policy_kwargs": "dict(net_arch=[8])", "env_kwargs": {"config": {"episode_duration": 5.0}},
    }}))
    return ["--hyperparams", str(hyperparams), "--no-warmup", "--out", str(out), "--no-progress-bar",
            "--curve-freq", "0", *extra]


def contents(directory: Path) -> dict[str, bytes]:
    """Every file under ``directory``, by relative path."""
    return {str(path.relative_to(directory)): path.read_bytes() for path in sorted(directory.rglob("*"))
            if path.is_file()}


def interrupt_after(monkeypatch: pytest.MonkeyPatch, calls: int) -> None:
    """Make training stop with a KeyboardInterrupt at the ``calls``-th environment step (as Ctrl-C would)."""
    seen = [0]

    def step(self) -> bool:
        seen[0] += 1
        if seen[0] >= calls:
            raise KeyboardInterrupt
        return True

    monkeypatch.setattr(train_ppo.EpisodeSummaries, "_on_step", step)


def test_an_interrupted_run_fresh_or_resumed_leaves_the_previous_run_whole(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.chdir(tmp_path)  # where TensorBoard's logs used to go (./runs)
    out = tmp_path / "run"
    train_ppo.main(tiny(tmp_path, out))
    assert sorted(path.name for path in out.iterdir()) == ["curve.csv", "curve.png", "env.json", "model.zip",
                                                           "tensorboard", "training.md", "vecnormalize.pkl"]
    assert any((out / "tensorboard").rglob("events.out.tfevents.*")) and not (tmp_path / "runs").exists()
    assert json.loads((out / "env.json").read_text())["normalize"] is True
    report = (out / "training.md").read_text()
    assert f"TensorBoard logs in `{out / 'tensorboard'}/`" in report and "| nan |" not in report
    before = contents(out)

    interrupt_after(monkeypatch, 3)  # a fresh run into the same directory, stopped before any checkpoint
    with pytest.raises(KeyboardInterrupt):
        train_ppo.main(tiny(tmp_path, out))
    assert contents(out) == before  # it used to delete vecnormalize.pkl, training.md and the curve first
    assert sorted(path.name for path in tmp_path.iterdir()) == ["ppo.yml", "run"]  # its work directory is gone

    interrupt_after(monkeypatch, 12)  # a resumed run, stopped after its checkpoint at 16 steps
    with pytest.raises(KeyboardInterrupt):
        train_ppo.main(tiny(tmp_path, out, "--resume", "--timesteps", "64", "--checkpoint-freq", "16"))
    assert contents(out) == before  # its checkpoints used to replace the run's model.zip
    partial = [path for path in tmp_path.iterdir() if path.name.startswith("run.partial-")]
    assert len(partial) == 1 and f"checkpoint at 48 steps is in {partial[0]}" in capsys.readouterr().err
    assert PPO.load(partial[0] / "model.zip", device="cpu").num_timesteps == 48
    assert LearnedPolicy.load(partial[0]).normalizer is not None  # a whole run: it can be evaluated or resumed

    monkeypatch.undo()
    monkeypatch.chdir(tmp_path)
    train_ppo.main(tiny(tmp_path, out, "--seed", "3"))  # a run that ends replaces the run (make train)
    assert "--seed 3` (fresh run)" in (out / "training.md").read_text()
    assert contents(out)["model.zip"] != before["model.zip"]
    assert not [path for path in tmp_path.iterdir() if ".replaced-" in path.name]


def test_out_that_is_a_file_or_holds_other_files_is_refused_before_any_work(tmp_path: Path) -> None:
    target = tmp_path / "table.md"
    target.write_text("keep me")
    with pytest.raises(NotADirectoryError, match=f"--out {target}: is an existing file"):
        train_ppo.main(tiny(tmp_path, target))
    with pytest.raises(NotADirectoryError, match=f"--out {target / 'run'}: {target} is a file"):
        train_ppo.main(tiny(tmp_path, target / "run"))
    assert target.read_text() == "keep me"
    # a directory that is not a run: a finished run would replace all of it
    with pytest.raises(ValueError, match=rf"--out {tmp_path}: holds \['ppo.yml', 'table.md'\], not only a training "
                                         "run's files"):
        train_ppo.main(tiny(tmp_path, tmp_path))
    assert sorted(path.name for path in tmp_path.iterdir()) == ["ppo.yml", "table.md"]


def test_bad_settings_are_one_line_on_the_command_line_before_any_work(tmp_path: Path) -> None:
    for arguments, message in (
            (["--env-config", '{"bogus": 1}'], "--env-config {\"bogus\": 1} merged into "),
            (["--env-config", '{"episode_duration": -1}'], "episode_duration"),
            (["--env-config", "[1]"], "argument --env-config: '[1]': must be a JSON object"),
    ):
        done = subprocess.run([sys.executable, "-m", "train.train_ppo", *tiny(tmp_path, tmp_path / "run"), *arguments],
                              cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert done.returncode != 0 and "Traceback" not in done.stderr, done.stderr
        assert message in done.stderr.strip().splitlines()[-1], done.stderr  # (argparse's usage lines before it)
        assert not (tmp_path / "run").exists()


def test_training_md_says_why_there_is_no_share_of_the_oracle_gap() -> None:
    # results/v0/ppo/training.md printed "nan": the oracle (-162.4) did not beat the best constant (-159.6) there
    reference = train_ppo.CurveReference([9000], 1.0, -159.6, "oracle_lookup_episode", -162.4, (-5.0, -0.5))
    assert math.isnan(reference.share(-160.0))
    assert train_ppo.share_text(reference, -160.0) == (
        "n/a: the oracle (-162.4) does not measurably beat the best constant (-159.6) on these episodes, its gain's interval "
        "[-5.0, -0.5] not above 0, so there is no gap to capture")
    assert train_ppo.share_text(train_ppo.CurveReference([9000], 1.0, -160.0, "o", -150.0, (2.0, 18.0)), -155.0) == "0.50"
    # a gain whose interval reaches 0 is no gap to divide by: v1's check episodes, a gain of 0.4
    assert math.isnan(train_ppo.CurveReference([9000], 1.0, -76.0, "o", -75.6, (-0.3, 1.1)).share(-70.0))


def test_a_run_into_a_symlinked_directory_replaces_the_directory_it_points_to(tmp_path: Path) -> None:
    target, link = tmp_path / "runs" / "ppo-1", tmp_path / "latest"
    train_ppo.main(tiny(tmp_path, target, "--tensorboard-log", str(tmp_path / "tb")))
    link.symlink_to(target, target_is_directory=True)
    before = contents(target)
    train_ppo.main(tiny(tmp_path, link, "--seed", "3", "--tensorboard-log", str(tmp_path / "tb")))
    assert link.is_symlink() and link.resolve() == target
    assert contents(target)["model.zip"] != before["model.zip"]
    assert sorted(path.name for path in target.parent.iterdir()) == ["ppo-1"]  # no work or replaced directory left


def test_a_run_that_fails_after_training_keeps_its_model(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """A failure between the final save and the publishing (the report here; the check episodes, a full disk) keeps the
    trained model in the work directory, whatever the checkpoint frequency (this run writes no periodic one)."""
    out = tmp_path / "run"

    def broken(*args: object) -> str:
        raise OSError("disk full")

    monkeypatch.setattr(train_ppo, "share_text", broken)
    with pytest.raises(OSError, match="disk full"):
        train_ppo.main(tiny(tmp_path, out))
    assert not out.exists()
    partial = [path for path in tmp_path.iterdir() if path.name.startswith("run.partial-")]
    assert len(partial) == 1 and f"checkpoint at 32 steps is in {partial[0]}" in capsys.readouterr().err
    assert LearnedPolicy.load(partial[0]).normalizer is not None


def test_a_publish_that_fails_leaves_out_as_it_was(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from timegap_env import cli

    out, work = tmp_path / "run", tmp_path / "work"
    for directory, text in ((out, "old"), (work, "new")):
        directory.mkdir()
        (directory / "training.md").write_text(text)
    real_rename = cli.os.rename

    def rename(source: object, target: object) -> None:
        if Path(str(source)) == work:
            raise PermissionError("no")
        real_rename(source, target)

    monkeypatch.setattr(cli.os, "rename", rename)
    with pytest.raises(PermissionError):
        cli.publish(work, out)
    assert (out / "training.md").read_text() == "old" and (work / "training.md").read_text() == "new"
    assert sorted(path.name for path in tmp_path.iterdir()) == ["run", "work"]
