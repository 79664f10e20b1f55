"""Offset-free MPC: an extended Kalman filter on the state augmented with an unknown force.

The augmented state is ``[x, y, psi, u, v, r, X, Y, N]``: the vehicle state plus a
disturbance fixed in the WORLD frame (force X, Y in N, yaw moment N in N m). A
current is constant in the world frame (paper-model.md section 6), so it is a
constant to the filter even while the vehicle turns; model errors (inertia,
damping) are absorbed as an equivalent slowly varying force. The disturbance is a
random walk, so a slowly varying current is tracked too. Every MPC feeds the
estimate into its prediction, which removes the steady-state offset
(Maeder, Borrelli, Morari 2009, "Linear offset-free model predictive control").

The covariance stays a covariance for any run length: the measurement update is in
Joseph form, P = (I - K H) P (I - K H)' + K R K' (Bucy and Joseph 1968; Simon 2006,
"Optimal State Estimation", sec. 5.1), which keeps P symmetric positive semi-definite
under round-off where the short form P - K H P does not; P is symmetrised after every
update and its eigenvalues are held inside [floor, ceiling] (``covariance_bounds``).
Without this the antisymmetric round-off of the short form grew tenfold every ~40 s on
a 1500 s circle and P lost positive definiteness at 487 s (docs/model.md).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
from pydantic import Field

from auvmpc.config import Positive, StrictModel
from auvmpc.models.discrete import horizontal_model, world_disturbance_dynamics
from auvmpc.models.layout import (
    HORIZONTAL,
    OBSTACLE_TRACK,
    PLANAR_FORCE,
    PLANAR_FORCE_XY,
    PLANAR_MOMENT,
)
from auvmpc.models.vehicle import VehicleParams

__all__ = [
    "AugmentedEkf",
    "ConstantVelocityKalman",
    "DisturbanceObserver",
    "ObserverConfig",
    "condition_covariance",
    "covariance_bounds",
    "ekf_functions",
    "world_disturbance_dynamics",
]

# The state [x, y, psi, u, v, r] and the world force and moment [X, Y, N].
NX, ND = HORIZONTAL.size, PLANAR_FORCE.size


# Disturbance statistics as fractions of the thrust authority (ObserverConfig.for_vehicle).
_PRIOR_FORCE_FRACTION = 0.5
_PRIOR_MOMENT_FRACTION = 0.1
_RATE_FORCE_FRACTION = 0.025  # per sqrt(s)
_RATE_MOMENT_FRACTION = 0.003  # per sqrt(s)
# An underactuated vehicle answers a sideways force by turning (its reference crabs,
# ocp/underactuated_reference.py), so the force estimate steers its heading and must be
# slower than the heading loop. Measured on videoray-pro3 (generality benchmark, disturbed
# figure-eight): at 2.5 % the estimate and the heading swung together every sample
# (0.75 m max error), at 0.4 % 0.16 m.
_RATE_FORCE_FRACTION_UNDERACTUATED = 0.004  # per sqrt(s)


# Model error per sample on [x, y, psi, u, v, r] (m, rad, m/s, rad/s). The velocities' 0.02
# (was 0.005) admits that a real model is 20-35 % off: with 0.005 the filter trusted the model
# and put every mismatch into the disturbance force, whose estimate then swung with the
# vehicle's own motion. Measured (docs/tuning.md): a BlueROV2 campaign run with 20 % less yaw
# inertia spun at 0.005 and tracks within 0.054 m at 0.02; a 173 kg random vehicle went from
# lost to 0.063 m RMS; paper-disturbed with ltv-mpc-offset-free 0.0066 m either way.
STATE_PROCESS_STD = (1e-3, 1e-3, 1e-3, 2e-2, 2e-2, 2e-2)


class ObserverConfig(StrictModel):
    """Noise levels the filter assumes (tuning knobs, not the simulated noise)."""

    # One per horizontal state, one per entry of the world force and moment.
    measurement_std: tuple[(Positive,) * HORIZONTAL.size] = Field(
        default=(0.01, 0.01, 0.005, 0.01, 0.01, 0.005),
        description="assumed sensor noise of [x, y, psi, u, v, r] (m, rad, m/s, rad/s)",
    )
    state_process_std: tuple[(Positive,) * HORIZONTAL.size] = Field(
        default=STATE_PROCESS_STD,
        description="model error per sample on [x, y, psi, u, v, r]",
    )
    disturbance_rate_std: tuple[(Positive,) * PLANAR_FORCE.size] | None = Field(
        default=None,
        description="random-walk intensity of the world force X, Y (N/sqrt(s)) and moment "
        "N (N m/sqrt(s)): larger tracks faster, smaller is smoother; omitted: 2.5 % of the "
        "vehicle's planar thrust authority (0.4 % if it is underactuated) and 0.3 % of its yaw "
        "authority per sqrt(s), see docs/tuning.md",
    )
    initial_disturbance_std: tuple[(Positive,) * PLANAR_FORCE.size] | None = Field(
        default=None,
        description="prior uncertainty of X, Y (N) and N (N m); omitted: half the vehicle's "
        "planar thrust authority and a tenth of its yaw authority, see docs/tuning.md",
    )

    def for_vehicle(self, model: VehicleParams) -> ObserverConfig:
        """This tuning with the omitted disturbance statistics scaled to ``model``.

        The unknown force of a 15 N vehicle and of a 2 t ROV differ by two orders of
        magnitude, so a prior or random walk in newtons cannot transfer; a fraction of the
        thrust authority (VehicleParams.thrust_authority) does. The fractions keep the
        paper vehicle near its former fixed tuning (20 N, 1 N/sqrt(s); 2 N m,
        0.05 N m/sqrt(s)): 21 N, 1.06 N/sqrt(s); 1.8 N m, 0.054 N m/sqrt(s).
        """
        update = {}
        # The world-frame X and Y share one scale: the current turns with the heading.
        planar = float(max(model.thrust_authority[PLANAR_FORCE_XY]))
        yaw = float(model.thrust_authority[PLANAR_MOMENT])
        if self.initial_disturbance_std is None:
            update["initial_disturbance_std"] = (
                _PRIOR_FORCE_FRACTION * planar,
                _PRIOR_FORCE_FRACTION * planar,
                _PRIOR_MOMENT_FRACTION * yaw,
            )
        if self.disturbance_rate_std is None:
            force_rate = (
                _RATE_FORCE_FRACTION_UNDERACTUATED if model.underactuated else _RATE_FORCE_FRACTION
            ) * planar
            update["disturbance_rate_std"] = (force_rate, force_rate, _RATE_MOMENT_FRACTION * yaw)
        return self.model_copy(update=update) if update else self


# The smallest eigenvalue a covariance may have, as a fraction of the smallest noise
# variance the filter assumes: far below any real uncertainty, far above round-off.
COVARIANCE_FLOOR_FRACTION = 1e-6
# The largest, as a multiple of the largest prior variance: a filter that knows 100 times
# less than at the start carries no information, and beyond that only round-off grows.
COVARIANCE_CEILING_FACTOR = 100.0


def covariance_bounds(
    process_covariance: np.ndarray,
    measurement_covariance: np.ndarray,
    prior_covariance: np.ndarray,
) -> tuple[float, float]:
    """(floor, ceiling) for the eigenvalues of the filter covariance (see the constants)."""
    noise = np.concatenate([np.diag(process_covariance), np.diag(measurement_covariance)])
    floor = COVARIANCE_FLOOR_FRACTION * float(np.min(noise[noise > 0]))
    ceiling = COVARIANCE_CEILING_FACTOR * float(np.max(np.diag(prior_covariance)))
    return floor, ceiling


def condition_covariance(covariance: np.ndarray, floor: float, ceiling: float) -> np.ndarray:
    """The symmetric part of ``covariance`` with its eigenvalues clipped to [floor, ceiling].

    The eigen-decomposition is only rebuilt when a bound is crossed, so a healthy
    covariance comes back as its symmetric part, unchanged otherwise.
    """
    symmetric = 0.5 * (covariance + covariance.T)
    eigenvalues = np.linalg.eigvalsh(symmetric)
    if eigenvalues[0] >= floor and eigenvalues[-1] <= ceiling:
        return symmetric
    eigenvalues, vectors = np.linalg.eigh(symmetric)
    clipped = np.clip(eigenvalues, floor, ceiling)
    rebuilt = (vectors * clipped) @ vectors.T
    return 0.5 * (rebuilt + rebuilt.T)


class AugmentedEkf:
    """Extended Kalman filter for a state augmented with a random-walk disturbance.

    ``step`` is a CasADi function (z, u, e) -> (z_next, dz_next/dz) over one sample, ``e``
    the actuators' effectiveness (n,; 1 healthy, 0 dead) that scales what ``u`` does; the
    first ``measured`` entries of z are measured directly (H = [I 0]). The covariance
    is updated in Joseph form and kept symmetric with bounded eigenvalues (module
    docstring), so it stays positive definite however long the filter runs.

    The update and the propagation are CasADi functions (:attr:`update`, :attr:`propagation`,
    :func:`ekf_functions`): evaluated here, generated to C by ``export-c``, so the exported
    estimator computes what this one does, operation for operation.
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
        self._measured = measured
        self.prior = prior_covariance
        self._angle_index = angle_index
        self.bounds = covariance_bounds(
            process_covariance, measurement_covariance, prior_covariance
        )
        self._floor, self._ceiling = self.bounds
        self.update, self.propagation = ekf_functions(
            step, measured, process_covariance, measurement_covariance
        )
        self._healthy = np.ones(step.size1_in(2))
        self.restarts = 0
        self.reset(np.zeros(prior_covariance.shape[0]))

    def reset(self, initial_estimate: np.ndarray) -> None:
        self.estimate = np.array(initial_estimate, dtype=float)
        self.covariance = self.prior.copy()
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
        estimate, joseph = self.update(self.estimate, self.covariance, innovation)
        self.estimate = np.asarray(estimate).ravel()
        self.covariance = condition_covariance(np.asarray(joseph), self._floor, self._ceiling)
        return self.estimate.copy()

    def predict(
        self,
        applied_input: np.ndarray,
        effectiveness: np.ndarray | None = None,
        added_covariance: np.ndarray | None = None,
    ) -> None:
        """Propagate over one sample with the input actually applied, acting with
        ``effectiveness`` (n,; None: all healthy); ``added_covariance`` (n x n), process noise
        of this sample beyond the fixed one (a model's error where the state is), is added to
        the propagated covariance.

        If the prediction is not finite (the model's integration diverged, e.g. an RK4
        step too long for the estimated speed), the filter restarts from the next
        measurement with its prior covariance, keeping the unmeasured part of the
        estimate if it is finite; ``restarts`` counts these.
        """
        next_estimate, propagated = (
            np.asarray(value)
            for value in self.propagation(
                self.estimate,
                self.covariance,
                applied_input,
                self._healthy if effectiveness is None else effectiveness,
            )
        )
        next_estimate = next_estimate.ravel()
        if not (np.all(np.isfinite(next_estimate)) and np.all(np.isfinite(propagated))):
            self.restarts += 1
            kept = self.estimate.copy()
            kept[: self._measured] = 0.0
            self.reset(np.where(np.isfinite(kept), kept, 0.0))
            return
        self.estimate = next_estimate
        self.covariance = condition_covariance(propagated, self._floor, self._ceiling)
        if added_covariance is not None:
            self.covariance = self.covariance + added_covariance


