"""train.compare_curves: several runs' learning curves side by side, refusing runs whose references differ."""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import pytest

from train import compare_curves

ROOT = Path(__file__).resolve().parents[2]
HEADER = "timesteps,mean_return,share_of_oracle_gap,best_blind_return,oracle_return\n"


def make_run(folder: Path, rows: list[str], hidden: bool = False) -> Path:
    folder.mkdir(parents=True)
    shutil.copy(ROOT / "results" / ("ppo_v1_nomonitor" if hidden else "ppo_v1") / "env.json", folder / "env.json")
    (folder / "curve.csv").write_text(HEADER + "".join(row + "\n" for row in rows))
    return folder


def run_main(monkeypatch: pytest.MonkeyPatch, *arguments: object) -> None:
    monkeypatch.setattr(sys, "argv", ["compare_curves", *map(str, arguments)])
    compare_curves.main()


def test_two_runs_side_by_side(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    a = make_run(tmp_path / "a", ["100,-90.0,nan,-80.0,-79.5", "200,-82.0,nan,-80.0,-79.5"])
    b = make_run(tmp_path / "b", ["100,-85.0,nan,-80.0,-79.5"], hidden=True)
    run_main(monkeypatch, a, b, "--out", tmp_path / "out")
    text = (tmp_path / "out" / "curves.md").read_text()
    assert "| a | ppo; relative; 1 frame(s) | 200 | -82.0 | -82.0 (200) |" in text
    assert "hidden deviation" in text and "the best blind constant returns -80.0 there, the oracle -79.5" in text
    assert "No share of the oracle's gap" in text and (tmp_path / "out" / "curves.png").is_file()


def test_runs_whose_references_differ_are_refused_and_nothing_is_written(tmp_path: Path,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    a = make_run(tmp_path / "a", ["100,-90.0,0.5,-80.0,-70.0"])
    b = make_run(tmp_path / "b", ["100,-90.0,0.5,-81.0,-70.0"])
    with pytest.raises(ValueError, match=r"different references .*: a: .*; b: "):
        run_main(monkeypatch, a, b, "--out", tmp_path / "out")
    (b / "curve.csv").write_text("timesteps,mean_return\n100,-90\n")  # an older curve.csv, without the references
    with pytest.raises(ValueError, match=f"{b / 'curve.csv'}: not a learning curve"):
        run_main(monkeypatch, a, b, "--out", tmp_path / "out")
    with pytest.raises(ValueError, match="no runs given"):
        run_main(monkeypatch, "--out", tmp_path / "out")
    assert not (tmp_path / "out").exists()
