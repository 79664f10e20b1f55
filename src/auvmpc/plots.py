"""Figures of a closed-loop run: SimLog in, ``matplotlib.figure.Figure`` out.

Object-oriented matplotlib only: no pyplot state, no backend selection, no
``show``. Every figure is built on an Agg canvas, so it renders and saves
headless; display it in a notebook or save it with :func:`save_figures`.

Colours are the same in every figure: reference grey dashed, actual (true
plant state) blue, hard limits red dotted. Time axes are in s, positions in m,
angles in rad, forces in N (``shared/spec/interfaces.md``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle
from numpy.typing import ArrayLike

from auvmpc.atomic_write import atomic_file
from auvmpc.controllers.base import ControlStatus
from auvmpc.environment.obstacles import ObstacleConfig
from auvmpc.models.actuators import ActuatorSet
from auvmpc.models.layout import DEPTH, HORIZONTAL
from auvmpc.models.six_dof import SIX_DOF
from auvmpc.models.vehicle import VehicleParams
from auvmpc.sim.log import HORIZONTAL_CURRENT_NAMES, SimLog
from auvmpc.sim.metrics import LIMIT_TOLERANCE_N, heading_error, position_error, thrust_increments

__all__ = [
    "figure_depth",
    "figure_actuators",
    "figure_compare_errors",
    "figure_compare_thrusts",
    "figure_compare_trajectory",
    "ACTUAL_STYLE",
    "REFERENCE_STYLE",
    "figure_error_vs_parameter",
    "figure_errors",
    "figure_solve_times",
    "figure_thrusts",
    "figure_trajectory",
    "figure_velocities",
    "FIGURE_FORMATS",
    "THRUSTER_COLORS",
    "controller_label",
    "run_figures",
    "run_title",
    "save_figures",
    "six_dof_figures",
]

REFERENCE_STYLE = {"color": "0.45", "linestyle": "--", "linewidth": 1.3}
ACTUAL_STYLE = {"color": "tab:blue", "linestyle": "-", "linewidth": 1.5}
LIMIT_STYLE = {"color": "tab:red", "linestyle": ":", "linewidth": 1.2}
OBSTACLE_FACE = "tab:orange"
OBSTACLE_EDGE = "saddlebrown"
HIGHLIGHT = "tab:red"
CURRENT_COLOR = "teal"
BEYOND_STYLE = {"linestyle": "none", "marker": "x", "color": HIGHLIGHT, "markersize": 7}
# Thruster colours: distinct from the reference grey, actual blue and limit red.
THRUSTER_COLORS = (
    "tab:purple", "tab:green", "tab:orange", "tab:cyan",
    "tab:olive", "tab:pink", "tab:brown", "black",
)  # fmt: skip

# Series of a parameter sweep: the first in the "actual" blue.
SERIES_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:purple", "tab:brown", "tab:pink")

FIGURE_FORMATS = ("png", "pdf", "svg")
TIME_LABEL = "time t (s)"
PANEL_WIDTH_IN = 7.0
PANEL_HEIGHT_IN = 2.1
_POSITION = HORIZONTAL.position  # x, y (m) of a horizontal log's state and reference
GHOST_POSITIONS = 5  # a moving obstacle is drawn at this many times while it exists


def figure_trajectory(
    log: SimLog,
    obstacles: Sequence[ObstacleConfig],
    vehicle_radius: float,
    title: str = "",
    *,
    envelope_interval_s: float = 10.0,
) -> Figure:
    """Path in the x-y plane: reference vs actual, obstacles and the vehicle envelope.

    Each obstacle is drawn as a filled disc where it was at the sample of closest
    approach (smallest gap between the vehicle disc and the obstacle disc, over the
    samples at which it exists). A moving obstacle is also drawn, faded and with
    its time, at a few positions over its lifetime; an obstacle that never exists
    during the run is not drawn. The vehicle disc of radius ``vehicle_radius``
    (with a tick along its heading) is drawn every ``envelope_interval_s`` and, in
    red with the gap marked, at the sample of minimum clearance.

    Parameters
    ----------
    log : SimLog
        The run; positions are ``state[:, HORIZONTAL.position]`` and the reference's (m).
    obstacles : sequence of ObstacleConfig
        The keep-out discs of the scenario (may be empty).
    vehicle_radius : float
        Radius of the vehicle's circular envelope (m), >= 0; 0 draws no envelope.
    title : str
        Figure title; empty for none.
    envelope_interval_s : float
        Time between drawn vehicle envelopes (s), > 0.

    Returns
    -------
    Figure
        One axes, equal aspect, axes in m.
    """
    if not (math.isfinite(vehicle_radius) and vehicle_radius >= 0):
        raise ValueError(f"vehicle_radius must be finite and >= 0 (m), got {vehicle_radius!r}")
    if not (math.isfinite(envelope_interval_s) and envelope_interval_s > 0):
        raise ValueError(
            f"envelope_interval_s must be finite and > 0 (s), got {envelope_interval_s!r}"
        )
    figure = _new_figure(PANEL_WIDTH_IN, 6.4, title)
    ax = figure.add_subplot()
    ax.plot(*log.reference[:, _POSITION].T, **REFERENCE_STYLE, label="reference")
    ax.plot(*log.state[:, _POSITION].T, **ACTUAL_STYLE, label="actual")

    approaches = [_closest_approach(log, obstacle, vehicle_radius) for obstacle in obstacles]
    labelled: set[str] = set()
    for obstacle, approach in zip(obstacles, approaches, strict=True):
        if approach is not None:
            _draw_obstacle(ax, log, obstacle, approach[0], labelled)

    if vehicle_radius > 0:
        step = max(1, round(envelope_interval_s / log.sample_time)) if log.sample_time > 0 else 1
        for i, k in enumerate(range(0, len(log.t), step)):
            label = f"vehicle envelope (every {envelope_interval_s:g} s)" if i == 0 else None
            _draw_vehicle(ax, log.state[k], vehicle_radius, ACTUAL_STYLE["color"], 0.55, label)

    drawn = [(a[1], a[0], o) for o, a in zip(obstacles, approaches, strict=True) if a is not None]
    if drawn:
        gap, k, obstacle = min(drawn, key=lambda item: item[0])
        _draw_min_clearance(ax, log, obstacle, k, gap, vehicle_radius)

    for row, marker, color, size, label in ((0, "o", "tab:green", 8, "start"),
                                            (-1, "s", "tab:blue", 7, "end")):  # fmt: skip
        ax.plot(
            *log.state[row, _POSITION],
            marker=marker,
            color=color,
            markeredgecolor="black",
            markersize=size,
            linestyle="none",
            label=label,
            zorder=5,
        )
    _finish_trajectory_axes(ax, log)
    return figure


def figure_errors(log: SimLog, title: str = "", *, log_position: bool = False) -> Figure:
    """Position error (m) and wrapped heading error (rad) against time, two panels.

    Parameters
    ----------
    log : SimLog
        The run.
    title : str
        Figure title; empty for none.
    log_position : bool
        Log-scale the position error axis (shows convergence to a small steady error).

    Returns
    -------
    Figure
        Two axes sharing the time axis.
    """
    figure, axes = _time_panels(2, title)
    top, bottom = axes
    top.plot(log.t, position_error(log), **ACTUAL_STYLE, label=r"$\|p - p_\mathrm{ref}\|$")
    top.set_ylabel("position error (m)")
    if log_position:
        top.set_yscale("log")
    else:
        top.set_ylim(bottom=0.0)
    bottom.plot(
        log.t, heading_error(log), **ACTUAL_STYLE, label=r"$\psi - \psi_\mathrm{ref}$, wrapped"
    )
    bottom.axhline(0.0, color="0.3", linewidth=0.6)
    bottom.set_ylabel("heading error (rad)")
    _finish_time_axes(log, axes)
    return figure


def figure_velocities(log: SimLog, title: str = "") -> Figure:
    """Surge u, sway v (m/s) and yaw rate r (rad/s) against their references, three panels.

    Parameters
    ----------
    log : SimLog
        The run; columns 3, 4, 5 of ``state`` and ``reference``.
    title : str
        Figure title; empty for none.

    Returns
    -------
    Figure
        Three axes sharing the time axis.
    """
    figure, axes = _time_panels(3, title)
    labels = ("surge u (m/s)", "sway v (m/s)", "yaw rate r (rad/s)")
    for column, (ax, label) in enumerate(zip(axes, labels, strict=True), start=3):
        ax.plot(log.t, log.reference[:, column], **REFERENCE_STYLE, label="reference")
        ax.plot(log.t, log.state[:, column], **ACTUAL_STYLE, label="actual")
        ax.set_ylabel(label)
    _figure_legend(figure, axes[:1])
    _finish_time_axes(log, axes)
    return figure


def figure_thrusts(log: SimLog, limits: VehicleParams, title: str = "") -> Figure:
    """Thruster forces with their limits, and the thrust rate with the rate limits.

    Top panel: force F_i of each thruster, held over [t_k, t_k+1) (a step plot).
    Bottom panel: the change at each sample over the sample time,
    (F_k - F_k-1) / Te (N/s), from ``log.initial_thrust`` for k = 0; this is the
    quantity the rate limit bounds. Samples beyond a limit are marked with a red x.

    Parameters
    ----------
    log : SimLog
        The run, ``thrust`` (N, n).
    limits : VehicleParams
        Supplies ``thrust_limits`` (N) and ``thrust_rate_limit`` (N/s).
    title : str
        Figure title; empty for none.

    Returns
    -------
    Figure
        Two axes sharing the time axis.
    """
    figure, axes = _time_panels(2, title, height_in=2.6)
    force_ax, rate_ax = axes
    lower, upper = limits.thrust_limits
    rate_limit = limits.thrust_rate_limit
    # A log without steps (read back from a one-row CSV) may carry sample_time 0.
    sample_time = log.sample_time if log.steps else 1.0
    rate = thrust_increments(log) / sample_time
    starts = log.t[:-1]
    for i in range(log.n_thrusters):
        color = THRUSTER_COLORS[i % len(THRUSTER_COLORS)]
        force_ax.stairs(
            log.thrust[:, i], log.t, color=color, linewidth=1.2, label=log.input_names[i]
        )
        rate_ax.plot(starts, rate[:, i], color=color, linewidth=0.9, marker=".", markersize=3)
    limit_label = f"limits [{lower:g}, {upper:g}] N, ±{rate_limit:g} N/s"
    beyond = []
    for ax, low, high, values, slack in (
        (force_ax, lower, upper, log.thrust, LIMIT_TOLERANCE_N),
        # Same slack as the metrics' check on the increment, scaled to a rate.
        (rate_ax, -rate_limit, rate_limit, rate, LIMIT_TOLERANCE_N / sample_time),
    ):
        ax.axhline(high, **LIMIT_STYLE, label=limit_label)
        ax.axhline(low, **LIMIT_STYLE)
        outside = (values < low - slack) | (values > high + slack)
        rows, _ = np.nonzero(outside)
        beyond.append(len(rows))
        if len(rows):
            ax.plot(starts[rows], values[outside], **BEYOND_STYLE)
    if any(beyond):
        force_ax.plot(
            [], [], **BEYOND_STYLE, label=f"beyond limit ({beyond[0]} force, {beyond[1]} rate)"
        )
    force_ax.set_ylabel("thrust F (N)")
    rate_ax.set_ylabel(r"rate $\Delta F / T_e$ (N/s)")
    _figure_legend(figure, axes)
    _finish_time_axes(log, axes)
    return figure


def figure_actuators(log: SimLog, inputs: ActuatorSet, title: str = "") -> Figure:
    """Each input in its own panel and units (a propeller's rpm, a fin's angle in deg), held
    over [t_k, t_k+1), with its hard limits; commands beyond a limit, or that changed faster
    than its rate limit, marked with a red x (the metrics' ``actuator_*_violations``).

    Parameters
    ----------
    log : SimLog
        The run, ``thrust`` (N, n): the commands of ``inputs``, in order.
    inputs : ActuatorSet
        The vehicle's inputs (``six_dof_actuators``): names, units and limits.
    """
    figure, axes = _time_panels(inputs.size, title, height_in=1.8)
    limits = inputs.limits
    lower, upper, rate = (
        np.broadcast_to(value, (inputs.size,))
        for value in (limits.lower, limits.upper, limits.rate)
    )
    sample_time = log.sample_time if log.steps else 1.0
    change = np.abs(thrust_increments(log))
    starts = log.t[:-1]
    beyond = [0, 0]
    for i, ax in enumerate(axes):
        values = log.thrust[:, i]
        color = THRUSTER_COLORS[i % len(THRUSTER_COLORS)]
        ax.stairs(values, log.t, color=color, linewidth=1.2, label=log.input_names[i])
        ax.axhline(upper[i], **LIMIT_STYLE, label="hard limits")
        ax.axhline(lower[i], **LIMIT_STYLE)
        outside = (values < lower[i] - LIMIT_TOLERANCE_N) | (values > upper[i] + LIMIT_TOLERANCE_N)
        too_fast = change[:, i] > rate[i] * sample_time + LIMIT_TOLERANCE_N
        beyond[0] += int(outside.sum())
        beyond[1] += int(too_fast.sum())
        marked = outside | too_fast
        if marked.any():
            ax.plot(starts[marked], values[marked], **BEYOND_STYLE)
        unit = inputs.units[i]
        ax.set_ylabel(f"{log.input_names[i]} ({unit})\nrate limit {rate[i]:g} {unit}/s")
    if any(beyond):
        axes[0].plot(
            [], [], **BEYOND_STYLE, label=f"beyond limit ({beyond[0]} box, {beyond[1]} rate)"
        )
    _figure_legend(figure, axes)
    _finish_time_axes(log, axes)
    return figure


def figure_solve_times(log: SimLog, title: str = "") -> Figure:
    """Wall time of each controller call (ms) with its median and 99th percentile.

    Samples whose status is ``fallback`` (solver failed) or ``relaxed`` (obstacle
    constraints softened) are marked.

    Parameters
    ----------
    log : SimLog
        The run, ``solve_ms`` (N,) and ``status`` (N,).
    title : str
        Figure title; empty for none.

    Returns
    -------
    Figure
        One axes.
    """
    figure, axes = _time_panels(1, title, height_in=3.0)
    (ax,) = axes
    starts = log.t[:-1]
    ax.plot(
        starts,
        log.solve_ms,
        **ACTUAL_STYLE | {"linewidth": 0.9},
        marker=".",
        markersize=3,
        label="controller call",
    )
    if log.steps:
        median, p99 = np.percentile(log.solve_ms, [50, 99])
        ax.axhline(
            median, color="0.2", linestyle="--", linewidth=1.1, label=f"median {median:.3g} ms"
        )
        ax.axhline(
            p99, color="tab:orange", linestyle="-.", linewidth=1.1, label=f"p99 {p99:.3g} ms"
        )
    status = np.array(log.status, dtype=object)
    for value, marker, color in (
        (ControlStatus.FALLBACK, "x", HIGHLIGHT),
        (ControlStatus.RELAXED, "^", "tab:purple"),
    ):
        hit = status == str(value)
        if hit.any():
            ax.plot(
                starts[hit],
                log.solve_ms[hit],
                linestyle="none",
                marker=marker,
                color=color,
                markersize=7,
                label=f"{value} ({int(hit.sum())})",
            )
    ax.set_ylim(bottom=0.0)
    ax.set_ylabel("controller time (ms)")
    _figure_legend(figure, axes)
    _finish_time_axes(log, axes)
    return figure


def controller_label(config) -> str:
    """Short name of a controller and its horizons, e.g. ``ltv-mpc (nc 30/ny 30, offset-free)``.

    Parameters
    ----------
    config : auvmpc.controllers.config.HorizontalControllerConfig
    """
    from auvmpc.controllers.config import Horizon, OffsetFree

    kind = str(config.type)
    if not isinstance(config, Horizon):  # baseline, thrust-playback, most of your own
        return kind
    moves = len(config.move_schedule())
    parts = [f"nc {moves}/ny {config.prediction_horizon}"]
    if config.move_steps is not None:
        parts[0] += " blocked"
    if kind == "nmpc":
        parts.append(str(config.nmpc_mode))
    if isinstance(config, OffsetFree) and config.offset_free:
        parts.append("offset-free")
    return f"{kind} ({', '.join(parts)})"


def run_title(scenario, vehicle_name: str) -> str:
    """Figure title naming the scenario, the controller and the vehicle."""
    return f"{scenario.name}: {controller_label(scenario.controller)}, vehicle {vehicle_name}"


def run_figures(
    log: SimLog,
    obstacles: Sequence[ObstacleConfig],
    vehicle_radius: float,
    limits: VehicleParams,
    title: str = "",
) -> dict[str, Figure]:
    """The standard figures of one run, keyed by the file stem they are saved under.

    Returns
    -------
    dict of str to Figure
        ``trajectory``, ``errors``, ``velocities``, ``thrusts`` (a vehicle with
        ``actuators:``: ``actuators``, each input in its units), ``solve_times``.
    """
    inputs = (
        {"thrusts": figure_thrusts(log, limits, title)}
        if limits.has_thrusters
        else {"actuators": figure_actuators(log, limits.six_dof_actuators, title)}
    )
    return {
        "trajectory": figure_trajectory(log, obstacles, vehicle_radius, title),
        "errors": figure_errors(log, title),
        "velocities": figure_velocities(log, title),
        **inputs,
        "solve_times": figure_solve_times(log, title),
    }


def save_figures(
    figures: Mapping[str, Figure], folder: Path, dpi: int = 120, fmt: str = "png"
) -> list[Path]:
    """Write each figure to ``folder/<name>.<fmt>`` atomically.

    Each image is written to a hidden temporary file in ``folder`` and moved onto
    its final name with ``os.replace``, so a reader never sees a partial file. The
    folder is created if missing; existing files of the same name are replaced. The
    bounding box is fitted to everything drawn, so no legend or label is clipped.

    Parameters
    ----------
    figures : mapping of str to Figure
        File stem (no directory part, no extension) to figure.
    folder : Path
        Output folder.
    dpi : int
        Resolution, > 0 (of the raster parts of a PDF or SVG).
    fmt : str
        ``png``, ``pdf`` or ``svg`` (:data:`FIGURE_FORMATS`).

    Returns
    -------
    list of Path
        The files written, in the order of ``figures``.
    """
    if not dpi > 0:
        raise ValueError(f"dpi must be > 0, got {dpi!r}")
    if fmt not in FIGURE_FORMATS:
        raise ValueError(f"figure format must be one of {list(FIGURE_FORMATS)}, got {fmt!r}")
    for name in figures:
        if not name or name in {".", ".."} or Path(name).name != name or "\\" in name:
            raise ValueError(f"figure name {name!r} must be a plain file stem (no folders)")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, figure in figures.items():
        target = folder / f"{name}.{fmt}"
        with atomic_file(target, "wb") as stream:  # a full disk names the figure's file
            figure.savefig(stream, format=fmt, dpi=dpi, bbox_inches="tight")
        written.append(target)
    return written


def figure_error_vs_parameter(
    levels: ArrayLike,
    values: ArrayLike | Mapping[str, ArrayLike],
    xlabel: str,
    ylabel: str,
    title: str = "",
) -> Figure:
    """Line-and-marker plot of a result against a swept parameter.

    Parameters
    ----------
    levels : array_like, (L,)
        Parameter values, e.g. an uncertainty level in %.
    values : array_like (L,) or mapping of str to array_like (L,)
        One series, or several keyed by their legend label (e.g. RMS and max
        error). NaN (a failed run) leaves a gap.
    xlabel, ylabel : str
        Axis labels, with units.
    title : str
        Figure title; empty for none.

    Returns
    -------
    Figure
        One axes.
    """
    x = np.asarray(levels, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"levels must be 1-D, got shape {x.shape}")
    series = dict(values) if isinstance(values, Mapping) else {"": values}
    figure = _new_figure(PANEL_WIDTH_IN, 3.6, title)
    ax = figure.add_subplot()
    markers = "osD^vP*X"
    for i, (label, raw) in enumerate(series.items()):
        y = np.asarray(raw, dtype=float)
        if y.shape != x.shape:
            where = f"values[{label!r}]" if label else "values"
            raise ValueError(f"{where} has shape {y.shape}, expected {x.shape} to match levels")
        style = ACTUAL_STYLE | {"color": SERIES_COLORS[i % len(SERIES_COLORS)]}
        ax.plot(x, y, **style, marker=markers[i % len(markers)], markersize=5, label=label or None)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, alpha=0.4)
    if any(series):
        ax.legend(loc="best", fontsize="small")
    return figure


def figure_depth(log, limits, title: str = "") -> Figure:
    """Depth step in the spirit of the paper's Figure 8: depth and reference, thrusts.

    Parameters
    ----------
    log : auvmpc.sim.log.SimLog
        A depth run's (``DEPTH_LOG``).
    limits : HeaveParams
        Vertical thrust limits to draw.
    """
    figure, axes = _time_panels(2, title)
    depth_ax, thrust_ax = axes
    depth_ax.plot(log.t, log.column("z_measured"), color="0.6", lw=0.8, label="measured (sensor)")
    depth_ax.step(log.t, log.column("z_ref"), where="post", color="0.3", ls="--", label="reference")
    depth_ax.plot(log.t, log.state[:, DEPTH.index("z")], color="tab:blue", label="depth z (true)")
    depth_ax.set_ylabel("z (m, up)")
    steps = len(log.thrust)
    for i in range(log.thrust.shape[1]):
        thrust_ax.step(
            log.t[:steps],
            log.thrust[:, i],
            where="post",
            color=THRUSTER_COLORS[i % len(THRUSTER_COLORS)],
            label=log.input_names[i],
        )
    for bound in limits.thrust_limits:
        thrust_ax.axhline(bound, color="tab:red", ls=":", lw=1.0)
    thrust_ax.plot([], [], color="tab:red", ls=":", label=f"limits {list(limits.thrust_limits)} N")
    thrust_ax.set_ylabel("vertical thrust (N)")
    for ax in axes:
        ax.grid(True, alpha=0.4)
    axes[-1].set_xlim(log.t[0], log.t[-1])
    axes[-1].set_xlabel(TIME_LABEL)
    _figure_legend(figure, axes)
    return figure


# --- 6-DOF runs (paper section 4.2, Figures 5-6) -------------------------------------------


def six_dof_figures(log, limits: VehicleParams, title: str = "") -> dict[str, Figure]:
    """The 6-DOF run's own figures, keyed by file stem: ``trajectory_3d`` (the paper's Figure
    5), ``tracking_errors`` (its Figure 6: horizontal position, yaw-rate, surge and sway
    errors) and ``depth_attitude`` (depth, roll, pitch, vertical thrust).

    Parameters
    ----------
    log : auvmpc.sim.log.SimLog
        A 6-DOF run's (``SIX_DOF_LOG``).
    limits : VehicleParams
        With a ``heave`` section: the vertical thrust limits drawn.
    """
    return {
        "trajectory_3d": figure_trajectory_3d(log, title),
        "tracking_errors": figure_tracking_errors(log.horizontal(), title),
        "depth_attitude": figure_depth_attitude(log, limits, title),
    }


def figure_trajectory_3d(log, title: str = "") -> Figure:
    """The vehicle's path and the 3-D reference, depth axis pointing down."""
    figure = _new_figure(7.0, 6.0, title)
    ax = figure.add_subplot(projection="3d")
    ax.plot(
        *log.reference[:, _POSITION].T, log.column("z_ref"),
        label="reference", **REFERENCE_STYLE,
    )  # fmt: skip
    position = log.state[:, SIX_DOF.span("x", "z")]  # x north, y east, z down (m)
    ax.plot(*position.T, label="vehicle (true)", **ACTUAL_STYLE)
    ax.scatter(*position[0], color=ACTUAL_STYLE["color"], marker="o", label="start")
    ax.set_xlabel("x north (m)")
    ax.set_ylabel("y east (m)")
    ax.set_zlabel("depth z (m, down)")
    ax.invert_zaxis()
    figure.legend(loc="outside lower center", ncol=3, fontsize="small", frameon=False)
    return figure


