"""Figures fit for a paper and `auvmpc compare` (issue 13): formats and resolution, the
controller and vehicle in every title, a unit on every axis, the current as an arrow,
one colour per thruster, overlays naming every run, and one-line errors."""

from __future__ import annotations

import json
import math
import re

import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure

from auvmpc import plots
from auvmpc.controllers.registry import retyped
from auvmpc.models.vehicle import load_vehicle
from auvmpc.scenario import load_scenario
from auvmpc.sim.log import SimLog
from tests.test_cli import run_cli

matplotlib.use("Agg")

# Magic numbers of the three formats (PNG signature, PDF header, SVG's XML declaration).
SIGNATURES = {"png": b"\x89PNG\r\n\x1a\n", "pdf": b"%PDF", "svg": b"<?xml"}
UNIT = re.compile(r"\(.+\)")  # "x (m)", "thrust F (N)", ...


def _log(n_thrusters: int, current=(10.0, 5.0), steps: int = 20) -> SimLog:
    log = SimLog.allocate(steps, n_thrusters, 0.5)
    log.state[:, 0] = np.linspace(0, 5, steps + 1)
    log.reference[:, 0] = np.linspace(0, 5.5, steps + 1)
    log.thrust[:] = np.arange(1, n_thrusters + 1)
    log.environment[:, :2] = current
    log.status[:] = ["ok"] * steps
    return log


@pytest.mark.parametrize("vehicle", ["jmse2210", "bluerov2-heavy"])
def test_every_axis_has_a_unit_and_thrusters_keep_their_colour(vehicle):
    model = load_vehicle(vehicle)
    log = _log(model.n_thrusters)
    figures = plots.run_figures(log, [], 0.5, model, title="t")
    for name, figure in figures.items():
        for ax in figure.axes:
            for label in (ax.get_xlabel(), ax.get_ylabel()):
                if label:
                    assert UNIT.search(label), (name, label)
            assert ax.get_ylabel(), name
        assert figure.axes[-1].get_xlabel(), name
    force_ax = figures["thrusts"].axes[0]
    colours = [matplotlib.colors.to_hex(p.get_edgecolor()) for p in force_ax.patches]
    expected = [matplotlib.colors.to_hex(c) for c in plots.THRUSTER_COLORS[: model.n_thrusters]]
    assert colours == expected


def test_the_current_is_an_arrow_along_its_direction():
    log = _log(4, current=(0.0, -3.0))
    figure = plots.figure_trajectory(log, [], 0.5)
    ax = figure.axes[0]
    (arrow,) = [a for a in ax.texts if a.arrow_patch is not None]
    start, end = np.array(arrow.xyann), np.array(arrow.xy)
    direction = (end - start) / np.linalg.norm(end - start)
    np.testing.assert_allclose(direction, [0.0, -1.0], atol=1e-12)
    labels = ax.get_legend_handles_labels()[1]
    assert "current force, 3 N (arrow: direction)" in labels


def test_no_current_no_arrow():
    ax = plots.figure_trajectory(_log(4, current=(0.0, 0.0)), [], 0.5).axes[0]
    assert not [a for a in ax.texts if a.arrow_patch is not None]


def test_titles_name_the_controller_and_the_vehicle():
    scenario = load_scenario("paper-obstacles", ["controller.type=ltv-mpc"]).scenario
    title = plots.run_title(scenario, "bluerov2-heavy")
    assert title == "paper-obstacles: ltv-mpc (nc 2/ny 30), vehicle bluerov2-heavy"
    assert plots.controller_label(retyped(scenario.controller, "baseline")) == "baseline"


@pytest.mark.parametrize("fmt", ["png", "pdf", "svg"])
def test_save_figures_writes_each_format(tmp_path, fmt):
    figure = plots.figure_errors(_log(4))
    (path,) = plots.save_figures({"errors": figure}, tmp_path, dpi=72, fmt=fmt)
    assert path.name == f"errors.{fmt}"
    assert path.read_bytes().startswith(SIGNATURES[fmt])


def test_dpi_sets_the_raster_size(tmp_path):
    from PIL import Image

    figure = plots.figure_errors(_log(4))
    sizes = []
    for dpi in (50, 100):
        (path,) = plots.save_figures({f"e{dpi}": figure}, tmp_path, dpi=dpi)
        sizes.append(Image.open(path).size)
    # The tight bounding box is the same in inches; pixels scale with dpi (+-1 px rounding).
    assert abs(sizes[1][0] - 2 * sizes[0][0]) <= 2 and abs(sizes[1][1] - 2 * sizes[0][1]) <= 2


def test_an_unknown_format_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r"figure format must be one of \['png', 'pdf', 'svg'\]"):
        plots.save_figures({"a": Figure()}, tmp_path, fmt="gif")


@pytest.fixture(scope="module")
def two_runs(tmp_path_factory):
    """paper-ideal for 5 s by the paper's MPC and by ltv-mpc-nc30 (two bench labels)."""
    from auvmpc.api import controller_overrides
    from auvmpc.experiments.run import simulate, write_run

    folder = tmp_path_factory.mktemp("runs")
    runs = []
    for label in ("mpc", "ltv-mpc-nc30"):
        overrides = [*controller_overrides(label), "duration=5"]
        result = simulate(load_scenario("paper-ideal", overrides))
        runs.append(write_run(result, folder / label, figures=False))
    return runs


