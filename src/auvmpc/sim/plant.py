"""The simulated vehicle over one zero-order-hold sample, as the closed loop (sim/loop.py)
steps it: a :class:`Plant` of the scenario's kind.

:class:`HorizontalPlant`: RK4 sub-steps of the 3-DOF model (auvmpc.models.vehicle) under the
world-frame disturbance, evaluated where each sub-step asks, and the water current (held over
the sample, like the force's slow part). :class:`HeavePlant`: RK4 sub-steps of the heave model
(auvmpc.models.heave) under the surface waves' vertical force. :class:`SixDofPlant`: RK4
sub-steps of the 6-DOF model (auvmpc.models.six_dof) in the water current, and
:class:`SixDofSensor`, what its controllers measure of it.

Two implementations of the same arithmetic: :func:`plant_step` in NumPy, and
:class:`PlantStepper`, which evaluates the disturbance at every RK4 stage of the sample
first (the force depends on time only) and integrates in C compiled from the same CasADi
expressions (auvmpc.native). The NumPy one evaluates the model 40 times a sample in Python
(10 sub-steps of the paper scenarios), about 40 % of a whole run of the real-time nmpc.
"""

from __future__ import annotations

import functools
import math
from typing import Protocol

import casadi as ca
import numpy as np

from auvmpc.environment.currents import WaterCurrent
from auvmpc.environment.disturbances import SensorNoise, WorldDisturbance
from auvmpc.environment.waves import WaveField, morison_inertia
from auvmpc.models.actuators import ActuatorSet
from auvmpc.models.heave import heave_plant_step
from auvmpc.models.integrators import rk4_step_time_varying
from auvmpc.models.layout import (
    DEPTH,
    HORIZONTAL,
    HORIZONTAL_COMPONENTS,
    PLANAR_FORCE,
    PLANAR_MOMENT,
    WORLD_VECTOR,
)
from auvmpc.models.six_dof import (
    HORIZONTAL_INDEX,
    SIX_DOF,
    depth_rate,
    horizontal_state,
    integrate,
    six_dof_model,
)
from auvmpc.models.vehicle import HeaveParams, VehicleParams, body_from_world, dynamics
from auvmpc.native import NativeFunction, native_function
from auvmpc.sim.log import DEPTH_LOG, HORIZONTAL_LOG, SIX_DOF_LOG, LogFormat

__all__ = [
    "HeavePlant",
    "HorizontalPlant",
    "Plant",
    "PlantStepper",
    "SixDofPlant",
    "SixDofSensor",
    "plant_step",
    "stage_times",
    "substeps_for",
]

_HEADING = HORIZONTAL.heading
_DEPTH = DEPTH.index("z")
_SIX_DOF_DEPTH = SIX_DOF.index("z")  # NED, down (m)


class Plant(Protocol):
    """What the closed loop integrates: one held-thrust sample at a time, in its environment."""

    log_format: LogFormat  # its state layout, logged columns and CSV form
    inputs: ActuatorSet  # what ``step``'s command drives, in order (names, limits)
    sample_time: float  # s, the sample :meth:`step` integrates over

    def environment(self, t: float, state: np.ndarray) -> np.ndarray:
        """What the environment does at ``t`` (the log's ``environment_names``, one row per
        sample): a force on the vehicle, or the water's velocity."""

    def step(
        self,
        state: np.ndarray,
        thrust: np.ndarray,
        t0: float,
        effectiveness: np.ndarray | None = None,
    ) -> np.ndarray:
        """The state one sample after ``t0`` under ``thrust`` held; the environment then
        moves on to the next sample. ``effectiveness`` (n,): each actuator's share of its
        wrench that acts (a fault, sim/faults.py; None: all healthy; only a plant whose
        scenarios take faults, horizontal and 6-DOF, is given one)."""


def substeps_for(sample_time: float, max_step: float) -> int:
    """RK4 sub-steps per sample so that none is longer than ``max_step``."""
    return max(1, math.ceil(sample_time / max_step - 1e-9))


class HorizontalPlant:
    """The 3-DOF vehicle under a :class:`WorldDisturbance` (force, moment and water current)."""

    log_format = HORIZONTAL_LOG

    def __init__(
        self,
        vehicle: VehicleParams,
        disturbance: WorldDisturbance,
        sample_time: float,
        max_step: float,
    ) -> None:
        self.vehicle, self.disturbance, self.sample_time = vehicle, disturbance, sample_time
        self.inputs = vehicle.actuators
        self.stepper = PlantStepper(vehicle, sample_time, substeps_for(sample_time, max_step))

    def environment(self, t: float, state: np.ndarray) -> np.ndarray:
        """World force and moment [X, Y, N] (N, N, N m), then the water velocity [north,
        east] (m/s, zero without a water current)."""
        water = self.disturbance.water_velocity_world(t)
        return np.concatenate(
            [self.disturbance.force_world(t), _STILL_WATER if water is None else water]
        )

    def step(
        self,
        state: np.ndarray,
        thrust: np.ndarray,
        t0: float,
        effectiveness: np.ndarray | None = None,
    ) -> np.ndarray:
        following = self.stepper(state, thrust, t0, self.disturbance, effectiveness)
        self.disturbance.advance()
        return following


