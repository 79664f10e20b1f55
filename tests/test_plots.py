"""Figures built from a synthetic SimLog: structure, drawn geometry, atomic PNG output."""

from __future__ import annotations

import math

import matplotlib
import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, StepPatch

from auvmpc import plots
from auvmpc.environment.obstacles import ObstacleConfig, clearance
from auvmpc.models.vehicle import load_vehicle
from auvmpc.sim.log import SimLog
from auvmpc.sim.metrics import heading_error, position_error

matplotlib.use("Agg")  # tests may pick a backend; the library never does

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
SAMPLE_TIME = 0.5  # s
STEPS = 120  # 60 s
RADIUS = 10.0  # m, reference circle
PERIOD = 60.0  # s, one lap
VEHICLE_RADIUS = 0.5  # m
OBSTACLE = ObstacleConfig(center=(0.0, 12.5), radius=1.0)  # just outside the circle at 90 deg
ATOL = 1e-12


@pytest.fixture(scope="module")
def vehicle():
    return load_vehicle("jmse2210")


@pytest.fixture(scope="module")
def circle_log() -> SimLog:
    """A lap of a circle, tracked with a decaying radial and heading error; thrust in limits."""
    log = SimLog.allocate(STEPS, 4, SAMPLE_TIME)
    t = log.t
    omega = 2.0 * math.pi / PERIOD
    theta = omega * t
    radial = RADIUS + 1.0 * np.exp(-t / 8.0) + 0.02
    log.reference[:, 0] = RADIUS * np.cos(theta)
    log.reference[:, 1] = RADIUS * np.sin(theta)
    log.reference[:, 2] = theta + math.pi / 2  # unwrapped, as logged
    log.reference[:, 3] = RADIUS * omega
    log.reference[:, 5] = omega
    log.state[:, 0] = radial * np.cos(theta)
    log.state[:, 1] = radial * np.sin(theta)
    log.state[:, 2] = log.reference[:, 2] + 0.2 * np.exp(-t / 5.0)
    log.state[:, 3] = RADIUS * omega + 0.05 * np.exp(-t / 8.0)
    log.state[:, 4] = 0.03 * np.exp(-t / 8.0)
    log.state[:, 5] = omega + 0.01 * np.exp(-t / 4.0)
    log.thrust[:] = 4.0 * np.sin(0.2 * t[:-1, None] + np.arange(4))  # |rate| <= 0.8 N/s
    log.initial_thrust = log.thrust[0].copy()
    log.solve_ms[:] = 2.0 + np.linspace(0.0, 1.0, STEPS)
    log.status[:] = ["ok"] * STEPS
    log.status[10] = "fallback"
    for k in range(STEPS + 1):
        log.clearance_m[k] = clearance(log.state[k, :2], t[k], [OBSTACLE], VEHICLE_RADIUS)
    return log


def circles(figure: Figure) -> list[Circle]:
    return [p for p in figure.axes[0].patches if isinstance(p, Circle)]


def with_radius(figure: Figure, radius: float) -> list[Circle]:
    return [c for c in circles(figure) if math.isclose(c.radius, radius)]


def line(ax, label: str) -> Line2D:
    matches = [artist for artist in ax.get_lines() if artist.get_label() == label]
    assert len(matches) == 1, [artist.get_label() for artist in ax.get_lines()]
    return matches[0]


def test_trajectory_draws_reference_actual_and_the_obstacle(circle_log):
    figure = plots.figure_trajectory(circle_log, [OBSTACLE], VEHICLE_RADIUS, title="circle")
    assert isinstance(figure, Figure)
    assert len(figure.axes) == 1
    ax = figure.axes[0]
    reference, actual = line(ax, "reference"), line(ax, "actual")
    np.testing.assert_array_equal(reference.get_xydata(), circle_log.reference[:, :2])
    np.testing.assert_array_equal(actual.get_xydata(), circle_log.state[:, :2])
    assert reference.get_linestyle() == "--"
    (obstacle,) = with_radius(figure, OBSTACLE.radius)
    np.testing.assert_allclose(obstacle.center, OBSTACLE.center, atol=ATOL)
    assert obstacle.get_fill()
    assert ax.get_aspect() == 1.0
    assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "y (m)"
    assert figure.get_suptitle() == "circle"


def test_trajectory_draws_the_vehicle_envelope_every_interval_and_at_min_clearance(circle_log):
    figure = plots.figure_trajectory(circle_log, [OBSTACLE], VEHICLE_RADIUS)
    envelopes = with_radius(figure, VEHICLE_RADIUS)
    every_10_s = len(range(0, STEPS + 1, round(10.0 / SAMPLE_TIME)))  # t = 0, 10, ..., 60
    assert len(envelopes) == every_10_s + 1
    k_min = int(np.argmin(circle_log.clearance_m))
    centres = np.array([c.center for c in envelopes])
    assert np.any(np.all(np.isclose(centres, circle_log.state[k_min, :2], atol=ATOL), axis=1))
    gap = float(circle_log.clearance_m[k_min])
    (gap_line,) = [
        a for a in figure.axes[0].get_lines() if a.get_label().startswith("min clearance")
    ]
    assert f"{gap:.2f} m" in gap_line.get_label()
    drawn_gap = np.hypot(*np.diff(gap_line.get_xydata(), axis=0)[0])
    assert drawn_gap == pytest.approx(gap, abs=1e-9)


