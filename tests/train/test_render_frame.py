"""train/render_frame.py writes a rendered frame of the env as a PNG."""

import sys

import matplotlib.pyplot as plt

from train import render_frame


def test_render_frame_writes_a_picture(tmp_path, monkeypatch):
    out = tmp_path / "frame.png"
    monkeypatch.setattr(sys, "argv", ["render_frame", "--out", str(out)])
    render_frame.main()
    picture = plt.imread(out)
    assert picture.shape[:2] == (640, 1000) and picture.std() > 0.05
