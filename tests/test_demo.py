"""The demo writes its figure and table."""

import sys

from train import demo


def test_demo_writes_figure_and_table(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", ["demo", "--out", str(tmp_path)])
    demo.main()
    assert (tmp_path / "paper_scenario.png").stat().st_size > 10_000
    table = (tmp_path / "paper_scenario.md").read_text()
    assert table.count("\n| ") == 6  # header + five followers
    assert "| 5 |" in capsys.readouterr().out
