"""``python -m train.train_morl``: Envelope on ``mo-TimeGapMonitor-v1``, its front against the constants (issue 25).

Slow and needing the ``mo`` extra (part of ``clients``): ``bash .ci/clients -k train_morl``. Skips, saying how to
install them, where the libraries are missing.
"""

from __future__ import annotations

import csv
import math
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

INSTALL = "needs the mo extra: pip install -e '.[mo]' (part of clients; or run bash .ci/clients)"
pytest.importorskip("mo_gymnasium", reason=INSTALL)
pytest.importorskip("morl_baselines", reason=INSTALL)

ROOT = Path(__file__).resolve().parents[2]
# 800 steps > learning_starts (500): 300 gradient updates, so the rerun checks that training is deterministic too
TINY = ["--timesteps", "800", "--selection", "2", "--held-out", "3"]
NUMBERS = ("efficiency", "string_stability", "tracking", "selection_return", "held_out_return", "hypervolume",
           "constants_hypervolume")


def run(out: Path, *arguments: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "train.train_morl", *arguments, "--out", str(out)], check=False,
                          cwd=ROOT, capture_output=True, text=True, timeout=600)


def test_a_tiny_run_writes_the_front_and_a_rerun_gives_the_same_bytes(tmp_path: Path) -> None:
    first = run(tmp_path / "a", *TINY)
    assert first.returncode == 0, first.stderr
    assert sorted(path.name for path in (tmp_path / "a").iterdir()) == ["front.csv", "front.md", "front.png"]
    with open(tmp_path / "a" / "front.csv", newline="", encoding="utf-8") as file:
        rows = list(csv.DictReader(file))
    assert [row["kind"] for row in rows] == ["constant"] * 9 + ["envelope"] * 10
    for row in rows:
        assert all(math.isfinite(float(row[name])) for name in NUMBERS), row
        assert int(row["collisions"]) <= 3
    for row in rows[9:]:  # each weight vector on the simplex
        assert sum(float(row[f"w_{name}"]) for name in ("efficiency", "string_stability", "tracking", "collision")) \
            == pytest.approx(1.0, abs=1e-5)
    text = (tmp_path / "a" / "front.md").read_text(encoding="utf-8")
    assert "2 selection seeds from 5000" in text and "3 held-out seeds from 10000" in text and "nan" not in text

    second = run(tmp_path / "b", *TINY)
    assert second.returncode == 0, second.stderr
    for name in ("front.csv", "front.png"):  # the same seeds, one torch thread: the same bits
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name


def test_an_out_naming_a_file_is_refused_before_training(tmp_path: Path) -> None:
    target = tmp_path / "front.md"
    target.write_text("keep me")
    done = run(target, *TINY)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert done.stderr.strip().splitlines()[-1].startswith("python -m train.train_morl: error: --out")
    assert target.read_text() == "keep me"
