"""``train.train_seeds``: a recipe's seeds through the harness's backends, each a train_ppo run as make train gives it;
a run trained elsewhere comes back; a failed seed stops no other."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from timegap_env import DEFAULT_TASK
from train import train_seeds

TINY = {"n_envs": 2, "n_timesteps": 64, "policy": "MlpPolicy", "normalize": True, "n_steps": 16, "batch_size": 32,
        "n_epochs": 1, "policy_kwargs": "dict(net_arch=[8])", "env_kwargs": {"config": {"episode_duration": 10.0}}}


@pytest.mark.parametrize("arguments, says", [
    (["--seeds", "0", "--out", "runs/x"], "must hold {seed}"),
    (["--seeds", "1", "1", "--out", "runs/x{seed}"], "each seed once"),
    (["--seeds", "1", "--out", "runs/x{seed}", "--", "--seed", "3"], "set per seed"),
    (["--seeds", "1", "--out", "runs/x{seed}{y}"], "no other braces"),
    (["--seeds", "-1", "--out", "runs/x{seed}"], "must be >= 0"),
    (["--seeds", "1", "--out", "/abs/x{seed}", "--backend", "ray", "--address", "auto"], "relative with --address"),
])
def test_bad_command_lines_are_refused(arguments: list[str], says: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        train_seeds.parse_args(arguments)
    assert says in capsys.readouterr().err


def test_each_seed_is_a_train_ppo_run_and_a_failed_one_stops_no_other(tmp_path: Path) -> None:
    hyperparams = tmp_path / "ppo.yml"
    hyperparams.write_text(yaml.safe_dump({DEFAULT_TASK: TINY}))
    out = f"{tmp_path}/seed{{seed}}"
    (tmp_path / "seed4").mkdir()
    (tmp_path / "seed4" / "notes.txt").write_text("keep me")  # train_ppo refuses an --out holding other files
    with pytest.raises(RuntimeError, match=r"--seeds \[4\]"):
        train_seeds.main(["--seeds", "4", "3", "--out", out, "--", "--hyperparams", str(hyperparams), "--no-warmup",
                          "--curve-freq", "0"])
    report = (tmp_path / "seed3" / "training.md").read_text()  # seed 3 trained after seed 4 failed
    assert "--seed 3" in report and "| timesteps, this command / total | 64 / 64 |" in report
    assert [path.name for path in (tmp_path / "seed4").iterdir()] == ["notes.txt"]


def test_a_run_trained_on_another_node_is_written_here(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def elsewhere(arguments: list[str], seed: int, out: str) -> train_seeds.Trained:
        return train_seeds.Trained("node-2:/tmp/ray/working_dir", {"training.md": f"seed {seed}".encode(),
                                                                   "tensorboard/events": b"\x00\x01"})

    monkeypatch.setattr(train_seeds, "train_one", elsewhere)
    train_seeds.main(["--seeds", "0", "1", "--out", f"{tmp_path}/r{{seed}}"])
    assert (tmp_path / "r1" / "training.md").read_text() == "seed 1"
    assert (tmp_path / "r0" / "tensorboard" / "events").read_bytes() == b"\x00\x01"
    assert sorted(path.name for path in tmp_path.iterdir()) == ["r0", "r1"]  # no partial directory left


def test_a_seeds_out_naming_a_file_is_refused_before_any_work(tmp_path: Path) -> None:
    (tmp_path / "seed1").write_text("keep me")
    with pytest.raises(NotADirectoryError, match=f"--out {tmp_path / 'seed1'}: is an existing file"):
        train_seeds.main(["--seeds", "0", "1", "--out", f"{tmp_path}/seed{{seed}}"])
    assert sorted(path.name for path in tmp_path.iterdir()) == ["seed1"]
