"""Horizontal-plane linear MPC on the incremental model (paper-model.md sections 3-4).

The condensed-QP machinery (moves, hard limits, soft constraints, fallback) is in
condensed.py; this module adds what is horizontal: the 3-DOF prediction models,
the heading reference alignment, the offset-free estimator, and the obstacles.

* :class:`PaperMpc` (``mpc``): the paper's state-dependent-coefficient (SDC)
  model ``x' = A_c(x) x + B_c F + g_c w_b`` frozen at the current state,
  RK4-discretised;
* ``LtvMpc`` (``ltv-mpc``, ltv.py): the RK4 model linearised along the shifted
  previous solution with exact CasADi Jacobians.

Obstacles: each keep-out disc becomes one half-plane per predicted step, tangent
to the inflated disc, each row softened by its own exact-penalty slack. The paper's
frozen model leaves out how the vehicle turns over the horizon, so :class:`PaperMpc`
checks its plan on the nonlinear model and, where that enters a disc, moves those
half-planes out by the prediction's error and solves once more (:meth:`PaperMpc.plan_check`).
"""

from __future__ import annotations

import math
from abc import abstractmethod
from typing import Literal

import numpy as np
from pydantic import Field

from auvmpc.controllers.base import (
    Observation,
    ObstacleState,
    align_heading,
    tracked_reference,
)
from auvmpc.controllers.config import (
    ControllerType,
    OptimisingControllerConfig,
    Relinearisation,
    TightenedConstraints,
    type_field,
)
from auvmpc.controllers.incremental import IncrementalMpc, Tightened
from auvmpc.controllers.shell import BACKOFF_KEYS
from auvmpc.errors import ConfigError
from auvmpc.estimation import DisturbanceObserver
from auvmpc.models.discrete import horizontal_model
from auvmpc.models.layout import HORIZONTAL, PLANAR_FORCE, PLANAR_MOMENT
from auvmpc.models.sdc import disturbance_matrix, input_matrix, rk4_discretize, sdc_matrix
from auvmpc.models.vehicle import VehicleParams, body_from_world, steady_speed
from auvmpc.ocp.tightening import GAIN_SPEED_STEP, Tightening, tightened_box, tube_gain
from auvmpc.solvers.condensed_qp import AffinePrediction, CondensedQp, SoftRows

__all__ = ["AffinePrediction", "LinearMpc", "PaperMpc", "PaperMpcConfig"]

NX = HORIZONTAL.size
# Relative trust-region weights on [x, y, psi, u, v, r] deviations from the nominal: the
# heading and velocities carry the nonlinearity (rotation, Coriolis), positions follow them.
_TRUST_REGION_SCALE = HORIZONTAL.vector({"psi": 1.0, "u": 1.0, "v": 1.0, "r": 1.0})
# Obstacle rows are kept for predicted steps whose nominal position is within this distance
# of the half-plane (m): 15 s at the vehicle's top speed is far more than one re-plan moves.
_OBSTACLE_RANGE_M = 5.0
# Half-plane normals are kept at least this far from the along-track direction, so a
# disc sitting on the path is passed on one side instead of blocking the prediction.
_MAX_NORMAL_ANGLE_FROM_SIDE = math.radians(60.0)


class PaperMpcConfig(TightenedConstraints, Relinearisation, OptimisingControllerConfig):
    """``mpc``: the optimising controllers' knobs, the tightening and the rollout check."""

    type: Literal[ControllerType.MPC] = type_field(ControllerType.MPC)
    rollout_check: bool = Field(
        default=True,
        description="mpc: after the QP, roll the plan's thrusts through the nonlinear model; "
        "where that rollout enters an obstacle's keep-out disc, solve the same QP once more "
        "with those steps' half-planes moved out by the frozen prediction's error there "
        "(docs/paper-reproduction.md#obstacles-and-the-frozen-model); false: the paper's "
        "frozen prediction alone",
    )


