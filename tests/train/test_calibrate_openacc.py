"""train/calibrate_openacc.py on two car models: it writes the report, the table, the figures and the presets."""

import csv

import pytest

from timegap_env.leaders import default_openacc_dir
from timegap_env.sim.presets import COMMERCIAL_ACC, acc_presets
from train import calibrate_openacc


def test_calibration_writes_its_report_and_presets(tmp_path):
    if not default_openacc_dir().exists():
        pytest.skip(f"OpenACC data absent at {default_openacc_dir()} (set $TIMEGAP_OPENACC_PATH)")
    presets = tmp_path / "presets.json"
    calibrate_openacc.main(["--out", str(tmp_path), "--presets", str(presets), "--cars", "MAZDA_3", "TOYOTA_RAV4"])
    for name in ("calibration.md", "calibration.csv", "calibration_rmse.png", "calibration_example.png",
                 "calibration_stability.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    report = (tmp_path / "calibration.md").read_text()
    assert "| MAZDA_3 |" in report and "| TOYOTA_RAV4 |" in report and "nan" not in report.lower()
    with open(tmp_path / "calibration.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert [row["car"] for row in rows] == ["MAZDA_3", "TOYOTA_RAV4"]
    for row in rows:  # held out: each car's own fit predicts its spacing better than the median car does
        assert 0 < float(row["calibrated: spacing_rmse"]) < float(row["commercial ACC: spacing_rmse"]) < 10, row["car"]
        assert 0 < float(row["calibrated: dynamics_rmse"]) <= float(row["calibrated: spacing_rmse"]), row["car"]
    assert set(acc_presets(presets)) == {"MAZDA_3", "TOYOTA_RAV4", COMMERCIAL_ACC}
