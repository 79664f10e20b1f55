"""Classical baseline tracker: PID in the path frame on top of feedback linearisation.

The yardstick every MPC in this package must beat, so it is a good classical design rather
than a strawman ("computed-torque" tracking, i.e. feedback linearisation with the nominal
model, plus integral action). State, frames and units as in :mod:`auvmpc.models.vehicle`.
Per sample:

1. Errors. The world position error ``e = p - p_r`` is resolved in the reference (path)
   frame into along-track and cross-track parts. The heading error
   ``e_psi = wrap(psi - psi_d)`` lies in (-pi, pi]; ``psi_d = psi_r``, optionally turned
   towards the path by a line-of-sight term ``-atan(cross_track / lookahead)``.
2. Desired accelerations. Translation, with diagonal path-frame gains K_P, K_D::

       v_cmd = p_r' - sat(K_D^-1 K_P e, max_approach_speed)
       a_des = p_r'' - K_D (p' - v_cmd)

   This is the PD law ``p_r'' - K_P e - K_D (p' - p_r')`` while the error is small, and a
   bounded closing speed (no overshoot, no absurd demand) when it is large. Yaw:
   ``r_des' = r_r' - k_P e_psi - k_D (r - r_r)``. The feedforward ``p_r''`` and ``r_r'`` are
   the reference's mean accelerations over the coming sample, from one sample of preview:
   exactly what a zero-order-held command must deliver, centripetal part included.
3. Feedback linearisation (paper-model.md section 1). With ``p'' = R(psi) (nu' + r [-v, u])``
   the desired world acceleration becomes body accelerations ``nu_des'``, and::

       tau = M nu_des' - D(nu_ref) nu_ref - C(nu) - d_hat

   M = diag(m11, m22, Iz). Damping ``D`` is taken at the reference velocity, the Coriolis and
   Munk terms ``C`` at the measured one (reasons at the code).
4. Integral action is a disturbance estimate ``d_hat`` in force units: a world-frame force
   (X, Y) and a yaw moment N. A current fixed in the world frame (paper-model.md section 6)
   is then a constant for the integrator even while the vehicle turns; a body- or path-frame
   integrator would have to chase a rotating bias. The update is scaled by the inertia, so
   each nominal axis has the closed-loop polynomial ``s^3 + k_D s^2 + k_P s + k_I``. The
   integrators see the position error shrunk by the same factor as the closing speed, so a
   large error cannot pile up integral in a few samples.
5. Allocation and limits. ``F = T_pinv tau``; within the force limits the yaw moment is kept
   and the planar force scaled down along its own direction; then each thruster is clipped
   into the box the per-sample rate limit allows around the previous command
   (``project_to_limits``). Both hard limits hold by construction; the status is SATURATED
   whenever the command differs from ``T_pinv tau``. Anti-windup: conditional integration
   (no integrator step that would deepen a cut the limits just made) plus a hard bound on
   ``|d_hat|``.
"""

from __future__ import annotations

import math
import time
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from auvmpc.config import NonNegative, Positive, StrictModel
from auvmpc.controllers.base import Observation, horizontal_limits, project_to_limits
from auvmpc.controllers.config import ControllerType, HorizontalControllerConfig, type_field
from auvmpc.controllers.shell import Proposal, ShelledController
from auvmpc.controllers.tracking_law import PATH_ERRORS, apply_law, tracking_law
from auvmpc.errors import FieldError
from auvmpc.models.layout import HORIZONTAL, PLANAR_FORCE, PLANAR_FORCE_XY, PLANAR_MOMENT
from auvmpc.models.vehicle import VehicleParams

__all__ = ["BaselineConfig", "BaselineController", "BaselineControllerConfig"]


# A command is "saturated" when the limits moved it by more than this (N): float round-off
# in the allocation is far smaller, any real clipping far larger.
_SATURATION_TOLERANCE_N = 1e-9
_HEADING = HORIZONTAL.heading
_FORCE_X, _FORCE_Y = (PLANAR_FORCE.index(name) for name in ("X", "Y"))
_ALONG, _CROSS, _HEADING_ERROR = (PATH_ERRORS.index(name) for name in PATH_ERRORS.names)
_POSITION_ERROR = PATH_ERRORS.span("along", "cross")


