"""A run as a moving picture (``auvmpc animate``): GIF through Pillow, MP4 through ffmpeg.

Each frame shows the vehicle's outline and heading, one arrow per thruster (its force,
in the thruster colours of the figures; a propeller's or fin's: its command along the force
it makes), the path so far, the reference with the part
the controller previews over its prediction horizon, the obstacles where they are at
that moment (moving and appearing ones too), the current and a clock.

The still parts (axes, reference, legend) are drawn once; per frame only the moving
artists are drawn over that background (blitting), so a 100 s run at the default two
frames per simulated second renders in seconds.
"""

from __future__ import annotations

import math
import os
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Polygon

from auvmpc.environment.obstacles import ObstacleConfig
from auvmpc.errors import ConfigError
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.vehicle import VehicleParams
from auvmpc.plots import (
    ACTUAL_STYLE,
    OBSTACLE_EDGE,
    OBSTACLE_FACE,
    REFERENCE_STYLE,
    THRUSTER_COLORS,
    run_title,
)
from auvmpc.scenario import Scenario
from auvmpc.sim.log import SimLog

__all__ = ["AnimationFormat", "AnimationSettings", "animate_run", "ffmpeg_path", "frame_rows"]

_POSITION = HORIZONTAL.position  # x, y (m) of a horizontal log's state and reference


class AnimationFormat(StrEnum):
    GIF = "gif"  # Pillow: no extra program
    MP4 = "mp4"  # needs an ffmpeg (on PATH, or from imageio-ffmpeg: auvmpc[video])


@dataclass(frozen=True)
class AnimationSettings:
    """How the animation plays.

    ``speed`` simulated seconds pass per second of playback at ``fps`` frames per second,
    so a frame is drawn every ``speed / fps`` simulated seconds (rounded to whole samples).
    """

    fps: float = 20.0
    speed: float = 10.0
    dpi: int = 80
    size_in: float = 6.0

    def __post_init__(self) -> None:
        for name, low, high in (("fps", 1, 60), ("speed", 0.1, 1000), ("dpi", 20, 600)):
            value = getattr(self, name)
            if not (math.isfinite(value) and low <= value <= high):
                raise ConfigError(f"--{name}", value, f"must be between {low} and {high}")


def frame_rows(log: SimLog, settings: AnimationSettings) -> np.ndarray:
    """Log rows drawn as frames: every ``stride`` samples, always including the last."""
    sample_time = log.sample_time if log.steps else 1.0
    stride = max(1, round(settings.speed / (settings.fps * sample_time)))
    rows = np.arange(0, len(log.t), stride)
    if rows[-1] != len(log.t) - 1:
        rows = np.append(rows, len(log.t) - 1)
    return rows


def ffmpeg_path() -> str | None:
    """An ffmpeg executable: imageio-ffmpeg's bundled one if installed, else one on PATH."""
    try:
        import imageio_ffmpeg

        return imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError):
        import shutil

        return shutil.which("ffmpeg")


def animate_run(
    log: SimLog,
    scenario: Scenario,
    model: VehicleParams,
    path: Path,
    settings: AnimationSettings | None = None,
    on_frame: Callable[[int, int], None] | None = None,
) -> Path:
    """Render the run to ``path`` (``.gif`` or ``.mp4``), written atomically.

    Parameters
    ----------
    log, scenario, model
        The run as ``runner.read_run`` gives it, its scenario and the controller's model
        (thruster geometry and limits).
    path : Path
        Output file; the suffix picks the format.
    settings : AnimationSettings
        Frame rate, playback speed, resolution.
    on_frame : callable(done, total), optional
        Progress report after each frame.
    """
    settings = settings or AnimationSettings()
    path = Path(path)
    try:
        fmt = AnimationFormat(path.suffix.lstrip(".").lower())
    except ValueError:
        raise ConfigError("--out", str(path), "must end in .gif or .mp4") from None
    executable = None
    if fmt is AnimationFormat.MP4:
        executable = ffmpeg_path()
        if executable is None:
            raise ConfigError(
                "--out", str(path), "MP4 needs ffmpeg: pip install 'auvmpc[video]' or use .gif"
            )
    scene = _Scene(log, scenario, model, settings)
    rows = frame_rows(log, settings)
    path.parent.mkdir(parents=True, exist_ok=True)

    def frames():
        for done, k in enumerate(rows, start=1):
            yield scene.frame(int(k))
            if on_frame is not None:
                on_frame(done, len(rows))

    temporary = path.with_name(f".{path.stem}.{os.getpid()}.{uuid.uuid4().hex}{path.suffix}")
    try:
        if executable is None:
            _write_gif(frames(), temporary, settings.fps)
        else:
            _write_mp4(frames(), temporary, settings.fps, executable)
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
    return path


