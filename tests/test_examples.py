"""examples/ run as a user runs them: the scripts as programs, the notebook in a kernel."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.mark.parametrize(
    ("script", "outputs"),
    [
        ("quickstart.py", ["quickstart-trajectory.png", "quickstart-run/log.csv"]),
        ("compare_vehicles.py", ["compare-vehicles-errors.png"]),
        ("own_simulator.py", ["own-simulator-run/log.csv", "own-simulator-run/run.json"]),
        ("own_controller.py", ["pid-tracker-run/log.csv", "pid-tracker-run/run.json"]),
    ],
)
def test_example_script_runs(tmp_path, script, outputs):
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / script), str(tmp_path / "out")],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    for name in outputs:
        assert (tmp_path / "out" / name).is_file(), name


def test_the_notebook_runs_in_a_kernel(tmp_path):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    notebook = nbformat.read(EXAMPLES / "tour.ipynb", as_version=4)
    nbclient.NotebookClient(
        notebook, timeout=300, kernel_name="python3", resources={"metadata": {"path": tmp_path}}
    ).execute()
    outputs = [o for cell in notebook.cells if cell.cell_type == "code" for o in cell.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    assert any("image/png" in o.get("data", {}) for o in outputs)  # the figures show inline


def test_every_example_is_tested():
    tested = {
        "quickstart.py",
        "compare_vehicles.py",
        "own_simulator.py",
        "own_controller.py",  # tests/test_extending.py
        "own_actuator.py",  # tests/test_actuators.py
        "tour.ipynb",
    }
    present = {p.name for p in EXAMPLES.iterdir() if p.suffix in (".py", ".ipynb")}
    assert present == tested
