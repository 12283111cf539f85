"""The detection benchmark on a few episodes: matched thresholds, labelled delays, a report without NaN."""

import numpy as np

from train import detection_benchmark as bench


def test_a_calibrated_width_is_the_smallest_meeting_the_false_alarm_target():
    batch = bench.simulate(1.0, [20_000, 20_001, 20_002], None)
    dt = 0.1
    threshold = bench.calibrate(batch, 1.0, "shewhart", "bayes", dt)
    rate = bench.false_alarms_per_hour(bench.charted_starts(batch, 1.0, "bayes_shewhart", threshold), dt)
    tighter = threshold._replace(width=threshold.width * 0.97)
    assert rate <= bench.TARGET_FALSE_ALARMS < bench.false_alarms_per_hour(
        bench.charted_starts(batch, 1.0, "bayes_shewhart", tighter), dt)


def test_delays_count_from_onset_and_only_detected_followers():
    batch = bench.Batch({}, start=200, onset=1000)
    starts = np.zeros((2300, 1, 3), dtype=bool)  # charted ticks 200 .. 2499
    starts[100, 0, 0] = True  # tick 300: before onset, a false alarm
    starts[850, 0, 1] = True  # tick 1050: 5 s after onset
    found, followers = bench.detection_delays(starts, batch, 0.1)
    assert followers == 3 and found.tolist() == [5.0]


def test_the_benchmark_writes_its_report(tmp_path):
    bench.main(["--episodes", "2", "--nominal-episodes", "3", "--out", str(tmp_path)])
    report = (tmp_path / "detection.md").read_text()
    assert "## Setting 1 s" in report and "bayes_cusum" in report and "nan" not in report.lower()
    assert (tmp_path / "detection.png").stat().st_size > 0 and (tmp_path / "detection.csv").stat().st_size > 0


def test_calibration_selection_training_and_held_out_seeds_are_apart():
    from timegap_env.agents.protocol import EVAL_SEED_START
    from timegap_env.studies import value as value_of_information

    calibration = range(bench.CALIBRATION_SEED_START, bench.CALIBRATION_SEED_START + 96)
    selection = range(value_of_information.SELECTION_SEED_START,
                      value_of_information.SELECTION_SEED_START + value_of_information.SELECTION_EPISODES)
    lookup_training = range(value_of_information.DEFAULT_TRAIN_EPISODES)
    held_out = range(EVAL_SEED_START, EVAL_SEED_START + 1000)
    ranges = [set(calibration), set(selection), set(lookup_training), set(held_out)]
    for i, first in enumerate(ranges):
        for second in ranges[i + 1:]:
            assert not first & second