def figure_tracking_errors(log, title: str = "") -> Figure:
    """Horizontal position error and the yaw-rate, surge and sway errors (true - reference)."""
    figure, axes = _time_panels(4, title)

    def error(name: str) -> np.ndarray:
        column = HORIZONTAL.index(name)
        return log.state[:, column] - log.reference[:, column]

    rows = (
        (position_error(log), "position error (m)"),
        (error("r"), "yaw-rate error (rad/s)"),
        (error("u"), "surge error (m/s)"),
        (error("v"), "sway error (m/s)"),
    )
    for ax, (values, label) in zip(axes, rows, strict=True):
        ax.plot(log.t, values, **ACTUAL_STYLE)
        ax.axhline(0.0, color="0.6", lw=0.8)
        ax.set_ylabel(label)
    _finish_time_axes(log, axes)
    return figure


def figure_depth_attitude(log, limits: VehicleParams, title: str = "") -> Figure:
    """Depth and its reference, roll and pitch, and the vertical thrusters' forces (a
    vehicle with ``actuators:`` has none apart: its fins are in the ``actuators`` figure)."""
    vertical = log.horizontal_inputs < log.n_thrusters
    figure, axes = _time_panels(4 if vertical else 3, title)
    depth_ax, roll_ax, pitch_ax = axes[:3]
    depth_ax.plot(log.t, log.column("z_ref"), label="reference", **REFERENCE_STYLE)
    depth_ax.plot(log.t, log.column("z"), label="true", **ACTUAL_STYLE)
    depth_ax.invert_yaxis()
    depth_ax.set_ylabel("depth z (m, down)")
    roll_ax.plot(log.t, np.degrees(log.state[:, SIX_DOF.index("phi")]), **ACTUAL_STYLE)
    roll_ax.set_ylabel("roll phi (deg)")
    pitch_ax.plot(log.t, np.degrees(log.state[:, SIX_DOF.index("theta")]), **ACTUAL_STYLE)
    pitch_ax.set_ylabel("pitch theta (deg)")
    if not vertical:
        _figure_legend(figure, axes)
        _finish_time_axes(log, axes)
        return figure
    thrust_ax = axes[3]
    n, steps = log.horizontal_inputs, log.steps
    for i in range(n, log.n_thrusters):
        thrust_ax.step(
            log.t[:steps], log.thrust[:, i], where="post",
            color=THRUSTER_COLORS[i % len(THRUSTER_COLORS)], label=log.input_names[i],
        )  # fmt: skip
    if limits.heave is not None:
        for bound in limits.heave.thrust_limits:
            thrust_ax.axhline(bound, **LIMIT_STYLE)
        thrust_ax.plot([], [], label=f"limits {list(limits.heave.thrust_limits)} N", **LIMIT_STYLE)
    thrust_ax.set_ylabel("vertical thrust (N)")
    _figure_legend(figure, axes)
    _finish_time_axes(log, axes)
    return figure