def test_trajectory_without_obstacles_or_envelope(circle_log):
    figure = plots.figure_trajectory(circle_log, [], 0.0)
    assert circles(figure) == []
    assert not any(a.get_label().startswith("min clearance") for a in figure.axes[0].get_lines())


def test_moving_obstacle_is_drawn_only_where_it_exists(circle_log):
    moving = ObstacleConfig(
        center=(-15.0, 0.0), radius=0.7, velocity=(0.5, 0.0), appear_time=10.0, vanish_time=40.0
    )
    figure = plots.figure_trajectory(circle_log, [moving], VEHICLE_RADIUS)
    discs = with_radius(figure, moving.radius)
    assert len(discs) >= 3  # closest approach plus ghosted positions
    for disc in discs:
        # Every disc lies on the obstacle's path at a time it exists.
        t = (disc.center[0] - moving.center[0]) / moving.velocity[0]
        assert moving.exists_at(t + 1e-9), t
        assert disc.center[1] == pytest.approx(moving.center[1])
    solid = [d for d in discs if d.get_alpha() > 0.5]
    assert len(solid) == 1


def test_obstacle_that_never_exists_during_the_run_is_not_drawn(circle_log):
    late = ObstacleConfig(center=(0.0, 12.5), radius=1.3, appear_time=1000.0)
    figure = plots.figure_trajectory(circle_log, [late, OBSTACLE], VEHICLE_RADIUS)
    assert with_radius(figure, late.radius) == []
    assert len(with_radius(figure, OBSTACLE.radius)) == 1


@pytest.mark.parametrize(
    ("vehicle_radius", "interval", "match"),
    [(-0.1, 10.0, "vehicle_radius"), (math.nan, 10.0, "vehicle_radius"), (0.5, 0.0, "envelope")],
)
def test_trajectory_rejects_bad_geometry(circle_log, vehicle_radius, interval, match):
    with pytest.raises(ValueError, match=match):
        plots.figure_trajectory(circle_log, [], vehicle_radius, envelope_interval_s=interval)


def test_errors_plots_position_and_wrapped_heading_error(circle_log):
    figure = plots.figure_errors(circle_log)
    assert len(figure.axes) == 2
    position, heading = (ax.get_lines()[0] for ax in figure.axes)
    np.testing.assert_array_equal(position.get_xdata(), circle_log.t)
    np.testing.assert_array_equal(position.get_ydata(), position_error(circle_log))
    np.testing.assert_array_equal(heading.get_ydata(), heading_error(circle_log))
    assert "(m)" in figure.axes[0].get_ylabel() and "(rad)" in figure.axes[1].get_ylabel()
    assert plots.figure_errors(circle_log, log_position=True).axes[0].get_yscale() == "log"


def test_velocities_plot_u_v_r_against_their_references(circle_log):
    figure = plots.figure_velocities(circle_log)
    assert len(figure.axes) == 3
    for column, ax in enumerate(figure.axes, start=3):
        np.testing.assert_array_equal(
            line(ax, "reference").get_ydata(), circle_log.reference[:, column]
        )
        np.testing.assert_array_equal(line(ax, "actual").get_ydata(), circle_log.state[:, column])
    assert [ax.get_ylabel() for ax in figure.axes] == [
        "surge u (m/s)",
        "sway v (m/s)",
        "yaw rate r (rad/s)",
    ]


def test_thrusts_are_held_steps_with_force_and_rate_limits(circle_log, vehicle):
    figure = plots.figure_thrusts(circle_log, vehicle)
    assert len(figure.axes) == 2
    force_ax, rate_ax = figure.axes
    steps = [p for p in force_ax.patches if isinstance(p, StepPatch)]
    assert len(steps) == circle_log.n_thrusters
    values, edges, _ = steps[0].get_data()
    np.testing.assert_array_equal(values, circle_log.thrust[:, 0])
    np.testing.assert_array_equal(edges, circle_log.t)  # F_k held over [t_k, t_k+1)

    def horizontal_levels(ax) -> set[float]:
        return {float(a.get_ydata()[0]) for a in ax.get_lines() if a.get_linestyle() == ":"}

    assert horizontal_levels(force_ax) == set(vehicle.thrust_limits)
    rate = vehicle.thrust_rate_limit
    assert horizontal_levels(rate_ax) == {-rate, rate}
    assert not any("beyond limit" in text.get_text() for text in figure.legends[0].get_texts())