def _write_gif(frames: Iterator[np.ndarray], path: Path, fps: float) -> None:
    """Pillow GIF; every frame is mapped onto the first frame's 256-colour palette."""
    from PIL import Image

    images = []
    palette = None
    for rgba in frames:
        image = Image.fromarray(rgba[:, :, :3])
        if palette is None:
            palette = image.quantize(colors=256)
            images.append(palette)
        else:
            images.append(image.quantize(palette=palette, dither=Image.Dither.NONE))
    duration_ms = round(1000.0 / fps)
    images[0].save(
        path, format="GIF", save_all=True, append_images=images[1:], duration=duration_ms, loop=0
    )


def _write_mp4(frames: Iterator[np.ndarray], path: Path, fps: float, ffmpeg: str) -> None:
    """H.264 MP4 through an ffmpeg process fed raw RGB frames on its standard input."""
    import subprocess

    process = None
    try:
        for rgba in frames:
            rgb = np.ascontiguousarray(rgba[:, :, :3])
            if process is None:
                height, width = rgb.shape[:2]
                command = [
                    ffmpeg,
                    "-loglevel",
                    "error",
                    "-y",
                    "-f",
                    "rawvideo",
                    "-pix_fmt",
                    "rgb24",
                    "-s",
                    f"{width}x{height}",
                    "-r",
                    f"{fps:g}",
                    "-i",
                    "-",
                    "-c:v",
                    "libx264",
                    "-pix_fmt",
                    "yuv420p",
                    # yuv420p needs even sizes
                    "-vf",
                    "pad=ceil(iw/2)*2:ceil(ih/2)*2",
                    "-f",
                    "mp4",
                    str(path),
                ]
                process = subprocess.Popen(command, stdin=subprocess.PIPE, stderr=subprocess.PIPE)
            process.stdin.write(rgb.tobytes())
    finally:
        if process is not None:
            process.stdin.close()
            error = process.stderr.read().decode(errors="replace").strip()
            if process.wait() != 0:
                raise RuntimeError(f"ffmpeg failed: {error.splitlines()[-1] if error else '?'}")


def _arrows(model: VehicleParams) -> tuple[np.ndarray, np.ndarray, Any, str]:
    """Where each input's arrow starts (n, 2) (m, body x, y), its direction (n, 2), the
    command drawn at full length (a value, or one per input) and what the legend calls it.
    Thrusters push along their direction, the largest thrust limit at full length; a
    propeller or fins (``actuators:``) along the horizontal force their largest command
    makes at 1 m/s ahead (none for stern planes, whose lift is vertical), at full length at
    that command."""
    if model.has_thrusters:
        angles = np.radians([t.angle_deg for t in model.thrusters])
        largest = max(abs(v) for v in model.thrust_limits) or 1.0
        return (
            np.array([t.position for t in model.thrusters]),
            np.column_stack([np.cos(angles), np.sin(angles)]),
            largest,
            f"{largest:g} N",
        )
    inputs = model.six_dof_actuators
    ahead = np.array([1.0, 0, 0, 0, 0, 0])
    largest = np.maximum(np.abs(inputs.limits.lower), np.abs(inputs.limits.upper))
    largest = np.where(largest > 0, largest, 1.0)
    directions = []
    for actuator, command in zip(inputs.actuators, largest, strict=True):
        force = np.asarray(actuator.wrench(ahead, command), dtype=float)[:2]
        norm = float(np.hypot(*force))
        directions.append(force / norm if norm > 1e-9 else np.zeros(2))
    units = ", ".join(
        f"{value:g} {unit}" for value, unit in zip(largest, inputs.units, strict=True)
    )
    positions = np.array([actuator.position[:2] for actuator in inputs.actuators])
    return positions, np.array(directions), largest, units


