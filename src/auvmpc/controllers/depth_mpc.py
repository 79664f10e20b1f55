"""Depth MPC: the condensed incremental MPC of condensed.py on the 1-DOF heave model.

Same principles as the horizontal controllers (paper-model.md section 8): hard
vertical-thrust and thrust-rate limits, incremental form, the model linearised
along the shifted previous plan with exact CasADi Jacobians. The surface and the
tank bottom are soft state constraints (exact penalty). An EKF on
``[z, w, d_z]`` estimates the heave velocity from depth alone and, with
``offset_free``, the unknown net buoyancy (and slow wave-induced mean force) as d_z.
"""

from __future__ import annotations

from typing import Literal

import casadi as ca
import numpy as np
from pydantic import Field

from auvmpc.config import NonNegative, Positive, StrictModel
from auvmpc.controllers.config import (
    DEPTH_MPC,
    DEPTH_TYPE,
    DepthChannelConfig,
    HorizonLengths,
    QpSolverOptions,
    type_field,
)
from auvmpc.controllers.incremental import IncrementalMpc
from auvmpc.estimation import AugmentedEkf
from auvmpc.models.heave import heave_dynamics, resolve_heave
from auvmpc.models.integrators import rk4
from auvmpc.models.layout import DEPTH
from auvmpc.models.vehicle import HeaveParams, VehicleParams
from auvmpc.ocp.tracking import ThrustPenalty, TrackingOcp
from auvmpc.solvers.condensed_qp import AffinePrediction, CondensedQp, SoftRows

__all__ = [
    "DepthControllerConfig",
    "DepthFilter",
    "DepthMpc",
    "DepthObserverConfig",
    "DepthTrackingWeights",
]

NX = DEPTH.size  # [z, w]
_Z = DEPTH.index("z")
# The soft rows' coefficients on [z, w]: -z >= surface margin, z >= bottom + margin.
_BELOW_SURFACE = np.array([-1.0 if name == "z" else 0.0 for name in DEPTH.names])
_ABOVE_BOTTOM = np.array([1.0 if name == "z" else 0.0 for name in DEPTH.names])


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


class DepthFilter(StrictModel):
    """The filter the depth MPC always runs, an EKF on [z, w, d_z]: it estimates the heave
    velocity from the measured depth, and with ``offset_free`` the unknown vertical force d_z
    as well (without, d_z stays 0). Unlike the horizontal controllers' offset-free estimator
    (controllers/config.py ``OffsetFree``), which runs only for the offset, ``observer``
    tunes a filter that runs either way."""

    offset_free: bool = Field(default=True, description="estimate the unknown vertical force")
    observer: DepthObserverConfig = Field(default_factory=DepthObserverConfig)

    def force_statistics(self) -> tuple[float, float]:
        """The random walk (N/sqrt(s)) and the prior standard deviation (N) of d_z: zero
        without ``offset_free``, so that d_z keeps its initial 0."""
        if not self.offset_free:
            return 0.0, 0.0
        return self.observer.disturbance_rate_std, self.observer.initial_disturbance_std


class DepthTrackingWeights(StrictModel):
    """The depth tracking cost: [z, w] against the setpoint, the vertical thrusts."""

    Q: tuple[NonNegative, NonNegative] = Field(default=(200.0, 1.0), description="on [z, w]")
    S: tuple[NonNegative, NonNegative] = Field(default=(400.0, 2.0), description="terminal")
    R: NonNegative = Field(default=0.01, description="weight per vertical thruster")
    thrust_penalty: ThrustPenalty = Field(
        default=ThrustPenalty.INCREMENT, description="R on F or dF"
    )


class DepthControllerConfig(  # the bases in reverse: the common fields come first
    DepthFilter, QpSolverOptions, DepthTrackingWeights, HorizonLengths, DepthChannelConfig
):
    """Depth MPC choice and tuning (controllers/depth_mpc.py): a depth scenario's
    ``controller``, a 6-DOF scenario's ``depth_controller``."""

    type: Literal["depth-mpc"] = type_field(DEPTH_MPC, DEPTH_TYPE)
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