# --- helpers -------------------------------------------------------------------------------


def _new_figure(width_in: float, height_in: float, title: str) -> Figure:
    """A pyplot-free figure on an Agg canvas with a constrained (tight) layout."""
    figure = Figure(figsize=(width_in, height_in), layout="constrained")
    FigureCanvasAgg(figure)
    if title:
        figure.suptitle(title)
    return figure


def _time_panels(
    rows: int, title: str, height_in: float = PANEL_HEIGHT_IN
) -> tuple[Figure, list[Axes]]:
    figure = _new_figure(PANEL_WIDTH_IN, 0.5 + height_in * rows, title)
    axes = figure.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    return figure, list(axes)


def _figure_legend(figure: Figure, axes: list[Axes]) -> None:
    """One legend for all panels, below them (first use of each label wins)."""
    entries: dict[str, object] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels(), strict=True):
            entries.setdefault(label, handle)
    if entries:
        figure.legend(
            list(entries.values()),
            list(entries),
            loc="outside lower center",
            ncol=min(len(entries), 6),
            fontsize="small",
            frameon=False,
        )


def _finish_time_axes(log: SimLog, axes: list[Axes]) -> None:
    for ax in axes:
        ax.grid(True, alpha=0.4)
    if log.t[-1] > log.t[0]:
        axes[-1].set_xlim(log.t[0], log.t[-1])
    axes[-1].set_xlabel(TIME_LABEL)


