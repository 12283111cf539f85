"""train/field_validation.py: the monitor on a few real OpenACC runs writes its report, table and figures."""

import csv
import os
import re
import sys

import numpy as np
import pytest

from timegap_env.leaders import default_openacc_dir, read_openacc
from train import field_validation

DATA = default_openacc_dir()
RUNS = [  # S and L in both halves (name order alternates A, B), and one run driven by people
    "astazero_dynamic_part18", "astazero_dynamic_part19", "astazero_dynamic_part20", "astazero_dynamic_part21",
    "astazero_handling_part22",
]
FIGURES = ("openacc_distributions.png", "openacc_separation.png", "openacc_chart_example.png", "openacc_window.png")


def shared_data():
    if not DATA.exists():
        pytest.skip(f"OpenACC data absent at {DATA} (set $TIMEGAP_OPENACC_PATH)")
    return DATA


@pytest.fixture(scope="module")
def out(tmp_path_factory):
    shared_data()
    out = tmp_path_factory.mktemp("field")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(sys, "argv", ["field_validation", "--out", str(out), "--runs", *RUNS])
        field_validation.main()
    return out


def section(report: str, number: int) -> str:
    """The text of the report's section ``number`` (from its heading to the next)."""
    return report.split(f"\n## {number}.")[1].split("\n## ")[0]


def table_rows(report: str, first_cell: str) -> list[list[str]]:
    """The cells of every markdown table row of ``report`` whose first cell starts with ``first_cell``."""
    return [[cell.strip() for cell in line.strip("|").split("|")] for line in report.splitlines()
            if line.startswith(f"| {first_cell}")]


def test_the_report_table_and_figures_are_written_without_nan(out):
    report = (out / "openacc.md").read_text()
    assert report.startswith("# The monitor on real cars") and "`python -m train.field_validation`" in report
    assert f"`{os.path.relpath(DATA.resolve(), field_validation.REPO)}`" in report and all(run in report for run in RUNS)
    assert not re.search(r"\bnan\b", report, re.IGNORECASE)
    with (out / "openacc_followers.csv").open() as handle:
        followers = list(csv.DictReader(handle))
    assert {row["run"] for row in followers} == set(RUNS)
    assert not any(value.lower() == "nan" or value == "" for row in followers for value in row.values())
    for figure in FIGURES:
        assert (out / figure).stat().st_size > 20_000, figure


def test_the_numbers_are_sane(out):
    report = (out / "openacc.md").read_text()
    with (out / "openacc_followers.csv").open() as handle:
        followers = list(csv.DictReader(handle))
    gap = {group: np.array([float(row["tau_default"]) for row in followers if row["group"] == group])
           for group in ("S", "L", "human")}
    assert all(values.size for values in gap.values())
    assert np.all((gap["S"] > 0.3) & (gap["S"] < 2.5)) and np.median(gap["L"]) > np.median(gap["S"]) + 0.5
    assert all(float(row["driving_s"]) >= field_validation.MIN_DRIVING_TIME for row in followers)
    # The env's monitor separates S from L on half B: its row of the accuracy table.
    (separation,) = table_rows(section(report, 3), "monitor, prior s0 = 5 m")
    threshold, accuracy_b = float(separation[1]), float(separation[3])
    assert np.median(gap["S"]) < threshold < np.median(gap["L"]) and accuracy_b >= 0.8
    # The chart raises alarms on every setting, and the window study covers every candidate on both halves.
    for group in ("S", "L"):
        (chart,) = table_rows(section(report, 4), f"{group} | ")
        assert 0 < float(chart[3]) < 3600 / 0.1
    windows = table_rows(section(report, 5), "0.5") + table_rows(section(report, 5), "all data")
    assert len(windows) == 4 and "**Verdict.**" in report


def test_a_repeated_run_is_found():
    directory = shared_data()
    runs = [read_openacc(directory / f"{name}.csv.gz") for name in ("astazero_dynamic_part22", "astazero_dynamic_part23")]
    assert field_validation.repeated_runs(runs) == {"astazero_dynamic_part22": "astazero_dynamic_part23"}
    assert field_validation.repeated_runs(runs[1:]) == {}


def test_the_threshold_separates_and_the_accuracy_counts_both_classes():
    values = np.array([0.8, 0.9, 1.0, 1.1, 2.0, 2.2, 2.5])
    is_long = np.array([False, False, False, False, True, True, True])
    threshold = field_validation.best_threshold(values, is_long)
    assert threshold == pytest.approx(1.55)
    assert field_validation.accuracy(values, is_long, threshold) == 1.0
    assert field_validation.balanced_accuracy(values, is_long, 2.1) == pytest.approx((1.0 + 2 / 3) / 2)


def test_a_missing_data_directory_is_named(tmp_path, monkeypatch):
    missing = tmp_path / "no_openacc_here"
    monkeypatch.setattr(sys, "argv", ["field_validation", "--data", str(missing), "--out", str(tmp_path / "out")])
    with pytest.raises(SystemExit, match="no_openacc_here"):
        field_validation.main()
    assert not (tmp_path / "out").exists()