class DepthMpc(IncrementalMpc):
    """Depth controller; ``config`` is a :class:`DepthControllerConfig`, ``water_depth`` (m)
    where the bottom is (z = -water_depth)."""

    @classmethod
    def from_config(
        cls, model: VehicleParams, config, obstacle_count: int = 0, *, water_depth_m: float
    ) -> DepthMpc:
        """Built by the registry on the vehicle's heave section (no obstacles in depth)."""
        return cls(resolve_heave(model, {}), config, water_depth_m)

    def __init__(self, heave: HeaveParams, config, water_depth: float) -> None:
        self.take_config(config)
        if not config.known_net_buoyancy:
            heave = heave.model_copy(update={"net_buoyancy_N": 0.0})
        self.heave = heave
        self.water_depth = water_depth
        self.limits = heave.actuators.limits
        self.ocp = TrackingOcp.from_config(
            config, heave.thruster_count, self.limits, slack_penalty=config.depth_slack_penalty
        )
        self.qp = CondensedQp(self.ocp, config.qp_solver, config.qp_iteration_limit)
        self.trust_region_weights = None  # the heave model is nearly linear
        state = ca.SX.sym("x", NX)
        thrust = ca.SX.sym("F", heave.thruster_count)
        force = ca.SX.sym("d")
        # The model in the vertical thrust that acts, a = e * F (e: each thruster's
        # effectiveness, 1 healthy, 0 dead, a runtime input), evaluated at a = e * F with the
        # thrust Jacobian's columns times e: differentiated in a, the healthy model's numbers
        # are what they were before e was an input (models/discrete.py says why).
        acting = ca.SX.sym("a", heave.thruster_count)
        effectiveness = ca.SX.sym("e", heave.thruster_count)
        next_state = rk4(
            lambda x, u: heave_dynamics(x, u, heave, force), state, acting, config.sample_time
        )
        healthy = ca.Function(
            "heave_step_acting",
            [state, acting, force],
            [next_state, ca.jacobian(next_state, state), ca.jacobian(next_state, acting)],
        )
        following, jac_x, jac_a = healthy.call([state, thrust * effectiveness, force])
        jac_u = jac_a * ca.repmat(effectiveness.T, NX, 1)
        step = ca.Function(
            "heave_step", [state, thrust, force, effectiveness], [following, jac_x, jac_u]
        )
        # The model over the horizon with its one-step Jacobians, and the filter below: the
        # functions export-c generates a six-dof export's depth channel from (export/six_dof_c.py).
        self.rollout = step.mapaccum("heave_rollout", config.prediction_horizon)
        augmented = ca.SX.sym("z", NX + 1)
        next_augmented = ca.vertcat(
            healthy(augmented[:NX], acting, augmented[NX])[0], augmented[NX]
        )
        healthy_observer = ca.Function(
            "heave_observer_acting",
            [augmented, acting],
            [next_augmented, ca.jacobian(next_augmented, augmented)],
        )
        observer_step = ca.Function(
            "heave_observer",
            [augmented, thrust, effectiveness],
            healthy_observer.call([augmented, thrust * effectiveness]),
        )
        observer = config.observer
        rate, prior = config.force_statistics()
        self.filter = AugmentedEkf(
            observer_step,
            measured=1,
            process_covariance=np.diag(
                [
                    observer.depth_process_std**2,
                    observer.velocity_process_std**2,
                    rate**2 * config.sample_time,
                ]
            ),  # fmt: skip
            measurement_covariance=np.array([[observer.measurement_std**2]]),
            prior_covariance=np.diag([observer.measurement_std**2, 0.1**2, prior**2]),
        )
        self.reset(np.zeros(NX), np.zeros(heave.thruster_count))

    def reset(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        super().reset(initial_state, initial_thrust)
        self.filter.reset(np.array([initial_state[_Z], 0.0, 0.0]))

    def estimate(self, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        estimate = self.filter.correct(measured[:1])  # the pressure sensor's [z]
        return estimate[:NX], estimate[NX:]

    def after_command(self, command: np.ndarray) -> None:
        self.filter.predict(command, self.effectiveness)

    def prediction_model(
        self, state: np.ndarray, nominal_input: np.ndarray, disturbance: np.ndarray
    ) -> AffinePrediction:
        ny, n = self.horizon, self.heave.thruster_count
        forces = np.full((1, ny), float(disturbance[0]))
        states, jac_x, jac_u = self.rollout(state, nominal_input.T, forces, self.effectiveness)
        A = np.asarray(jac_x).reshape(NX, ny, NX).transpose(1, 0, 2)
        B = np.asarray(jac_u).reshape(NX, ny, n).transpose(1, 0, 2)
        nominal = np.vstack([state, np.asarray(states).T])
        c = nominal[1:] - np.einsum("nij,nj->ni", A, nominal[:-1])
        c -= np.einsum("nij,nj->ni", B, nominal_input)
        return AffinePrediction(A=A, B=B, c=c, nominal=nominal)

    def soft_rows(
        self, nominal: np.ndarray, reference: np.ndarray, observation, correction=None
    ) -> SoftRows:
        """Below the surface and above the bottom by the margins, at every predicted step."""
        ny = self.horizon
        steps = np.concatenate([np.arange(1, ny + 1)] * 2)
        coefficients = np.vstack(
            [np.tile(_BELOW_SURFACE, (ny, 1)), np.tile(_ABOVE_BOTTOM, (ny, 1))]
        )
        lower = np.concatenate(
            [
                np.full(ny, self.config.surface_margin_m),  # -z >= margin
                np.full(ny, -self.water_depth + self.config.bottom_margin_m),  # z >= bottom
            ]
        )
        return SoftRows(steps, coefficients, lower)