def _closest_approach(
    log: SimLog, obstacle: ObstacleConfig, vehicle_radius: float
) -> tuple[int, float] | None:
    """(k, gap): sample of the smallest vehicle-to-obstacle gap (m) while it exists, or None."""
    exists = np.array([obstacle.exists_at(t) for t in log.t], dtype=bool)
    if not exists.any():
        return None
    gap = np.hypot(*(log.state[:, _POSITION] - _centres(obstacle, log.t)).T)
    gap = np.where(exists, gap - obstacle.radius - vehicle_radius, np.inf)
    k = int(np.argmin(gap))
    return k, float(gap[k])


def _centres(obstacle: ObstacleConfig, t: np.ndarray) -> np.ndarray:
    """(len(t), 2) obstacle centre at each time (same motion as ``center_at``)."""
    return np.array(obstacle.center) + np.outer(t, obstacle.velocity)


def _draw_obstacle(
    ax: Axes, log: SimLog, obstacle: ObstacleConfig, k_closest: int, labelled: set[str]
) -> None:
    """Filled disc at closest approach; faded, time-stamped discs along a moving one's path."""
    exists = np.flatnonzero([obstacle.exists_at(t) for t in log.t])
    moving = any(obstacle.velocity)
    always = len(exists) == len(log.t)

    def label(text: str) -> str:
        if text in labelled:
            return "_nolegend_"
        labelled.add(text)
        return text

    if moving:
        spread = np.linspace(0, len(exists) - 1, GHOST_POSITIONS).round().astype(int)
        picks = exists[np.unique(spread)]
        path = _centres(obstacle, log.t[exists[[0, -1]]])
        ax.plot(*path.T, color=OBSTACLE_EDGE, linestyle=":", linewidth=1.0, zorder=1)
        for k in picks:
            if k == k_closest:
                continue
            ghost = Circle(
                tuple(obstacle.center_at(log.t[k])),
                obstacle.radius,
                facecolor=OBSTACLE_FACE,
                edgecolor=OBSTACLE_EDGE,
                alpha=0.18,
                linestyle="--",
                zorder=1,
                label=label("moving obstacle, other times"),
            )
            ax.add_patch(ghost)
            _annotate_below(ax, ghost.center, obstacle.radius, f"{log.t[k]:g} s", alpha=0.7)
    centre = tuple(obstacle.center_at(log.t[k_closest]))
    disc = Circle(
        centre,
        obstacle.radius,
        facecolor=OBSTACLE_FACE,
        edgecolor=OBSTACLE_EDGE,
        alpha=0.6,
        linewidth=1.2,
        zorder=2,
        label=label("obstacle"),
    )
    ax.add_patch(disc)
    if moving:
        _annotate_below(ax, centre, obstacle.radius, f"{log.t[k_closest]:g} s", alpha=1.0)
    elif not always:
        until = "" if obstacle.vanish_time is None else f"{obstacle.vanish_time:g}"
        _annotate_below(ax, centre, obstacle.radius, f"{obstacle.appear_time:g}-{until} s", 1.0)


