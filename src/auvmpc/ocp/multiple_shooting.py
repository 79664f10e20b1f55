"""The nonlinear tracking program in multiple-shooting form, built once per configuration.

The decision variables are the states X_0..X_ny and the thrusts at the move steps; the thrust
is held between moves. A keep-out disc is an exact constraint in distance form with a slack
in metres; obstacles fill ``MAX_OBSTACLES`` slots (the nearest ones when there are more) and
an empty slot's rows have no lower bound, so the program is built once, as expanded SX, with
all that changes between samples passed as parameters and bounds. IPOPT (solvers/ipopt.py)
and the real-time iterations (solvers/real_time_iteration.py) solve it.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import casadi as ca
import numpy as np

from auvmpc.models.discrete import horizontal_model
from auvmpc.models.layout import HORIZONTAL, PLANAR_FORCE, Layout
from auvmpc.models.vehicle import VehicleParams
from auvmpc.ocp.tracking import SLACK_QUADRATIC_WEIGHT, ThrustPenalty

if TYPE_CHECKING:  # read, never imported at run time: ocp sits below controllers
    from auvmpc.controllers.config import ControllerConfig
    from auvmpc.environment.obstacles import ObstacleState

__all__ = ["MAX_OBSTACLES", "Iterate", "MultipleShootingProgram", "Sample", "Solution"]

NX, ND = HORIZONTAL.size, PLANAR_FORCE.size  # state [x, y, psi, u, v, r], force [X, Y, N]
# Obstacle slots in the program (built once): the nearest this many visible obstacles count.
MAX_OBSTACLES = 8
# Per slot: centre x, y now (m), velocity x, y (m/s), reach = radius + vehicle radius + margin.
SLOT = Layout(names=("x", "y", "vx", "vy", "reach"))
SLOT_FIELDS = SLOT.size
SLOT_CENTRE, SLOT_VELOCITY, SLOT_REACH = SLOT.position, SLOT.span("vx", "vy"), SLOT.index("reach")
_POSITION = HORIZONTAL.position
# Smooths the distance at an obstacle's centre, sqrt(d^2 + eps) (m^2): differentiable
# everywhere, and the constraint moves by at most sqrt(eps) = 1 mm (only at the centre).
DISTANCE_SMOOTHING_M2 = 1e-6
# Where an unused obstacle slot is parked, from the vehicle (m); its rows are unbounded anyway.
_PARKED_OBSTACLE_M = 1e4


class Nlp(NamedTuple):
    """The nonlinear program: variables w, parameters p, cost, constraint rows g."""

    w: ca.SX
    p: ca.SX
    cost: ca.SX
    g: ca.SX


@dataclass
class Iterate:
    """A primal point of the program: the plan and its predicted states."""

    states: np.ndarray  # (ny + 1, NX): X_0..X_ny
    thrust: np.ndarray  # (nc, n): the thrust set at each move step
    slack: np.ndarray  # (ny, slots): s_{o,n} for n = 1..ny


@dataclass(frozen=True)
class Sample:
    """What one sample's program depends on besides the iterate."""

    state: np.ndarray  # (NX,) X_0
    previous: np.ndarray  # (n,) F_{-1}
    reference: np.ndarray  # (ny + 1, NX) aligned
    disturbance: np.ndarray  # (ND,) world force and moment [X, Y, N]
    slots: np.ndarray  # (slots, 5) obstacle data, parked where unused
    used: np.ndarray  # (slots,) bool
    effectiveness: np.ndarray  # (n,) each thruster's share of its command that acts


@dataclass
class Solution:
    iterate: Iterate | None  # None: no usable solution
    iterations: int
    solve_time_s: float
    status: str
    resume: Iterate | None = None  # an unfinished solve's last point, worth continuing from