class LinearMpc(IncrementalMpc):
    """Horizontal condensed MPC; subclasses provide :meth:`prediction_model`."""

    def __init__(self, model: VehicleParams, config: OptimisingControllerConfig) -> None:
        config = config.for_vehicle(model)
        self.model = model
        self.take_config(config)
        self.ocp = config.ocp(model)
        self.limits = self.ocp.limits
        self.qp = CondensedQp(self.ocp, config.qp_solver, config.qp_iteration_limit)
        self.linearisation_iterations = config.linearisation_iterations
        self._observer = (
            DisturbanceObserver(model, config.sample_time, config.observer, config.model_substeps)
            if config.offset_free
            else None
        )
        self.tightening = robust_tightening(model, config)
        self.reset(np.zeros(NX), np.zeros(model.n_thrusters))

    @abstractmethod
    def prediction_model(
        self, state: np.ndarray, nominal_input: np.ndarray, disturbance: np.ndarray
    ) -> AffinePrediction:
        """Affine model over the horizon around the thrusts ``nominal_input`` (ny, n), with
        the estimated world-frame force and moment ``disturbance`` [X, Y, N] acting
        throughout."""

    def reset(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        super().reset(initial_state, initial_thrust)
        if self._observer is not None:
            self._observer.reset(initial_state)

    def estimate(self, measured: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._observer is None:
            return measured, np.zeros(PLANAR_FORCE.size)
        return self._observer.correct(measured)

    def after_command(self, command: np.ndarray) -> None:
        if self._observer is not None:
            self._observer.predict(command, self.effectiveness)

    def aligned_reference(self, state: np.ndarray, reference: np.ndarray) -> np.ndarray:
        return align_heading(state, reference)

    def tightened(
        self,
        prediction: AffinePrediction,
        nominal: np.ndarray,
        soft: SoftRows,
        previous: np.ndarray,
    ) -> Tightened:
        """The obstacle rows and the thrust box backed off for the disturbance bound
        (ocp/tightening.py); unchanged without one."""
        if self.tightening is None:
            return soft, None, {}
        backoffs = self.tightening.backoffs(
            prediction.A,
            prediction.B,
            prediction.G,
            nominal[:-1],
            soft.steps,
            soft.coefficients,
        )
        ocp = self.ocp
        box = tightened_box(
            ocp.input_lower,
            ocp.input_upper,
            backoffs.thrust,
            np.asarray(ocp.move_steps),
            previous,
            ocp.max_move,
        )
        rows = SoftRows(soft.steps, soft.coefficients, soft.lower + backoffs.rows)
        given_up = 2.0 * backoffs.thrust / (ocp.input_upper - ocp.input_lower)
        took = (float(backoffs.rows.max(initial=0.0)), float(given_up.max(initial=0.0)))
        return rows, box, dict(zip(BACKOFF_KEYS, took, strict=True))

    def tracked_reference(
        self, state: np.ndarray, disturbance: np.ndarray, reference: np.ndarray
    ) -> np.ndarray:
        return tracked_reference(self.model, state, disturbance, reference, self.sample_time)

    def soft_rows(
        self,
        nominal: np.ndarray,
        reference: np.ndarray,
        observation: Observation,
        correction: tuple[np.ndarray, ...] | None = None,
    ) -> SoftRows:
        """Half-planes a . p_n >= b for the predicted steps n near any obstacle.

        Steps whose nominal position is farther than ``_OBSTACLE_RANGE_M`` beyond the
        inflated disc are left out: the plan cannot move that far from its nominal in
        one re-plan, and every row saved keeps the QP small.

        ``correction``, one (ny, 2) array per obstacle, is the prediction's position error
        (predicted minus nonlinear, :meth:`PaperMpc.plan_check`) at steps n = 1..ny: each
        half-plane moves out by the error's component against it, a . p_n >= b + max(0,
        a . e_n), so that a position that far off the prediction still meets a . p >= b.
        """
        all_normals, all_offsets, all_steps = [], [], []
        for index, obstacle in enumerate(observation.obstacles):
            normals, offsets = self._half_planes(obstacle, nominal, reference)
            if correction is not None:
                offsets = offsets + np.maximum(
                    0.0, np.einsum("nk,nk->n", normals, correction[index])
                )
            gaps = np.einsum("nk,nk->n", normals, nominal[1:, HORIZONTAL.position]) - offsets
            near = np.flatnonzero(gaps < _OBSTACLE_RANGE_M)
            all_normals.append(normals[near])
            all_offsets.append(offsets[near])
            all_steps.append(near + 1)
        if not all_steps:
            return SoftRows.empty(NX)
        normals = np.vstack(all_normals)
        coefficients = np.zeros((len(normals), NX))
        coefficients[:, HORIZONTAL.position] = normals
        return SoftRows(np.concatenate(all_steps), coefficients, np.concatenate(all_offsets))

    def _half_planes(
        self, obstacle: ObstacleState, nominal: np.ndarray, reference: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Unit normals a_n (ny, 2) and offsets b_n: the constraint is a_n . p_n >= b_n.

        Each half-plane is tangent to the disc inflated by the vehicle radius and margin, so
        any point satisfying it is clear of the obstacle whatever the normal. The normal
        points from the obstacle's predicted centre to the nominal predicted position,
        turned towards the pass side when that direction is nearly along the track (a
        disc on the path would otherwise stop the vehicle in front of it).
        """
        steps = np.arange(1, self.horizon + 1)
        # Step n against the obstacle predicted at t + n Te, with that step's keep-out radius.
        centres, radii = obstacle.predict(steps * self.sample_time)
        radial = nominal[1:, HORIZONTAL.position] - centres
        heading = reference[1:, HORIZONTAL.heading]
        tangent = np.column_stack([np.cos(heading), np.sin(heading)])
        left = np.column_stack([-tangent[:, 1], tangent[:, 0]])
        closest = int(np.argmin(np.einsum("nk,nk->n", radial, radial)))
        side_sign = np.sign(left[closest] @ radial[closest]) or 1.0
        side = side_sign * left
        normals = _clamp_towards(radial, side, _MAX_NORMAL_ANGLE_FROM_SIDE)
        reach = radii + self.ocp.keep_out_extra
        offsets = np.einsum("nk,nk->n", normals, centres) + reach
        return normals, offsets


def robust_tightening(model: VehicleParams, config: TightenedConstraints) -> Tightening | None:
    """The back-offs for ``config.disturbance_bound``, or None for a zero bound (the nominal
    controller). The ancillary gains: LQR gains of the model linearised in straight motion
    at heading 0, from its top reverse to its top forward speed (ocp/tightening.py)."""
    bound = config.disturbance_bound
    if bound.is_zero:
        return None
    if model.underactuated:
        raise ConfigError(
            "controller.disturbance_bound",
            bound.model_dump(),
            f"{model.describe_actuation()}: the tightening's feedback at rest needs full "
            "actuation (leave the bound zero)",
        )
    sampled = horizontal_model(model, config.sample_time, config.model_substeps, config.jit)
    half_range = np.broadcast_to((model.thrust_max - model.thrust_min) / 2.0, model.n_thrusters)
    surge = model.T[PLANAR_FORCE.index("X")]  # each thruster's surge force per newton
    forward = float(np.maximum(surge * model.thrust_max, surge * model.thrust_min).sum())
    reverse = float(-np.minimum(surge * model.thrust_max, surge * model.thrust_min).sum())
    top = [steady_speed(model.Xu, model.Xuu, force) for force in (reverse, forward)]
    speeds = np.arange(-top[0], top[1] + GAIN_SPEED_STEP, GAIN_SPEED_STEP)
    allocation = np.linalg.pinv(model.T)
    gains = []
    for speed in speeds:
        at = HORIZONTAL.vector({"u": speed})
        drag = -(model.Xu * speed + model.Xuu * speed * abs(speed))
        # the thrust that keeps the speed
        holding = allocation @ PLANAR_FORCE.vector({"X": drag})
        # The tube's gains are the healthy vehicle's (built once, not per fault).
        healthy = np.ones(model.n_thrusters)
        _, A, B = sampled.linearised_step(at, holding, np.zeros(PLANAR_FORCE.size), healthy)
        gains.append(tube_gain(np.asarray(A), np.asarray(B), half_range))
    return Tightening(bound.total_force_N, bound.moment_Nm, speeds, np.array(gains), half_range)


def _clamp_towards(vectors: np.ndarray, side: np.ndarray, max_angle: float) -> np.ndarray:
    """Unit vectors from ``vectors``, rotated towards ``side`` where further than max_angle."""
    norms = np.linalg.norm(vectors, axis=1)
    safe = np.where(norms[:, None] > 1e-9, vectors / np.maximum(norms, 1e-12)[:, None], side)
    cos_angle = np.clip(np.einsum("nk,nk->n", safe, side), -1.0, 1.0)
    too_far = np.arccos(cos_angle) > max_angle
    if not np.any(too_far):
        return safe
    # Component of the direction across ``side`` keeps its sign; the angle becomes max_angle.
    across = safe - cos_angle[:, None] * side
    across_norm = np.linalg.norm(across, axis=1)
    across_unit = np.where(
        across_norm[:, None] > 1e-9, across / np.maximum(across_norm, 1e-12)[:, None], 0.0
    )
    clamped = math.cos(max_angle) * side + math.sin(max_angle) * across_unit
    return np.where(too_far[:, None], clamped, safe)


class PaperMpc(LinearMpc):
    """The paper's controller: SDC matrices refreshed at the current state every sample."""

    def __init__(self, model: VehicleParams, config: PaperMpcConfig) -> None:
        model.require_full_actuation(
            "mpc",
            "its model frozen at the current heading cannot move the vehicle sideways by "
            "turning: without sway thrust the lateral position is uncontrollable in it",
        )
        super().__init__(model, config)
        # Thrust and body-frame disturbance enter the same velocity rows: [B_c, G_c]; B_c's
        # columns scaled by the thrusters' effectiveness, remade when that changes.
        self._input_matrix = np.hstack([input_matrix(model), disturbance_matrix(model)])
        self._healthy_input_matrix = self._input_matrix
        self._input_effectiveness = np.ones(model.n_thrusters)
        config = self.config  # with what the vehicle decides filled in
        sampled = horizontal_model(model, config.sample_time, config.model_substeps, config.jit)
        self._rollout = sampled.rollout(config.prediction_horizon)  # for plan_check

    def plan_check(
        self,
        observation: Observation,
        state: np.ndarray,
        disturbance: np.ndarray,
        plan: np.ndarray,
        predicted: np.ndarray,
    ) -> tuple[np.ndarray, ...] | None:
        """Where the plan's thrusts, on the nonlinear model, enter a keep-out disc: the
        frozen prediction's position error there, one (ny, 2) array per obstacle (zero at
        the other steps), for :meth:`soft_rows`; None when the rollout stays clear.

        The frozen model neither turns the predicted velocity with the heading nor lets
        the Munk moment (m11 - m22) u v follow the sway, so beside a disc passed with sway
        the vehicle can turn into the disc where the plan predicted a steady heading
        (docs/paper-reproduction.md#obstacles-and-the-frozen-model). The check costs one
        rollout per sample with an obstacle in view; the model, the cost, the moves and the
        QP are the paper's, and while no rollout enters a disc the result is the paper's
        plan unchanged.
        """
        if not self.config.rollout_check or not observation.obstacles:
            return None
        forces = np.tile(np.reshape(disturbance, (PLANAR_FORCE.size, 1)), (1, self.horizon))
        rolled = self._rollout(state, plan.T, forces, self.effectiveness)
        rollout = np.asarray(rolled).T[:, HORIZONTAL.position]
        steps = np.arange(1, self.horizon + 1)
        errors, entered = [], False
        for obstacle in observation.obstacles:
            centres, radii = obstacle.predict(steps * self.sample_time)
            reach = radii + self.ocp.keep_out_extra
            inside = np.hypot(*(rollout - centres).T) < reach
            errors.append(
                np.where(inside[:, None], predicted[1:, HORIZONTAL.position] - rollout, 0.0)
            )
            entered = entered or bool(inside.any())
        return tuple(errors) if entered else None

    def prediction_model(
        self, state: np.ndarray, nominal_input: np.ndarray, disturbance: np.ndarray
    ) -> AffinePrediction:
        h = self.sample_time / self.config.model_substeps
        if not np.array_equal(self.effectiveness, self._input_effectiveness):
            self._input_effectiveness = np.array(self.effectiveness, dtype=float)
            n = self.model.n_thrusters
            scaled = self._healthy_input_matrix.copy()
            scaled[:, :n] *= self._input_effectiveness
            self._input_matrix = scaled
        step_A, step_B = rk4_discretize(sdc_matrix(state, self.model), self._input_matrix, h)
        Ad, Bd = step_A, step_B
        for _ in range(self.config.model_substeps - 1):  # compose the sub-steps, inputs held
            Ad, Bd = step_A @ Ad, step_A @ Bd + step_B
        n, ny = self.model.n_thrusters, self.horizon
        # The paper's g_c w_b term: the disturbance rotated at the frozen heading.
        d_u, d_v = body_from_world(disturbance, state[HORIZONTAL.heading])
        offset = Bd[:, n:] @ np.array([d_u, d_v, disturbance[PLANAR_MOMENT]])
        G = None
        if self.tightening is not None:  # in the world force: rotated at the frozen heading
            heading = state[HORIZONTAL.heading]
            cos, sin = math.cos(heading), math.sin(heading)
            world_to_body = np.array([[cos, sin, 0.0], [-sin, cos, 0.0], [0.0, 0.0, 1.0]])
            G = np.broadcast_to(Bd[:, n:] @ world_to_body, (ny, NX, PLANAR_FORCE.size))
        return AffinePrediction(
            A=np.broadcast_to(Ad, (ny, NX, NX)),
            B=np.broadcast_to(Bd[:, :n], (ny, NX, n)),
            c=np.broadcast_to(offset, (ny, NX)),
            G=G,
        )