class HeavePlant:
    """The heave model (depth experiment) under the surface waves, or in calm water."""

    log_format = DEPTH_LOG

    def __init__(
        self,
        vehicle: VehicleParams,
        heave: HeaveParams,
        waves: WaveField | None,
        sample_time: float,
        max_step: float,
    ) -> None:
        self.heave, self.waves, self.sample_time = heave, waves, sample_time
        self.inputs = heave.actuators
        self.substeps = substeps_for(sample_time, max_step)
        # Froude-Krylov plus added mass: the water around the body accelerates with the wave.
        self.inertia = morison_inertia(vehicle, heave)

    def wave_force(self, z: float, t: float) -> float:
        """The waves' vertical force (N, up) on the vehicle at height ``z`` (m) at ``t``."""
        return 0.0 if self.waves is None else self.inertia * self.waves.vertical_acceleration(z, t)

    def environment(self, t: float, state: np.ndarray) -> np.ndarray:
        """The waves' vertical force [Z] (N, up)."""
        return np.array([self.wave_force(state[_DEPTH], t)])

    def step(self, state: np.ndarray, thrust: np.ndarray, t0: float) -> np.ndarray:
        return heave_plant_step(
            self.heave, state, thrust, t0, self.sample_time, self.substeps, self.wave_force
        )


class SixDofPlant:
    """The 6-DOF vehicle in the water current (or still water); its environment, logged at
    each sample, is the water velocity at the vehicle (world NED, m/s)."""

    log_format = SIX_DOF_LOG

    def __init__(
        self,
        vehicle: VehicleParams,
        current: WaterCurrent | None,
        sample_time: float,
        max_step: float,
    ) -> None:
        self.model = six_dof_model(vehicle)
        self.current, self.sample_time = current, sample_time
        self.inputs = vehicle.six_dof_actuators
        self.substeps = substeps_for(sample_time, max_step)
        # A current that changes with depth is looked up at every RK4 stage; a uniform one is
        # held over the sample (the compiled RK4 step).
        self.profiled = current is not None and bool(current.config.depth_profile)

    def environment(self, t: float, state: np.ndarray) -> np.ndarray:
        """The water velocity at the vehicle (world NED, m/s), held over [t, t + sample)."""
        if self.current is None:
            return np.zeros(len(SIX_DOF_LOG.environment_names))
        return self.current.at(t, state[_SIX_DOF_DEPTH], depth_rate(state))[0]

    def step(
        self,
        state: np.ndarray,
        thrust: np.ndarray,
        t0: float,
        effectiveness: np.ndarray | None = None,
    ) -> np.ndarray:
        if self.profiled:
            current = self.current
            state = integrate(
                self.model, state, thrust, self.sample_time, self.substeps,
                lambda time_s, x: current.at(time_s, x[_SIX_DOF_DEPTH], depth_rate(x)), t0=t0,
                effectiveness=effectiveness,
            )  # fmt: skip
        else:  # uniform in space: held over the sample
            velocity = self.environment(t0, state)
            state = integrate(
                self.model, state, thrust, self.sample_time, self.substeps,
                held_current=velocity, effectiveness=effectiveness,
            )  # fmt: skip
        if self.current is not None:
            self.current.advance()
        return state


class SixDofSensor:
    """What the 6-DOF controllers measure (``SIX_DOF_MEASUREMENT``): the navigation sensor's
    ``[x, y, psi, u, v, r]`` and a depth sensor's depth and depth rate (NED), with Gaussian
    noise: the navigation sensor's from its generator, the depth sensor's from ``rng``."""

    def __init__(
        self,
        navigation: SensorNoise,
        depth_std_m: float,
        depth_rate_std_m_per_s: float,
        rng: np.random.Generator,
    ) -> None:
        self.navigation, self._rng = navigation, rng
        self.depth_std, self.rate_std = depth_std_m, depth_rate_std_m_per_s

    def measure(self, true_state: np.ndarray, t: float) -> np.ndarray:
        horizontal = self.navigation.measure(horizontal_state(true_state))
        depth = true_state[_SIX_DOF_DEPTH] + self.depth_std * self._rng.standard_normal()
        rate = depth_rate(true_state) + self.rate_std * self._rng.standard_normal()
        return np.concatenate([horizontal, [depth, rate]])  # SIX_DOF_MEASUREMENT's order


class WholeStateSensor(SixDofSensor):
    """What a controller of the whole vehicle measures: the whole 6-DOF state (SIX_DOF's
    order), the navigation sensor's ``[x, y, psi, u, v, r]`` and the depth with their noise
    as :class:`SixDofSensor` draws it; roll, pitch, heave velocity and the roll and pitch rates
    as they are (an attitude and heading reference and a DVL measure them far better than the
    position: their noise is not modelled)."""

    def measure(self, true_state: np.ndarray, t: float) -> np.ndarray:
        noisy = self.navigation.measure(horizontal_state(true_state))
        measured = np.array(true_state, dtype=float)
        measured[HORIZONTAL_INDEX] = noisy
        measured[_SIX_DOF_DEPTH] += self.depth_std * self._rng.standard_normal()
        return measured


