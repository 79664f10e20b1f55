"""Nonlinear MPC on the exact RK4 model: multiple shooting, IPOPT or real-time iterations.

The optimal control problem is the one :class:`~auvmpc.controllers.mpc.LinearMpc` poses
(paper-model.md section 4), with nothing linearised:

    min  sum_{n=1}^{ny-1} |X_n - r_n|_Q^2 + |X_ny - r_ny|_S^2 + sum_{n=0}^{ny-1} |F_n|_R^2
         + rho sum s + sum s^2
    s.t. X_0 = x_hat,   X_{n+1} = RK4(X_n, F_n, d_hat)        (model_substeps steps over Te)
         F_min <= F_n <= F_max,   |F_n - F_{n-1}| <= rate Te  (F_{-1}: last applied thrust)
         |p_n - c_o(t + n Te)| - (r_o + vehicle_radius + obstacle_margin) + s_{o,n} >= 0,
         s >= 0,   for every obstacle slot o and n = 1..ny

With ``thrust_penalty: increment`` R weights F_n - F_{n-1} instead. The decision variables
are the states X_0..X_ny and the thrusts at the move steps of ``config.move_schedule()``
(multiple shooting); the thrust is held between moves. The reference heading is shifted by
2 pi k to the turn the vehicle is on, as in LinearMpc. A keep-out disc is an exact
constraint in distance form, so its slack is in metres and ``obstacle_slack_penalty`` (per m)
means what it means for LinearMpc; its linearisation is the half-plane tangent to the
inflated disc facing the linearisation point. Obstacles fill ``MAX_OBSTACLES`` slots (the
nearest ones when there are more); an empty slot's rows have no lower bound. The program
is therefore built once, as expanded SX, with all that changes between samples passed as
parameters and bounds.

Two ways to solve it (``config.nmpc_mode``):

* ``full``: IPOPT to convergence, warm-started from the previous solution shifted one
  sample (primal and dual): the accuracy reference.
* ``real-time``: the real-time iteration (Diehl, Bock, Schloeder 2005, "A real-time
  iteration scheme for nonlinear optimization in optimal feedback control"): one SQP step
  per sample from the shifted previous solution. The cost is a linear least-squares cost,
  so the Gauss-Newton Hessian is exact for it and constant. The step's QP is built from
  the RK4 map's Jacobians at every shooting node, stage by stage (ocp/stage_qp.py). By
  default (``qp_structure: sparse``) it keeps the states and HPIPM solves it (well posed for
  unstable vehicles), the whole step in one call to C built with the system compiler where
  there is one; ``condensed`` (and move blocking) eliminates the states for the configured
  dense QP backend (``qp_solver``); solvers/real_time_iteration.py has the three ways. Obstacle
  rows are kept where the linearisation point is within 5 m of the disc.
  ``linearisation_iterations`` > 1 takes that many SQP steps per sample.

Without a previous solution (after a reset or a failed solve) both start from the states
on the reference and the last thrust held (multiple shooting need not start on a
trajectory; on 8 random states IPOPT took 160-500 iterations from the model's run under the
held thrust, failing twice, and 60-300 from the reference). The real-time scheme then takes
``_COLD_START_ITERATIONS`` SQP steps, each followed by re-simulating the states from the
new thrusts: from a crude guess the linear state update can run away (measured on random
states, 24 of 48 samples failed with it, 1 with re-simulated states). From a shifted
solution it keeps the multiple-shooting update, which tracks far better under model error
(paper-disturbed, offset-free, inertia level -1, RMS after 30 s: 0.045 m, against 0.46 m
with re-simulated states). Where the re-simulated cold start fails too (a light, weakly
yaw-damped vehicle whose rollout spins up), once more with the multiple-shooting update.

The safety rules are the shell's (controllers/shell.py), as for every MPC: the applied
command is projected into the hard-limit box; a failed or late solve applies the previous
plan's next move (FALLBACK); an active slack marks the step RELAXED. With ``offset_free``
the EKF of auvmpc.estimation supplies the state and the world-frame force the prediction
model uses.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import Field

from auvmpc.controllers.base import (
    Controller,
    MemoryNeed,
    Observation,
    horizontal_limits,
    nlp_memory_need,
    tracked_reference,
)
from auvmpc.controllers.config import (
    ControllerType,
    NmpcMode,
    OptimisingControllerConfig,
    PlanLinearisation,
    QpStructure,
    Relinearisation,
    type_field,
)
from auvmpc.controllers.shell import Proposal, ShelledController
from auvmpc.estimation import DisturbanceObserver
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.vehicle import VehicleParams
from auvmpc.ocp.multiple_shooting import (
    MAX_OBSTACLES,
    ND,
    NX,
    Iterate,
    MultipleShootingProgram,
    Sample,
)
from auvmpc.solvers.ipopt import IpoptSolver
from auvmpc.solvers.real_time_iteration import RealTimeIteration

__all__ = [
    "MAX_OBSTACLES",
    "Iterate",
    "MultipleShootingProgram",
    "NmpcConfig",
    "NonlinearMpc",
    "Sample",
    "rescue_solver",
]

# SQP steps on a sample without a solution to shift (first sample, after a failure): the
# real-time iteration then goes on from a (nearly) converged solution, as it assumes.
# Measured: 10 steps bring the first thrust within 5e-8 N of IPOPT's on the paper oval.
_COLD_START_ITERATIONS = 10
# IPOPT iterations of the last-resort solve after every real-time try failed.
RESCUE_IPOPT_ITERATIONS = 150


class NmpcConfig(PlanLinearisation, Relinearisation, OptimisingControllerConfig):
    """``nmpc``: the optimising controllers' knobs, the SQP's and how it solves."""

    type: Literal[ControllerType.NMPC] = type_field(ControllerType.NMPC)
    nmpc_mode: NmpcMode = Field(default=NmpcMode.REAL_TIME, description="nmpc solution mode")


class NonlinearMpc(ShelledController):
    """Nonlinear multiple-shooting MPC (``nmpc``): full IPOPT solve or real-time iterations."""

    def __init__(
        self, model: VehicleParams, config: NmpcConfig, obstacle_slots: int = MAX_OBSTACLES
    ) -> None:
        config = config.for_vehicle(model)
        self.model = model
        self.take_config(config)
        self.limits = horizontal_limits(model)
        self.program = MultipleShootingProgram(model, config, obstacle_slots)
        if config.nmpc_mode is NmpcMode.FULL:
            self._solver: IpoptSolver | RealTimeIteration = IpoptSolver(self.program, config)
        else:
            # Held thrusts would be equality boxes, which an interior point handles badly
            # (HPIPM took 50 iterations without converging): move blocking condenses.
            condensed = (
                config.qp_structure is QpStructure.CONDENSED or self.program.n_moves < self.horizon
            )
            self._solver = RealTimeIteration(self.program, condensed)
            if config.jit and not condensed and not self._solver.compiled:
                self.build_warnings = (
                    "nmpc: no C compiler (or no HPIPM in the casadi wheel), so the real-time "
                    "step runs through CasADi's virtual machine: same QP, 2-3x slower per step",
                )
        self._rescue: IpoptSolver | None = None  # the real-time mode's last resort
        self._observer = (
            DisturbanceObserver(model, config.sample_time, config.observer, config.model_substeps)
            if config.offset_free
            else None
        )
        self.reset(np.zeros(NX), np.zeros(model.n_thrusters))

    @classmethod
    def memory_need(cls, config, n_inputs: int, n_states: int) -> MemoryNeed:
        return nlp_memory_need(config)

    @classmethod
    def from_config(cls, model, config, obstacle_count: int = 0) -> Controller:
        """Room for the scenario's obstacles (at most MAX_OBSTACLES; none without obstacles):
        every unused slot is rows and variables each solve carries. Where the C controller
        covers the configuration, it is that (controllers/compiled_nmpc.py)."""
        from auvmpc.controllers.compiled_nmpc import CompiledNmpc, runs_in_c

        slots = min(MAX_OBSTACLES, obstacle_count)
        config = config.for_vehicle(model)
        if runs_in_c(model, config):
            return CompiledNmpc(model, config, slots)
        return cls(model, config, obstacle_slots=slots)

    # -- the back end of the safety shell -------------------------------------------------
    def restart(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        self._guess: Iterate | None = None  # where the next solve starts (None: cold)
        self._next_guess: Iterate | None = None
        self._solver.reset()
        if self._observer is not None:
            self._observer.reset(initial_state)

    def propose(self, observation: Observation, previous: np.ndarray) -> Proposal:
        state = np.asarray(observation.state, dtype=float)
        disturbance = np.zeros(ND)
        if self._observer is not None:
            state, disturbance = self._observer.correct(state)
        reference = tracked_reference(
            self.model, state, disturbance, observation.reference[: self.horizon + 1],
            self.sample_time,
        )  # fmt: skip
        self._next_guess = None
        finite = np.isfinite(state).all() and np.isfinite(disturbance).all()
        if not (finite and np.isfinite(reference).all()):
            # Never hand NaN to a solver (IPOPT raises on it): a failed step, not an error.
            return Proposal(plan=None, disturbance=disturbance)
        sample = self.program.sample(
            state, previous, reference, disturbance, observation.obstacles, self.effectiveness
        )
        cold = self._guess is None
        cold_iterations = max(_COLD_START_ITERATIONS, self.config.linearisation_iterations)
        if cold:
            guess, iterations = self.program.reference_guess(sample), cold_iterations
        else:
            guess = _aligned_guess(self._guess, state)
            iterations = self.config.linearisation_iterations
        solution = self._solver.solve(guess, sample, iterations, cold)
        if self.config.nmpc_mode is NmpcMode.REAL_TIME:
            # Failed: start again from the reference within the same sample, as after a reset,
            # each try only if every one before failed. (1) After a shifted iterate (it can be
            # what failed: a prediction that left the range where the model's RK4 step is
            # stable), re-simulated as a cold start: on the random-vehicle sweep 1 fallback in
            # 100 vehicles without it, none with it. (2) With the multiple-shooting update: the
            # re-simulated rollout of a 15 s plan can itself spin up (the light BlueROV2 with a
            # disc ahead fell back on every sample; 0 fallbacks with it, tests/test_nmpc.py).
            for resimulate in ([] if cold else [True]) + [False]:
                if solution.iterate is not None:
                    break
                retry = self._solver.solve(
                    self.program.reference_guess(sample), sample, cold_iterations, True,
                    resimulate=resimulate,
                )  # fmt: skip
                retry.solve_time_s += solution.solve_time_s
                solution = retry
            if solution.iterate is None:
                # (3) The same program solved by IPOPT (docs/recovery.md): it backtracks where a
                # real-time iteration's rollout leaves the model's stable range (non-finite
                # states on light, strongly powered vehicles), and from the vehicle at rest
                # where it is, since the reference may run through the disc it is avoiding.
                rescue = self._rescue_solver().solve(
                    self.program.resting_guess(sample), sample, 0, True
                )
                rescue.solve_time_s += solution.solve_time_s
                rescue.iterations += solution.iterations
                solution = rescue
        # Where the next solve starts: this solution shifted, also when the shell finds it
        # late (a solve that needs more than one sample gets it over several), or the last
        # point of a solve stopped at its limits; after any other failure, cold (its
        # starting point may be what made it fail).
        resume = solution.iterate if solution.iterate is not None else solution.resume
        if resume is not None:
            self._next_guess = self.program.shifted(resume, sample)
        iterate = solution.iterate
        return Proposal(
            plan=None if iterate is None else self.program.plan(iterate),
            solve_time_s=solution.solve_time_s,
            iterations=solution.iterations,
            max_slack=0.0 if iterate is None else float(iterate.slack.max(initial=0.0)),
            predicted_states=None if iterate is None else iterate.states.copy(),
            disturbance=disturbance,
        )

    def _rescue_solver(self) -> IpoptSolver:
        """Built when first needed."""
        if self._rescue is None:
            self._rescue = rescue_solver(self.program, self.config)
        return self._rescue

    def forget_plan(self) -> None:
        self._next_guess = None

    def applied(self, command: np.ndarray, fell_back: bool) -> None:
        """Propagate the estimator with the applied thrust; move the warm start on."""
        self._guess = self._next_guess
        if self._observer is not None:
            self._observer.predict(command, self.effectiveness)


def rescue_solver(program: MultipleShootingProgram, config: NmpcConfig) -> IpoptSolver:
    """The real-time mode's last resort: IPOPT on the same program, at most
    RESCUE_IPOPT_ITERATIONS iterations (an iteration limit, not a wall-clock one, so that runs
    repeat to the bit)."""
    limit = config.qp_iteration_limit or RESCUE_IPOPT_ITERATIONS
    return IpoptSolver(program, config.model_copy(update={"qp_iteration_limit": limit}))


def _aligned_guess(guess: Iterate, state: np.ndarray) -> Iterate:
    """The guess with its headings shifted by 2 pi k to the turn of the measured heading."""
    heading = HORIZONTAL.heading
    turns = np.round((state[heading] - guess.states[0, heading]) / (2.0 * math.pi))
    if not turns:
        return guess
    states = guess.states.copy()
    states[:, heading] += 2.0 * math.pi * turns
    return Iterate(states, guess.thrust, guess.slack)
