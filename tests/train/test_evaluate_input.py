"""train.evaluate checks its input before any work and says what is wrong in one line (issue 22, items 2 and 8): a run
that cannot be evaluated as it was trained, a --model broken in any way, --out naming a file, a truncated data file."""

from __future__ import annotations

import os
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from timegap_env.agents.protocol import ENV_FILE, MODEL_FILE, VECNORMALIZE_FILE
from timegap_env.leaders import default_ngsim_path, default_openacc_dir
from train import evaluate

ROOT = Path(__file__).resolve().parents[2]
COMMITTED = ROOT / "results" / "ppo"
OPENACC_FILE = "astazero_dynamic_part22.csv.gz"  # a small one


@pytest.fixture
def run(tmp_path: Path) -> Path:
    """A copy of the committed run (relative actions, normalised)."""
    copy = tmp_path / "run"
    copy.mkdir()
    for name in (MODEL_FILE, VECNORMALIZE_FILE, ENV_FILE):
        shutil.copy(COMMITTED / name, copy / name)
    return copy


@pytest.fixture
def no_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if the evaluation gets to its work: the held-out groups, the oracle or the episodes."""
    def reached(*args, **kwargs):
        raise AssertionError("the evaluation started its work before checking its input")

    for name in ("available_groups", "measure_lookup", "run_all", "check_data"):
        monkeypatch.setattr(evaluate, name, reached, raising=False)


def test_a_run_without_env_json_is_not_evaluated_as_platoon_mode(run: Path, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    (run / ENV_FILE).unlink()  # it used to be read as platoon mode: a table of 0.6-1.0 s settings, exit 0
    with pytest.raises(SystemExit):
        evaluate.main(["--episodes", "1", "--policies", "ppo", "--model", str(run), "--out", str(tmp_path / "eval")])
    assert f"{run / ENV_FILE}: missing" in capsys.readouterr().err
    assert not (tmp_path / "eval").exists()


def test_a_broken_model_is_named_before_any_work(run: Path, tmp_path: Path, no_work: None,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    with open(run / VECNORMALIZE_FILE, "rb") as file:
        saved = pickle.load(file)
    saved.obs_rms.mean[0] = float("nan")  # the observations would all become NaN mid-run
    saved.venv, saved.class_attributes, saved.returns = None, {}, None  # what its pickling drops, absent after a load
    with open(run / VECNORMALIZE_FILE, "wb") as file:
        pickle.dump(saved, file)
    with pytest.raises(SystemExit):  # the default policies: the oracle's 25 s would come first
        evaluate.main(["--model", str(run), "--out", str(tmp_path / "eval")])
    assert "vecnormalize.pkl': obs_rms.mean = [nan] at entries [0]: must be finite" in capsys.readouterr().err
    (run / VECNORMALIZE_FILE).unlink()
    with pytest.raises(SystemExit):
        evaluate.main(["--model", str(run), "--out", str(tmp_path / "eval")])
    assert f"{run / VECNORMALIZE_FILE}: missing" in capsys.readouterr().err


def test_out_naming_a_file_is_refused_before_any_work(tmp_path: Path, no_work: None,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "table.md"
    target.write_text("keep me")
    with pytest.raises(SystemExit):
        evaluate.main(["--policies", "fixed_1.6", "--out", str(target)])
    assert f"--out {target}: is an existing file" in capsys.readouterr().err and target.read_text() == "keep me"


def truncated(source: Path, target: Path) -> Path:
    """``target``, the first half of the gzip file ``source``."""
    data = source.read_bytes()
    target.write_bytes(data[:len(data) // 2])
    return target


def shared(path: Path) -> Path:
    if not path.exists():
        pytest.skip(f"data absent at {path}")
    return path


def test_a_truncated_data_file_is_named_before_the_other_groups_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                                                    ) -> None:
    (tmp_path / "openacc").mkdir()
    bad_openacc = truncated(shared(default_openacc_dir()) / OPENACC_FILE, tmp_path / "openacc" / OPENACC_FILE)
    bad_ngsim = truncated(shared(default_ngsim_path()), tmp_path / default_ngsim_path().name)
    monkeypatch.setattr(evaluate, "run_all", lambda *args: pytest.fail("the episodes ran before the data was read"))
    monkeypatch.setenv("TIMEGAP_OPENACC_PATH", str(tmp_path / "openacc"))
    with pytest.raises(ValueError, match=f"held-out group 'openacc' .*{bad_openacc}"):
        evaluate.main(["--policies", "fixed_1.6", "--out", str(tmp_path / "eval")])
    monkeypatch.delenv("TIMEGAP_OPENACC_PATH")
    monkeypatch.setenv("TIMEGAP_NGSIM_PATH", str(bad_ngsim))
    with pytest.raises(ValueError, match=f"held-out group 'ngsim_in_band' .*{bad_ngsim}"):
        evaluate.main(["--policies", "fixed_1.6", "--out", str(tmp_path / "eval")])
    assert not (tmp_path / "eval").exists()


def test_a_truncated_data_file_is_one_line_on_the_command_line(tmp_path: Path) -> None:
    (tmp_path / "openacc").mkdir()
    bad = truncated(shared(default_openacc_dir()) / OPENACC_FILE, tmp_path / "openacc" / OPENACC_FILE)
    done = subprocess.run([sys.executable, "-m", "train.evaluate", "--policies", "fixed_1.6", "--episodes", "7",
                           "--out", str(tmp_path / "eval")], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env={**os.environ, "TIMEGAP_OPENACC_PATH": str(tmp_path / "openacc")})
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("python -m train.evaluate: error: held-out group 'openacc'") and str(bad) in last
    assert not (tmp_path / "eval").exists()