def ekf_functions(
    step: ca.Function,
    measured: int,
    process_covariance: np.ndarray,
    measurement_covariance: np.ndarray,
) -> tuple[ca.Function, ca.Function]:
    """The EKF's two steps on an estimate z (n) and covariance P (n x n), with H = [I 0]:

    ``ekf_update`` (z, P, innovation) -> (z + K innovation, the Joseph form
    (I - K H) P (I - K H)' + K R K'), K = P H' (H P H' + R)^-1 by a Cholesky factorisation;
    ``ekf_propagation`` (z, P, u, e) -> (step(z, u, e), A P A' + Q), A the step's Jacobian
    and ``e`` the actuators' effectiveness.

    Both are written once, symbolically, so that Python (CasADi's virtual machine) and the
    exported C (CasADi's generated code) evaluate the same operations in the same order.
    """
    n, m = step.size1_in(0), measured
    z, P = ca.SX.sym("z", n), ca.SX.sym("P", n, n)
    innovation, u = ca.SX.sym("innovation", m), ca.SX.sym("u", step.size1_in(1))
    effectiveness = ca.SX.sym("e", step.size1_in(2))
    R = ca.SX(measurement_covariance)
    S = P[:m, :m] + R  # H P H' + R, positive definite
    # K' = S^-1 P[:m, :], column by column through S = L L'.
    L = _cholesky(S)
    gain_t = ca.horzcat(*(_cholesky_solve(L, P[:m, j]) for j in range(n)))
    gain = gain_t.T
    keep = ca.SX.eye(n)
    keep[:, :m] -= gain
    joseph = keep @ P @ keep.T + gain @ R @ gain.T
    update = ca.Function(
        "ekf_update", [z, P, innovation], [z + gain @ innovation, ca.densify(joseph)],
        ["z", "P", "innovation"], ["z_corrected", "P_joseph"],
    )  # fmt: skip
    following, A = step(z, u, effectiveness)
    propagated = A @ P @ A.T + ca.SX(process_covariance)
    propagation = ca.Function(
        "ekf_propagation", [z, P, u, effectiveness],
        [ca.densify(following), ca.densify(propagated)],
        ["z", "P", "u", "e"], ["z_next", "P_next"],
    )  # fmt: skip
    return update, propagation


