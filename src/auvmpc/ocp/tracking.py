"""The tracking optimal control problem, stated once (paper-model.md section 4).

    min  sum_{n=1}^{N-1} |x_n - r_n|_Q^2 + |x_N - r_N|_S^2 + sum_{n=0}^{N-1} |F_n|_R^2
         (or R on F_n - F_{n-1})  +  penalty * slack of the soft constraints
    s.t. the vehicle's sampled model, F_min <= F_n <= F_max, |F_n - F_{n-1}| <= rate * Te,
         the thrust held between the move steps, obstacle keep-out discs (soft, exact penalty).

:class:`TrackingOcp` holds every number of that statement. Every back end (the paper's
frozen-SDC MPC, LTV-MPC, real-time and full NMPC, the do-mpc yardstick, the depth MPC) and
every QP form (condensed, sparse) reads it, so a weight or a limit is stated in one place.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from auvmpc.models.actuators import ActuatorLimits

__all__ = ["SLACK_QUADRATIC_WEIGHT", "ActuatorLimits", "ThrustPenalty", "TrackingOcp"]

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
        cls, config: Any, n_inputs: int, limits: ActuatorLimits, **extra
    ) -> TrackingOcp:
        """From a controller configuration (horizontal or depth) with Q, S, R, horizons."""
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
            **extra,
        )


def _frozen(values) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.setflags(write=False)
    return array
