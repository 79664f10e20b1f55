"""Nonlinear MPC of the whole 6-DOF vehicle (``six-dof-nmpc``): every input at once, on the
6-DOF model, for any actuator kinds (thrusters, a propeller, fins).

The paper's architecture splits the 6-DOF vehicle into a horizontal and a depth channel, each
on its own reduced model with fixed thrusters (controllers/channels.py). A torpedo AUV has no
such split: one propeller, a rudder and stern planes whose forces grow with the speed squared
and couple surge, yaw, pitch and depth (models/actuators). This controller predicts with the
6-DOF model itself (models/six_dof.py, through the vehicle's ``six_dof_actuators``), so one
statement flies a thruster vehicle and a torpedo.

The program (multiple shooting, built once as expanded SX; IPOPT from the shifted previous
solution, to convergence or its iteration cap):

    min  sum_{n=1}^{N} |e(x_n, r_n)|_Q^2 + sum_{n=0}^{N-1} |(u_n - u_{n-1}) / range|_R^2
    s.t. x_{n+1} = RK4(x_n, u_n; e, v_c),  lower <= u_n <= upper,
         |u_n - u_{n-1}| <= rate Te,  |theta_n| <= PITCH_BOUND_RAD

e(x, r): the position and depth errors, the heading's as 2 (1 - cos(psi - psi_r)), the
surge's, and roll, pitch and the angular rates against the reference's (level, the path's
turn rate). Each input is weighted over its own range, so rpm and degrees weigh alike; e is
each actuator's effectiveness, the share of its wrench that acts (a parameter: a fault
changes it, not the program; the model scales each wrench, not the command, as the plant
does: a propeller's thrust goes with rpm squared).

Path following with a speed profile: the reference is the path's point at t_k + n Te. A
vehicle that can push sideways tracks the reference's heading; one that cannot (a torpedo:
no actuator makes a sway force at rest) is asked for the crab heading that holds the path's
ground track through the estimated current (the velocity through the water is the path's
ground velocity less the current), not to point along a path it can only follow crabbing.
The program starts from an extended Kalman filter's estimate of the 6-DOF state and the
horizontal current (``estimator: ekf``, the default; estimation/six_dof_current.py) on the
prediction's own RK4 model: the fix (USBL- or INS-grade, noisy by a decimetre) is filtered
with the model and the commands, and the current the prediction uses is the filter's. Its
process noise is where the model's error is: beside a fixed part that trusts the model on a
straight line (heading, sway and yaw rate at their one-step error there), each sample adds
how far the prediction moves when the model's added mass, linear or quadratic damping is
off by ``model_uncertainty`` (``_model_spread``), which is large in a turn (sideslip, yaw
rate) and small on a straight crab. With fixed noise alone the filter either trusted the
model in the turns, where its error is a bias, or let the fix's noise through on straight
legs (docs/remus100.md). ``estimator: filters`` is the former chain: the position fix
dead-reckoned with the measured velocities and moved by ``position_fix_gain`` of each new
fix's difference (a complementary filter; nothing in the vehicle's motion depends on where
it is, so this is the program started from the fix with the position targets moved back by
the filter's correction, ``_nodes``), and the current a damped Gauss-Newton step of the
one-step prediction error each sample (``current_gain``).

A vehicle that a fault leaves unable to keep the mission's pace (a stuck input, declared or
found; an input below full effectiveness) is flown no faster than its fastest straight,
level flight as it is now (models/level_flight.py, solved once per fault): a jammed stern
plane holds the depth at one speed only, and at the mission's it dives or climbs whatever
the propeller does. The path is then followed on the controller's own, slower clock
(controllers/schedule.py); the log keeps how far behind the mission it flies
(``schedule_lag_s``). Healthy, the reference rows are the loop's, untouched.

Safety shell (controllers/shell.py, the one every optimising controller has): only a
converged solve is a proposal; one that failed, did not converge within ``max_iterations`` or
came later than ``solver_time_limit_ms`` is replaced by the previous plan's next move
(``fallback``) for at most ``PLAN_FALLBACK_STEPS`` samples, then by the recovery feedback the
registry gives it (controllers/recovery.py, whole_vehicle_recovery) until a solve converges
again: for a torpedo (a propeller, a rudder and stern planes) its classical autopilot,
``los-pid`` (AutopilotFeedback); for a thruster vehicle the channel pair flies (the BlueROV2
Heavy) the pair's stabilising and depth feedbacks on its horizontal and vertical thrusters
(ChannelFeedback); any other vehicle has none and keeps the plan's last move. Whatever is
applied is projected into the hard box and rate limits (a move the projection changed is
logged ``saturated``).
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from pathlib import Path
from typing import Any, ClassVar, Literal

import casadi as ca
import numpy as np
from pydantic import Field

from auvmpc.angles import wrap_angle
from auvmpc.config import NonNegative, Positive
from auvmpc.controllers.base import Observation
from auvmpc.controllers.config import (
    ControllerType,
    PredictionModel,
    SolverTimeLimit,
    WholeVehicleConfig,
    type_field,
)
from auvmpc.controllers.pace import DepthHoldingPace
from auvmpc.controllers.schedule import ReferenceSchedule
from auvmpc.controllers.shell import Proposal, ShelledController
from auvmpc.errors import ConfigError
from auvmpc.estimation.six_dof_current import SixDofCurrentEkf
from auvmpc.models.integrators import rk4
from auvmpc.models.level_flight import LevelFlight, fastest_level_flight
from auvmpc.models.six_dof import (
    PITCH_LIMIT_RAD,
    SIX_DOF,
    ground_velocity,
    six_dof_model,
    stable_substeps,
)
from auvmpc.models.vehicle import VehicleParams, scaled
from auvmpc.native import compiler, shared_library
from auvmpc.solvers.ipopt import ipopt_options, warm_start_options

__all__ = ["SIX_DOF_NMPC", "SixDofNmpc", "SixDofNmpcConfig"]

SIX_DOF_NMPC = ControllerType.SIX_DOF_NMPC
NX = SIX_DOF.size
# The reference rows a 6-DOF controller sees (controllers/channels.py, ReferenceWithDepth):
# [x, y, psi, u, v, r, z, z'].
_REF_XY, _REF_R, _REF_Z = slice(0, 2), 5, 6
_REF_PSI = 2
_REF_RATES = (3, 4, 5, 7)  # u, v, r, z': what a slower clock makes slower
_XY = SIX_DOF.span("x", "y")
_Z, _PHI, _THETA, _PSI = (SIX_DOF.index(name) for name in ("z", "phi", "theta", "psi"))
_U = SIX_DOF.index("u")
_RATES = SIX_DOF.span("p", "r")
# What the current observer compares: the horizontal position and the body velocities.
_OBSERVED = np.array([SIX_DOF.index(name) for name in ("x", "y", "u", "v", "w")])
# IPOPT's tolerance and iteration cap per sample; its barrier start from a shifted solution.
_TOLERANCE = 1e-6
_WARM_MU_INIT = 1e-4
# The prediction's pitch bound (rad), well short of the kinematics' singularity.
PITCH_BOUND_RAD = math.radians(45.0)
assert PITCH_BOUND_RAD < PITCH_LIMIT_RAD
# Reference parameters per node: x, y, z, heading, surge, yaw rate, pitch.
_NODE = 7
# The current observer's ridge, as a share of its normal matrix's trace, and that trace's floor
# (a vehicle feeling no current at all: the estimate then stays where it is).
_RIDGE = 1e-2
_RIDGE_FLOOR = 1e-12
# The level flight is looked for up to this many times the speed the preview asks: a fault
# found in a turn with the current behind sees a slower stretch of the mission than the rest
# (1.29 against 1.53 m/s on remus100-stuck-fin); the schedule slows only where it must.
_CEILING = 2.0
# Below this ground speed (m/s) the path gives no direction: hold the reference's heading.
_STILL_M_PER_S = 1e-3
# The EKF's defaults (SixDofNmpcConfig's descriptions say where they come from).
_MEASUREMENT_STD = (0.1, 0.1, 0.02, 0.005, 0.005, 0.005, 0.01, 0.01, 0.01, 0.005, 0.005, 0.005)
_PROCESS_STD = (
    9e-4, 9e-4, 6e-3, 9e-3, 6e-3, 3e-5, 1.2e-2, 1e-4, 4.5e-2, 6e-2, 3e-2, 2e-4,
)  # fmt: skip
_CURRENT_RATE_STD = 3e-3
# The EKF's measurement noise at least this share of its default (the REMUS presets'
# sensors), where the scenario's sensor has less or none: the filter then follows the
# measurement closely; at 1e-6 its covariance against the model's spread (1e-2 m/s a sample
# on the surge) was too ill-conditioned to decompose (numpy: eigenvalues did not converge).
_LEAST_NOISE_SHARE = 0.1
# What the model's error in the EKF's process noise varies (models/vehicle.py, scaled).
_UNCERTAIN_PARTS = ("added_mass", "linear_damping", "quadratic_damping")


class SixDofNmpcConfig(SolverTimeLimit, PredictionModel, WholeVehicleConfig):
    """``six-dof-nmpc``: the whole vehicle's nonlinear MPC (module docstring)."""

    default_sample_time_s: ClassVar[float] = 0.25

    type: Literal[ControllerType.SIX_DOF_NMPC] = type_field(SIX_DOF_NMPC)
    prediction_horizon: int = Field(default=20, ge=2, le=400, description="N (samples)")
    position_weight: NonNegative = Field(default=1.0, description="Q of x and y (1/m2)")
    depth_weight: NonNegative = Field(default=4.0, description="Q of the depth (1/m2)")
    heading_weight: NonNegative = Field(
        default=1.0, description="Q of 2 (1 - cos(heading error)) (1/rad2)"
    )
    speed_weight: NonNegative = Field(default=1.0, description="Q of the surge (s2/m2)")
    attitude_weight: NonNegative = Field(default=1.0, description="Q of roll and pitch (1/rad2)")
    rate_weight: NonNegative = Field(
        default=1.0, description="Q of the angular rates p, q, r (s2/rad2)"
    )
    input_change_weight: NonNegative = Field(
        default=1.0, description="R of each input's change per sample, over its range"
    )
    current_gain: float = Field(
        default=0.2, ge=0.0, le=1.0,
        description="share of the least-squares correction of the one-step prediction error "
        "(position and body velocities) taken into the current estimate each sample (0: no "
        "estimate)",
    )  # fmt: skip
    position_fix_gain: float = Field(
        default=0.1, gt=0.0, le=1.0,
        description="share of each horizontal position fix's difference from the position "
        "dead-reckoned from the last estimate with the measured velocities, taken into the "
        "position the prediction starts from (1: the raw fix)",
    )  # fmt: skip
    estimator: Literal["filters", "ekf"] = Field(
        default="ekf",
        description="what the program starts from and the current it predicts with: 'ekf', "
        "one extended Kalman filter of the 6-DOF state and the horizontal current on the "
        "prediction model, its process noise the model's spread where the vehicle is "
        "(estimation/six_dof_current.py; measurement_std, process_std, model_uncertainty, "
        "model_error_gain, current_rate_std, initial_current_std); 'filters', the position "
        "fix's complementary filter and the current observer (position_fix_gain, "
        "current_gain)",
    )  # fmt: skip
    measurement_std: tuple[(Positive,) * NX] = Field(
        default=_MEASUREMENT_STD,
        description="the EKF's sensor noise of [x, y, z, phi, theta, psi, u, v, w, p, q, r] "
        "(m, rad, m/s, rad/s): the REMUS 100 presets' sensing (x, y 0.1; psi 0.005; u, v "
        "0.01; r 0.005; depth 0.02); roll and pitch as the heading, w as u and v, p and q as "
        "r (the simulated sensor measures these exactly: an AHRS and a DVL do them no worse)",
    )  # fmt: skip
    process_std: tuple[(Positive,) * NX] = Field(
        default=_PROCESS_STD,
        description="the EKF's fixed model error per sample on the 6-DOF state (same order "
        "and units), beside the model's spread (model_uncertainty): heading, sway and yaw rate "
        "at about the one-step prediction error measured on the REMUS 100 presets' straight "
        "legs (plant 20 % off in added mass and damping, noise-free), the other states 30 "
        "times theirs, chosen by measurement (docs/remus100.md)",
    )  # fmt: skip
    current_rate_std: Positive = Field(
        default=_CURRENT_RATE_STD,
        description="the EKF's random walk of each horizontal current component "
        "(m/s per sqrt(s)): larger follows a changing current (and model error) faster",
    )  # fmt: skip
    initial_current_std: Positive = Field(
        default=0.5, description="the EKF's prior uncertainty of each current component (m/s)"
    )
    model_uncertainty: float = Field(
        default=0.2, ge=0.0, le=1.0,
        description="the EKF's relative uncertainty of the model's added mass, linear and "
        "quadratic damping (each): how far one sample's prediction moves when each is off by "
        "it, times model_error_gain, adds to the process noise where the vehicle is (0: the "
        "fixed process_std alone)",
    )  # fmt: skip
    model_error_gain: float = Field(
        default=3.0, ge=0.0,
        description="the model's error per sample as a multiple of one sample's spread "
        "(model_uncertainty): the error is a bias that persists, not white noise",
    )  # fmt: skip
    max_iterations: int = Field(default=100, ge=1, le=3000, description="IPOPT's cap per sample")

    def for_sensing(self, sensing: Any) -> tuple[SixDofNmpcConfig, dict[str, Any]]:
        """The EKF's ``measurement_std`` from the scenario's sensors where omitted: the
        navigation's x, y, heading, u, v, r and the depth's noise as they are; roll and
        pitch as the heading, w as u and v, p and q as r (the simulated sensor measures these
        exactly: an AHRS and a DVL do them no worse); none below _LEAST_NOISE_SHARE of the
        default."""
        if "measurement_std" in self.model_fields_set:
            return self, {}
        x, y, psi, u, v, r = (float(entry) for entry in sensing.std)
        z = float(getattr(sensing, "depth_std_m", 0.0))
        sensed = (x, y, z, psi, psi, psi, u, v, max(u, v), r, r, r)
        std = tuple(
            max(entry, _LEAST_NOISE_SHARE * least)
            for entry, least in zip(sensed, _MEASUREMENT_STD, strict=True)
        )
        why = ("the scenario's sensing (std, depth_std_m); roll and pitch as the heading, w "
               "as u and v, p and q as r")  # fmt: skip
        return self.model_copy(update={"measurement_std": std}), {
            "measurement_std": {"value": list(std), "why": why}
        }

    def _filled(self, model: VehicleParams, sample_time: float) -> dict[str, Any]:
        """The RK4 steps per sample, where omitted."""
        if self.model_substeps is None and model.six_dof is not None:
            return {"model_substeps": stable_substeps(model, sample_time)}
        return {}

    def _chosen(self, filled: WholeVehicleConfig) -> dict[str, dict[str, Any]]:
        chosen: dict[str, dict[str, Any]] = {}
        if self.model_substeps is None and filled.model_substeps is not None:
            chosen["model_substeps"] = {
                "value": filled.model_substeps,
                "why": "fewest RK4 steps per sample stable on the 6-DOF model's fastest mode "
                "(models/six_dof.py, stable_substeps)",
            }
        if "prediction_horizon" not in self.model_fields_set:
            chosen["prediction_horizon"] = {
                "value": filled.prediction_horizon,
                "why": f"the default {filled.prediction_horizon} samples "
                f"({filled.prediction_horizon * filled.sample_time:g} s ahead)",
            }
        return chosen