def _annotate_below(
    ax: Axes, centre: tuple[float, float], radius: float, text: str, alpha: float
) -> None:
    """Small text centred just under a disc."""
    ax.annotate(
        text,
        (centre[0], centre[1] - radius),
        xytext=(0, -2),
        textcoords="offset points",
        fontsize=7,
        ha="center",
        va="top",
        alpha=alpha,
    )


def _finish_trajectory_axes(ax, log: SimLog) -> None:
    """Equal axes in metres, grid, the current's arrows and the legend of a trajectory plot."""
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.grid(True, alpha=0.4)
    force = np.column_stack([log.column("dist_X"), log.column("dist_Y")])
    water = np.column_stack([log.column(name) for name in HORIZONTAL_CURRENT_NAMES])
    _draw_current_arrow(ax, force, (0.1, 0.9), "current force, {mean}{size:.3g} N")
    _draw_current_arrow(ax, water, (0.1, 0.8), "water current, {mean}{size:.3g} m/s")
    ax.legend(loc="best", fontsize="small", framealpha=0.85)


def _draw_current_arrow(ax: Axes, vectors: np.ndarray, corner, label: str) -> None:
    """The mean of world-frame ``vectors`` (k, 2) as an arrow at ``corner`` (axes fraction),
    labelled with its size (``label``'s ``{size}``; ``{mean}`` says "mean " if it varies).

    The arrow's direction is the mean's (axes have equal aspect); its length is fixed.
    Nothing is drawn where the mean is zero.
    """
    if not len(vectors):
        return
    mean = vectors.mean(axis=0)
    magnitude = float(np.hypot(*mean))
    if magnitude < 1e-9:
        return
    varies = float(np.ptp(np.hypot(vectors[:, 0], vectors[:, 1]))) > 1e-6 * max(1.0, magnitude)
    direction = mean / magnitude
    centre, half = np.array(corner), 0.05
    ax.annotate(
        "",
        xy=tuple(centre + half * direction),
        xytext=tuple(centre - half * direction),
        xycoords="axes fraction",
        arrowprops={"arrowstyle": "-|>", "color": CURRENT_COLOR, "linewidth": 2.0},
        zorder=6,
    )
    text = label.format(mean="mean " if varies else "", size=magnitude) + " (arrow: direction)"
    ax.plot([], [], color=CURRENT_COLOR, marker=r"$\rightarrow$", markersize=12, linestyle="none",
            label=text)  # fmt: skip


