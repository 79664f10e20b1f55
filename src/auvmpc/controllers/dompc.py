"""The paper's optimal control problem solved by do-mpc: a yardstick, not a controller to fly.

do-mpc (https://www.do-mpc.com) is the Python MPC toolkit many users already know. This
module poses the same problem as our MPCs (paper-model.md sections 3-4 and 7) in do-mpc's
own terms and lets it solve the full nonlinear program with IPOPT every sample, so that
``auvmpc bench`` can time both in one process on one machine. Install with
``pip install 'auvmpc[compare]'``.

The problem, stage by stage (k = 0 .. ny-1, ``X_k = [x_k; F_{k-1}]``, input ``dF_k``):

    F_k     = F_{k-1} + g_k dF_k             g_k = 1 at the free moves, 0 after (nc, blocking)
    x_{k+1} = RK4(vehicle.dynamics)(x_k, F_k) over Te, ``model_substeps`` steps
    cost    = sum_k (x_k - r_k)' Q (x_k - r_k) + F_k' R F_k  (or dF_k' R dF_k)
              + (x_ny - r_ny)' S (x_ny - r_ny)
    s.t.    |dF_k| <= rate * Te,  F_min <= F_k <= F_max
            reach_m - |p_k - c_m,k| <= eps_m,k,  eps >= 0,  penalty * eps in the cost

This is :class:`~auvmpc.controllers.mpc.LinearMpc`'s cost term for term: the k = 0 state
term is a constant (x_0 is measured) and changes no minimiser. Differences, all deliberate:

* the dynamics are the nonlinear RK4 map itself, not a linearisation (the point of the
  comparison: the same OCP solved to convergence by a general NLP solver);
* obstacles are the exact distance constraint (``reach = radius + vehicle_radius +
  obstacle_margin``), where ``LinearMpc`` uses a tangent half-plane, and do-mpc imposes them
  on the stage states x_0 .. x_{ny-1} where ``LinearMpc`` constrains x_1 .. x_ny: x_0 is
  fixed (its slack only absorbs an unavoidable violation and is ignored for the status)
  and x_ny, 15 s ahead in the paper's setting, is not constrained;
* the slack penalty is do-mpc's, linear only (``LinearMpc`` adds a small quadratic part);
* there is no offset-free estimator (do-mpc has none): ``offset_free=true`` is rejected;
* do-mpc warm-starts IPOPT from the previous solution as it stands (not shifted).
"""

from __future__ import annotations

import time
import warnings
from typing import Literal

import casadi as ca
import numpy as np

from auvmpc.controllers.base import MemoryNeed, Observation, align_heading, nlp_memory_need
from auvmpc.controllers.config import ControllerType, OptimisingControllerConfig, type_field
from auvmpc.controllers.shell import Proposal, ShelledController
from auvmpc.errors import ConfigError
from auvmpc.models.integrators import rk4
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.vehicle import VehicleParams, dynamics
from auvmpc.ocp.tracking import ThrustPenalty

__all__ = ["DoMpcConfig", "DoMpcController"]

NX = HORIZONTAL.size
# Unused obstacle slots sit this far away (m) with zero reach: never active.
_PARKED_OBSTACLE_M = 1e6
# Keeps the distance differentiable if a predicted position ever hits a centre exactly (m^2).
_DISTANCE_REGULARISATION_M2 = 1e-12
# Weight pinning the moves after the control horizon to zero (they act on nothing there).
_HELD_MOVE_WEIGHT = 1.0


class DoMpcConfig(OptimisingControllerConfig):
    """``do-mpc``: the optimising controllers' knobs (offset_free must be false: do-mpc has
    no disturbance estimator)."""

    type: Literal[ControllerType.DO_MPC] = type_field(ControllerType.DO_MPC)