def test_thrusts_mark_samples_beyond_the_limits(circle_log, vehicle):
    log = SimLog.allocate(4, 4, SAMPLE_TIME)
    log.thrust[2, 1] = vehicle.thrust_max + 1.0  # a force violation and two rate violations
    figure = plots.figure_thrusts(log, vehicle)
    labels = [text.get_text() for text in figure.legends[0].get_texts()]
    assert "beyond limit (1 force, 2 rate)" in labels


def test_solve_times_show_median_and_p99(circle_log):
    figure = plots.figure_solve_times(circle_log)
    assert len(figure.axes) == 1
    ax = figure.axes[0]
    np.testing.assert_array_equal(line(ax, "controller call").get_ydata(), circle_log.solve_ms)
    median = np.median(circle_log.solve_ms)
    (median_line,) = [a for a in ax.get_lines() if a.get_label().startswith("median")]
    assert median_line.get_ydata()[0] == pytest.approx(median)
    assert any(a.get_label().startswith("p99") for a in ax.get_lines())
    assert any(a.get_label() == "fallback (1)" for a in ax.get_lines())


def test_run_figures_returns_the_five_named_figures(circle_log, vehicle):
    figures = plots.run_figures(circle_log, [OBSTACLE], VEHICLE_RADIUS, vehicle, title="t")
    assert list(figures) == ["trajectory", "errors", "velocities", "thrusts", "solve_times"]
    assert [len(f.axes) for f in figures.values()] == [1, 2, 3, 2, 1]
    assert all(f.get_suptitle() == "t" for f in figures.values())


@pytest.mark.parametrize("sample_time", [SAMPLE_TIME, 0.0])  # 0.0: read back from a 1-row CSV
def test_figures_of_a_log_without_steps(vehicle, sample_time):
    log = SimLog.allocate(0, 4, sample_time)
    figures = plots.run_figures(log, [OBSTACLE], VEHICLE_RADIUS, vehicle)
    for figure in figures.values():
        figure.canvas.draw()


def test_save_figures_writes_pngs_atomically(circle_log, vehicle, tmp_path):
    folder = tmp_path / "run" / "figures"  # created on demand
    figures = plots.run_figures(circle_log, [OBSTACLE], VEHICLE_RADIUS, vehicle)
    written = plots.save_figures(figures, folder, dpi=60)
    assert written == [folder / f"{name}.png" for name in figures]
    for path in written:
        data = path.read_bytes()
        assert len(data) > 1000
        assert data.startswith(PNG_SIGNATURE)
    assert sorted(p.name for p in folder.iterdir()) == sorted(f"{n}.png" for n in figures)
    # Writing again replaces the files and still leaves nothing else behind.
    plots.save_figures({"errors": figures["errors"]}, folder, dpi=60)
    assert len(list(folder.iterdir())) == len(figures)


def test_save_figures_cleans_up_when_rendering_fails(tmp_path):
    class Broken(Figure):
        def savefig(self, *args, **kwargs):
            raise RuntimeError("render failed")

    with pytest.raises(RuntimeError, match="render failed"):
        plots.save_figures({"broken": Broken()}, tmp_path)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("name", ["", "..", "sub/errors", "/abs"])
def test_save_figures_rejects_names_with_folders(tmp_path, name):
    with pytest.raises(ValueError, match="plain file stem"):
        plots.save_figures({name: Figure()}, tmp_path)
    assert list(tmp_path.iterdir()) == []


def test_error_vs_parameter_plots_each_series():
    levels = [-30.0, -15.0, 0.0, 15.0, 30.0]
    rms = [0.3, 0.1, 0.05, 0.08, 0.2]
    figure = plots.figure_error_vs_parameter(
        levels, {"RMS": rms, "max": [1.0, 0.6, 0.4, 0.5, math.nan]}, "uncertainty (%)", "error (m)"
    )
    assert len(figure.axes) == 1
    ax = figure.axes[0]
    series = line(ax, "RMS")
    np.testing.assert_array_equal(series.get_xdata(), levels)
    np.testing.assert_array_equal(series.get_ydata(), rms)
    assert series.get_marker() != "None"
    assert line(ax, "max").get_color() != series.get_color()
    assert (ax.get_xlabel(), ax.get_ylabel()) == ("uncertainty (%)", "error (m)")
    single = plots.figure_error_vs_parameter(levels, rms, "x", "y")
    assert len(single.axes[0].get_lines()) == 1


def test_error_vs_parameter_rejects_mismatched_lengths():
    with pytest.raises(ValueError, match=r"values\['rms'\] has shape \(2,\), expected \(3,\)"):
        plots.figure_error_vs_parameter([1, 2, 3], {"rms": [0.1, 0.2]}, "x", "y")
