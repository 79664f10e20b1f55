"""Depth control: the paper's tank step experiment (paper-model.md section 8).

A depth scenario (``kind: depth``) steps the depth reference in a tank, with calm
water or surface waves, a pressure sensor with noise and a sample rate, and the
depth MPC. The log keeps the true depth; the controller sees the measurement.
Sign convention: z up, negative below the still surface; the bottom is at -depth.
"""

from __future__ import annotations

import csv
import io
import math
import time
from dataclasses import dataclass
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import Field, model_validator

from auvmpc.config import NonNegative, Positive, StrictModel
from auvmpc.controllers.base import ControlStatus, Observation
from auvmpc.controllers.config import ThrustPenalty
from auvmpc.environment.waves import GRAVITY, WaveConfig, WaveField, WaveType, wave_number
from auvmpc.errors import FieldError
from auvmpc.models.integrators import rk4_step_time_varying
from auvmpc.models.vehicle import HeaveParams, VehicleParams, heave_dynamics
from auvmpc.solvers.dense_qp import QpSolverName

__all__ = [
    "DepthScenario",
    "DepthLog",
    "depth_metrics",
    "simulate_depth",
    "STEP_METRIC_KEYS",
]

STEADY_WINDOW_S = 10.0  # "over the last 10 s" (issue 5)
WATER_DENSITY = 1025.0  # kg/m^3, sea water (a fresh-water tank: 1000; 2.5 % on the wave force)


class TankConfig(StrictModel):
    length_m: Positive = Field(default=4.2, description="tank length (m)")
    width_m: Positive = Field(default=2.0, description="tank width (m)")
    depth_m: Positive = Field(default=1.25, description="water depth (m)")


class DepthStepConfig(StrictModel):
    """The reference: hold ``initial_depth_m``, then step to ``final_depth_m``."""

    initial_depth_m: float = Field(default=-0.3, description="z before the step (m, negative)")
    final_depth_m: float = Field(default=-0.5, description="z after the step (m, negative)")
    step_time_s: NonNegative = Field(default=10.0, description="time of the step (s)")

    def depth(self, t: np.ndarray) -> np.ndarray:
        return np.where(np.asarray(t) >= self.step_time_s, self.final_depth_m, self.initial_depth_m)


class DepthSensorConfig(StrictModel):
    noise_std_m: NonNegative = Field(default=0.002, description="pressure-sensor noise (m)")
    rate_hz: Positive = Field(default=10.0, description="new samples per second (held between)")


class DepthObserverConfig(StrictModel):
    """Filter tuning. The defaults trust the model more than the sensor, so that wave-frequency
    motion, which 5 N/s thrusters cannot cancel, is filtered out rather than chased."""

    measurement_std: Positive = Field(default=0.02, description="assumed depth noise (m)")
    depth_process_std: Positive = Field(default=1e-3, description="model error per sample (m)")
    velocity_process_std: Positive = Field(default=5e-3, description="model error per sample (m/s)")
    disturbance_rate_std: Positive = Field(
        default=0.1, description="random walk of the unknown vertical force (N/sqrt(s))"
    )
    initial_disturbance_std: Positive = Field(
        default=5.0, description="prior uncertainty of the unknown vertical force (N)"
    )


class DepthControllerConfig(StrictModel):
    type: Literal["depth-mpc"] = Field(default="depth-mpc", description="depth controller")
    sample_time: Positive = Field(default=0.1, description="Te (s)")
    prediction_horizon: Annotated[int, Field(ge=1)] = Field(default=30, description="ny (steps)")
    control_horizon: Annotated[int, Field(ge=1)] | None = Field(
        default=None, description="nc (steps); omitted = every move free"
    )
    Q: tuple[NonNegative, NonNegative] = Field(default=(200.0, 1.0), description="on [z, w]")
    S: tuple[NonNegative, NonNegative] = Field(default=(400.0, 2.0), description="terminal")
    R: NonNegative = Field(default=0.01, description="weight per vertical thruster")
    thrust_penalty: ThrustPenalty = Field(
        default=ThrustPenalty.INCREMENT, description="R on F or dF"
    )
    offset_free: bool = Field(default=True, description="estimate the unknown vertical force")
    preview: bool = Field(
        default=False,
        description="see future setpoint changes (false: a commanded step, unknown until it "
        "happens, as in the tank experiment)",
    )
    known_net_buoyancy: bool = Field(
        default=False, description="give the model the vehicle file's net buoyancy"
    )
    surface_margin_m: NonNegative = Field(default=0.1, description="keep this far below z = 0")
    bottom_margin_m: NonNegative = Field(default=0.1, description="keep this far above the bottom")
    depth_slack_penalty: Positive = Field(default=1e5, description="exact penalty on depth slack")
    qp_solver: QpSolverName = Field(default=QpSolverName.DAQP)
    qp_iteration_limit: Annotated[int, Field(ge=1)] | None = None
    solver_time_limit_ms: Positive | None = None
    observer: DepthObserverConfig = Field(default_factory=DepthObserverConfig)

    @model_validator(mode="after")
    def _horizons(self) -> DepthControllerConfig:
        if self.control_horizon is not None and self.control_horizon > self.prediction_horizon:
            raise FieldError(
                "control_horizon",
                self.control_horizon,
                f"exceeds prediction_horizon {self.prediction_horizon}",
            )
        return self

    def move_schedule(self) -> tuple[int, ...]:
        return tuple(range(self.control_horizon or self.prediction_horizon))


