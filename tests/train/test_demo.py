"""The demo writes its figure and table, and the committed table is what it writes today."""

import sys
from pathlib import Path

from train import demo

RESULTS = Path(__file__).resolve().parents[2] / "results"


def test_demo_writes_figure_and_table(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["demo", "--out", str(tmp_path)])
    demo.main()
    assert (tmp_path / "paper_scenario.png").stat().st_size > 10_000
    table = (tmp_path / "paper_scenario.md").read_text()
    assert table.count("\n| ") == 6  # header + five followers
    assert "| 5 |" in capsys.readouterr().out
    assert table == (RESULTS / "paper_scenario.md").read_text(), "results/ is stale: rerun `make demo` and commit"
