"""The real-time iteration: Gauss-Newton SQP steps on the multiple-shooting program, each one
QP of the stage form (ocp/stage_qp.py), solved one of three ways:

- sparse, compiled: the stage functions generated to C with a small HPIPM driver, one call
  per SQP step (solvers/compiled_qp_step.py), the default where a C compiler is present;
- sparse, through CasADi: the same functions evaluated by CasADi and the assembled QP solved
  by its HPIPM interface (solvers/casadi_qp_step.py): the same QP, slower;
- condensed: the states eliminated and the dense QP solved by ``qp_solver``
  (solvers/condensed_qp_step.py), for move blocking (held thrusts would be equality boxes,
  which an interior point handles badly: HPIPM took 50 iterations without converging) and
  ``qp_structure: condensed``.

Why sparse by default: the condensed QP eliminates the states, so its Hessian carries the
products A_{N-1} ... A_0 of the linearised dynamics. Along a plan of an open-loop-unstable
vehicle (light yaw inertia, where the Munk moment (m11 - m22) u v destabilises sway-yaw)
those products grow like e^{lambda t} over the 15 s horizon, the condensed Hessian's
condition number reaches 1e17 and the dense QP solvers fail on most steps (measured:
BlueROV2 literature parameters on a lawnmower in a current, 181 of 300 steps fell back, the
vehicle left the path by 19 m RMS). The sparse QP keeps the states as variables, so its data
are the one-step Jacobians, bounded whatever the vehicle, and HPIPM's Riccati recursion
factorises it stably (same run: 0 fallbacks, 0.248 m RMS, against 0.254 m for IPOPT on the
same OCP). ``benchmarks/vehicle_sweep.py`` checks this on random vehicles.
"""

from __future__ import annotations

import time

import numpy as np

from auvmpc.ocp.multiple_shooting import NX, Iterate, MultipleShootingProgram, Solution
from auvmpc.ocp.stage_qp import stage_qp
from auvmpc.solvers.casadi_qp_step import CasadiQpStep
from auvmpc.solvers.compiled_qp_step import compiled_qp_step
from auvmpc.solvers.condensed_qp_step import CondensedQpStep
from auvmpc.solvers.hpipm import NOT_FINITE, SOLVED, hpipm_settings, slack_scale

__all__ = ["RealTimeIteration"]


class RealTimeIteration:
    """Gauss-Newton SQP steps on a :class:`MultipleShootingProgram`, each one stage QP."""

    def __init__(
        self,
        program: MultipleShootingProgram,
        condensed: bool = False,
        compiled: bool | None = None,
    ) -> None:
        """``condensed``: solve each QP condensed, by the configuration's ``qp_solver``
        (module docstring). ``compiled`` (sparse only): None (default) compiles where a C
        compiler is present and the configuration's ``jit`` allows, False never (CasADi
        evaluates the same QP), True requires it (RuntimeError without)."""
        self.program = program
        N, n, slots = program.horizon, program.n_thrusters, program.n_slots
        qp = stage_qp(program)
        config = program.config
        limit = config.qp_iteration_limit
        step = None
        if condensed:
            step = CondensedQpStep(qp, N, slots, config.qp_solver, limit, config.jit)
        elif compiled or (compiled is None and config.jit):
            step = compiled_qp_step(qp, N, n, slots, hpipm_settings(limit))
            if step is None and compiled:
                raise RuntimeError("no C compiler, or no HPIPM in the casadi wheel")
        self.compiled = step is not None and not condensed
        self._step = step if step is not None else CasadiQpStep(qp, N, n, slots, limit)
        movable = np.zeros(N)
        movable[program.move_steps] = 1.0
        weights = np.tile(program.ocp.stage_weight, (N, 1))
        weights[0] = 0.0  # X_0 is fixed: no cost
        self._movable, self._weights = movable, weights

    def reset(self) -> None:
        """Nothing to reset: the compiled step keeps HPIPM's last solution (its hot start),
        which the next sample's QP only starts from."""

    def solve(self, guess, sample, iterations: int, cold: bool, resimulate: bool | None = None):
        """``iterations`` SQP steps from ``guess``; on a cold start the states are re-simulated
        from x_hat under the new thrusts after each step (module docstring of nmpc), unless
        ``resimulate`` is False (the multiple-shooting update, as from a shifted solution)."""
        resimulate = cold if resimulate is None else resimulate
        program = self.program
        n, N = program.n_thrusters, program.horizon
        started = time.perf_counter()
        states = np.asarray(guess.states, dtype=float)  # (N + 1, nx)
        thrust = np.asarray(program.plan(guess), dtype=float)  # (N, n)
        used = sample.used.astype(float)
        fixed = (sample.state, sample.previous, sample.reference, self._weights,
                 sample.disturbance, sample.slots, used, self._movable,
                 sample.effectiveness)  # fmt: skip
        total, status, slack = 0, "not run", np.zeros(N)
        with np.errstate(over="ignore", invalid="ignore"):
            for sqp_step in range(iterations):
                previous = np.vstack([sample.previous, thrust])
                hot_start = sqp_step == 0 and not cold
                code, used_iterations = self._step(
                    states, previous, thrust, *fixed, hot_start=hot_start
                )
                total += used_iterations
                if code == NOT_FINITE:
                    # A diverged iterate: never hand NaN to the solver.
                    return Solution(
                        None, total, time.perf_counter() - started, "non-finite QP data"
                    )
                status = self._step.describe(code)
                dz, dv = self._step.dz, self._step.dv
                if code != SOLVED or not (np.isfinite(dz).all() and np.isfinite(dv).all()):
                    return Solution(None, total, time.perf_counter() - started, status)
                thrust = thrust + dz[:N, NX:] + dv[:, :n]  # dF_k = dp_k + w_k (stage_qp)
                if program.n_slots:
                    slack = dv[:, n] / slack_scale(program.ocp.slack_penalty)
                if resimulate:
                    disturbance = np.tile(sample.disturbance[:, None], (1, N))
                    rolled = program.rollout(
                        sample.state, thrust.T, disturbance, sample.effectiveness
                    )
                    states = np.vstack([sample.state, np.asarray(rolled).T])
                else:
                    states = states + dz[:, :NX]  # z_k = [dX_k; dp_k]
                if not np.all(np.isfinite(states)):
                    return Solution(None, total, time.perf_counter() - started, "non-finite states")
        slacks = np.zeros((N, program.n_slots))
        if program.n_slots:
            slacks[:, 0] = np.maximum(slack, 0.0)
        iterate = Iterate(states.copy(), thrust[program.move_steps].copy(), slacks)
        return Solution(iterate, total, time.perf_counter() - started, status)
