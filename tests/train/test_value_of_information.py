"""The value-of-information and mix-choice scripts on a few episodes: files written, same bytes on a rerun."""

import numpy as np

from train import choose_degradation_mix, value_of_information


def test_value_of_information_writes_the_same_report_twice(tmp_path):
    outputs = []
    for run in ("a", "b"):
        out = tmp_path / run
        value_of_information.main(["--episodes", "4", "--train-episodes", "1", "--out", str(out)])
        outputs.append({name: (out / name).read_bytes() for name in ("value.md", "value.csv", "lookup.csv", "value.png")})
    assert outputs[0] == outputs[1]
    report = outputs[0]["value.md"].decode()
    assert "| best blind constant" in report and "**the oracle**" in report and "nan" not in report.lower()


def test_a_mix_scores_its_oracle_against_the_best_blind_constant_and_pair():
    levels = 3
    pair_means = np.full((2, levels, levels), -100.0)
    pair_means[0] = -100.0 - 10.0 * np.arange(levels)[:, None]  # kind 0 (V2V up) prefers the smallest level
    pair_means[1] = -130.0 + 10.0 * np.arange(levels)[None, :]  # kind 1 (V2V down) prefers the largest
    oracle = np.array([[-100.0, -110.0]])
    mix = choose_degradation_mix.score(np.array([1.0, 1.0]), pair_means, oracle)
    assert mix.pair == (0, 2) and mix.pair_mean == -105.0 and mix.oracle_mean == -105.0 and mix.gain == 0.0
    assert mix.blind_mean == max(np.diagonal(pair_means, axis1=1, axis2=2).mean(axis=0)) and mix.blind_gain > 0