class DepthPlantConfig(StrictModel):
    scale: dict[str, Positive] = Field(
        default_factory=dict, description="factor per heave field, e.g. {net_buoyancy_N: 2}"
    )
    max_step: Annotated[float, Field(gt=0, le=0.1)] = Field(
        default=0.01, description="longest RK4 step of the plant (s)"
    )


class DepthScenario(StrictModel):
    """A depth-step experiment in a tank."""

    kind: Literal["depth"] = Field(description="selects this schema")
    name: str
    description: str = ""
    duration: Positive = Field(description="simulated time (s)")
    vehicle: str | dict[str, Any] = Field(default="jmse2210")
    plant: DepthPlantConfig = Field(default_factory=DepthPlantConfig)
    tank: TankConfig = Field(default_factory=TankConfig)
    waves: WaveConfig | None = Field(default=None, description="surface waves, or calm water")
    sensor: DepthSensorConfig = Field(default_factory=DepthSensorConfig)
    reference: DepthStepConfig = Field(default_factory=DepthStepConfig)
    initial_state: tuple[float, float] | None = Field(
        default=None, description="[z, w]; default: at the initial depth, at rest"
    )
    controller: DepthControllerConfig = Field(default_factory=DepthControllerConfig)
    seed: Annotated[int, Field(ge=0)] = 0

    @model_validator(mode="after")
    def _inside_the_tank(self) -> DepthScenario:
        bottom = -self.tank.depth_m
        for field in ("initial_depth_m", "final_depth_m"):
            value = getattr(self.reference, field)
            if not bottom < value < 0.0:
                where = "below the tank bottom" if value <= bottom else "above the surface"
                raise FieldError(f"reference.{field}", value, f"{where} (water depth {-bottom} m)")
        if self.initial_state is not None and not bottom < self.initial_state[0] <= 0.0:
            raise FieldError("initial_state.0", self.initial_state[0], "outside the water")
        if self.reference.step_time_s >= self.duration:
            raise FieldError("reference.step_time_s", self.reference.step_time_s, "after the end")
        steps = self.duration / self.controller.sample_time
        if abs(steps - round(steps)) > 1e-9 * max(1.0, steps):
            raise FieldError("duration", self.duration, "not a whole number of samples")
        waves = self.waves
        if waves is not None:
            if waves.height_m >= self.tank.depth_m:
                raise FieldError("waves.height_m", waves.height_m, "not below the water depth")
            if waves.type is WaveType.REGULAR and waves.height_m > 0:
                k = wave_number(2.0 * math.pi / waves.period_s, self.tank.depth_m)
                if waves.height_m * k / (2.0 * math.pi) > 1.0 / 7.0:
                    raise FieldError(
                        "waves.height_m",
                        waves.height_m,
                        f"breaks: steeper than 1/7 of its {2 * math.pi / k:.2f} m wavelength",
                    )
        return self

    def start_state(self) -> np.ndarray:
        if self.initial_state is not None:
            return np.array(self.initial_state, dtype=float)
        return np.array([self.reference.initial_depth_m, 0.0])


