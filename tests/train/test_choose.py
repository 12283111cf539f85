"""train/choose_learner.py's rule and train/choose_recipe.py's recipes (their studies run in make reproduce)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from train import choose_learner, choose_recipe
from timegap_env.studies import training

ROOT = Path(__file__).resolve().parents[2]


def test_the_learner_rule_takes_the_fastest_setting_not_shown_worse() -> None:
    speed = {"base": 1.0, "fast": 5.0, "faster": 6.0, "slow": 0.5}
    assert choose_learner.choose(speed, {"fast": 0.3, "faster": -0.1, "slow": 2.0}) == "fast"
    assert choose_learner.choose(speed, {"fast": -1.0, "faster": -0.1, "slow": 2.0}) == "base"  # slower than base
    assert choose_learner.choose(speed, {"fast": 0.0}) == "fast"  # an interval reaching 0 is not shown worse


def test_a_candidate_is_a_hyperparameter_file_train_ppo_reads(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(ROOT)
    path = choose_learner.write_hyperparams("small_relu_256", tmp_path)
    loaded = training.load_hyperparams(path)
    assert loaded["n_envs"] == 256 and loaded["policy_kwargs"]["activation_fn"] is torch.nn.ReLU
    assert training.load_hyperparams(choose_learner.write_hyperparams("base", tmp_path)) == training.load_hyperparams(
        ROOT / "hyperparams" / "ppo.yml")
    assert choose_learner.write_hyperparams("small_relu_256", tmp_path) == path  # the same again: kept
    path.write_text(path.read_text().replace("256", "512"))
    with pytest.raises(FileExistsError, match="other hyperparameters"):
        choose_learner.write_hyperparams("small_relu_256", tmp_path)


def test_a_recipe_names_its_runs_by_glob(tmp_path: Path) -> None:
    for seed in (0, 1):
        (tmp_path / f"seed{seed}").mkdir()
    name, runs = choose_recipe.parse_recipe(f"real={tmp_path}/seed*")
    assert name == "real" and runs == [tmp_path / "seed0", tmp_path / "seed1"]
    with pytest.raises(ValueError, match="matches no run directory"):
        choose_recipe.parse_recipe(f"real={tmp_path}/nothing*")
    with pytest.raises(ValueError, match="NAME=RUN"):
        choose_recipe.parse_recipe("real")
    for clash in ("real", "v2v_aware", "fixed_1.0"):
        with pytest.raises(SystemExit):  # a name twice, or a name whose rows would merge with a reference's
            choose_recipe.parse_args(["--recipe", f"real={tmp_path}/seed0", "--recipe", f"{clash}={tmp_path}/seed1"])


def test_the_answer_to_an_alarm_is_the_setting_change_after_its_onset() -> None:
    from train.policy_behaviour import ANSWER_WINDOW, Episode, statistics

    steps = 12
    setting = np.full(steps, 1.6)
    setting[4 + ANSWER_WINDOW - 1:] = 1.0  # down on the window's last decision
    alarm = np.zeros(steps, dtype=bool)
    alarm[[4, 5, 10]] = True  # two onsets: 4 (answered down) and 10 (not answered: nothing changes after it)
    found = statistics([Episode(np.arange(1.0, steps + 1), setting, alarm)], preferred=1.6)
    assert found["onsets"] == 2 and found["answered_down"] == 0.5 and found["answered_up"] == 0.0
    assert found["changes"] == 1 and found["alarms"] == 3
    assert found["at_preferred"] == (4 + ANSWER_WINDOW - 1) / steps


def test_the_recipe_rule_takes_the_smallest_worst_group_loss() -> None:
    rows = [{"policy": "a", "vs_best_percent": +6.0}, {"policy": "a", "vs_best_percent": -30.0},
            {"policy": "b", "vs_best_percent": -1.0}, {"policy": "b", "vs_best_percent": -10.0},
            {"policy": "fixed_1.6", "vs_best_percent": 0.0}]
    assert choose_recipe.choose(rows, ["a", "b"]) == ("b", -10.0)
    assert choose_recipe.choose(rows[:2] + [{"policy": "c", "vs_best_percent": -30.0}], ["a", "c"])[0] == "a"
