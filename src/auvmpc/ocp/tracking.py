"""The tracking optimal control problem, stated once (paper-model.md section 4).

    min  sum_{n=1}^{N-1} |x_n - r_n|_Q^2 + |x_N - r_N|_S^2 + sum_{n=0}^{N-1} |F_n|_R^2
         (or R on F_n - F_{n-1} plus R on the internal thrust Pi F_n)
         +  penalty * slack of the soft constraints
    s.t. the vehicle's sampled model, F_min <= F_n <= F_max, |F_n - F_{n-1}| <= rate * Te,
         the thrust held between the move steps, obstacle keep-out discs (soft, exact penalty).

:class:`TrackingOcp` holds every number of that statement. Every back end (the paper's
frozen-SDC MPC, LTV-MPC, real-time and full NMPC, the do-mpc yardstick, the depth MPC) and
every QP form (condensed, sparse) reads it, so a weight or a limit is stated in one place.

The internal thrust. Where there are more thrusters than the three planar axes (BlueROV2
Heavy: four at 45 degrees), a part of the thrust pushes the thrusters against each other:
Pi F, Pi the orthogonal projector onto the null space of the allocation T (tau = T F), makes
no force or moment. With R on the increment alone nothing in the problem says what that part
should be: the optimum keeps whatever the previous command held, so a perturbation of it is
never corrected (a neutral mode of the closed loop), and in the QP it is the direction of
least curvature (2 R on the horizon's constant internal thrust, R ~ 1e-6 on a 40 kg vehicle),
the one an interior point resolves last. Measured on a random vehicle (docs/onboard.md): the
C controller on aarch64 and the Python one drifted apart along it by 3.6e-6 N, all of it
internal thrust, and tighter QP tolerances made it worse (1e-8: 5e-6 N). So the increment
penalty also weights the internal thrust itself, as the absolute penalty already does:
|Pi F_n|_R^2, which costs nothing the vehicle needs (no force or moment) and decides the part
the increment left open.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from functools import cached_property
from typing import Any

import casadi as ca
import numpy as np

from auvmpc.models.actuators import ActuatorLimits

__all__ = ["SLACK_QUADRATIC_WEIGHT", "ActuatorLimits", "ThrustPenalty", "TrackingOcp"]

# The soft constraints' cost is penalty * s + SLACK_QUADRATIC_WEIGHT * s^2: the linear part
# makes the penalty exact, the quadratic part makes every QP definite in the slack.
SLACK_QUADRATIC_WEIGHT = 1.0
# The internal thrust's projector is damped by this share of the largest eigenvalue of T T'
# (TrackingOcp.internal_weight), so that it is defined, and stays a projector to that order,
# whatever the thrusters' effectiveness.
_DAMPING = 1e-9


class ThrustPenalty(StrEnum):
    """What R weights: the absolute thrust (paper's energy term) or its change per sample."""

    ABSOLUTE = "absolute"
    INCREMENT = "increment"


@dataclass(frozen=True, eq=False)
class TrackingOcp:
    """Every number of the tracking problem (module docstring); arrays are read-only."""

    sample_time: float  # Te (s)
    horizon: int  # N (samples)
    move_steps: tuple[int, ...]  # samples at which the thrust may change, from 0
    stage_weight: np.ndarray  # Q (nx,), by the model's state order
    terminal_weight: np.ndarray  # S (nx,)
    input_weight: np.ndarray  # R (nu,)
    penalty: ThrustPenalty
    limits: ActuatorLimits  # force box and rate (N/s, independent of Te)
    slack_penalty: float  # exact-penalty weight of the soft constraints (per m)
    keep_out_extra: float = 0.0  # added to every obstacle radius: vehicle radius + margin (m)
    # T (3, nu), tau = T F: where given, with the increment penalty and more thrusters than
    # T's rank, R weights the internal thrust too (module docstring, internal_weight)
    allocation: np.ndarray | None = None

    @property
    def n_inputs(self) -> int:
        return len(self.input_weight)

    @cached_property
    def weights_internal_thrust(self) -> bool:
        """Whether R weights the internal thrust too (module docstring): the increment
        penalty, on thrusters some of whose thrust makes no force or moment when healthy."""
        return (
            self.penalty is ThrustPenalty.INCREMENT
            and self.allocation is not None
            and np.linalg.matrix_rank(self.allocation) < self.n_inputs
        )

    def internal_weight(self, effectiveness):
        """M(e) = Pi' diag(R) Pi (nu, nu), the weight of the internal thrust Pi F: Pi the
        projector onto the thrusts the acting allocation A = T diag(e) maps to no force or
        moment, I - A' (A A' + lambda I)^-1 A, lambda = _DAMPING x the largest eigenvalue of
        T T' (the projector to that order where A keeps T's rank; where a fault takes a rank,
        the thrust that direction can no longer make is weighted too, and a dead thruster's
        command with it). ``effectiveness`` (nu,): CasADi symbols (the problem's runtime
        input) or numbers (a NumPy array back)."""
        numeric = isinstance(effectiveness, np.ndarray | list | tuple)
        e = ca.DM(np.asarray(effectiveness, dtype=float)) if numeric else effectiveness
        T = ca.DM(self.allocation)
        damping = _DAMPING * float(np.linalg.eigvalsh(self.allocation @ self.allocation.T)[-1])
        acting = T @ ca.diag(e)
        gram = acting @ acting.T + damping * ca.DM.eye(T.shape[0])
        projector = ca.DM.eye(self.n_inputs) - acting.T @ ca.solve(gram, acting)
        weight = projector.T @ ca.diag(ca.DM(self.input_weight)) @ projector
        return np.array(weight) if numeric else weight

    @property
    def n_moves(self) -> int:
        return len(self.move_steps)

    @property
    def every_move_free(self) -> bool:
        return self.n_moves == self.horizon

    @property
    def input_lower(self) -> np.ndarray:
        return np.broadcast_to(self.limits.lower, (self.n_inputs,)).astype(float)

    @property
    def input_upper(self) -> np.ndarray:
        return np.broadcast_to(self.limits.upper, (self.n_inputs,)).astype(float)

    @property
    def max_move(self) -> np.ndarray:
        """Largest thrust change in one sample, per input (N)."""
        return np.broadcast_to(self.limits.rate * self.sample_time, (self.n_inputs,)).astype(float)

    @property
    def held(self) -> np.ndarray:
        """held[n]: index of the move whose thrust acts at step n."""
        return np.searchsorted(self.move_steps, np.arange(self.horizon), side="right") - 1

    def stage_weights(self) -> np.ndarray:
        """(N, nx): the weight of x_n for n = 1..N (Q, then S on the last)."""
        return np.vstack([np.tile(self.stage_weight, (self.horizon - 1, 1)), self.terminal_weight])

    @classmethod
    def from_config(
        cls,
        config: Any,
        n_inputs: int,
        limits: ActuatorLimits,
        allocation: np.ndarray | None = None,
        **extra,
    ) -> TrackingOcp:
        """From a controller configuration (horizontal or depth) with Q, S, R, horizons;
        ``allocation``: T (tau = T F), for the internal thrust's weight (none without)."""
        weights = np.broadcast_to(np.asarray(config.R, dtype=float), (n_inputs,))
        return cls(
            sample_time=float(config.sample_time),
            horizon=int(config.prediction_horizon),
            move_steps=tuple(config.move_schedule()),
            stage_weight=_frozen(config.Q),
            terminal_weight=_frozen(config.S),
            input_weight=_frozen(weights),
            penalty=ThrustPenalty(config.thrust_penalty),
            limits=limits,
            allocation=None if allocation is None else _frozen(allocation),
            **extra,
        )


def _frozen(values) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.setflags(write=False)
    return array
