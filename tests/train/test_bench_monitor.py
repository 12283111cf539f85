"""train/bench_monitor.py runs at its quick sizes."""


def test_benchmark_quick_runs(capsys):
    from train import bench_monitor

    bench_monitor.main(["--quick"])
    out = capsys.readouterr().out
    assert "vehicle-updates/s" in out and "ratio" in out