def _draw_vehicle(
    ax: Axes, state: np.ndarray, radius: float, color: str, alpha: float, label: str | None
) -> None:
    """Envelope disc outline with a tick from the centre along the heading."""
    (x, y), psi = state[_POSITION], state[HORIZONTAL.heading]
    ax.add_patch(
        Circle(
            (x, y),
            radius,
            fill=False,
            edgecolor=color,
            linewidth=1.0,
            alpha=alpha,
            zorder=3,
            label=label or "_nolegend_",
        )
    )
    ax.plot(
        [x, x + radius * math.cos(psi)],
        [y, y + radius * math.sin(psi)],
        color=color,
        linewidth=1.0,
        alpha=alpha,
        zorder=3,
    )


def _draw_min_clearance(
    ax: Axes, log: SimLog, obstacle: ObstacleConfig, k: int, gap: float, vehicle_radius: float
) -> None:
    """Vehicle disc at the sample of minimum clearance and the gap to the obstacle disc."""
    position = log.state[k, _POSITION]
    centre = obstacle.center_at(log.t[k])
    offset = centre - position
    distance = float(np.hypot(*offset))
    contact = ", contact" if gap < 0 else ""
    text = f"min clearance {gap:.2f} m (t = {log.t[k]:g} s{contact})"
    if vehicle_radius > 0:
        _draw_vehicle(ax, log.state[k], vehicle_radius, HIGHLIGHT, 1.0, "vehicle at min clearance")
    if distance > 0:
        direction = offset / distance
        start = position + vehicle_radius * direction
        end = centre - obstacle.radius * direction
        ax.plot(
            *np.array([start, end]).T,
            color=HIGHLIGHT,
            linewidth=2.0,
            zorder=4,
            solid_capstyle="butt",
            label=text,
        )
    else:
        ax.plot([], [], color=HIGHLIGHT, linewidth=2.0, label=text)