def _compiled(solver: ca.Function, options: dict, config: SixDofNmpcConfig) -> ca.Function:
    """``solver`` with its program's functions (cost, constraints, their derivatives and the
    Lagrangian's Hessian) generated to C and compiled, when ``config.jit`` and there is a C
    compiler: the same IPOPT on the same numbers, faster per step (REMUS 100 5x, BlueROV2
    Heavy 2.4x: benchmarks/six_dof_nmpc_speed.py). The library is cached on disk by its code
    (native.py), so the compile, 1 to 4 minutes, is paid once per vehicle and configuration
    (the stage is mapped: its size does not grow with the horizon)."""
    if not config.jit or compiler() is None:
        return solver
    with tempfile.TemporaryDirectory(prefix="auvmpc-six-dof-nmpc-") as scratch:
        generator = ca.CodeGenerator("six_dof_nmpc.c")
        generator.add(solver.oracle())  # "nlp": what the solver loads the rest by
        for name in solver.get_function():  # nlp_f, nlp_g, nlp_grad_f, nlp_jac_g, nlp_hess_l
            generator.add(solver.get_function(name))
        generator.generate(scratch + os.sep)
        library = shared_library("six-dof-nmpc", [Path(scratch) / "six_dof_nmpc.c"])
    if library is None:
        return solver
    return ca.nlpsol("six_dof_nmpc", "ipopt", library._name, options)