class DoMpcController(ShelledController):
    """The paper's OCP (incremental form, nonlinear RK4 model) built and solved by do-mpc.

    Parameters
    ----------
    model : VehicleParams
        The controller's (nominal) vehicle.
    config : DoMpcConfig
        Horizons, weights, limits and obstacle settings, as for ``mpc`` / ``ltv-mpc``.
    obstacle_slots : int
        Obstacles the problem has room for (give the scenario's count). A sample that sees
        more rebuilds the problem with enough slots (its time includes the rebuild, and
        ``rebuilt`` is True after it); unused slots are parked far away, which costs IPOPT
        iterations, hence the default of none.

    Raises
    ------
    ConfigError
        If do-mpc is not installed (``controller.type``), or ``controller.offset_free`` is
        set (do-mpc has no disturbance estimator).
    """

    def __init__(self, model: VehicleParams, config: DoMpcConfig, obstacle_slots: int = 0) -> None:
        config = config.for_vehicle(model)
        try:
            with warnings.catch_warnings():
                # do-mpc warns at import about optional features (ONNX, OPC UA, torch).
                warnings.simplefilter("ignore")
                import do_mpc
        except ImportError:
            raise ConfigError(
                "controller.type",
                "do-mpc",
                "needs the optional extra: pip install 'auvmpc[compare]'",
            ) from None
        if config.offset_free:
            raise ConfigError(
                "controller.offset_free",
                True,
                "do-mpc has no disturbance estimator; set controller.offset_free=false",
            )
        if obstacle_slots < 0:
            raise ValueError(f"obstacle_slots must be >= 0, got {obstacle_slots}")
        self._do_mpc = do_mpc
        self.model = model
        self.take_config(config)
        self.ocp = config.ocp(model)
        self.limits = self.ocp.limits
        # g_k: 1 where a move is free (0..nc-1, or the blocking steps), 0 where F is held.
        self._gates = np.zeros(self.horizon + 1)
        self._gates[list(self.ocp.move_steps)] = 1.0
        self._reach_extra = self.ocp.keep_out_extra
        self._build(obstacle_slots)
        self.reset(np.zeros(NX), np.zeros(model.n_thrusters))

    # -- the do-mpc problem --------------------------------------------------------------
    def _build(self, slots: int) -> None:
        """Model, objective, bounds and constraints in do-mpc's terms; IPOPT set up once."""
        do_mpc, p, cfg, ocp = self._do_mpc, self.model, self.config, self.ocp
        n = p.n_thrusters
        model = do_mpc.model.Model("discrete", "SX")
        state = model.set_variable("_x", "state", (NX, 1))
        previous = model.set_variable("_x", "F_prev", (n, 1))
        move = model.set_variable("_u", "dF", (n, 1))
        model.set_variable("_tvp", "reference", (NX, 1))
        gate = model.set_variable("_tvp", "gate")
        # The thrusters' effectiveness (1 healthy, 0 dead): a parameter, so a fault needs no
        # rebuild.
        effectiveness = model.set_variable("_tvp", "effectiveness", (n, 1))
        if slots:  # per slot: centre x, centre y, reach (m)
            model.set_variable("_tvp", "obstacles", (3 * slots, 1))
        thrust = previous + gate * move
        model.set_rhs(
            "state",
            rk4(
                lambda x, f: dynamics(x, f, p, effectiveness=effectiveness),
                state,
                thrust,
                ocp.sample_time,
                cfg.model_substeps,
            ),
        )
        model.set_rhs("F_prev", thrust)
        model.setup()

        mpc = do_mpc.controller.MPC(model)
        mpc.set_param(
            n_horizon=self.horizon,
            t_step=ocp.sample_time,
            n_robust=0,
            use_terminal_bounds=True,  # the F_prev bounds hold at the last stage too (F_{ny-1})
            store_full_solution=False,
            store_lagr_multiplier=False,
            store_solver_stats=[],
            nlpsol_opts={"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": 0},
        )
        error = model.x["state"] - model.tvp["reference"]
        dF, F = model.u["dF"], model.x["F_prev"] + model.tvp["gate"] * model.u["dF"]
        penalised = F if ocp.penalty is ThrustPenalty.ABSOLUTE else dF
        lterm = (
            ca.mtimes([error.T, ca.diag(ca.DM(ocp.stage_weight)), error])
            + ca.mtimes([penalised.T, ca.diag(ca.DM(ocp.input_weight)), penalised])
            + _HELD_MOVE_WEIGHT * (1 - model.tvp["gate"]) * ca.sumsqr(dF)
        )
        if ocp.weights_internal_thrust:  # the internal thrust (ocp/tracking.py)
            lterm += ca.mtimes([F.T, ocp.internal_weight(effectiveness), F])
        mterm = ca.mtimes([error.T, ca.diag(ca.DM(ocp.terminal_weight)), error])
        mpc.set_objective(lterm=lterm, mterm=mterm)
        mpc.set_rterm(dF=0.0)  # R weights F (or dF) in lterm already; do-mpc's move term stays 0
        mpc.bounds["lower", "_u", "dF"] = -ocp.max_move
        mpc.bounds["upper", "_u", "dF"] = ocp.max_move
        mpc.bounds["lower", "_x", "F_prev"] = ocp.input_lower
        mpc.bounds["upper", "_x", "F_prev"] = ocp.input_upper
        position = model.x["state"][HORIZONTAL.position]
        for slot in range(slots):
            cx, cy, reach = (model.tvp["obstacles"][3 * slot + i] for i in range(3))
            distance = ca.sqrt(
                (position[0] - cx) ** 2 + (position[1] - cy) ** 2 + _DISTANCE_REGULARISATION_M2
            )
            mpc.set_nl_cons(
                f"obstacle_{slot}",
                reach - distance,
                ub=0.0,
                soft_constraint=True,
                penalty_term_cons=ocp.slack_penalty,
            )
        tvp = mpc.get_tvp_template()
        mpc.set_tvp_fun(lambda t_now: tvp)  # filled in place before every make_step
        with warnings.catch_warnings():
            # casadi 3.8 warns about a numpy call inside do-mpc's own checks.
            warnings.filterwarnings("ignore", category=FutureWarning, module="casadi")
            mpc.setup()

        self._mpc, self._tvp, self._slots = mpc, tvp, slots
        self.dompc_model, self.dompc_mpc = model, mpc  # do-mpc objects, for tests and inspection
        # Flat indices into do-mpc's parameter and solution vectors, found once.
        stages = range(self.horizon + 1)
        self._tvp_index = {
            name: np.array([tvp.f["_tvp", k, name] for k in stages]).reshape(len(stages), -1)
            for name in ("reference", "gate", "effectiveness", *(("obstacles",) if slots else ()))
        }
        opt_x = mpc.opt_x
        self._state_index = np.array([opt_x.f["_x", k, 0, -1, "state"] for k in stages])
        self._move_index = np.array([opt_x.f["_u", k, 0, "dF"] for k in stages[:-1]])
        slacks = [[f"obstacle_{s}" for s in range(slots)] for _ in stages[:-1]]
        self._slack_index = np.array(
            [[opt_x.f["_eps", k, 0, name][0] for name in row] for k, row in enumerate(slacks)],
            dtype=int,
        ).reshape(self.horizon, slots)
        self._needs_guess = True

    # -- Controller interface ------------------------------------------------------------
    @classmethod
    def libraries(cls, config) -> tuple[str, ...]:
        return ("do-mpc",)

    @classmethod
    def memory_need(cls, config, n_inputs: int, n_states: int) -> MemoryNeed:
        return nlp_memory_need(config)

    @classmethod
    def from_config(cls, model, config, obstacle_count: int = 0) -> DoMpcController:
        return cls(model, config, obstacle_slots=obstacle_count)

    def restart(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        self._needs_guess = True
        self._mpc.reset_history()

    def propose(self, observation: Observation, previous: np.ndarray) -> Proposal:
        ny = self.horizon
        state = np.asarray(observation.state, dtype=float)
        self.rebuilt = False
        if len(observation.obstacles) > self._slots:
            self._build(len(observation.obstacles))
            self.rebuilt = True
        self._set_parameters(state, observation)
        x0 = np.concatenate([state, previous])
        mpc = self._mpc
        if self._needs_guess:
            # Every stage at the measured state and thrust, no moves: do-mpc's own start.
            mpc.x0 = x0
            mpc.u0 = np.zeros(self.model.n_thrusters)
            mpc.set_initial_guess()
            self._needs_guess = False
        started = time.perf_counter()
        mpc.make_step(x0)
        solve_time = time.perf_counter() - started
        iterations = int(mpc.solver_stats.get("iter_count", 0))
        if not mpc.solver_stats["success"]:  # CasADi's verdict on IPOPT's return status
            return Proposal(plan=None, solve_time_s=solve_time, iterations=iterations)
        solution = np.asarray(mpc.opt_x_num.cat).ravel()
        moves = solution[self._move_index] * self._gates[:ny, None]  # (ny, n)
        slack = solution[self._slack_index]  # (ny, slots)
        return Proposal(
            plan=previous + np.cumsum(moves, axis=0),
            solve_time_s=solve_time,
            iterations=iterations,
            # Stage 0 is the measured state: its slack is an unavoidable violation.
            max_slack=float(slack[1:].max(initial=0.0)),
            predicted_states=solution[self._state_index],
        )

    # -- pieces --------------------------------------------------------------------------
    def _set_parameters(self, state: np.ndarray, observation: Observation) -> None:
        """Reference (heading aligned by 2 pi k to the measured one), gates, the thrusters'
        effectiveness and obstacles."""
        ny = self.horizon
        reference = align_heading(state, observation.reference[: ny + 1])
        values = np.zeros(self._tvp.cat.shape[0])
        values[self._tvp_index["reference"]] = reference
        values[self._tvp_index["gate"][:, 0]] = self._gates
        values[self._tvp_index["effectiveness"]] = self.effectiveness
        if self._slots:
            slots = np.tile([_PARKED_OBSTACLE_M, _PARKED_OBSTACLE_M, 0.0], (ny + 1, self._slots, 1))
            times = np.arange(ny + 1) * self.sample_time
            for slot, obstacle in enumerate(observation.obstacles):
                centres, radii = obstacle.predict(times)
                slots[:, slot, :2] = centres
                slots[:, slot, 2] = radii + self._reach_extra
            values[self._tvp_index["obstacles"]] = slots.reshape(ny + 1, -1)
        self._tvp.master = ca.DM(values)
