"""train/field_validation.py: the monitor on a few real OpenACC runs writes its report, table and figures."""

import csv
import os
import re
import sys

import numpy as np
import pytest

from timegap_env.leaders import default_openacc_dir
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
    assert f"`{os.path.relpath(DATA.resolve(), field_validation.REPO)}`" in report
    assert f"{len(RUNS)} runs read, {len(RUNS)} used;" in report
    assert not re.search(r"\bnan\b", report, re.IGNORECASE)
    with (out / "openacc_followers.csv").open() as handle:
        followers = list(csv.DictReader(handle))
    assert {row["run"] for row in followers} == set(RUNS)
    assert {"car", "reference_excursions", "invented_excursions"} <= set(followers[0]) and "model" not in followers[0]
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
    # The chart raises alarms on every setting, at the rate the table's follower-runs add up to.
    for group in ("S", "L"):
        (chart,) = table_rows(section(report, 4), f"{group} | ")
        members = [row for row in followers if row["group"] == group]
        hours = sum(float(row["driving_s"]) for row in members) / 3600
        assert float(chart[3]) > 0 and float(chart[3]) == round(sum(int(row["excursions"]) for row in members) / hours)
    # Section 4's share of invented alarms is the ACC follower-runs' own, and counts some of their alarms.
    acc = [row for row in followers if row["group"] != "human"]
    hours = sum(float(row["driving_s"]) for row in acc) / 3600
    alarms, invented = (sum(int(row[column]) for row in acc) / hours for column in ("excursions", "invented_excursions"))
    assert all(int(row["invented_excursions"]) <= int(row["excursions"]) for row in followers) and alarms > invented
    assert f"both halves: {alarms:.0f} alarms per hour of driving), {invented:.0f} per hour" in section(report, 4)
    # The window study covers every candidate on both halves.
    windows = table_rows(section(report, 5), "0.5") + table_rows(section(report, 5), "all data")
    assert len(windows) == 4 and "**Verdict.**" in report


def test_the_threshold_separates_and_the_accuracy_counts_both_classes():
    values = np.array([0.8, 0.9, 1.0, 1.1, 2.0, 2.2, 2.5])
    is_long = np.array([False, False, False, False, True, True, True])
    threshold = field_validation.best_threshold(values, is_long)
    assert threshold == pytest.approx(1.55)
    assert field_validation.accuracy(values, is_long, threshold) == 1.0
    assert field_validation.balanced_accuracy(values, is_long, 2.1) == pytest.approx((1.0 + 2 / 3) / 2)


def test_an_invented_excursion_is_one_the_reference_does_not_share():
    # Two followers: the estimate leaves its limits twice each; the reference leaves its own during the first
    # excursion of follower 0 only (at its last tick), and never for follower 1.
    estimate = np.array([[1, 1], [1, 0], [0, 1], [1, 1], [1, 0]], dtype=bool)
    reference = np.array([[0, 0], [1, 0], [0, 0], [0, 0], [0, 0]], dtype=bool)
    assert field_validation.invented_excursions(estimate, reference).tolist() == [1, 2]
    assert field_validation.invented_excursions(estimate, estimate).tolist() == [0, 0]


def test_the_window_rule_prefers_windows_without_invented_alarms():
    def rows(invented: dict) -> dict:
        return {("A", window, noise): field_validation.WindowRow(
                    rmse=0.1, rmse_fast=0.1, excursion_ratio=1.0 + abs((window or 40.0) - 2.0) / 10,
                    excursions_per_hour=100.0, invented_per_hour=invented.get(window, 0.0))
                for window in field_validation.WINDOWS for noise in field_validation.NOISE_LEVELS}
    # Every window invents alarms: the rule ranks them all, and 2 s counts excursions best.
    noisy_everywhere = rows({window: 5.0 for window in field_validation.WINDOWS})
    assert field_validation.quiet_windows(noisy_everywhere, "A") == []
    assert field_validation.chosen_window(noisy_everywhere, "A") == 2.0
    # Only 10 s and 20 s are quiet: the rule picks the better of those two.
    quiet_long = rows({window: 5.0 for window in field_validation.WINDOWS if window not in (10.0, 20.0)})
    assert field_validation.quiet_windows(quiet_long, "A") == [10.0, 20.0]
    assert field_validation.chosen_window(quiet_long, "A") == 10.0


def test_a_missing_data_directory_is_named_and_skipped(tmp_path, monkeypatch, capsys):
    """make demo runs field_validation last: without the data it says where it looked and writes nothing."""
    missing = tmp_path / "no_openacc_here"
    monkeypatch.setattr(sys, "argv", ["field_validation", "--data", str(missing), "--out", str(tmp_path / "out")])
    field_validation.main()
    assert f"skipped, OpenACC data not found at {missing}" in capsys.readouterr().out
    assert not (tmp_path / "out").exists()