def test_compare_overlays_both_controllers_by_name(monkeypatch, capsys, tmp_path, two_runs):
    out = tmp_path / "cmp"
    code, stdout, err = run_cli(
        monkeypatch, capsys, "compare", *map(str, two_runs), "--out", str(out), "--format", "svg"
    )
    assert code == 0, err
    names = {p.name for p in out.iterdir()}
    assert {"trajectory.svg", "errors.svg", "thrusts.svg", "metrics.md", "metrics.csv"} <= names
    from auvmpc.experiments.compare import load_compared_runs
    from auvmpc.plots import figure_compare_trajectory

    runs = load_compared_runs(two_runs)
    labels = [run.label for run in runs]
    assert labels == ["mpc (nc 2/ny 30)", "ltv-mpc (nc 30/ny 30)"]
    legend = figure_compare_trajectory([(r.label, r.log) for r in runs]).axes[0].get_legend()
    assert set(labels) <= {text.get_text() for text in legend.get_texts()}
    table = (out / "metrics.md").read_text()
    for run in runs:
        rms = run.metrics["rms_position_error_m"]
        assert f"| {run.label} | {rms:.4g} |" in table
    assert "ltv-mpc (nc 30/ny 30)" in stdout
    # A second compare into the same folder rewrites it (it wrote it).
    code, _, err = run_cli(monkeypatch, capsys, "compare", *map(str, two_runs), "--out", str(out))
    assert code == 0, err


def test_compare_names_duplicates_and_vehicles_apart(tmp_path, two_runs):
    from auvmpc.experiments.compare import load_compared_runs

    runs = load_compared_runs([two_runs[0], two_runs[0]])
    assert [r.label for r in runs] == ["mpc (nc 2/ny 30) [mpc]"] * 2
    runs = load_compared_runs(two_runs, labels=["A", "B"])
    assert [r.label for r in runs] == ["A", "B"]


def test_compare_on_another_vehicle(tmp_path, monkeypatch, capsys, two_runs):
    from auvmpc.experiments.run import simulate, write_run

    result = simulate(load_scenario("paper-ideal", ["duration=5", "vehicle=bluerov2-heavy"]))
    blue = write_run(result, tmp_path / "blue", figures=False)
    from auvmpc.experiments.compare import load_compared_runs

    runs = load_compared_runs([two_runs[1], blue])
    assert [r.label.split(", ")[-1] for r in runs] == ["jmse2210", "bluerov2-heavy"]
    thrusts = plots.figure_compare_thrusts([(r.label, r.log) for r in runs], runs[0].model)
    assert len(thrusts.axes) == max(r.model.n_thrusters for r in runs)


def test_compare_never_replaces_a_folder_it_did_not_write(monkeypatch, capsys, tmp_path, two_runs):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep")
    code, _, err = run_cli(monkeypatch, capsys, "compare", *map(str, two_runs), "--out", str(out))
    assert code == 2
    assert "--out: holds files auvmpc did not write" in err
    assert (out / "notes.txt").read_text() == "keep" and len(list(out.iterdir())) == 1


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--format", "gif"], "--format: one of ['png', 'pdf', 'svg'] (got 'gif')"),
        (["--dpi", "0"], "--dpi: must be between 10 and 2400 (got 0)"),
        (["--label", "only-one"], "--label: give one per run (2)"),
    ],
)
def test_compare_bad_options_are_one_line(monkeypatch, capsys, tmp_path, two_runs, extra, message):
    args = ["compare", *map(str, two_runs), "--out", str(tmp_path / "o"), *extra]
    code, _, err = run_cli(monkeypatch, capsys, *args)
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1


def test_compare_needs_two_horizontal_runs(monkeypatch, capsys, tmp_path, two_runs):
    code, _, err = run_cli(monkeypatch, capsys, "compare", str(two_runs[0]), "--out", "x")
    assert code == 2 and "compare needs two or more runs" in err


def test_plot_writes_the_chosen_format(monkeypatch, capsys, two_runs):
    code, _, err = run_cli(monkeypatch, capsys, "plot", str(two_runs[0]), "--format", "pdf")
    assert code == 0, err
    for name in ("trajectory", "errors", "velocities", "thrusts", "solve_times"):
        assert (two_runs[0] / f"{name}.pdf").read_bytes().startswith(b"%PDF")
    info = json.loads((two_runs[0] / "run.json").read_text())
    assert math.isfinite(info["metrics"]["rms_position_error_m"])


def test_run_draws_its_figures_in_the_chosen_format(monkeypatch, capsys, tmp_path):
    out = tmp_path / "run"
    code, _, err = run_cli(
        monkeypatch, capsys, "run", "paper-ideal", "--set", "duration=2", "--set",
        "vehicle=bluerov2-heavy", "--figure-format", "svg", "--dpi", "72", "--out", str(out),
    )  # fmt: skip
    assert code == 0, err
    assert (out / "trajectory.svg").read_bytes().startswith(SIGNATURES["svg"])
    assert not list(out.glob("*.png"))
    code, _, err = run_cli(monkeypatch, capsys, "run", "paper-ideal", "--figure-format", "eps")
    assert code == 2 and "--figure-format: one of ['png', 'pdf', 'svg'] (got 'eps')" in err
