"""``train.backends`` and the scripts' pieces: order, errors, the description, pieces a Ray task can take."""

import argparse
import os
import dataclasses
import importlib.util
import pickle

import pytest

from timegap_env.tasks import HeldOutGroup
from timegap_env.agents.policies import FixedPolicy, PaperRulePolicy
from timegap_env.config import EnvConfig
from timegap_env.studies import value
from train import benchmark, detection_benchmark, value_of_information
from timegap_env.experiments.backends import Backend, add_arguments


def power(base: int, exponent: int) -> int:
    return base**exponent


class Recording(Backend):
    """A serial backend that keeps every piece it was given."""

    def __init__(self) -> None:
        super().__init__()
        self.pieces: list[tuple] = []

    def map(self, function, pieces):
        self.pieces += [(function, *piece) for piece in pieces]
        return super().map(function, pieces)


def test_serial_map_keeps_the_order_and_says_how_it_ran():
    backend = Backend()
    assert backend.describe() == "not used yet"
    assert backend.map(power, [(2, 3), (3, 2), (5, 0)]) == [8, 9, 1]
    assert backend.describe().startswith("serial: 3 pieces one after another in this process, ")
    assert backend.describe().endswith(" s wall")
    assert backend.map(power, []) == [] and backend.describe().startswith("serial: 0 pieces")


def test_a_bad_backend_or_address_is_named():
    with pytest.raises(ValueError, match="backend = 'dask'"):
        Backend("dask")
    with pytest.raises(ValueError, match="address = 'auto': only with the ray backend"):
        Backend("serial", "auto")


def test_the_command_line_flags():
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args([])
    assert (args.backend, args.address) == ("serial", None)
    backend = Backend.from_args(parser.parse_args(["--backend", "ray", "--address", "ray://head:10001"]))
    assert (backend.name, backend.address) == ("ray", "ray://head:10001")
    with pytest.raises(SystemExit):
        parser.parse_args(["--backend", "dask"])


@pytest.mark.parametrize("script", [benchmark, value_of_information, detection_benchmark])
def test_the_scripts_refuse_an_address_without_ray(script, capsys):
    with pytest.raises(SystemExit):
        script.main(["--address", "auto"])
    assert "address = 'auto': only with the ray backend" in capsys.readouterr().err


@pytest.mark.skipif(importlib.util.find_spec("ray") is not None, reason="Ray is installed here")
def test_without_ray_the_ray_backend_says_how_to_get_it():
    with pytest.raises(RuntimeError, match=r"pip install -e '\.\[ray\]'"):
        Backend("ray").map(power, [(2, 3)])


def test_the_benchmark_runs_picklable_pieces_of_at_most_a_chunk_and_the_serial_results():
    group = HeldOutGroup("tiny", "short episodes", {"episode_duration": 10.0}, 5, references=False, selection=3)
    entries = [benchmark.registered("fixed_1.6"), benchmark.registered("rule_platoon")]
    backend = Recording()
    result = benchmark.run_group(group, entries, 10_000, 5, benchmark.Cache(None), backend)
    played = [piece for piece in backend.pieces if list(piece[3]) == list(range(10_000, 10_005))]
    assert [type(piece[1]).__name__ for piece in played] == ["FixedPolicy", "PaperRulePolicy"]
    assert all(piece[0] is benchmark.play and len(piece[3]) <= benchmark.CHUNK for piece in backend.pieces)
    for piece in backend.pieces:
        pickle.loads(pickle.dumps(piece))  # plain pickle: no lambda, no local function
    direct = benchmark.play(PaperRulePolicy(benchmark.group_config(group)), benchmark.group_config(group),
                            list(range(10_000, 10_005)))
    assert dataclasses.asdict(result.played["rule_platoon"]).keys() == dataclasses.asdict(direct).keys()
    assert all((getattr(result.played["rule_platoon"], name) == getattr(direct, name)).all()
               for name in dataclasses.asdict(direct))


def test_value_of_information_pieces_are_picklable_and_give_the_serial_results():
    config = EnvConfig()
    pieces = value.constant_pieces(config, [0, 1], flag_aware=True)
    assert len(pieces) == 1 and len(pieces[0][1]) == 2 * len(config.setting_levels) ** 2
    oracle = value.all_oracles(config, {"none": 1.6})[0]
    for piece in [*pieces, value.oracle_piece(config, [5], oracle)]:
        pickle.loads(pickle.dumps(piece))
    backend = Recording()
    pairs = value.constants(config, [0, 1], backend=backend)
    assert len(backend.pieces) == 1 and pairs["return"].shape == (2, len(config.setting_levels))


def test_the_sweep_estimate_of_bench_ray():
    from train.bench_ray import Costs, break_even_work, serial_seconds, sweep_seconds

    costs = Costs(work=100.0, pieces=100, driver=1.0, start=4.0, warm_up=6.0, per_task=0.001, efficiency=1.0)
    assert serial_seconds(costs, 2) == 202.0
    assert sweep_seconds(costs, 2, nodes=1, cpus_per_node=2) == 10.0 + 100 * 1.0 + 2.0  # 100 rounds of a 1 s piece
    assert sweep_seconds(costs, 2, nodes=100, cpus_per_node=2) == 10.0 + 1.0 + 2.0  # one round: the rest is fixed
    slow_driver = dataclasses.replace(costs, per_task=1.0)
    assert sweep_seconds(slow_driver, 2, nodes=100, cpus_per_node=2) == 10.0 + 200.0 + 2.0  # the driver's tasks
    assert break_even_work(costs, 2) == 20.0  # W = 10 + W / 2
    assert break_even_work(dataclasses.replace(costs, efficiency=0.5), 2) == float("inf")  # no speed-up


def test_worker_processes_give_the_serial_results_in_order():
    pieces = [(2, 3), (3, 2), (5, 0)]
    backend = Backend("processes", workers=2)
    assert backend.map(power, pieces) == Backend().map(power, pieces) == [8, 9, 1]
    assert backend.describe().startswith("processes: 3 pieces on 2 worker processes")
    assert backend.map(power, []) == []
    with pytest.raises(ValueError, match="workers = 0"):
        Backend("processes", workers=0)
    with pytest.raises(ValueError, match="workers = 2: an integer >= 1, only with the processes backend"):
        Backend("serial", workers=2)


def test_the_worker_processes_serve_every_map_until_a_piece_fails():
    """One pool for every map of a backend (what a worker builds once serves later pieces); a piece that raises
    stops it, and the next map starts fresh workers."""
    backend = Backend("processes", workers=2)
    first = set(backend.map(os.getpid, [()] * 4))
    assert set(backend.map(os.getpid, [()] * 4)) <= first and os.getpid() not in first
    with pytest.raises(TypeError):
        backend.map(power, [(2, "x")])
    assert not set(backend.map(os.getpid, [()] * 4)) & first
    backend.close()
    backend.close()  # twice is harmless