@dataclass
class DepthLog:
    """Row k: true [z, w] and the reference at t_k; thrust applied over [t_k, t_k+1)."""

    t: np.ndarray  # (N+1,)
    state: np.ndarray  # (N+1, 2) true z, w
    z_ref: np.ndarray  # (N+1,)
    z_measured: np.ndarray  # (N+1,) what the controller saw
    thrust: np.ndarray  # (N, nv)
    solve_ms: np.ndarray  # (N,)
    status: list[str]
    wave_force: np.ndarray  # (N+1,) vertical wave force at t_k (N)
    sample_time: float
    initial_thrust: np.ndarray

    @classmethod
    def read_csv(cls, path, sample_time: float) -> DepthLog:
        """Load a log written by ``to_csv_text``."""
        with open(path, newline="") as handle:
            rows = list(csv.DictReader(handle))
        thrusters = sorted((c for c in rows[0] if c.startswith("Fz")), key=lambda c: int(c[2:]))
        steps = len(rows) - 1
        number = lambda row, name: float(row[name])  # noqa: E731
        return cls(
            t=np.array([number(r, "t") for r in rows]),
            state=np.array([[number(r, "z"), number(r, "w")] for r in rows]),
            z_ref=np.array([number(r, "z_ref") for r in rows]),
            z_measured=np.array([number(r, "z_measured") for r in rows]),
            thrust=np.array([[number(r, c) for c in thrusters] for r in rows[:steps]]),
            solve_ms=np.array([number(r, "solve_ms") for r in rows[:steps]]),
            status=[r["status"] for r in rows[:steps]],
            wave_force=np.array([number(r, "wave_force_N") for r in rows]),
            sample_time=sample_time,
            initial_thrust=np.zeros(len(thrusters)),
        )

    def to_csv_text(self) -> str:
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        nv = self.thrust.shape[1]
        writer.writerow(
            ["t", "z", "w", "z_ref", *(f"Fz{i + 1}" for i in range(nv)), "solve_ms", "status",
             "z_measured", "wave_force_N"]
        )  # fmt: skip
        steps = len(self.thrust)
        for k in range(steps + 1):
            applied = k < steps
            writer.writerow(
                [
                    repr(float(self.t[k])), repr(float(self.state[k, 0])),
                    repr(float(self.state[k, 1])), repr(float(self.z_ref[k])),
                    *([repr(float(f)) for f in self.thrust[k]] if applied else [""] * nv),
                    repr(float(self.solve_ms[k])) if applied else "",
                    self.status[k] if applied else "",
                    repr(float(self.z_measured[k])), repr(float(self.wave_force[k])),
                ]
            )  # fmt: skip
        return buffer.getvalue()


def resolve_heave(vehicle: VehicleParams, scale: dict[str, float]) -> HeaveParams:
    """The heave parameters of a vehicle, with the plant's scale factors applied."""
    if vehicle.heave is None:
        raise FieldError("vehicle", vehicle.name, "has no heave section (needed for depth control)")
    changes = {}
    for field, factor in scale.items():
        if field not in ("m_heave", "Zw", "Zww", "net_buoyancy_N", "thrust_rate_limit"):
            raise FieldError(f"plant.scale.{field}", factor, "not a scalable heave field")
        changes[field] = getattr(vehicle.heave, field) * factor
    return vehicle.heave.model_copy(update=changes)


def simulate_depth(
    scenario: DepthScenario, vehicle: VehicleParams, on_step=None
) -> tuple[DepthLog, HeaveParams]:
    """Run a depth scenario; returns the log and the heave parameters simulated."""
    from auvmpc.controllers.depth_mpc import DepthMpc

    model = resolve_heave(vehicle, {})
    plant = resolve_heave(vehicle, scenario.plant.scale)
    config = scenario.controller
    controller = DepthMpc(model, config, scenario.tank.depth_m)
    wave_seed, sensor_seed = np.random.SeedSequence(scenario.seed).spawn(2)
    waves = (
        WaveField(scenario.waves, scenario.tank.depth_m, np.random.default_rng(wave_seed))
        if scenario.waves is not None
        else None
    )
    sensor_rng = np.random.default_rng(sensor_seed)
    # Froude-Krylov plus added mass: the water around the body accelerates with the wave.
    displaced_mass = vehicle.mass + plant.net_buoyancy_N / GRAVITY
    inertia = displaced_mass * WATER_DENSITY / 1025.0 + (plant.m_heave - vehicle.mass)

    def wave_force(z: float, t: float) -> float:
        return 0.0 if waves is None else inertia * waves.vertical_acceleration(z, t)

    sample_time = config.sample_time
    steps = int(round(scenario.duration / sample_time))
    substeps = max(1, math.ceil(sample_time / scenario.plant.max_step - 1e-9))
    nv = plant.thruster_count
    t = sample_time * np.arange(steps + 1)
    log = DepthLog(
        t=t,
        state=np.zeros((steps + 1, 2)),
        z_ref=scenario.reference.depth(t),
        z_measured=np.zeros(steps + 1),
        thrust=np.zeros((steps, nv)),
        solve_ms=np.zeros(steps),
        status=[""] * steps,
        wave_force=np.zeros(steps + 1),
        sample_time=sample_time,
        initial_thrust=np.zeros(nv),
    )
    state = scenario.start_state()
    controller.reset(state, np.zeros(nv))
    sensor_period = 1.0 / scenario.sensor.rate_hz
    next_sensor_time = 0.0
    measured = state[0]
    preview = sample_time * np.arange(controller.preview_steps + 1)
    for k in range(steps + 1):
        log.state[k] = state
        log.wave_force[k] = wave_force(state[0], t[k])
        if t[k] >= next_sensor_time - 1e-9:  # a new pressure sample; held until the next
            measured = state[0] + scenario.sensor.noise_std_m * sensor_rng.standard_normal()
            next_sensor_time += sensor_period * max(
                1, math.floor((t[k] - next_sensor_time) / sensor_period) + 1
            )
        log.z_measured[k] = measured
        if k == steps:
            break
        z_ref = scenario.reference.depth(
            t[k] + preview if config.preview else np.full_like(preview, t[k])
        )
        observation = Observation(
            k=k,
            t=t[k],
            state=np.array([measured]),
            reference=np.column_stack([z_ref, np.zeros_like(z_ref)]),
        )
        started = time.perf_counter()
        result = controller.compute(observation)
        log.solve_ms[k] = 1e3 * (time.perf_counter() - started)
        thrust = np.asarray(result.thrust, dtype=float)
        log.thrust[k] = thrust
        log.status[k] = str(result.status)
        state = _heave_plant_step(plant, state, thrust, t[k], sample_time, substeps, wave_force)
        if on_step is not None:
            on_step(k + 1, steps)
    return log, plant


