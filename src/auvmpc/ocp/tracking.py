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
from typing import Any

import numpy as np
import scipy.linalg

from auvmpc.models.actuators import ActuatorLimits

__all__ = [
    "SLACK_QUADRATIC_WEIGHT",
    "ActuatorLimits",
    "ThrustPenalty",
    "TrackingOcp",
    "internal_thrust_weight",
]

# The soft constraints' cost is penalty * s + SLACK_QUADRATIC_WEIGHT * s^2: the linear part
# makes the penalty exact, the quadratic part makes every QP definite in the slack.
SLACK_QUADRATIC_WEIGHT = 1.0


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
    # (nu, nu) Pi diag(R) Pi: the weight of the internal thrust with the increment penalty
    # (module docstring, internal_thrust_weight); None where it has none (no null space, or R
    # on the thrust itself, which weights it already)
    internal_weight: np.ndarray | None = None

    @property
    def n_inputs(self) -> int:
        return len(self.input_weight)

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
        penalty = ThrustPenalty(config.thrust_penalty)
        internal = None
        if allocation is not None:
            internal = internal_thrust_weight(allocation, weights, penalty)
        return cls(
            sample_time=float(config.sample_time),
            horizon=int(config.prediction_horizon),
            move_steps=tuple(config.move_schedule()),
            stage_weight=_frozen(config.Q),
            terminal_weight=_frozen(config.S),
            input_weight=_frozen(weights),
            penalty=penalty,
            limits=limits,
            internal_weight=internal,
            **extra,
        )


def internal_thrust_weight(
    allocation: np.ndarray, input_weight: np.ndarray, penalty: ThrustPenalty
) -> np.ndarray | None:
    """Pi diag(R) Pi, Pi the orthogonal projector onto the null space of ``allocation`` (the
    thrusts that make no force or moment, module docstring): what the increment penalty adds
    on the thrust itself. None with the absolute penalty (R weights all the thrust) or where
    every thrust pushes the vehicle (no null space)."""
    null = scipy.linalg.null_space(np.asarray(allocation, dtype=float))
    if penalty is ThrustPenalty.ABSOLUTE or null.shape[1] == 0:
        return None
    projector = null @ null.T
    weight = projector @ np.diag(np.asarray(input_weight, dtype=float)) @ projector
    return _frozen(0.5 * (weight + weight.T))  # symmetric to the bit


def _frozen(values) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.setflags(write=False)
    return array
