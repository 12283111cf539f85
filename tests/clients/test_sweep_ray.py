"""``train.sweep`` on Ray writes the same bits as serially (slow: starts Ray on this machine; needs the ray extra)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from train import sweep
from timegap_env.experiments.backends import Backend

pytestmark = pytest.mark.slow

TINY = {  # 2 cells x 3 policies (the trained one included) x 2 seed batches = 12 pieces of 2 episodes of 20 s
    "axes": {"degradation.gain_range": [[0.6, 0.85], [0.4, 0.6]]},
    "base": {"episode_duration": 20.0, "degradation": {"kind_weights": {"gain": 1.0}}},
    "policies": ["rule_platoon", "v2v_aware", "ppo"],
    "seeds": {"start": 10_000, "count": 4, "batch": 2},
}


@pytest.fixture
def ray() -> Iterator[object]:
    ray = pytest.importorskip("ray", reason="needs the ray extra: pip install -e '.[ray]' (or bash .ci/clients)")
    yield ray
    ray.shutdown()


def test_ray_writes_the_same_table_as_serial(ray, tmp_path: Path) -> None:
    path = tmp_path / "tiny.yml"
    path.write_text(yaml.safe_dump(TINY, sort_keys=False))
    grid = sweep.load_grid(path)
    serial = sweep.sweep(grid, tmp_path / "serial", Backend("serial"))
    on_ray = sweep.sweep(grid, tmp_path / "ray", Backend("ray"), chunk=5)  # three map calls, each written
    table = sweep.EPISODES_FILE
    assert (tmp_path / "ray" / table).read_bytes() == (tmp_path / "serial" / table).read_bytes()
    assert on_ray.split("\nRuntime: ")[0] == serial.split("\nRuntime: ")[0]
    assert "12 of 12 pieces run now in 3 map call(s) of up to 5; the last: ray (started on this machine)" in on_ray
    assert ray.is_initialized()