def _heave_plant_step(plant, state, thrust, t0, duration, substeps, wave_force) -> np.ndarray:
    """Integrate the heave plant over one held-thrust sample with RK4 sub-steps."""

    def rhs(time_s: float, x: np.ndarray) -> np.ndarray:
        return heave_dynamics(x, thrust, plant, wave_force(x[0], time_s))

    h = duration / substeps
    for i in range(substeps):
        state = rk4_step_time_varying(rhs, t0 + i * h, state, h)
    return state


STEP_METRIC_KEYS = (
    "rise_time_s", "settling_time_0p05m_s", "settling_time_2pct_s", "overshoot_m",
    "steady_state_error_mean_abs_m", "steady_state_error_max_abs_m",
)  # fmt: skip


def depth_metrics(log: DepthLog, scenario: DepthScenario, limits: HeaveParams) -> dict[str, Any]:
    """Step-response metrics of the true depth, plus violations and solve times."""
    step = scenario.reference
    z = log.state[:, 0]
    after = log.t >= step.step_time_s - 1e-9
    t_after, z_after = log.t[after] - step.step_time_s, z[after]
    change = step.final_depth_m - step.initial_depth_m
    progress = (z_after - step.initial_depth_m) / change  # 0 before, 1 at the target
    error = np.abs(z_after - step.final_depth_m)
    steady = log.t >= log.t[-1] - STEADY_WINDOW_S - 1e-9
    increments = np.diff(np.vstack([log.initial_thrust, log.thrust]), axis=0)
    tolerance = 1e-9
    lower, upper = limits.thrust_limits
    return {
        "rise_time_s": _rise_time(t_after, progress),
        "settling_time_0p05m_s": _settling_time(t_after, error, 0.05),
        "settling_time_2pct_s": _settling_time(t_after, error, 0.02 * abs(change)),
        "overshoot_m": float(max(0.0, np.max((z_after - step.final_depth_m) * np.sign(change)))),
        "steady_state_error_mean_abs_m": float(np.mean(np.abs(z[steady] - log.z_ref[steady]))),
        "steady_state_error_max_abs_m": float(np.max(np.abs(z[steady] - log.z_ref[steady]))),
        "max_z_m": float(z.max()),
        "min_z_m": float(z.min()),
        "thrust_limit_violations": int(
            np.sum((log.thrust < lower - tolerance) | (log.thrust > upper + tolerance))
        ),
        "thrust_rate_violations": int(
            np.sum(np.abs(increments) > limits.thrust_rate_limit * log.sample_time + tolerance)
        ),
        "max_abs_thrust_N": float(np.abs(log.thrust).max()),
        "solve_ms_median": float(np.median(log.solve_ms)),
        "solve_ms_p99": float(np.percentile(log.solve_ms, 99)),
        "solve_ms_max": float(log.solve_ms.max()),
        "solver_failures": sum(s == ControlStatus.FALLBACK for s in log.status),
    }


def _rise_time(t: np.ndarray, progress: np.ndarray) -> float | None:
    """10 % to 90 % of the step, first crossings."""
    ten = np.flatnonzero(progress >= 0.1)
    ninety = np.flatnonzero(progress >= 0.9)
    if len(ten) == 0 or len(ninety) == 0:
        return None
    return float(t[ninety[0]] - t[ten[0]])


def _settling_time(t: np.ndarray, error: np.ndarray, band: float) -> float | None:
    """Time of the last entry into the band (None if it ends outside)."""
    outside = np.flatnonzero(error > band)
    if len(outside) == 0:
        return 0.0
    if outside[-1] == len(error) - 1:
        return None
    return float(t[outside[-1] + 1])
