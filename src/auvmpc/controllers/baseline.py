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

import numpy as np
from pydantic import Field, model_validator

from auvmpc.config import NonNegative, Positive, StrictModel
from auvmpc.controllers.base import Observation, horizontal_limits, project_to_limits
from auvmpc.controllers.shell import Proposal, ShelledController
from auvmpc.errors import FieldError
from auvmpc.models.layout import HORIZONTAL, PLANAR_FORCE_XY, PLANAR_MOMENT
from auvmpc.models.vehicle import VehicleParams, yaw_damping_moment

__all__ = ["BaselineConfig", "BaselineController"]


# A command is "saturated" when the limits moved it by more than this (N): float round-off
# in the allocation is far smaller, any real clipping far larger.
_SATURATION_TOLERANCE_N = 1e-9
_POSITION, _HEADING, _YAW_RATE = HORIZONTAL.position, HORIZONTAL.heading, HORIZONTAL.index("r")


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
        check_actuation: bool = True,
        settling_yaw: bool = False,
    ) -> None:
        if not (math.isfinite(sample_time) and sample_time > 0):
            raise ValueError(f"sample_time must be finite and > 0, got {sample_time!r}")
        if not isinstance(gains, BaselineConfig):
            raise TypeError(f"gains must be a BaselineConfig, got {type(gains).__name__}")
        if check_actuation:  # the shell's recovery takes the least-squares force instead
            model.require_full_actuation(
                "baseline", "it commands surge, sway and yaw forces through the pseudo-inverse"
            )
        self.model = model
        self.sample_time = float(sample_time)
        self.limits = horizontal_limits(model)
        self.gains = gains
        self._settling_yaw = settling_yaw  # the shell's recovery: _settled_yaw_accel
        n = model.n_thrusters
        self._kp = np.array([gains.along_kp, gains.cross_kp])
        self._kd = np.array([gains.along_kd, gains.cross_kd])
        self._ki = np.array([gains.along_ki, gains.cross_ki])
        self._mass = np.array([model.m11, model.m22])
        # Scaling tau towards zero keeps its direction only if zero thrust is allowed.
        self._zero_thrust_feasible = model.thrust_min <= 0.0 <= model.thrust_max
        self.reset(np.zeros(HORIZONTAL.size), np.zeros(n))

    # ----------------------------------------------------------------------------------------
    # Controller interface
    # ----------------------------------------------------------------------------------------

    @property
    def disturbance_estimate(self) -> np.ndarray:
        """Integral state ``[X, Y, N]``: world-frame force (N) and yaw moment (N m), a copy."""
        return np.array([*self._force_integral, self._moment_integral])

    def assume_disturbance(self, disturbance: np.ndarray) -> None:
        """Start the integral state at a known ``[X, Y, N]`` (world force N, moment N m)."""
        self._force_integral = np.array(disturbance[PLANAR_FORCE_XY], dtype=float)
        self._moment_integral = float(disturbance[PLANAR_MOMENT])

    @classmethod
    def from_config(cls, model, config, obstacle_count: int = 0) -> BaselineController:
        return cls(model, config.for_vehicle(model).sample_time, config.baseline)

    def restart(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        """Clear the integrators and remember ``initial_thrust`` as F(-1) for the rate limit.

        ``initial_state`` is not needed: the law has no state besides the integrators and the
        previous command.
        """
        thrust = np.asarray(initial_thrust, dtype=float)
        if thrust.shape != (self.model.n_thrusters,):
            raise ValueError(
                f"initial_thrust must have shape ({self.model.n_thrusters},), got {thrust.shape}"
            )
        self._previous_thrust = thrust.copy()
        self._force_integral = np.zeros(2)
        self._moment_integral = 0.0

    def propose(self, observation: Observation, previous: np.ndarray) -> Proposal:
        """Thrust for the coming sample, already inside the limits; ``limited`` when a hard
        limit had to cut the demand."""
        started = time.perf_counter()
        self._previous_thrust = previous
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

        tau_des, errors, integrated = self._desired_generalised_force(state, reference)
        thrust, saturated = self._saturate(tau_des)
        deficit = tau_des - self.model.T @ thrust  # zero unless a limit cut the demand
        self._integrate(state[_HEADING], reference[0, _HEADING], integrated, deficit, saturated)

        details = {
            "tau_u_N": float(tau_des[0]),
            "tau_v_N": float(tau_des[1]),
            "tau_r_N_m": float(tau_des[PLANAR_MOMENT]),
            "along_track_error_m": float(errors[0]),
            "cross_track_error_m": float(errors[1]),
            "heading_error_rad": float(errors[2]),
            "integral_force_x_N": float(self._force_integral[0]),
            "integral_force_y_N": float(self._force_integral[1]),
            "integral_moment_N_m": float(self._moment_integral),
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

    def _desired_generalised_force(
        self, state: np.ndarray, reference: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The generalised force the control law asks for, before any limit.

        Returns
        -------
        tau : (3,) array
            ``[f_u, f_v, M_r]`` (N, N, N m), body frame.
        errors : (3,) array
            Along-track, cross-track (m) and wrapped heading error (rad).
        integrated : (3,) array
            The errors the integrators are to see (position part shrunk by the speed cap).
        """
        g, p, te = self.gains, self.model, self.sample_time
        _, _, psi, u, v, r = state
        now = reference[0]
        ahead = reference[1] if reference.shape[0] > 1 else now
        psi_r, r_r = now[_HEADING], now[_YAW_RATE]

        # Reference world velocity now and one sample ahead; their difference over Te is the
        # mean acceleration the held command must produce (centripetal part included).
        velocity_r = _world_velocity(now)
        accel_r = (_world_velocity(ahead) - velocity_r) / te
        yaw_accel_r = (ahead[_YAW_RATE] - r_r) / te

        # Position loop in the path frame (x along the reference heading, y to its starboard).
        to_path = _rotation(psi_r).T
        error_path = to_path @ (state[_POSITION] - now[_POSITION])
        velocity = _rotation(psi) @ np.array([u, v])
        velocity_error_path = to_path @ (velocity - velocity_r)
        # Cascade form of PD: the position error asks for a closing speed K_D^-1 K_P e,
        # capped so that a large error is closed at a bounded speed instead of by a huge
        # acceleration. (The config guarantees K_D > 0 wherever K_P > 0.)
        closing = np.divide(self._kp * error_path, self._kd, out=np.zeros(2), where=self._kd > 0)
        speed = float(np.hypot(*closing))
        cap = min(1.0, g.max_approach_speed / speed) if speed > 0 else 1.0
        closing *= cap
        accel_path = -self._kd * (velocity_error_path + closing)
        accel_world = accel_r + _rotation(psi_r) @ accel_path

        # Heading loop: wrapped error to the (optionally line-of-sight corrected) reference.
        psi_d = psi_r
        if g.los_lookahead_m is not None:
            psi_d = psi_r - math.atan(error_path[1] / g.los_lookahead_m)
        heading_error = _wrap(psi - psi_d)
        yaw_accel = yaw_accel_r - g.heading_kp * heading_error - g.heading_kd * (r - r_r)
        if self._settling_yaw:
            yaw_accel = self._settled_yaw_accel(r, r_r, heading_error, yaw_accel)

        # Feedback linearisation: p'' = R(psi) (nu' + r [-v, u]) gives the body accelerations.
        nu_dot = _rotation(psi).T @ accel_world - r * np.array([-v, u])
        # Damping is fed forward at the velocity the vehicle should have (the reference's,
        # in the body frame): with the measured velocity a model that over-estimates damping
        # turns it into positive feedback, and the plant's own damping then adds to K_D.
        # Coriolis and Munk terms use the measured velocity: they are not dissipative, and
        # the Munk moment (m11 - m22) u v is what upsets the heading while the vehicle crabs.
        u_d, v_d = _rotation(psi).T @ velocity_r
        damping = np.array(
            [
                p.Xu * u_d + p.Xuu * abs(u_d) * u_d,
                p.Yv * v_d + p.Yvv * abs(v_d) * v_d,
                yaw_damping_moment(p, r_r),
            ]
        )
        coriolis = np.array([p.m22 * v * r, -p.m11 * u * r, (p.m11 - p.m22) * u * v])
        tau = (
            np.array([p.m11 * nu_dot[0], p.m22 * nu_dot[1], p.Iz * yaw_accel]) - damping - coriolis
        )
        tau[PLANAR_FORCE_XY] -= _rotation(psi).T @ self._force_integral
        tau[PLANAR_MOMENT] -= self._moment_integral
        # The integrators see the position error shrunk by the same cap: outside the range
        # where the loop is linear a large error must not pile up integral in a few samples.
        integrated = np.array([cap * error_path[0], cap * error_path[1], heading_error])
        return tau, np.array([error_path[0], error_path[1], heading_error]), integrated

    def _settled_yaw_accel(
        self, r: float, r_r: float, heading_error: float, inertial: float
    ) -> float:
        """The yaw term for a yaw that settles within the sample: where the yaw damping's
        time constant at ``r`` is below a third of the sample, the moment that holds the
        wanted rate ``r_r - (K_P / K_D) e_psi`` against the damping in steady state (as the
        term the caller turns into a moment), else ``inertial``, the law's own.

        On a light, strongly damped yaw (the hard survey's 0.38 kg m2 vehicle: 0.02 s) the
        inertial law's moment, held for 0.5 s, overshoots the wanted rate by several rad/s
        each sample and keeps the vehicle spinning."""
        p, g = self.model, self.gains
        slope = abs(p.Nr + 2.0 * p.Nrr * abs(r))  # N m s: the damping's, linearised at r
        if slope * self.sample_time < 3.0 * p.Iz:
            return inertial
        wanted = r_r - g.heading_kp / g.heading_kd * heading_error
        # the moment that holds ``wanted``, as an acceleration past the reference's damping,
        # which the caller subtracts
        return (yaw_damping_moment(p, r_r) - yaw_damping_moment(p, wanted)) / p.Iz

    def _saturate(self, tau_des: np.ndarray) -> tuple[np.ndarray, bool]:
        """Allocate, fit inside the force limits keeping direction, then clip to the rate box.

        Force limits: the yaw moment is kept whole if it fits and the planar force
        ``(f_u, f_v)`` is scaled down along its own direction until every thruster is within
        ``[F_min, F_max]``; if the moment alone does not fit, it is scaled and the planar force
        dropped. Yaw goes first because a heading error rotates every other error, and
        because scaling all of tau lets the Munk moment of a crabbing vehicle win.
        Rate limit: each thruster is clipped into the box one rate step around the previous
        command (``project_to_limits``); since both ends are within the force limits, so is
        the result.
        """
        p = self.model
        thrust_yaw = p.T_pinv[:, PLANAR_MOMENT] * tau_des[PLANAR_MOMENT]
        thrust_planar = p.T_pinv[:, PLANAR_FORCE_XY] @ tau_des[PLANAR_FORCE_XY]
        if self._zero_thrust_feasible:
            lower = np.full(p.n_thrusters, p.thrust_min)
            upper = np.full(p.n_thrusters, p.thrust_max)
            if np.all((lower <= thrust_yaw) & (thrust_yaw <= upper)):
                scale = _largest_step(thrust_yaw, thrust_planar, lower, upper)
                target = thrust_yaw + scale * thrust_planar
            else:
                target = (
                    _largest_step(np.zeros(p.n_thrusters), thrust_yaw, lower, upper) * thrust_yaw
                )
        else:  # limits exclude zero thrust (odd but valid): nothing to scale towards
            target = thrust_yaw + thrust_planar
        limited, _ = project_to_limits(target, self._previous_thrust, p, self.sample_time)
        requested = thrust_yaw + thrust_planar
        saturated = bool(np.any(np.abs(limited - requested) > _SATURATION_TOLERANCE_N))
        return limited, saturated

    def _integrate(
        self, psi: float, psi_r: float, errors: np.ndarray, deficit: np.ndarray, saturated: bool
    ) -> None:
        """Update the disturbance estimate: conditional integration plus a hard bound."""
        g, p, te = self.gains, self.model, self.sample_time
        body_to_world = _rotation(psi)
        # The step in acceleration units along the path axes, then times the inertia along the
        # body axes: every axis gets s^3 + k_D s^2 + k_P s + k_I whatever the vehicle's mass.
        accel_step = _rotation(psi_r) @ (te * self._ki * errors[:2])  # world frame (m/s^2)
        force_step = body_to_world @ (self._mass * (body_to_world.T @ accel_step))  # world (N)
        moment_step = te * g.heading_ki * p.Iz * errors[2]  # N m
        if saturated:
            # The integral changes tau by -R^T force_step (and -moment_step); skip a step that
            # would deepen the cut the limits just made (deficit = asked - applied).
            if -(body_to_world.T @ force_step) @ deficit[PLANAR_FORCE_XY] > 0:
                force_step = np.zeros(2)
            if -moment_step * deficit[PLANAR_MOMENT] > 0:
                moment_step = 0.0
        self._force_integral = _clip_norm(self._force_integral + force_step, g.max_integral_force_N)
        limit = g.max_integral_moment_N_m
        self._moment_integral = float(np.clip(self._moment_integral + moment_step, -limit, limit))


def _world_velocity(reference_row: np.ndarray) -> np.ndarray:
    """World velocity (x', y') of a reference state row [x, y, psi, u, v, r]."""
    return _rotation(reference_row[_HEADING]) @ reference_row[HORIZONTAL.body_velocity]


def _rotation(angle: float) -> np.ndarray:
    """R(angle), shape (2, 2): body (or path) frame to world frame in the plane."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _wrap(angle: float) -> float:
    """Angle wrapped to (-pi, pi]."""
    return math.pi - (math.pi - angle) % (2.0 * math.pi)


def _largest_step(
    start: np.ndarray, direction: np.ndarray, lower: np.ndarray, upper: np.ndarray
) -> float:
    """Largest s in [0, 1] with lower <= start + s * direction <= upper (start inside)."""
    room = np.where(direction > 0, upper - start, np.where(direction < 0, lower - start, np.inf))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratios = np.where(direction != 0, room / direction, np.inf)
    return float(np.clip(ratios.min(), 0.0, 1.0))


def _clip_norm(vector: np.ndarray, limit: float) -> np.ndarray:
    norm = float(np.hypot(*vector))
    return vector * (limit / norm) if norm > limit else vector