# --- overlays of several runs (auvmpc compare) ------------------------------------------------


def figure_compare_trajectory(
    runs: Sequence[tuple[str, SimLog]],
    obstacles: Sequence[ObstacleConfig] = (),
    title: str = "",
) -> Figure:
    """Paths of several runs over the first run's reference, obstacles and current.

    Parameters
    ----------
    runs : sequence of (label, SimLog)
        One legend entry per run, in :data:`SERIES_COLORS` order.
    obstacles : sequence of ObstacleConfig
        Drawn where they are at the first run's closest approach.
    title : str
        Figure title; empty for none.
    """
    _check_runs(runs)
    figure = _new_figure(PANEL_WIDTH_IN, 6.4, title)
    ax = figure.add_subplot()
    first = runs[0][1]
    ax.plot(*first.reference[:, _POSITION].T, **REFERENCE_STYLE, label="reference")
    labelled: set[str] = set()
    for obstacle in obstacles:
        approach = _closest_approach(first, obstacle, 0.0)
        if approach is not None:
            _draw_obstacle(ax, first, obstacle, approach[0], labelled)
    for i, (label, log) in enumerate(runs):
        color = _series_color(i)
        ax.plot(*log.state[:, _POSITION].T, **ACTUAL_STYLE | {"color": color}, label=label)
        ax.plot(*log.state[-1, _POSITION], marker="s", color=color, markeredgecolor="black",
                markersize=6, linestyle="none", zorder=5)  # fmt: skip
    ax.plot(*first.state[0, _POSITION], marker="o", color="tab:green", markeredgecolor="black",
            markersize=8, linestyle="none", label="start", zorder=5)  # fmt: skip
    ax.plot([], [], marker="s", color="white", markeredgecolor="black", linestyle="none",
            label="end of each run")  # fmt: skip
    _finish_trajectory_axes(ax, first)
    return figure