class SixDofNmpc(ShelledController):
    """The whole vehicle's nonlinear MPC (module docstring)."""

    #: Commands every 6-DOF input itself (experiments/kinds.py pairs no depth channel).
    whole_vehicle = True

    def __init__(self, model: VehicleParams, config: SixDofNmpcConfig) -> None:
        if model.six_dof is None:
            raise ConfigError("vehicle.six_dof", model.name, "missing: six-dof-nmpc predicts "
                              "with the 6-DOF model (docs/six-dof.md)")  # fmt: skip
        self.model = model
        self.take_config(config.for_vehicle(model))
        self.sample_time = float(self.config.sample_time)
        inputs = model.six_dof_actuators
        self.limits = inputs.limits
        self.n_inputs = nu = inputs.size
        self._range = np.asarray(self.limits.upper - self.limits.lower, dtype=float)
        self.crabs = not inputs.pushes_sideways
        self._build()
        self.reset(np.zeros(NX), np.zeros(nu))

    # -- the program --------------------------------------------------------------------
    def _build(self) -> None:
        config, n, nu = self.config, self.horizon, self.n_inputs
        derivative = six_dof_model(self.model).derivative_with_effectiveness
        x, u = ca.SX.sym("x", NX), ca.SX.sym("u", nu)
        current, share = ca.SX.sym("v_c", 3), ca.SX.sym("e", nu)
        still = ca.DM.zeros(3)

        def sample(derivative):
            """One sample of RK4 on ``derivative`` from x under u, current and share."""

            def f(state, command):
                return derivative(state, command, current, still, share)

            return rk4(f, x, u, self.sample_time, config.model_substeps)

        stepped = sample(derivative)
        step = ca.Function("step", [x, u, current, share], [stepped])
        # The observer's one-step prediction and how it moves with the horizontal current,
        # from one evaluation (one call per sample on the controller's step).
        predicted = step(x, u, current, share)
        # The model in still water as the vehicle is (its effectiveness), for its level flight
        self._flow = ca.Function("flow", [x, u, share], [derivative(x, u, still, still, share)])
        self._prediction = ca.Function(
            "prediction", [x, u, current, share],
            [predicted, ca.jacobian(predicted, current)[:, 0:2]],
        )  # fmt: skip
        self._ekf = None
        if config.estimator == "ekf":
            self._ekf = SixDofCurrentEkf(
                step, self.sample_time, np.array(config.measurement_std),
                np.array(config.process_std), config.current_rate_std,
                config.initial_current_std,
                self._model_spread(sample, stepped, x, u, current, share),
            )  # fmt: skip
        # One stage, written once and mapped over the horizon: its shooting gap and its cost.
        reached, previous = ca.SX.sym("x_next", NX), ca.SX.sym("u_previous", nu)
        node = ca.SX.sym("node", _NODE)  # x, y, z, psi, u, r, theta of the node reached
        stage = ca.Function(
            "stage", [x, u, reached, previous, node, current, share],
            [reached - step(x, u, current, share), self._stage_cost(u, reached, previous, node)],
        )  # fmt: skip
        X, U = ca.MX.sym("X", NX, n + 1), ca.MX.sym("U", nu, n)
        x0, u_prev = ca.MX.sym("x0", NX), ca.MX.sym("u_prev", nu)
        nodes = ca.MX.sym("r", _NODE, n)
        water, acting = ca.MX.sym("v_c", 3), ca.MX.sym("e", nu)
        previous_moves = ca.horzcat(u_prev, U[:, :-1])
        gaps, costs = stage.map(n)(
            X[:, :-1], U, X[:, 1:], previous_moves, nodes,
            ca.repmat(water, 1, n), ca.repmat(acting, 1, n),
        )  # fmt: skip
        nlp = {
            "x": ca.vertcat(ca.vec(X), ca.vec(U)),
            "p": ca.vertcat(x0, u_prev, ca.vec(nodes), water, acting),
            "f": ca.sum2(costs),
            "g": ca.vertcat(X[:, 0] - x0, ca.vec(gaps), ca.vec(U - previous_moves)),
        }
        options = {
            "ipopt": ipopt_options(
                _TOLERANCE, config.max_iterations, config.solver_time_limit_ms,
                **warm_start_options(_WARM_MU_INIT),
            ),
            "print_time": False,
        }  # fmt: skip
        self._solver = _compiled(ca.nlpsol("six_dof_nmpc", "ipopt", nlp, options), options, config)
        # Bounds: states free but the pitch; inputs in their box; gaps zero; changes in rate.
        lower_x = np.full((NX, n + 1), -np.inf)
        upper_x = np.full((NX, n + 1), np.inf)
        lower_x[_THETA, 1:], upper_x[_THETA, 1:] = -PITCH_BOUND_RAD, PITCH_BOUND_RAD
        lower_u = np.tile(np.broadcast_to(self.limits.lower, (nu,)), n)
        upper_u = np.tile(np.broadcast_to(self.limits.upper, (nu,)), n)
        self._lbw = np.concatenate([lower_x.ravel(order="F"), lower_u])
        self._ubw = np.concatenate([upper_x.ravel(order="F"), upper_u])
        max_change = np.tile(np.broadcast_to(self.limits.rate * self.sample_time, (nu,)), n)
        zeros = np.zeros(NX * (n + 1))
        self._lbg = np.concatenate([zeros, -max_change])
        self._ubg = np.concatenate([zeros, max_change])
        self._n_states = NX * (n + 1)

    def _model_spread(self, sample, nominal, x, u, current, share) -> ca.Function | None:
        """(x, u, v_c, e) -> (NX, 3): how far one sample's prediction (``nominal``; ``sample``
        of another vehicle's derivative) moves when each of the model's uncertain parts is off by
        ``model_uncertainty`` (its added mass, its linear and its quadratic damping, each
        scaled alone), times ``model_error_gain``; None without uncertainty. The EKF adds
        their outer products to its process covariance each sample: the model's error where
        the vehicle is, large in a turn (sideslip, yaw rate), small on a straight crab."""
        config = self.config
        if config.model_uncertainty == 0.0:
            return None
        columns = [
            config.model_error_gain * (sample(six_dof_model(off).derivative_with_effectiveness)
                                       - nominal)
            for off in (scaled(self.model, {part: 1.0 + config.model_uncertainty})
                        for part in _UNCERTAIN_PARTS)
        ]  # fmt: skip
        return ca.Function("model_spread", [x, u, current, share], [ca.horzcat(*columns)])

    def _stage_cost(self, command, reached, previous, node):
        """The cost of one stage (module docstring): the move's change over each input's
        range, and the tracking error of the node it reaches."""
        weights = self.config
        change = (command - previous) * ca.DM(1.0 / self._range)
        rates = reached[_RATES.start : _RATES.stop] - ca.vertcat(0, 0, node[5])
        return (
            weights.input_change_weight * ca.sumsqr(change)
            + weights.position_weight * ca.sumsqr(reached[_XY.start : _XY.stop] - node[0:2])
            + weights.depth_weight * (reached[_Z] - node[2]) ** 2
            + weights.heading_weight * 2.0 * (1.0 - ca.cos(reached[_PSI] - node[3]))
            + weights.speed_weight * (reached[_U] - node[4]) ** 2
            + weights.attitude_weight * (reached[_PHI] ** 2 + (reached[_THETA] - node[6]) ** 2)
            + weights.rate_weight * ca.sumsqr(rates)
        )

    # -- the back end (the shell, controllers/shell.py, decides what is applied) -----------
    def restart(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        self._guess: tuple[np.ndarray, np.ndarray] | None = None  # (w, lam_g) shifted
        self._solution: tuple[np.ndarray, np.ndarray] | None = None  # this sample's, shifted
        self._current = np.zeros(3)
        self._predicted: np.ndarray | None = None  # x_{k} as the last sample predicted it
        self._sample: tuple | None = None  # (state, share, stuck values or None) now
        self._fix_correction = np.zeros(2)  # filtered less measured horizontal position (m)
        self._last_fix: tuple[np.ndarray, np.ndarray] | None = None
        self._schedule = ReferenceSchedule(self.sample_time, _REF_PSI, _REF_RATES)
        self._level_flights: dict[tuple, LevelFlight | None] = {}  # by the fault (_pace's key)
        self._depth_pace = DepthHoldingPace(self.sample_time)
        self._depth_target: float | None = None  # the last sample's flown depth reference
        if self._ekf is not None:
            self._ekf.reset(np.asarray(initial_state, dtype=float))

    def propose(self, observation: Observation, previous: np.ndarray) -> Proposal:
        state = np.asarray(observation.state, dtype=float)
        share = np.asarray(self.effectiveness, dtype=float)
        share, lower, upper, previous, stuck = self._fixed_at_stuck(observation, share, previous)
        if self._ekf is None:
            self._estimate_current(state)
        else:  # the program starts from the estimate, with the estimated current
            state, self._current[:2] = self._ekf.correct(state)
        self._sample = (state, share, stuck)
        speed = self._pace(share, lower, upper, previous, observation.reference, state)
        shown = observation.reference  # as many rows as the loop shows, for the recovery
        reference = self._schedule.rows(
            observation.k, shown, len(shown) - 1, speed, self._current[:2]
        )
        self._depth_target = float(reference[0, _REF_Z])
        nodes = self._nodes(state, reference)
        parameters = np.concatenate([state, previous, nodes.ravel(order="F"), self._current, share])
        w0, lam0 = self._guess if self._guess is not None else self._cold(state, previous)
        started = time.perf_counter()
        solution = self._solver(
            x0=w0, lam_g0=lam0, p=parameters,
            lbx=lower, ubx=upper, lbg=self._lbg, ubg=self._ubg,
        )  # fmt: skip
        solve_time = time.perf_counter() - started
        stats = self._solver.stats()
        iterations = int(stats.get("iter_count", 0))
        w = np.asarray(solution["x"], dtype=float).ravel()
        # Only a converged solve is a proposal: one cut short by the iteration cap (or the
        # time limit) is a failure, so the run's fallback metrics see every such sample.
        told = {  # what the shell and the log get either way
            "details": self._details(observation.k),
            "reference": self._flown(reference, observation),
            "current": self._current[:2].copy(),
        }
        if not (stats["success"] and np.all(np.isfinite(w))):
            self._solution = None
            return Proposal(None, solve_time, iterations, **told)
        states = w[: self._n_states].reshape((NX, self.horizon + 1), order="F")
        plan = w[self._n_states :].reshape((self.n_inputs, self.horizon), order="F").T
        self._solution = self._shifted(states, plan, np.asarray(solution["lam_g"]).ravel())
        return Proposal(plan, solve_time, iterations, predicted_states=states.T, **told)

    def applied(self, command: np.ndarray, fell_back: bool) -> None:
        """Warm-start the next solve from this one's (none after a fallback), and predict
        the next state under the command applied, for the current observer."""
        self._guess = None if fell_back else self._solution
        state, share, stuck = self._sample
        acting = command if stuck is None else np.where(np.isnan(stuck), command, stuck)
        if self._ekf is not None:
            self._ekf.predict(acting, share)
            return
        predicted, sensitivity = self._prediction(state, acting, self._current, share)
        self._predicted = np.asarray(predicted, dtype=float).ravel()
        self._sensitivity = np.asarray(sensitivity, dtype=float)

    def forget_plan(self) -> None:
        self._solution = None

    def _fixed_at_stuck(self, observation: Observation, share: np.ndarray, previous: np.ndarray):
        """``(share, lower, upper, previous, stuck)``: the program's effectiveness, bounds on
        its variables and previous move, with each input ``observation.stuck_at`` says is
        stuck fixed at its value (clipped into its limits) over the horizon, acting in full,
        and its previous move that value (so its first move's rate holds); ``stuck``: the
        values, NaN where free (None: none stuck, and the program's own bounds unchanged).
        The shell moves the command to a stuck input there within the rate limit."""
        told = observation.stuck_at
        if told is None or np.isnan(told).all():
            return share, self._lbw, self._ubw, previous, None
        held = ~np.isnan(told)
        value = np.clip(np.where(held, told, 0.0), self.limits.lower, self.limits.upper)
        stuck = np.where(held, value, np.nan)
        lower, upper = self._lbw.copy(), self._ubw.copy()
        for bound in (lower, upper):  # the inputs, node by node: (N, nu) after the states
            bound[self._n_states :].reshape(self.horizon, self.n_inputs)[:, held] = value[held]
        share = np.where(held, 1.0, share)
        return share, lower, upper, np.where(held, value, previous), stuck

    def _pace(self, share, lower, upper, previous, reference, state) -> float | None:
        """The speed through the water (m/s) the vehicle can hold its depth at as it is now,
        or None: healthy, or no level flight at all (then the mission's pace is flown as it
        is, whatever comes of it). The fastest level flight (models/level_flight.py), no
        faster than twice what the mission asks over the preview, solved once per fault,
        trimmed by the depth error (controllers/pace.py)."""
        if np.all(share >= 1.0) and lower is self._lbw:  # healthy: nothing held either
            return None
        first = self._n_states  # the first move's bounds: the stuck inputs' values in them
        low, high = lower[first : first + self.n_inputs], upper[first : first + self.n_inputs]
        key = (tuple(np.round(share, 6)), tuple(np.round(low, 6)), tuple(np.round(high, 6)))
        if key not in self._level_flights:
            ground = np.diff(np.asarray(reference, dtype=float)[:, _REF_XY], axis=0)
            asked = np.hypot(*(ground / self.sample_time - self._current[:2]).T).max()
            x, u = ca.SX.sym("x", NX), ca.SX.sym("u", self.n_inputs)
            flow = ca.Function("flow_now", [x, u], [self._flow(x, u, share)])
            self._level_flights[key] = fastest_level_flight(
                flow, low, high, _CEILING * float(asked), PITCH_BOUND_RAD, start=previous
            )
        flight = self._level_flights[key]
        if flight is None:
            return None
        target = reference[0, _REF_Z] if self._depth_target is None else self._depth_target
        return self._depth_pace.speed(flight, float(state[_Z] - target))

    def _flown(self, reference: np.ndarray, observation: Observation) -> np.ndarray | None:
        """The rows flown, for the shell's recovery, where they are not the loop's (None
        while on the mission's clock)."""
        return None if reference is observation.reference else reference

    def _details(self, k: int) -> dict[str, float]:
        """What the log keeps of this controller's own: how far behind the mission's clock
        its schedule flies (s)."""
        return {"schedule_lag_s": self._schedule.lag(k) * self.sample_time}

    def _estimate_current(self, state: np.ndarray) -> None:
        """The world-frame horizontal current, moved by ``current_gain`` of the least-squares
        correction that explains the last one-step prediction's error (the prediction
        assumed the estimate; its sensitivity to the current maps the error back); first
        the position fix's filter (:meth:`_filter_fix`)."""
        self._filter_fix(state)
        if self._predicted is None:
            return
        error = state[_OBSERVED] - self._predicted[_OBSERVED]
        sensitivity = self._sensitivity[_OBSERVED]
        # Ridge-regularised: where the flow barely acts (a vehicle at rest under quadratic
        # damping alone feels no first-order change of a small current) the plain least
        # squares would divide by almost nothing (measured: a 3000 m/s estimate).
        normal = sensitivity.T @ sensitivity
        ridge = _RIDGE * max(float(np.trace(normal)), _RIDGE_FLOOR)
        correction = np.linalg.solve(normal + ridge * np.eye(2), sensitivity.T @ error)
        self._current[:2] += self.config.current_gain * correction

    def _filter_fix(self, state: np.ndarray) -> None:
        """The filtered horizontal position less the fix (m, world frame): the last estimate
        (the last fix plus the last correction) moved on by the measured velocity over
        ground (trapezoidal over the sample: dead reckoning), then ``position_fix_gain`` of
        the new fix's difference from it. A first-order filter of the fix's noise (its
        variance times K / (2 - K)) that passes the motion the velocities measure."""
        last = self._last_fix  # (its position, its velocity over ground)
        velocity = ground_velocity(state)
        self._last_fix = (state[_XY].copy(), velocity)
        if last is None:
            return
        moved = 0.5 * self.sample_time * (last[1] + velocity)
        keep = 1.0 - self.config.position_fix_gain
        self._fix_correction = keep * (self._fix_correction + last[0] + moved - state[_XY])

    def _nodes(self, state: np.ndarray, reference: np.ndarray) -> np.ndarray:
        """(_NODE, N) targets of nodes 1..N: position, depth, the crab heading through the
        estimated current (continuous with the vehicle's heading), the surge that makes the
        ground speed good along it, the path's turn rate and the pitch of its climb.

        The program starts from the measured state, the position a raw fix: its position
        targets are moved back by the filter's correction, which makes the predicted
        positions' errors those of a prediction from the filtered position."""
        reference = np.asarray(reference, dtype=float)
        rows = reference[1 : self.horizon + 1]
        ground = np.diff(reference[:, _REF_XY], axis=0)[: self.horizon] / self.sample_time
        through_water = ground - self._current[:2]
        speed = np.hypot(through_water[:, 0], through_water[:, 1])
        tangent = rows[:, 2]
        crab = np.arctan2(through_water[:, 1], through_water[:, 0])
        heading = np.where(self.crabs & (speed > _STILL_M_PER_S), crab, tangent)
        # unwrap onto the vehicle's turn: the cost's cosine does not mind, the guess does
        heading = state[_PSI] + wrap_angle(heading - state[_PSI])
        surge = np.hypot(ground[:, 0], ground[:, 1]) * np.cos(
            np.arctan2(ground[:, 1], ground[:, 0]) - heading
        )
        climb = np.diff(reference[:, _REF_Z])[: self.horizon]
        pitch = np.arctan2(-climb / self.sample_time, np.maximum(speed, _STILL_M_PER_S))
        position = rows[:, _REF_XY] - self._fix_correction
        return np.vstack(
            [position[:, 0], position[:, 1], rows[:, _REF_Z], heading, surge, rows[:, _REF_R],
             pitch]
        )  # fmt: skip

    def _cold(self, state: np.ndarray, previous: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A first guess: the measured state held, the ``previous`` command held."""
        states = np.tile(state, self.horizon + 1)
        plan = np.tile(previous, self.horizon)
        return np.concatenate([states, plan]), np.zeros(self._lbg.size)

    def _shifted(self, states, plan, multipliers) -> tuple[np.ndarray, np.ndarray]:
        """The solution one sample on (its last node and move repeated) as the next guess."""
        states = np.hstack([states[:, 1:], states[:, -1:]])
        plan = np.vstack([plan[1:], plan[-1:]])
        return np.concatenate([states.ravel(order="F"), plan.ravel()]), multipliers
