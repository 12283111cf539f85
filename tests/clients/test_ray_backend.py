"""``--backend ray`` gives the serial results bit for bit (issue 15): evaluation, value of information, detection.

Slow and needing Ray (the ``ray`` extra, which the ``clients`` extra includes), so it runs in .venv-clients:
``bash .ci/clients -k ray_backend``. Ray is started on this machine once, by the first map, and shut down after
the module.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Iterator
from pathlib import Path

import pytest

from timegap_env.studies import value
from train import benchmark, detection_benchmark, value_of_information
from timegap_env.tasks import HeldOutGroup
from timegap_env.experiments.backends import Backend

pytestmark = pytest.mark.slow
ray = pytest.importorskip("ray", reason="needs the ray extra: pip install -e '.[ray]' (or run bash .ci/clients)")

RAY_SPREAD = "ray (started on this machine): "


@pytest.fixture(scope="module", autouse=True)
def ray_session() -> Iterator[None]:
    yield
    ray.shutdown()


def files(out: Path) -> dict[str, bytes]:
    """Every file ``out`` holds, by name: its bytes."""
    return {path.name: path.read_bytes() for path in sorted(out.iterdir())}


def test_ray_map_keeps_the_order_says_how_it_ran_and_raises_a_piece_error() -> None:
    backend = Backend("ray")  # the functions: importable on the workers (this test module is not)
    assert backend.map(operator.truediv, [(value, 2) for value in range(9)]) == [value / 2 for value in range(9)]
    assert backend.describe().startswith(f"{RAY_SPREAD}9 tasks of 1 CPU on ")
    with pytest.raises(ValueError, match="math domain error"):
        backend.map(math.sqrt, [(4.0,), (-1.0,)])


def test_the_benchmark_on_ray_equals_serial() -> None:
    group = HeldOutGroup("tiny", "short episodes", {"episode_duration": 20.0}, 12, references=False, selection=6)
    entries = [benchmark.registered(name) for name in ("fixed_1.0", "fixed_1.6", "rule_platoon", "v2v_aware")]
    rows = {}
    for backend in ("serial", "ray"):
        result = benchmark.run_group(group, entries, 10_000, 12, benchmark.Cache(None), Backend(backend))
        rows[backend] = result.rows
    assert rows["ray"] == rows["serial"]


def test_value_of_information_on_ray_equals_serial(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs = {}
    for backend in ("serial", "ray"):
        value_of_information.main(["--episodes", "6", "--train-episodes", "2", "--out", str(tmp_path / backend),
                                   "--backend", backend])
        runs[backend] = files(tmp_path / backend)
    assert runs["ray"] == runs["serial"]  # value.md, value.csv, lookup.csv, value.png
    assert f"held-out oracles: {RAY_SPREAD}5 tasks" in capsys.readouterr().out


def test_detection_benchmark_on_ray_equals_serial(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs = {}
    for backend in ("serial", "ray"):
        detection_benchmark.main(["--episodes", "2", "--nominal-episodes", "3", "--out", str(tmp_path / backend),
                                  "--backend", backend])
        runs[backend] = files(tmp_path / backend)
    assert runs["ray"] == runs["serial"]  # detection.md, detection.csv, detection.png
    assert f"calibration: {RAY_SPREAD}2 tasks" in capsys.readouterr().out


def test_a_recipes_seeds_train_side_by_side_on_ray_as_one_after_another(tmp_path: Path) -> None:
    """train_seeds: two seeds as Ray tasks give the runs the serial backend gives (SB3 on CPU: the same parameters)."""
    import yaml

    from timegap_env import DEFAULT_TASK
    from train import train_seeds

    hyperparams = tmp_path / "ppo.yml"
    hyperparams.write_text(yaml.safe_dump({DEFAULT_TASK: {
        "n_envs": 2, "n_timesteps": 64, "policy": "MlpPolicy", "normalize": True, "n_steps": 16, "batch_size": 32,
        "n_epochs": 1, "policy_kwargs": "dict(net_arch=[8])", "env_kwargs": {"config": {"episode_duration": 10.0}}}}))
    ppo = ["--", "--hyperparams", str(hyperparams), "--no-warmup", "--curve-freq", "0"]
    train_seeds.main(["--seeds", "0", "1", "--out", f"{tmp_path}/ray{{seed}}", "--backend", "ray", *ppo])
    train_seeds.main(["--seeds", "0", "1", "--out", f"{tmp_path}/serial{{seed}}", *ppo])
    from stable_baselines3 import PPO

    for seed in (0, 1):
        ray_run, serial = (PPO.load(tmp_path / f"{where}{seed}" / "model.zip", device="cpu") for where in ("ray", "serial"))
        assert all((a == b).all() for a, b in zip(ray_run.policy.state_dict().values(), serial.policy.state_dict().values()))
    assert "--seed 1" in (tmp_path / "ray1" / "training.md").read_text()