def _cholesky(S: ca.SX) -> ca.SX:
    """The lower Cholesky factor of the symmetric positive definite S (m x m), symbolically."""
    m = S.size1()
    L = ca.SX(m, m)
    for j in range(m):
        d = S[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        L[j, j] = ca.sqrt(d)
        for i in range(j + 1, m):
            e = S[i, j]
            for k in range(j):
                e -= L[i, k] * L[j, k]
            L[i, j] = e / L[j, j]
    return L


def _cholesky_solve(L: ca.SX, b: ca.SX) -> ca.SX:
    """x with L L' x = b: forward, then back substitution."""
    m = L.size1()
    y = [None] * m
    for i in range(m):
        e = b[i]
        for k in range(i):
            e -= L[i, k] * y[k]
        y[i] = e / L[i, i]
    x = [None] * m
    for i in reversed(range(m)):
        e = y[i]
        for k in range(i + 1, m):
            e -= L[k, i] * x[k]
        x[i] = e / L[i, i]
    return ca.vertcat(*x)


# Times the vehicle's thrust authority (per axis) above which a disturbance estimate is
# implausible: a current the vehicle could not hold against at twice its full thrust.
PLAUSIBLE_AUTHORITY_MULTIPLE = 2.0


class DisturbanceObserver:
    """EKF on [x; d_world] for the horizontal model; exact Jacobians from CasADi."""

    def __init__(
        self, model: VehicleParams, sample_time: float, config: ObserverConfig, substeps: int = 1
    ) -> None:
        config = config.for_vehicle(model)
        step = horizontal_model(model, sample_time, substeps).augmented_step
        rate = np.array(config.disturbance_rate_std) ** 2 * sample_time
        measurement = np.square(config.measurement_std)
        self._filter = AugmentedEkf(
            step,
            NX,
            np.diag(np.concatenate([np.square(config.state_process_std), rate])),
            np.diag(measurement),
            np.diag(np.concatenate([measurement, np.square(config.initial_disturbance_std)])),
            angle_index=HORIZONTAL.heading,
        )
        # Beyond this the estimate is no force the water could exert on the vehicle: the
        # filter has diverged (seen after a spin: 1.9e5 N on a 100 N vehicle, kept by
        # every later step), and starts again from the measurement.
        authority = np.asarray(model.thrust_authority)
        force, moment = authority[PLANAR_FORCE_XY].max(), authority[PLANAR_MOMENT]
        self._plausible_force = PLAUSIBLE_AUTHORITY_MULTIPLE * float(force)
        self._plausible_moment = PLAUSIBLE_AUTHORITY_MULTIPLE * float(moment)
        self.restarts = 0

    @property
    def filter(self) -> AugmentedEkf:
        """The filter on [x; d_world] (its functions and covariances are what export-c writes)."""
        return self._filter

    def reset(self, initial_state: np.ndarray) -> None:
        self._filter.reset(np.concatenate([np.asarray(initial_state, float), np.zeros(ND)]))

    @property
    def plausible(self) -> tuple[float, float]:
        """The largest force (N) and moment (N m) estimate kept; beyond either the filter
        starts again from the measurement (:meth:`correct`)."""
        return self._plausible_force, self._plausible_moment

    @property
    def disturbance_world(self) -> np.ndarray:
        """Current estimate of the world force [X, Y, N]."""
        return self._filter.estimate[NX:].copy()

    def correct(self, measured_state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fuse a measurement; returns (state estimate [x, y, psi, u, v, r], disturbance
        estimate [X, Y, N])."""
        estimate = self._filter.correct(measured_state)
        disturbance = estimate[NX:]
        force, moment = np.hypot(*disturbance[PLANAR_FORCE_XY]), abs(disturbance[PLANAR_MOMENT])
        if not (force <= self._plausible_force and moment <= self._plausible_moment):
            self.restarts += 1
            self.reset(measured_state)
            estimate = self._filter.estimate
        return estimate[:NX].copy(), estimate[NX:].copy()

    def predict(self, applied_thrust: np.ndarray, effectiveness: np.ndarray | None = None) -> None:
        """Propagate the estimate over one sample with the thrust actually applied, acting
        with the thrusters' ``effectiveness`` (n,; None: all healthy)."""
        self._filter.predict(applied_thrust, effectiveness)


# Smallest measurement variance the obstacle tracker uses (m^2): a noise-free sensor still
# leaves the innovation covariance invertible.
_MIN_MEASUREMENT_VARIANCE_M2 = 1e-12
_TRACK_POSITION, _TRACK_VELOCITY = OBSTACLE_TRACK.position, OBSTACLE_TRACK.span("vx", "vy")


class ConstantVelocityKalman:
    """Kalman filter on an obstacle's world [x, y, vx, vy] from position measurements.

    Constant velocity driven by white acceleration noise of spectral density ``q``
    (m^2/s^3): over dt, F = [[I, dt I], [0, I]] and Q = q [[dt^3/3 I, dt^2/2 I],
    [dt^2/2 I, dt I]] (Bar-Shalom, Li, Kirubarajan 2001, sec. 6.2.2). Started at the
    first measurement with zero velocity of standard deviation ``initial_speed_std``;
    updates in Joseph form. ``predict`` moves the filter to a later time, ``correct``
    applies a measurement there, ``predicted`` reads the estimate at a later time
    without changing the filter (coasting).
    """

    def __init__(
        self,
        position: np.ndarray,
        t: float,
        position_std: float,
        initial_speed_std: float,
        acceleration_psd: float,
    ) -> None:
        self.t = float(t)
        self.mean = np.zeros(OBSTACLE_TRACK.size)  # at rest
        self.mean[_TRACK_POSITION] = position
        self.R = max(position_std**2, _MIN_MEASUREMENT_VARIANCE_M2) * np.eye(2)
        variances = np.full(OBSTACLE_TRACK.size, initial_speed_std**2)
        variances[_TRACK_POSITION] = np.diag(self.R)
        self.covariance = np.diag(variances)
        self.q = float(acceleration_psd)

    def _transition(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        F = np.eye(OBSTACLE_TRACK.size)
        np.fill_diagonal(F[_TRACK_POSITION, _TRACK_VELOCITY], dt)
        blocks = self.q * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
        return F, np.kron(blocks, np.eye(2))

    def predicted(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(mean, covariance) of [x, y, vx, vy] at ``t`` >= the filter's time, filter
        unchanged."""
        F, Q = self._transition(t - self.t)
        return F @ self.mean, F @ self.covariance @ F.T + Q

    def predict(self, t: float) -> None:
        """Move the filter to time ``t`` (s)."""
        self.mean, self.covariance = self.predicted(t)
        self.t = float(t)

    def correct(self, position: np.ndarray) -> None:
        """Apply a measured position (2,) at the filter's time."""
        H = np.eye(OBSTACLE_TRACK.size)[_TRACK_POSITION]  # the position is measured
        innovation = np.asarray(position, dtype=float) - H @ self.mean
        S = H @ self.covariance @ H.T + self.R
        K = np.linalg.solve(S, H @ self.covariance).T
        self.mean = self.mean + K @ innovation
        joseph = np.eye(OBSTACLE_TRACK.size) - K @ H
        P = joseph @ self.covariance @ joseph.T + K @ self.R @ K.T
        self.covariance = 0.5 * (P + P.T)