class MultipleShootingProgram:
    """The NLP ``min J(w, p) s.t. lbg <= g(w, p) <= ubg, lbw <= w <= ubw``, built once.

    ``w`` stacks the states X_0..X_ny (NX each), the thrusts at the move steps (n each) and one
    slack per predicted step and obstacle slot. ``p`` stacks the last applied thrust (n), the
    aligned reference rows 1..ny (NX each), the world-frame force and moment (ND), the
    obstacle slots (5 each) and the thrusters' effectiveness (n: 1 healthy, 0 dead), so a
    fault changes a parameter, not the program. ``g`` stacks the shooting gaps
    X_{n+1} - RK4(X_n, F_n) (NX per step), the thrust changes at the move steps (n each) and,
    per step and slot, the distance to the obstacle minus its reach plus the slack.
    """

    def __init__(
        self, model: VehicleParams, config: ControllerConfig, n_slots: int = MAX_OBSTACLES
    ):
        config = config.for_vehicle(model)
        n, ny = model.n_thrusters, config.prediction_horizon
        self.model, self.config = model, config
        self.n_thrusters, self.horizon, self.n_slots = n, ny, n_slots
        self.ocp = ocp = config.ocp(model)
        self.sample_time = ocp.sample_time
        self.move_steps = np.array(ocp.move_steps)
        self.n_moves = ocp.n_moves
        self.held = ocp.held  # held[i]: the move whose thrust acts at step i
        # Per stacked thrust change (move by move): the largest change in one sample (N).
        self.max_change = np.tile(ocp.max_move, self.n_moves)

        sampled = horizontal_model(model, config.sample_time, config.model_substeps, config.jit)
        self.step = sampled.step
        self.acting_step = sampled.acting_step
        self._sampled = sampled
        self.rollout = sampled.rollout(ny)

        self.n_w = NX * (ny + 1) + n * self.n_moves + n_slots * ny
        self.n_gaps, self.n_changes = NX * ny, n * self.n_moves

    @property
    def numeric_step(self) -> Callable[..., np.ndarray]:
        """The step on NumPy values (compiled on first use: DiscreteModel.numeric_step)."""
        return self._sampled.numeric_step

    @functools.cached_property
    def linearised_steps(self) -> ca.Function:
        """The step with its Jacobians, evaluated at every shooting node in one call."""
        return self._sampled.linearised_nodes(self.horizon)

    @functools.cached_property
    def nlp(self) -> Nlp:
        """The program as expanded SX, built on first use: IPOPT needs it, the real-time
        iterations do not (~25 ms a controller on paper-obstacles)."""
        config, ocp = self.config, self.ocp
        n, ny, n_slots = self.n_thrusters, self.horizon, self.n_slots
        w = ca.SX.sym("w", self.n_w)
        X = ca.reshape(w[: NX * (ny + 1)], NX, ny + 1)  # column i: X_i
        U = ca.reshape(w[NX * (ny + 1) : NX * (ny + 1) + n * self.n_moves], n, self.n_moves)
        # column i: the slacks of step i + 1
        slack = ca.reshape(w[NX * (ny + 1) + n * self.n_moves :], n_slots, ny)
        previous = ca.SX.sym("F_prev", n)
        reference = ca.SX.sym("ref", NX, ny)  # column i: r_{i+1}
        disturbance = ca.SX.sym("d_world", ND)
        slots = ca.SX.sym("obstacles", SLOT_FIELDS, n_slots)
        effectiveness = ca.SX.sym("effectiveness", n)
        p = ca.vertcat(previous, ca.vec(reference), disturbance, ca.vec(slots), effectiveness)

        thrust_at = [U[:, int(j)] for j in self.held]
        gaps = [
            X[:, i + 1] - self.step(X[:, i], thrust_at[i], disturbance, effectiveness)
            for i in range(ny)
        ]
        changes = [U[:, 0] - previous] + [U[:, j] - U[:, j - 1] for j in range(1, self.n_moves)]
        clearances = []
        for i in range(1, ny + 1):
            for o in range(n_slots):
                centre = slots[SLOT_CENTRE, o] + (i * config.sample_time) * slots[SLOT_VELOCITY, o]
                distance = ca.sqrt(ca.sumsqr(X[_POSITION, i] - centre) + DISTANCE_SMOOTHING_M2)
                clearances.append(distance - slots[SLOT_REACH, o] + slack[o, i - 1])
        g = ca.vertcat(*gaps, *changes, *clearances)

        Q, S, R = np.diag(ocp.stage_weight), np.diag(ocp.terminal_weight), np.diag(ocp.input_weight)
        cost = 0
        for i in range(1, ny + 1):
            error = X[:, i] - reference[:, i - 1]
            cost += ca.bilin(S if i == ny else Q, error, error)
        if ocp.penalty is ThrustPenalty.ABSOLUTE:
            cost += sum(ca.bilin(R, F, F) for F in thrust_at)
        else:
            cost += sum(ca.bilin(R, dF, dF) for dF in changes)
            if ocp.weights_internal_thrust:  # the internal thrust (ocp/tracking.py)
                internal = ocp.internal_weight(effectiveness)
                cost += sum(ca.bilin(internal, F, F) for F in thrust_at)
        cost += ocp.slack_penalty * ca.sum1(ca.vec(slack))
        cost += SLACK_QUADRATIC_WEIGHT * ca.sumsqr(slack)
        return Nlp(w, p, cost, g)

    # -- packing -------------------------------------------------------------------------
    def pack(self, iterate: Iterate) -> np.ndarray:
        """w from an iterate (the states column by column, as ``w`` stacks them)."""
        return np.concatenate(
            [iterate.states.ravel(), iterate.thrust.ravel(), iterate.slack.ravel()]
        )

    def unpack(self, w: np.ndarray) -> Iterate:
        n, ny = self.n_thrusters, self.horizon
        states_end = NX * (ny + 1)
        thrust_end = states_end + n * self.n_moves
        return Iterate(
            states=w[:states_end].reshape(ny + 1, NX),
            thrust=w[states_end:thrust_end].reshape(self.n_moves, n),
            slack=w[thrust_end:].reshape(ny, self.n_slots),
        )

    def parameters(self, sample: Sample) -> np.ndarray:
        return np.concatenate(
            [
                sample.previous,
                sample.reference[1:].ravel(),
                sample.disturbance,
                sample.slots.ravel(),
                sample.effectiveness,
            ]
        )

    def bounds(self, sample: Sample) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """lbw, ubw, lbg, ubg: X_0 fixed, thrust box, rate box, obstacles of the used slots."""
        lbw, ubw = np.full(self.n_w, -np.inf), np.full(self.n_w, np.inf)
        lbw[:NX] = ubw[:NX] = sample.state
        thrust = slice(NX * (self.horizon + 1), NX * (self.horizon + 1) + self.n_changes)
        lbw[thrust] = np.tile(self.ocp.input_lower, self.n_moves)
        ubw[thrust] = np.tile(self.ocp.input_upper, self.n_moves)
        lbw[thrust.stop :] = 0.0
        lbg, ubg = np.zeros(self.n_gaps), np.zeros(self.n_gaps)
        obstacle_lower = np.where(np.tile(sample.used, self.horizon), 0.0, -np.inf)
        lbg = np.concatenate([lbg, -self.max_change, obstacle_lower])
        ubg = np.concatenate([ubg, self.max_change, np.full(obstacle_lower.size, np.inf)])
        return lbw, ubw, lbg, ubg

    # -- numeric pieces ------------------------------------------------------------------
    def sample(
        self,
        state: np.ndarray,
        previous: np.ndarray,
        reference: np.ndarray,
        disturbance: np.ndarray,
        obstacles: tuple[ObstacleState, ...],
        effectiveness: np.ndarray | None = None,
    ) -> Sample:
        """The sample's data; the nearest obstacles fill the slots, the rest are parked;
        ``effectiveness`` None: every thruster healthy."""
        if effectiveness is None:
            effectiveness = np.ones(self.n_thrusters)
        slots = np.zeros((self.n_slots, SLOT_FIELDS))
        slots[:, SLOT_CENTRE] = state[_POSITION] + _PARKED_OBSTACLE_M
        used = np.zeros(self.n_slots, dtype=bool)
        nearest = sorted(obstacles, key=lambda o: math.dist(o.center, state[HORIZONTAL.position]))
        extra = self.ocp.keep_out_extra
        steps = self.sample_time * np.arange(1, self.horizon + 1)
        for o, obstacle in enumerate(nearest[: self.n_slots]):
            # A slot holds one radius for the whole horizon: a tracked obstacle's is its
            # largest predicted one (the horizon's end; a per-step radius would need a slot
            # field, which changes the compiled QP layout).
            radius = obstacle.horizon_radius(steps)
            slots[o] = [*obstacle.center, *obstacle.velocity, radius + extra]
            used[o] = True
        return Sample(state, previous, reference, disturbance, slots, used, effectiveness)

    def plan(self, iterate: Iterate) -> np.ndarray:
        """Thrust at every step of the horizon (ny, n)."""
        return iterate.thrust[self.held]

    def shifted(self, iterate: Iterate, sample: Sample) -> Iterate:
        """The iterate one sample on: states, plan and slacks advanced by one step.

        The new terminal state is the model's step from the old one under the last thrust
        (with the sample's disturbance and effectiveness); the thrusts at the move steps are
        read from the plan shifted by one sample.
        """
        plan = self.plan(iterate)
        terminal = self.numeric_step(
            iterate.states[-1], plan[-1], sample.disturbance, sample.effectiveness
        )
        return Iterate(
            states=np.concatenate([iterate.states[1:], terminal[None]]),
            thrust=np.concatenate([plan[1:], plan[-1:]])[self.move_steps],
            slack=np.concatenate([iterate.slack[1:], iterate.slack[-1:]]),
        )

    def reference_guess(self, sample: Sample) -> Iterate:
        """A guess without a previous solution: the states on the reference (multiple
        shooting need not start from a trajectory), the last thrust held, no slack."""
        return Iterate(
            states=np.vstack([sample.state, sample.reference[1:]]),
            thrust=np.tile(sample.previous, (self.n_moves, 1)),
            slack=np.zeros((self.horizon, self.n_slots)),
        )

    def resting_guess(self, sample: Sample) -> Iterate:
        """A guess that stays where the vehicle is: every state the measured position and
        heading at rest, the last thrust held, no slack (outside every disc the vehicle is
        outside of, where the reference may pass through one)."""
        rest = np.array(sample.state, dtype=float)
        rest[HORIZONTAL.body_velocity] = 0.0
        rest[HORIZONTAL.index("r")] = 0.0
        states = np.tile(rest, (self.horizon + 1, 1))
        states[0] = sample.state
        return Iterate(
            states=states,
            thrust=np.tile(sample.previous, (self.n_moves, 1)),
            slack=np.zeros((self.horizon, self.n_slots)),
        )

    def clearances(self, states: np.ndarray, sample: Sample) -> tuple[np.ndarray, np.ndarray]:
        """Distance minus reach (ny, slots) at steps 1..ny, and its gradient in p (ny, slots, 2)."""
        steps = self.sample_time * np.arange(1, self.horizon + 1)
        slots = sample.slots
        centres = slots[None, :, SLOT_CENTRE] + steps[:, None, None] * slots[None, :, SLOT_VELOCITY]
        offset = states[1:, None, _POSITION] - centres
        distance = np.sqrt(np.einsum("nok,nok->no", offset, offset) + DISTANCE_SMOOTHING_M2)
        return distance - slots[None, :, SLOT_REACH], offset / distance[:, :, None]