class BaselineConfig(StrictModel):
    """Gains of the baseline tracker (units per field; every field has a default).

    Defaults are tuned for the ``jmse2210`` preset on the paper oval at Te = 0.5 s and put
    every nominal axis (along, cross, heading) at a triple real pole at -0.7 rad/s:
    ``K_P = 3 w^2 = 1.47``, ``K_D = 3 w = 2.1``, ``K_I = w^3 = 0.343``. Faster poles trade
    robustness to model error for little gain: the 5 N/s thrust-rate limit and the 0.5 s
    hold dominate the response, and a faster heading loop competes with the position loop
    for the same rate budget.
    """

    along_kp: NonNegative = Field(default=1.47, description="along-track position gain K_P (1/s^2)")
    along_kd: NonNegative = Field(default=2.1, description="along-track velocity gain K_D (1/s)")
    along_ki: NonNegative = Field(
        default=0.343, description="along-track integral gain K_I (1/s^3); 0 disables"
    )
    cross_kp: NonNegative = Field(default=1.47, description="cross-track position gain K_P (1/s^2)")
    cross_kd: NonNegative = Field(default=2.1, description="cross-track velocity gain K_D (1/s)")
    cross_ki: NonNegative = Field(
        default=0.343, description="cross-track integral gain K_I (1/s^3); 0 disables"
    )
    heading_kp: NonNegative = Field(
        default=1.47, description="heading gain on the wrapped heading error (1/s^2)"
    )
    heading_kd: NonNegative = Field(
        default=2.1, description="yaw-rate damping gain on r - r_ref (1/s)"
    )
    heading_ki: NonNegative = Field(
        default=0.343, description="heading integral gain (1/s^3); 0 disables"
    )
    max_approach_speed: Positive = Field(
        default=1.0,
        description=(
            "cap on the speed (m/s) at which a position error is closed, on top of the "
            "reference velocity; avoids overshoot after a large initial error"
        ),
    )
    los_lookahead_m: Positive | None = Field(
        default=None,
        description=(
            "line-of-sight look-ahead distance (m): the desired heading turns towards the path "
            "by atan(cross_track / lookahead). None tracks the reference heading and lets the "
            "sway loop remove cross-track error (the vehicle is fully actuated in the plane)"
        ),
    )
    max_integral_force_N: NonNegative = Field(
        default=25.0,
        description="bound on the norm of the integral (estimated current) force (N)",
    )
    max_integral_moment_N_m: NonNegative = Field(
        default=3.0, description="bound on the magnitude of the integral yaw moment (N m)"
    )

    @model_validator(mode="after")
    def _stable_axes(self) -> BaselineConfig:
        # Each nominal axis is s^3 + k_D s^2 + k_P s + k_I (s^2 + k_D s + k_P without k_I).
        # Reject gains whose continuous-time polynomial is not Hurwitz (Routh): they cannot
        # track, whatever the sample time.
        for axis in ("along", "cross", "heading"):
            kp, kd, ki = (getattr(self, f"{axis}_{name}") for name in ("kp", "kd", "ki"))
            if kp > 0 and kd == 0:
                raise FieldError(
                    f"{axis}_kd", kd, f"must be > 0 when {axis}_kp = {kp} > 0 (undamped loop)"
                )
            if ki > 0 and not kp * kd > ki:
                raise FieldError(
                    f"{axis}_ki",
                    ki,
                    f"needs {axis}_kp * {axis}_kd > {axis}_ki (Routh-Hurwitz); "
                    f"{axis}_kp = {kp}, {axis}_kd = {kd}",
                )
        return self


class BaselineControllerConfig(HorizontalControllerConfig):
    """``baseline``: the classical tracker's gains."""

    type: Literal[ControllerType.BASELINE] = type_field(ControllerType.BASELINE)
    baseline: BaselineConfig = Field(
        default_factory=BaselineConfig, description="gains of the classical baseline tracker"
    )


