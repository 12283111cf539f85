"""The example notebook runs top to bottom in a fresh kernel (issue 23): it trains a small PPO policy, evaluates it
beside the paper's rule and a fixed setting through the rollout harness, and plots the intervals."""

from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parents[1] / "examples" / "train_evaluate_plot.ipynb"


def test_the_example_notebook_runs_top_to_bottom(tmp_path: Path) -> None:
    nbformat = pytest.importorskip("nbformat", reason="the dev extra (nbclient, ipykernel) runs the notebook")
    nbclient = pytest.importorskip("nbclient", reason="the dev extra (nbclient, ipykernel) runs the notebook")
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    assert all(not cell.get("outputs") for cell in notebook.cells if cell.cell_type == "code"), \
        "commit the notebook without outputs (the test makes them)"
    nbclient.NotebookClient(notebook, timeout=600, kernel_name="python3",
                            resources={"metadata": {"path": str(NOTEBOOK.parents[1])}}).execute()
    printed = "".join(output.get("text", "") for cell in notebook.cells for output in cell.get("outputs", []))
    for name in ("PPO (tiny)", "paper rule", "fixed 1.6 s"):
        assert f"{name}" in printed and "mean return" in printed
    assert any(output.get("output_type") == "display_data" and "image/png" in output.get("data", {})
               for cell in notebook.cells for output in cell.get("outputs", [])), "the plot"
