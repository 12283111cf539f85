"""The SUMO cross-check's measurements (issue 26), natively: what drive() measures, and what crosscheck_rows refuses.
The SUMO side runs in tests/sim/test_sumo.py (marked sumo)."""

from __future__ import annotations

import numpy as np
import pytest

from timegap_env.config import EnvConfig
from timegap_env.experiments.backends import Backend
from timegap_env.studies.crosscheck import METRICS, SETUPS, crosscheck_rows, drive, piece_rows
from timegap_env.leaders import LeaderProfile, make_leader


def test_a_steady_leader_gives_no_variation_no_alarm_and_no_growth() -> None:
    profile = LeaderProfile.from_speed(np.full(600, 25.0))
    metrics = drive(EnvConfig(), profile, 1.2, v2v=True, seed=0)
    assert set(metrics) == set(METRICS)
    assert metrics["gap_std"] < 1e-6 and abs(metrics["gap_error"]) < 1e-6
    assert metrics["alarm_rate"] == 0.0 and metrics["collision"] == 0.0


def test_the_paper_leader_grows_through_a_short_acc_gap_and_not_through_a_long_one() -> None:
    profile = make_leader("paper", 10_000)
    short, long = (drive(EnvConfig(), profile, setting, v2v=False, seed=0) for setting in (0.6, 1.6))
    assert short["amplification"] > 1.05 and short["string_stable"] == 0.0
    assert long["string_stable"] == 1.0 and long["gap_std"] < short["gap_std"]


def test_unknown_sources_are_named_before_any_work() -> None:
    with pytest.raises(ValueError, match=r"sources \['highd'\]: unknown"):
        crosscheck_rows(EnvConfig(), {"highd": 2}, Backend())


@pytest.mark.sumo
def test_a_piece_runs_through_every_simulator() -> None:
    pytest.importorskip("libsumo")
    rows = piece_rows("paper", 10_000, EnvConfig.from_dict({"setting_levels": (1.0, 1.6)}))
    assert len(rows) == len(SETUPS) * 2 * 2
    assert {row["simulator"] for row in rows} == set(SETUPS)
    assert all(np.isfinite(row[metric]) for row in rows for metric in METRICS)


@pytest.mark.sumo
@pytest.mark.parametrize("setup", ["sumo_cc", "sumo_cacc"])
def test_a_steady_sumo_platoon_keeps_its_setting(setup: str) -> None:
    pytest.importorskip("libsumo")
    config = EnvConfig().nested_overrides(SETUPS[setup])
    metrics = drive(config, LeaderProfile.from_speed(np.full(600, 25.0)), 1.4, v2v=True, seed=0)
    assert abs(metrics["gap_error"]) < 0.01 and metrics["gap_std"] < 0.01  # s0 and the setting mapped, in seconds
    assert metrics["alarm_rate"] == 0.0 and metrics["collision"] == 0.0


def test_a_recorded_source_gives_distinct_pieces() -> None:
    from timegap_env.studies.crosscheck import distinct_seeds

    seeds = distinct_seeds("paper", 3, EnvConfig())
    profiles = {make_leader("paper", seed).speed.tobytes() for seed in seeds}
    assert len(seeds) == len(profiles) == 3