class _Scene:
    """The figure and the artists that move: the whole run on the left, a close-up of the
    vehicle (its outline, envelope and thrust arrows at true scale) on the right."""

    def __init__(
        self, log: SimLog, scenario: Scenario, model: VehicleParams, settings: AnimationSettings
    ) -> None:
        self.log = log
        self.obstacles: tuple[ObstacleConfig, ...] = scenario.obstacles
        controller = scenario.controller
        self.preview_rows = controller.prediction_horizon
        self.thruster_xy, self.thruster_dir, self.full_scale, self.scale_label = _arrows(model)
        # The world force on the vehicle (N), by its log.csv columns.
        self.force = np.column_stack([log.column(name) for name in ("dist_X", "dist_Y")])
        self.radius = controller.vehicle_radius
        half_length = max(float(np.abs(self.thruster_xy[:, 0]).max()) * 1.25, self.radius, 0.3)
        half_width = max(float(np.abs(self.thruster_xy[:, 1]).max()) * 1.25, 0.45 * half_length)
        self.hull = _hull(half_length, half_width)
        # Length drawn for a thruster at its limit (m): in the close-up the hull's half
        # length; in the overview 6 % of the scene, so that the arrows stay visible.
        span = float(
            np.ptp(np.vstack([log.state[:, _POSITION], log.reference[:, _POSITION]]), axis=0).max()
        )
        self.arrow_length = {"main": max(half_length, 0.06 * span), "zoom": half_length}
        self.zoom_half_width = 2.5 * max(half_length, self.radius)

        size = settings.size_in
        figure = Figure(figsize=(1.5 * size, size), dpi=settings.dpi, layout="constrained")
        FigureCanvasAgg(figure)
        figure.suptitle(run_title(scenario, model.name), fontsize="medium")
        axes = figure.subplot_mosaic(
            [["main", "zoom"], ["main", "legend"]], width_ratios=[2, 1], height_ratios=[1, 1]
        )
        self.figure, self.ax, self.zoom = figure, axes["main"], axes["zoom"]
        self.parts = {name: self._populate(axes[name], name) for name in ("main", "zoom")}
        ax = self.ax
        self.clock = ax.text(
            0.02, 0.98, "", transform=ax.transAxes, va="top", ha="left", fontsize="medium",
            family="monospace", bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "0.7"},
        )  # fmt: skip
        self.current = ax.text(
            0.98, 0.02, "", transform=ax.transAxes, va="bottom", ha="right", fontsize="small",
            color="teal", bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "none"},
        )  # fmt: skip
        self._limits()
        for axis in (ax, self.zoom):
            axis.set_aspect("equal", adjustable="box")
            axis.grid(True, alpha=0.4)
            axis.set_xlabel("x (m)")
            axis.set_ylabel("y (m)")
        self.zoom.set_title(f"close-up, {2 * self.zoom_half_width:.2g} m wide", fontsize="small")
        legend_ax = axes["legend"]
        legend_ax.axis("off")
        handles, labels = ax.get_legend_handles_labels()
        legend_ax.legend(handles, labels, loc="upper left", fontsize="x-small", frameon=False)
        # The close-up pans with the vehicle: it is redrawn whole every frame.
        self.zoom.set_animated(True)
        self.moving = [*self.parts["main"].values(), self.clock, self.current]
        self.moving = [
            a for item in self.moving for a in (item if isinstance(item, list) else [item])
        ]
        for artist in self.moving:
            artist.set_animated(True)
        # Draw the still parts once (and fix the layout), then blit the moving ones per frame.
        figure.canvas.draw()
        figure.set_layout_engine("none")
        self.background = figure.canvas.copy_from_bbox(figure.bbox)

    def _populate(self, ax, name: str) -> dict:
        """The reference and the moving artists of one axes (legend labels on the main one)."""
        log, main = self.log, name == "main"

        def label(text: str) -> str:
            return text if main else "_nolegend_"

        ax.plot(
            *log.reference[:, _POSITION].T,
            **REFERENCE_STYLE | {"alpha": 0.6},
            label=label("reference"),
        )
        parts: dict = {}
        (parts["preview"],) = ax.plot(
            [], [], color="0.25", linewidth=3.0, alpha=0.45,
            label=label(f"reference over the prediction horizon ({self.preview_rows} samples)"),
        )  # fmt: skip
        (parts["trail"],) = ax.plot([], [], **ACTUAL_STYLE, label=label("path so far"))
        (parts["target"],) = ax.plot(
            [], [], "o", color="0.3", markersize=4, label=label("reference now")
        )
        parts["discs"] = []
        for i, obstacle in enumerate(self.obstacles):
            disc = Circle(
                obstacle.center, obstacle.radius, facecolor=OBSTACLE_FACE, edgecolor=OBSTACLE_EDGE,
                alpha=0.6, zorder=2, label=label("obstacle (now)") if i == 0 else "_nolegend_",
            )  # fmt: skip
            ax.add_patch(disc)
            parts["discs"].append(disc)
        parts["body"] = Polygon(
            self.hull, closed=True, facecolor="tab:blue", edgecolor="navy", alpha=0.8, zorder=4,
            label=label("vehicle (bow forward)"),
        )  # fmt: skip
        ax.add_patch(parts["body"])
        envelope_label = f"envelope r = {self.radius:g} m" if self.radius > 0 else "_nolegend_"
        parts["envelope"] = Circle(
            (0, 0), self.radius, fill=False, edgecolor="tab:blue", linestyle=":", linewidth=0.9,
            zorder=4, label=label(envelope_label),
        )  # fmt: skip
        ax.add_patch(parts["envelope"])
        n = len(self.thruster_xy)
        colors = [THRUSTER_COLORS[i % len(THRUSTER_COLORS)] for i in range(n)]
        zeros = np.zeros(n)
        parts["quiver"] = ax.quiver(
            zeros, zeros, zeros, zeros, color=colors, angles="xy", scale_units="xy", scale=1.0,
            width=0.006 if main else 0.015, zorder=5,
        )  # fmt: skip
        if main:
            lengths = self.arrow_length
            prefix = "thrust " if self.scale_label.endswith(" N") else ""
            for name, color in zip(log.input_names, colors, strict=True):
                ax.plot([], [], color=color, linewidth=2, label=f"{prefix}{name}")
            ax.plot(
                [], [], color="none",
                label=f"arrow at {self.scale_label}: {lengths['main']:.2g} m here, "
                f"{lengths['zoom']:.2g} m in the close-up",
            )  # fmt: skip
        return parts

    def _limits(self) -> None:
        log = self.log
        points = [log.state[:, _POSITION], log.reference[:, _POSITION]]
        for obstacle in self.obstacles:
            t = log.t[[0, -1]]
            centres = np.array(obstacle.center) + np.outer(t, obstacle.velocity)
            points += [centres - obstacle.radius, centres + obstacle.radius]
        allpoints = np.vstack(points)
        low, high = allpoints.min(axis=0), allpoints.max(axis=0)
        margin = 0.08 * float(max(high - low)) + self.arrow_length["main"]
        self.ax.set_xlim(low[0] - margin, high[0] + margin)
        self.ax.set_ylim(low[1] - margin, high[1] + margin)

    def frame(self, k: int) -> np.ndarray:
        """The picture at log row k as an (height, width, 4) uint8 RGBA array."""
        self.draw(k)
        canvas = self.figure.canvas
        canvas.restore_region(self.background)
        for artist in self.moving:
            if artist.get_visible():
                self.figure.draw_artist(artist)
        self.figure.draw_artist(self.zoom)
        return np.asarray(canvas.buffer_rgba()).copy()

    def draw(self, k: int) -> None:
        """Move every artist to log row k."""
        log = self.log
        t = float(log.t[k])
        (x, y), psi = log.state[k, _POSITION], log.state[k, HORIZONTAL.heading]
        target_x, target_y = log.reference[k, _POSITION]
        rotation = np.array([[math.cos(psi), -math.sin(psi)], [math.sin(psi), math.cos(psi)]])
        position = np.array([x, y])
        end = min(len(log.t), k + self.preview_rows + 1)
        # The command applied from this sample on (the last row has none: keep the previous).
        n = len(self.thruster_xy)
        thrust = log.thrust[min(k, log.steps - 1)] if log.steps else np.zeros(n)
        origins = self.thruster_xy @ rotation.T + position
        for name, parts in self.parts.items():
            parts["body"].set_xy(self.hull @ rotation.T + position)
            parts["envelope"].set_center((x, y))
            parts["trail"].set_data(*log.state[: k + 1, _POSITION].T)
            parts["target"].set_data([target_x], [target_y])
            parts["preview"].set_data(*log.reference[k:end, _POSITION].T)
            scale = thrust / self.full_scale * self.arrow_length[name]
            world = (self.thruster_dir * scale[:, None]) @ rotation.T
            parts["quiver"].set_offsets(origins)
            parts["quiver"].set_UVC(world[:, 0], world[:, 1])
            for disc, obstacle in zip(parts["discs"], self.obstacles, strict=True):
                disc.set_center(tuple(obstacle.center_at(t)))
                disc.set_visible(obstacle.exists_at(t))
        half = self.zoom_half_width
        self.zoom.set_xlim(x - half, x + half)
        self.zoom.set_ylim(y - half, y + half)
        error = float(np.hypot(*(log.state[k, _POSITION] - log.reference[k, _POSITION])))
        self.clock.set_text(f"t = {t:6.1f} s\nerror {error:5.2f} m")
        force = self.force[k]
        magnitude = float(np.hypot(*force))
        if magnitude > 1e-9:
            bearing = math.degrees(math.atan2(force[1], force[0]))
            self.current.set_text(f"current {magnitude:.3g} N towards {bearing:.0f}° from +x")
        else:
            self.current.set_text("")


def _hull(half_length: float, half_width: float) -> np.ndarray:
    """A boat-like outline in the body frame (x forward), pointed at the bow."""
    return np.array(
        [
            [half_length, 0.0],
            [0.55 * half_length, half_width],
            [-half_length, half_width],
            [-half_length, -half_width],
            [0.55 * half_length, -half_width],
        ]
    )
