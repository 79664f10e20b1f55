"""Offset-free MPC: an extended Kalman filter on the state augmented with an unknown force.

The augmented state is ``[x, y, psi, u, v, r, X, Y, N]``: the vehicle state plus a
disturbance fixed in the WORLD frame (force X, Y in N, yaw moment N in N m). A
current is constant in the world frame (paper-model.md section 6), so it is a
constant to the filter even while the vehicle turns; model errors (inertia,
damping) are absorbed as an equivalent slowly varying force. The disturbance is a
random walk, so a slowly varying current is tracked too. Every MPC feeds the
estimate into its prediction, which removes the steady-state offset
(Maeder, Borrelli, Morari 2009, "Linear offset-free model predictive control").
"""

from __future__ import annotations

import math
from typing import Annotated

import casadi as ca
import numpy as np
from pydantic import Field

from auvmpc.config import StrictModel
from auvmpc.integrators import rk4
from auvmpc.vehicle import VehicleParams, body_from_world, dynamics

__all__ = [
    "AugmentedEkf",
    "DisturbanceObserver",
    "ObserverConfig",
    "world_disturbance_dynamics",
]

NX, ND = 6, 3
Positive = Annotated[float, Field(gt=0)]


class ObserverConfig(StrictModel):
    """Noise levels the filter assumes (tuning knobs, not the simulated noise)."""

    measurement_std: tuple[Positive, Positive, Positive, Positive, Positive, Positive] = Field(
        default=(0.01, 0.01, 0.005, 0.01, 0.01, 0.005),
        description="assumed sensor noise of [x, y, psi, u, v, r] (m, rad, m/s, rad/s)",
    )
    state_process_std: tuple[Positive, Positive, Positive, Positive, Positive, Positive] = Field(
        default=(1e-3, 1e-3, 1e-3, 5e-3, 5e-3, 5e-3),
        description="model error per sample on [x, y, psi, u, v, r]",
    )
    disturbance_rate_std: tuple[Positive, Positive, Positive] = Field(
        default=(1.0, 1.0, 0.05),
        description="random-walk intensity of the world force X, Y (N/sqrt(s)) and moment "
        "N (N m/sqrt(s)): larger tracks faster, smaller is smoother",
    )
    initial_disturbance_std: tuple[Positive, Positive, Positive] = Field(
        default=(20.0, 20.0, 2.0), description="prior uncertainty of X, Y (N) and N (N m)"
    )


def world_disturbance_dynamics(model: VehicleParams):
    """x' = f(x, F, d_world): the model with a world-frame force and moment added."""

    def f(state, thrust, disturbance_world):
        d_u, d_v = body_from_world(disturbance_world, state[2])
        return dynamics(state, thrust, model, (d_u, d_v, disturbance_world[2]))

    return f


class AugmentedEkf:
    """Extended Kalman filter for a state augmented with a random-walk disturbance.

    ``step`` is a CasADi function (z, u) -> (z_next, dz_next/dz) over one sample; the
    first ``measured`` entries of z are measured directly (H = [I 0]).
    """

    def __init__(
        self,
        step: ca.Function,
        measured: int,
        process_covariance: np.ndarray,
        measurement_covariance: np.ndarray,
        prior_covariance: np.ndarray,
        angle_index: int | None = None,
    ) -> None:
        self._step = step
        self._measured = measured
        self._process = process_covariance
        self._measurement = measurement_covariance
        self._prior = prior_covariance
        self._angle_index = angle_index
        self.reset(np.zeros(prior_covariance.shape[0]))

    def reset(self, initial_estimate: np.ndarray) -> None:
        self.estimate = np.array(initial_estimate, dtype=float)
        self.covariance = self._prior.copy()
        self._initialised = False

    def correct(self, measurement: np.ndarray) -> np.ndarray:
        """Fuse a measurement of the first ``measured`` states; returns the estimate."""
        m = self._measured
        measured = np.asarray(measurement, dtype=float)
        if not self._initialised:
            # First sample: the measured part is what we measure; the rest keeps its prior.
            self.estimate[:m] = measured
            self._initialised = True
        innovation = measured - self.estimate[:m]
        if self._angle_index is not None:
            i = self._angle_index
            innovation[i] = math.remainder(innovation[i], 2.0 * math.pi)
        P = self.covariance
        S = P[:m, :m] + self._measurement
        gain = np.linalg.solve(S, P[:m, :]).T  # P H' S^-1 with H = [I 0]
        self.estimate = self.estimate + gain @ innovation
        self.covariance = P - gain @ P[:m, :]
        return self.estimate.copy()

    def predict(self, applied_input: np.ndarray) -> None:
        """Propagate over one sample with the input actually applied."""
        next_estimate, jacobian = self._step(self.estimate, applied_input)
        A = np.asarray(jacobian)
        self.estimate = np.asarray(next_estimate).ravel()
        self.covariance = A @ self.covariance @ A.T + self._process


class DisturbanceObserver:
    """EKF on [x; d_world] for the horizontal model; exact Jacobians from CasADi."""

    def __init__(
        self, model: VehicleParams, sample_time: float, config: ObserverConfig, substeps: int = 1
    ) -> None:
        augmented = ca.SX.sym("z", NX + ND)
        thrust = ca.SX.sym("F", model.n_thrusters)
        f = world_disturbance_dynamics(model)
        next_state = rk4(
            lambda x, u: f(x, u, augmented[NX:]), augmented[:NX], thrust, sample_time, substeps
        )
        next_augmented = ca.vertcat(next_state, augmented[NX:])
        step = ca.Function(
            "observer_step",
            [augmented, thrust],
            [next_augmented, ca.jacobian(next_augmented, augmented)],
        )
        rate = np.array(config.disturbance_rate_std) ** 2 * sample_time
        measurement = np.square(config.measurement_std)
        self._filter = AugmentedEkf(
            step,
            NX,
            np.diag(np.concatenate([np.square(config.state_process_std), rate])),
            np.diag(measurement),
            np.diag(np.concatenate([measurement, np.square(config.initial_disturbance_std)])),
            angle_index=2,
        )

    def reset(self, initial_state: np.ndarray) -> None:
        self._filter.reset(np.concatenate([np.asarray(initial_state, float), np.zeros(ND)]))

    @property
    def disturbance_world(self) -> np.ndarray:
        """Current estimate of the world force [X, Y, N]."""
        return self._filter.estimate[NX:].copy()

    def correct(self, measured_state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fuse a measurement; returns (state estimate (6,), disturbance estimate (3,))."""
        estimate = self._filter.correct(measured_state)
        return estimate[:NX], estimate[NX:]

    def predict(self, applied_thrust: np.ndarray) -> None:
        """Propagate the estimate over one sample with the thrust actually applied."""
        self._filter.predict(applied_thrust)