def plant_step(
    plant: VehicleParams,
    state: np.ndarray,
    thrust: np.ndarray,
    t0: float,
    duration: float,
    disturbance: WorldDisturbance,
    substeps: int,
    effectiveness: np.ndarray | None = None,
) -> np.ndarray:
    """Integrate the plant over one zero-order-hold sample with RK4 sub-steps, each thruster
    making ``effectiveness`` (n,) of its force (None: all healthy)."""

    def rhs(t: float, x: np.ndarray) -> np.ndarray:
        force = disturbance.force_world(t)
        d_u, d_v = body_from_world(force, x[_HEADING])
        water = disturbance.water_velocity_world(t)
        return dynamics(
            x, thrust, plant, (d_u, d_v, force[PLANAR_MOMENT]), current_world=water,
            effectiveness=effectiveness,
        )  # fmt: skip

    h = duration / substeps
    for i in range(substeps):
        state = rk4_step_time_varying(rhs, t0 + i * h, state, h)
    return state


def stage_times(t0: float, duration: float, substeps: int) -> np.ndarray:
    """(substeps, 3): the times t, t + h/2, t + h at which :func:`plant_step`'s sub-step i
    evaluates the force, computed as it computes them (so the same floating-point times)."""
    h = duration / substeps
    starts = t0 + np.arange(substeps) * h  # the same roundings as t0 + i * h
    return np.stack([starts, starts + 0.5 * h, starts + h], axis=1)


class PlantStepper:
    """:func:`plant_step` for one plant, sample duration and sub-step count, compiled where
    a C compiler is present (``compiled``), else the NumPy function itself."""

    def __init__(self, plant: VehicleParams, duration: float, substeps: int) -> None:
        self.plant, self.duration, self.substeps = plant, duration, substeps
        self._native = _compiled_map(plant.model_dump_json(), duration, substeps)
        self.compiled = self._native is not None
        self._healthy = np.ones(plant.n_thrusters)  # e u is u to the bit: no fault, no change

    def __call__(
        self,
        state: np.ndarray,
        thrust: np.ndarray,
        t0: float,
        disturbance: WorldDisturbance,
        effectiveness: np.ndarray | None = None,
    ) -> np.ndarray:
        if self._native is None:
            return plant_step(
                self.plant, state, thrust, t0, self.duration, disturbance, self.substeps,
                effectiveness,
            )  # fmt: skip
        times = stage_times(t0, self.duration, self.substeps)
        # (3 substeps, PLANAR_FORCE.size), time-major
        forces = disturbance.forces_world(times.ravel())
        water = disturbance.water_velocity_world(t0)
        share = self._healthy if effectiveness is None else effectiveness
        return self._native(state, thrust, forces, _STILL_WATER if water is None else water, share)


# No current: the model's relative velocity is then its velocity, to the last bit (x - 0).
_STILL_WATER = np.zeros(WORLD_VECTOR.size)[HORIZONTAL_COMPONENTS].copy()  # its x, y


@functools.lru_cache(maxsize=32)
def _compiled_map(plant_json: str, duration: float, substeps: int) -> NativeFunction | None:
    """The sample's RK4 map (x, F, forces at the stage times, time-major, water velocity,
    effectiveness) -> x, compiled."""
    plant = VehicleParams.model_validate_json(plant_json)
    x = ca.SX.sym("x", HORIZONTAL.size)
    thrust = ca.SX.sym("F", plant.n_thrusters)
    # Column j: the force at stage time j (RK4 evaluates three times per sub-step).
    forces = ca.SX.sym("forces", PLANAR_FORCE.size, 3 * substeps)
    water = ca.SX.sym("water", len(_STILL_WATER))
    effectiveness = ca.SX.sym("e", plant.n_thrusters)

    def rhs(j: int, state):
        force = forces[:, j]
        d_u, d_v = body_from_world(force, state[_HEADING])
        return dynamics(
            state, thrust, plant, (d_u, d_v, force[PLANAR_MOMENT]), current_world=water,
            effectiveness=effectiveness,
        )  # fmt: skip

    h = duration / substeps
    state = x
    for i in range(substeps):  # rk4_step_time_varying, the force looked up by stage time
        start, middle, end = 3 * i, 3 * i + 1, 3 * i + 2
        k1 = rhs(start, state)
        k2 = rhs(middle, state + (0.5 * h) * k1)
        k3 = rhs(middle, state + (0.5 * h) * k2)
        k4 = rhs(end, state + h * k3)
        state = state + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return native_function(
        ca.Function("plant_sample", [x, thrust, forces, water, effectiveness], [state])
    )
