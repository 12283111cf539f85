"""SUMO episodes spread as Ray tasks give the serial records (issue 26, item 4): libsumo runs one simulation per
process, and each Ray worker is a process. Slow, needing Ray and libsumo (both in the clients extra): runs in
.venv-clients, ``bash .ci/clients -k sumo``."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from timegap_env.agents.policies import FixedPolicy, PaperRulePolicy
from timegap_env.tasks import get_task
from timegap_env.config import EnvConfig
from timegap_env.experiments.backends import Backend
from timegap_env.experiments.rollout import Job, run_jobs

pytestmark = [pytest.mark.slow, pytest.mark.sumo]
ray = pytest.importorskip("ray", reason="needs the ray extra (bash .ci/clients)")
pytest.importorskip("libsumo", reason="needs the sumo extra (bash .ci/clients)")


@pytest.fixture(scope="module", autouse=True)
def ray_session() -> Iterator[None]:
    yield
    ray.shutdown()


def test_sumo_episodes_on_ray_equal_the_serial_ones() -> None:
    config = get_task("TimeGapMonitor-v1").config({"simulator": "sumo"})
    jobs = [Job(policy, config, (10_000, 10_001)) for policy in (FixedPolicy(1.2), PaperRulePolicy(config))]
    serial, on_ray = run_jobs(jobs), run_jobs(jobs, Backend("ray"))
    assert [[(r.fingerprint, r.episode_return) for r in batch.records] for batch in on_ray] == \
        [[(r.fingerprint, r.episode_return) for r in batch.records] for batch in serial]
    assert all(batch.config.simulator == "sumo" for batch in on_ray)