def figure_compare_errors(runs: Sequence[tuple[str, SimLog]], title: str = "") -> Figure:
    """Position error (m) and wrapped heading error (rad) of several runs, two panels."""
    _check_runs(runs)
    figure, axes = _time_panels(2, title)
    top, bottom = axes
    for i, (label, log) in enumerate(runs):
        style = ACTUAL_STYLE | {"color": _series_color(i)}
        top.plot(log.t, position_error(log), **style, label=label)
        bottom.plot(log.t, heading_error(log), **style)
    top.set_ylim(bottom=0.0)
    top.set_ylabel(r"position error $\|p - p_\mathrm{ref}\|$ (m)")
    bottom.axhline(0.0, color="0.3", linewidth=0.6)
    bottom.set_ylabel(r"heading error $\psi - \psi_\mathrm{ref}$ (rad)")
    _figure_legend(figure, axes)
    _finish_compared_time_axes(runs, axes)
    return figure


def figure_compare_thrusts(
    runs: Sequence[tuple[str, SimLog]], limits: VehicleParams | None = None, title: str = ""
) -> Figure:
    """Each thruster's force in its own panel, one line per run, with the thrust limits (a
    vehicle with ``actuators:``: each input in its own units and limits).

    Runs of vehicles with fewer thrusters leave the extra panels to the others.
    """
    _check_runs(runs)
    panels = max(log.n_thrusters for _, log in runs)
    figure, axes = _time_panels(panels, title, height_in=1.6)
    for i, (label, log) in enumerate(runs):
        for j in range(log.n_thrusters):
            axes[j].stairs(log.thrust[:, j], log.t, color=_series_color(i), linewidth=1.1,
                           label=label)  # fmt: skip
    widest = max((log for _, log in runs), key=lambda log: log.n_thrusters)
    if limits is not None and not limits.has_thrusters:  # each input in its units and limits
        inputs = limits.six_dof_actuators
        lower, upper = (
            np.broadcast_to(v, (inputs.size,)) for v in (inputs.limits.lower, inputs.limits.upper)
        )
        # (runs of another vehicle may add panels: those keep no unit)
        labelled = zip(axes, inputs.layout.names, inputs.units, lower, upper, strict=False)
        for ax, name, unit, low, high in labelled:
            ax.set_ylabel(f"{name} ({unit})")
            ax.axhline(high, **LIMIT_STYLE, label="hard limits")
            ax.axhline(low, **LIMIT_STYLE)
        _figure_legend(figure, axes)
        _finish_compared_time_axes(runs, axes)
        return figure
    for name, ax in zip(widest.input_names, axes, strict=True):
        ax.set_ylabel(f"{name} (N)")
    if limits is not None:
        lower, upper = limits.thrust_limits
        for ax in axes:
            ax.axhline(upper, **LIMIT_STYLE, label=f"thrust limits [{lower:g}, {upper:g}] N")
            ax.axhline(lower, **LIMIT_STYLE)
    _figure_legend(figure, axes)
    _finish_compared_time_axes(runs, axes)
    return figure


def _series_color(i: int) -> str:
    return SERIES_COLORS[i % len(SERIES_COLORS)]


def _check_runs(runs: Sequence[tuple[str, SimLog]]) -> None:
    if not runs:
        raise ValueError("need at least one run to draw")


def _finish_compared_time_axes(runs: Sequence[tuple[str, SimLog]], axes: list[Axes]) -> None:
    for ax in axes:
        ax.grid(True, alpha=0.4)
    end = max(float(log.t[-1]) for _, log in runs)
    start = min(float(log.t[0]) for _, log in runs)
    if end > start:
        axes[-1].set_xlim(start, end)
    axes[-1].set_xlabel(TIME_LABEL)