class BaselineController(ShelledController):
    """Feedback-linearising PID tracker with direction-keeping saturation (module docstring).

    Parameters
    ----------
    model : VehicleParams
        The controller's nominal vehicle (inertia, damping, allocation, hard limits).
    sample_time : float
        Te (s), > 0.
    gains : BaselineConfig
        Tuning.
    """

    preview_steps = 1  # one sample ahead: the mean reference acceleration over the hold

    def __init__(
        self,
        model: VehicleParams,
        sample_time: float,
        gains: BaselineConfig,
    ) -> None:
        if not (math.isfinite(sample_time) and sample_time > 0):
            raise ValueError(f"sample_time must be finite and > 0, got {sample_time!r}")
        if not isinstance(gains, BaselineConfig):
            raise TypeError(f"gains must be a BaselineConfig, got {type(gains).__name__}")
        model.require_full_actuation(
            "baseline", "it commands surge, sway and yaw forces through the pseudo-inverse"
        )
        self.model = model
        self.sample_time = float(sample_time)
        self.limits = horizontal_limits(model)
        self.gains = gains
        self._law = tracking_law(model, self.sample_time, gains)
        n = model.n_thrusters
        self._ki = np.array([gains.along_ki, gains.cross_ki])
        self._mass = np.array([model.m11, model.m22])
        self.reset(np.zeros(HORIZONTAL.size), np.zeros(n))

    # ----------------------------------------------------------------------------------------
    # Controller interface
    # ----------------------------------------------------------------------------------------

    @property
    def disturbance_estimate(self) -> np.ndarray:
        """Integral state ``[X, Y, N]``: world-frame force (N) and yaw moment (N m), a copy."""
        return self._integral.copy()

    @classmethod
    def from_config(cls, model, config, obstacle_count: int = 0) -> BaselineController:
        return cls(model, config.for_vehicle(model).sample_time, config.baseline)

    def restart(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        """Clear the integrators (``initial_thrust``, F(-1), is the shell's to keep).

        ``initial_state`` is not needed: the law has no state besides the integrators.
        """
        thrust = np.asarray(initial_thrust, dtype=float)
        if thrust.shape != (self.model.n_thrusters,):
            raise ValueError(
                f"initial_thrust must have shape ({self.model.n_thrusters},), got {thrust.shape}"
            )
        self._integral = np.zeros(PLANAR_FORCE.size)  # [X, Y, N] (PLANAR_FORCE)

    def propose(self, observation: Observation, previous: np.ndarray) -> Proposal:
        """Thrust for the coming sample, already inside the limits; ``limited`` when a hard
        limit had to cut the demand."""
        started = time.perf_counter()
        state = np.asarray(observation.state, dtype=float)
        reference = np.asarray(observation.reference, dtype=float)
        if state.shape != (HORIZONTAL.size,):
            raise ValueError(
                f"observation.state must have shape ({HORIZONTAL.size},), got {state.shape}"
            )
        if reference.ndim != 2 or reference.shape[1] != HORIZONTAL.size or reference.shape[0] < 1:
            raise ValueError(
                f"observation.reference must have shape (n >= 1, {HORIZONTAL.size}), "
                f"got {reference.shape}"
            )

        law = apply_law(self._law, state, reference, self.disturbance_estimate, self.effectiveness)
        tau_des, errors, integrated, target, requested = law
        # Each thruster clipped into the box one rate step around the previous command; since
        # both ends are within the force limits, so is the result.
        thrust, _ = project_to_limits(target, previous, self.model, self.sample_time)
        saturated = bool(np.any(np.abs(thrust - requested) > _SATURATION_TOLERANCE_N))
        # Zero unless a limit cut the demand (or the thrusters left cannot make it).
        deficit = tau_des - self.model.T @ (self.effectiveness * thrust)
        self._integrate(state[_HEADING], reference[0, _HEADING], integrated, deficit, saturated)

        details = {
            "tau_u_N": float(tau_des[_FORCE_X]),
            "tau_v_N": float(tau_des[_FORCE_Y]),
            "tau_r_N_m": float(tau_des[PLANAR_MOMENT]),
            "along_track_error_m": float(errors[_ALONG]),
            "cross_track_error_m": float(errors[_CROSS]),
            "heading_error_rad": float(errors[_HEADING_ERROR]),
            "integral_force_x_N": float(self._integral[_FORCE_X]),
            "integral_force_y_N": float(self._integral[_FORCE_Y]),
            "integral_moment_N_m": float(self._integral[PLANAR_MOMENT]),
        }
        return Proposal(
            plan=thrust[None, :],
            solve_time_s=time.perf_counter() - started,
            disturbance=self.disturbance_estimate,
            limited=saturated,
            details=details,
        )

    # ----------------------------------------------------------------------------------------
    # Control law
    # ----------------------------------------------------------------------------------------

    def _integrate(
        self, psi: float, psi_r: float, errors: np.ndarray, deficit: np.ndarray, saturated: bool
    ) -> None:
        """Update the disturbance estimate: conditional integration plus a hard bound."""
        g, p, te = self.gains, self.model, self.sample_time
        body_to_world = _rotation(psi)
        # The step in acceleration units along the path axes, then times the inertia along the
        # body axes: every axis gets s^3 + k_D s^2 + k_P s + k_I whatever the vehicle's mass.
        accel_step = _rotation(psi_r) @ (te * self._ki * errors[_POSITION_ERROR])  # world (m/s^2)
        force_step = body_to_world @ (self._mass * (body_to_world.T @ accel_step))  # world (N)
        moment_step = te * g.heading_ki * p.Iz * errors[_HEADING_ERROR]  # N m
        if saturated:
            # The integral changes tau by -R^T force_step (and -moment_step); skip a step that
            # would deepen the cut the limits just made (deficit = asked - applied).
            if -(body_to_world.T @ force_step) @ deficit[PLANAR_FORCE_XY] > 0:
                force_step = np.zeros_like(force_step)
            if -moment_step * deficit[PLANAR_MOMENT] > 0:
                moment_step = 0.0
        force = _clip_norm(self._integral[PLANAR_FORCE_XY] + force_step, g.max_integral_force_N)
        limit = g.max_integral_moment_N_m
        moment = float(np.clip(self._integral[PLANAR_MOMENT] + moment_step, -limit, limit))
        self._integral[PLANAR_FORCE_XY], self._integral[PLANAR_MOMENT] = force, moment


def _rotation(angle: float) -> np.ndarray:
    """R(angle), shape (2, 2): body (or path) frame to world frame in the plane."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _clip_norm(vector: np.ndarray, limit: float) -> np.ndarray:
    norm = float(np.hypot(*vector))
    return vector * (limit / norm) if norm > limit else vector
