"""Grey-box identification of the 3-DOF velocity model from logged velocities and thrusts.

The model is the velocity part of :mod:`auvmpc.models.vehicle` (Fossen 2021, ch. 6)::

    m11 u' = Xu u + Xuu |u| u + m22 v r + tau_u
    m22 v' = Yv v + Yvv |v| v - m11 u r + tau_v
    Iz  r' = Nr r + Nrr |r| r + (m11 - m22) u v + tau_r,    Iz = Iz_rb + Iz_added

with ``tau = T F`` from the start vehicle's (known) thruster layout. The unknowns are
:data:`PARAMETERS`; ``Iz_rb`` is kept from the start file (only the sum Iz is observable).
Optionally (:class:`Unknowns`, :data:`EXTRAS`) also:

- a **constant current** ``(V_x, V_y)`` in the world frame of the log's heading. The model
  then holds for the velocity through the water ``nu_r = nu - nu_c`` with
  ``(u_c, v_c) = body_from_world(V, psi)`` (Fossen 2021, sec. 6.5; ``models.vehicle.dynamics``):
  since ``u_c' = r v_c`` and ``v_c' = -r u_c``, the relative velocity obeys the equations
  above exactly, current-free, and what is measured is ``nu_r + nu_c(psi)``, psi being the
  logged heading;
- a **thrust gain** ``g``, one factor on every thrust (``tau = g T F``). A gain and the
  masses and dampings scale together (``g tau = M nu' - D nu ...`` is unchanged when all of
  them are multiplied by one factor; ``Iz_rb`` does not help, ``Iz_added`` takes it up), so
  the gain is only identifiable against a parameter held at its start value
  (``Unknowns.fixed``): the estimates are then in that parameter's scale.

1. Equation error (:func:`equation_error`). The equations are linear in the parameters
   (and the gain) once the accelerations are known: ``A theta = b`` with rows per sample
   and axis. The velocities and their derivatives come from a Savitzky-Golay filter
   (Savitzky and Golay 1964), each axis' rows are scaled by its force level, and
   ``scipy.linalg.lstsq`` solves it. A current enters nonlinearly (through |u_r|); the
   least squares are solved for each trial current inside a trust-region Gauss-Newton
   search (``scipy.optimize.least_squares``) over the current's two components (variable
   projection, Golub and Pereyra 1973). Noise in the regressors biases this estimate; it
   is a start, not the answer.
2. Output error (:func:`output_error`). The velocity model is simulated (RK4, thrust held
   over each sample) over segments of the log, each segment from its own free initial
   velocity (multiple shooting without continuity: the segments are independent, so a
   poor start cannot make a long simulation diverge), and the weighted squared difference
   to the measured velocities is minimised by IPOPT over the parameters and the segments'
   initial velocities (CasADi, exact Hessian). It starts from the equation-error estimate
   or from the start file, whichever simulates the log better (on a vehicle faster than
   the log's sampling the filter's derivatives are poor). Weights are 1 / the noise level
   of each velocity: first what the filter removes, then, in a second fit, the first
   fit's residual RMS (the filter also removes dynamics it cannot follow). With white
   measurement noise and a noise-free plant this is the maximum-likelihood estimate
   (Ljung 1999, ch. 7; Klein and Morelli 2006, ch. 6).
3. Intervals (Fisher information). At the optimum the Gauss-Newton Hessian J'J of the
   weighted residuals, scaled by the residual variance, gives the covariance
   ``s^2 (J'J)^-1`` (the segments' initial velocities included as nuisance parameters);
   95 % intervals are +-1.96 standard deviations (Klein and Morelli 2006, sec. 6.2).
4. Excitation. A parameter is *excited* if its interval is narrower than its value
   (half-width <= 0.5 |value|) or if its interval moves its equation's force by less than
   :data:`SENSITIVITY_SHARE` of that force's RMS (a parameter that is small but well
   determined, e.g. a zero linear damping; for the current, the force through the
   equations' derivative with respect to it), judged on the second fit. Parameters that are
   not are fixed at their start value (no current, gain 1) and the fit is repeated without
   them; the vehicle file keeps their start values and the report names them.
5. Validation: the held-out end of each log is simulated from its first measured
   velocity with the identified and with the start parameters (the start without a current
   and with gain 1); RMS of the differences.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import casadi as ca
import numpy as np
from scipy.linalg import lstsq
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from auvmpc.errors import ConfigError
from auvmpc.identification.logs import MIN_SAMPLES, VelocityLog
from auvmpc.models.integrators import rk4_step
from auvmpc.models.vehicle import (
    RK4_STABLE_STEP,
    VehicleParams,
    body_from_world,
    damping_rates,
    velocity_derivative,
)
from auvmpc.scenario.model import DEFAULT_PLANT_STEP_S
from auvmpc.sim.plant import substeps_for

__all__ = [
    "EXTRAS",
    "PARAMETERS",
    "Identification",
    "ParameterEstimate",
    "Unknowns",
    "equation_error",
    "identify",
    "output_error",
    "regression",
    "velocity_rhs",
]

PARAMETERS = ("m11", "m22", "Iz_added", "Xu", "Xuu", "Yv", "Yvv", "Nr", "Nrr")
MASSES = ("m11", "m22", "Iz_added")
# Unknowns beside the vehicle's (module docstring): one factor on every thrust, and the
# world-frame current (m/s). Each has a neutral value, held where it is not estimated.
EXTRAS = ("thrust_gain", "current_x", "current_y")
NEUTRAL = np.array([1.0, 0.0, 0.0])
UNKNOWNS = PARAMETERS + EXTRAS
_P, _U = len(PARAMETERS), len(UNKNOWNS)
_GAIN = UNKNOWNS.index("thrust_gain")
_CURRENT = slice(UNKNOWNS.index("current_x"), UNKNOWNS.index("current_y") + 1)
# 95 % two-sided normal quantile.
Z95 = 1.959963984540054
# A parameter whose interval moves its equation's force by less than this share of the
# force's RMS counts as excited even where the interval is wide relative to its value.
SENSITIVITY_SHARE = 0.05
# An interval half-width up to this share of the value counts as excited.
RELATIVE_HALF_WIDTH = 0.5
# Savitzky-Golay filter: cubic over about this long a window (at least 7 samples).
FILTER_WINDOW_S = 0.7
FILTER_ORDER = 3
# Output-error segments: this long (s), each from its own initial velocity.
SEGMENT_S = 10.0


def velocity_rhs(nu, tau, theta, iz_rb: float, absolute=np.abs):
    """[u', v', r'] of the model above (models.vehicle.velocity_derivative) with the
    parameters ``theta`` in :data:`PARAMETERS` order. NumPy arrays (``nu``, ``tau`` of shape
    (3, ...)) or CasADi columns (``absolute=ca.fabs``)."""
    values = dict(zip(PARAMETERS, (theta[i] for i in range(len(PARAMETERS))), strict=True))
    coefficients = SimpleNamespace(**values, Iz=iz_rb + values["Iz_added"])
    derivative = velocity_derivative(coefficients, nu[0], nu[1], nu[2], tau, absolute)
    if isinstance(derivative[0], ca.SX | ca.MX):
        return ca.vertcat(*derivative)
    return np.array(derivative)


def start_vector(vehicle: VehicleParams) -> np.ndarray:
    return np.array([float(getattr(vehicle, name)) for name in PARAMETERS])


def start_unknowns(vehicle: VehicleParams) -> np.ndarray:
    """:data:`UNKNOWNS` at their start: the vehicle's parameters, gain 1, no current."""
    return np.concatenate([start_vector(vehicle), NEUTRAL])


@dataclass(frozen=True)
class Unknowns:
    """What :func:`identify` estimates besides the vehicle's parameters and what it holds at
    the start file's values (``auvmpc identify --current --thrust-gain --fix``)."""

    current: bool = False  # the constant world-frame current (V_x, V_y)
    thrust_gain: bool = False  # one factor on every thrust: needs a held parameter
    fixed: tuple[str, ...] = ()  # of PARAMETERS, held at the start file's values

    def held(self) -> tuple[str, ...]:
        """The names in :data:`UNKNOWNS` not estimated: the fixed ones and the extras not
        asked for (held at gain 1, no current)."""
        extras = () if self.thrust_gain else ("thrust_gain",)
        return (*self.fixed, *extras, *(() if self.current else ("current_x", "current_y")))

    def check(self, vehicle: VehicleParams, logs: list[VelocityLog]) -> None:
        """One ConfigError line for an unknown name, a gain without a scale to be measured
        in (module docstring), or a current asked of a log without a heading."""
        unknown = [name for name in self.fixed if name not in PARAMETERS]
        if unknown:
            raise ConfigError(
                "--fix", ",".join(unknown), f"not a parameter identify estimates: one of "
                f"{', '.join(PARAMETERS)}",
            )  # fmt: skip
        if self.thrust_gain and not any(getattr(vehicle, name) != 0 for name in self.fixed):
            raise ConfigError(
                "--thrust-gain", ",".join(self.fixed) or None,
                "a gain on every thrust and the masses and dampings scale together (the log "
                "cannot tell g tau = M nu' - D nu from tau = M/g nu' - D/g nu): hold one "
                "nonzero parameter at the start file's value, e.g. --fix m11",
            )  # fmt: skip
        for log in logs if self.current else ():
            if log.heading is None:
                raise ConfigError(
                    "LOG", log.name, "has no heading, which --current needs (a current fixed "
                    "in the world turns in the body as the vehicle turns)",
                )  # fmt: skip


def current_rows(current, heading: np.ndarray):
    """The current's body components (u_c, v_c, 0) at each heading (n,), as rows (3, n):
    ``current`` (2,) NumPy or a CasADi column (then a CasADi matrix)."""
    u_c, v_c = body_from_world(current, np.asarray(heading, dtype=float)[None, :])
    if isinstance(u_c, ca.MX | ca.SX):
        return ca.vertcat(u_c, v_c, ca.DM.zeros(1, len(heading)))
    return np.vstack([u_c, v_c, np.zeros_like(u_c)])


def _heading(log: VelocityLog) -> np.ndarray:
    """The log's heading, or zeros where it has none (then the current is held at zero)."""
    return np.zeros(log.steps + 1) if log.heading is None else log.heading


def regression(nu: np.ndarray, nu_dot: np.ndarray, tau: np.ndarray, iz_rb: float):
    """The model as ``A theta = b``: per axis a block of rows, one per sample.

    Parameters
    ----------
    nu, nu_dot, tau : (N, 3) velocities, their derivatives and the applied force
    iz_rb : kg m2, the rigid-body yaw inertia (known)

    Returns
    -------
    A : (3, N, 9), b : (3, N): block a is axis a (surge, sway, yaw).
    """
    u, v, r = nu.T
    du, dv, dr = nu_dot.T
    zero = np.zeros_like(u)
    surge = [-du, v * r, zero, u, np.abs(u) * u, zero, zero, zero, zero]
    sway = [-u * r, -dv, zero, zero, zero, v, np.abs(v) * v, zero, zero]
    yaw = [u * v, -u * v, -dr, zero, zero, zero, zero, r, np.abs(r) * r]
    A = np.stack([np.column_stack(block) for block in (surge, sway, yaw)])
    b = np.stack([-tau[:, 0], -tau[:, 1], -tau[:, 2] + iz_rb * dr])
    return A, b


def filter_window(sample_time: float) -> int:
    window = max(7, round(FILTER_WINDOW_S / sample_time))
    return window + 1 - window % 2  # odd


def smoothed(log: VelocityLog) -> tuple[np.ndarray, np.ndarray]:
    """Savitzky-Golay smoothed velocities and their derivatives, (N+1, 3) each."""
    window = filter_window(log.sample_time)
    nu = savgol_filter(log.velocity, window, FILTER_ORDER, axis=0)
    nu_dot = savgol_filter(
        log.velocity, window, FILTER_ORDER, deriv=1, delta=log.sample_time, axis=0
    )
    return nu, nu_dot


def applied_force(log: VelocityLog, vehicle: VehicleParams) -> np.ndarray:
    """The body force [X, Y, N] per command, (N, 3): the log's own, or tau = T F."""
    if log.force is not None:  # the log holds the body force itself: no allocation
        return log.force
    return log.thrust @ vehicle.T.T


def noise_levels(logs: list[VelocityLog]) -> np.ndarray:
    """Each velocity's noise standard deviation, from what the filter removes (3,), with a
    floor of 1 % of its RMS (a noise-free log still needs finite weights)."""
    removed = np.vstack([log.velocity - smoothed(log)[0] for log in logs])
    window = filter_window(logs[0].sample_time)
    # The filter passes a share (about its hat-matrix diagonal) of white noise through.
    passed = savgol_filter(np.eye(window)[window // 2], window, FILTER_ORDER)[window // 2]
    noise = removed.std(axis=0) / math.sqrt(max(1.0 - passed, 1e-6))
    level = np.sqrt(np.mean(np.vstack([log.velocity for log in logs]) ** 2, axis=0))
    return np.maximum(noise, 0.01 * np.maximum(level, 1e-6))


def _stacked_regression(logs: list[VelocityLog], vehicle: VehicleParams, current=NEUTRAL[1:]):
    """The rows of every log at a trial ``current`` (2,): ``A`` (3, N, 10) over the
    parameters and the gain (whose column is the applied force), ``b`` (3, N)."""
    blocks_a, blocks_b = [], []
    for log in logs:
        nu, nu_dot = smoothed(log)
        # The model holds for the velocity through the water (module docstring).
        psi = savgol_filter(_heading(log), filter_window(log.sample_time), FILTER_ORDER)
        u_c, v_c, _ = current_rows(np.asarray(current, dtype=float), psi)
        r = nu[:, 2]
        nu = nu - np.column_stack([u_c, v_c, np.zeros_like(r)])
        nu_dot = nu_dot - np.column_stack([r * v_c, -r * u_c, np.zeros_like(r)])
        tau = applied_force(log, vehicle)
        # The derivative at t_k spans the commands before and after it: their mean.
        tau_k = np.vstack([tau[:1], 0.5 * (tau[:-1] + tau[1:])])
        edge = filter_window(log.sample_time) // 2  # the filter's ends are extrapolations
        rows = slice(edge, log.steps - edge)
        A, b = regression(nu[:-1][rows], nu_dot[:-1][rows], tau_k[rows], vehicle.Iz_rb)
        force = tau_k[rows].T  # b holds -tau: with a gain it is the gain's column
        blocks_a.append(np.concatenate([A, force[:, :, None]], axis=2))
        blocks_b.append(b + force)
    return np.concatenate(blocks_a, axis=1), np.concatenate(blocks_b, axis=1)


# Central differences of the rows in the current (m/s): for the excitation test only.
CURRENT_STEP = 1e-4


def equation_error(
    logs: list[VelocityLog], vehicle: VehicleParams, held: tuple[str, ...] = EXTRAS
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares :data:`UNKNOWNS` (12,), the ``held`` ones at their start, and the
    regression ``A`` (3, N, 12), ``b`` (3, N) at that estimate, each axis' rows scaled by
    its force RMS so that N and N m weigh alike. ``A``'s current columns are the rows'
    derivatives with respect to the current (their equations are not linear in it)."""
    start = start_unknowns(vehicle)
    linear = np.array([name not in held for name in UNKNOWNS[: _GAIN + 1]])
    fixed_part = np.where(linear, 0.0, start[: _GAIN + 1])
    A, b = _stacked_regression(logs, vehicle)
    applied = b - A[..., _GAIN]  # b without the gain: -tau (+ Iz_rb r' for yaw)
    scale = np.sqrt(np.mean(applied**2, axis=1)) + np.sqrt(
        np.mean((A[..., :_P] @ start[:_P]) ** 2, 1)
    )
    scale = np.where(scale > 0, scale, 1.0)[:, None]

    def solve(current) -> tuple[np.ndarray, np.ndarray]:
        rows, rhs = _stacked_regression(logs, vehicle, current)
        rhs = (rhs - rows @ fixed_part) / scale
        rows = rows[..., linear] / scale[:, :, None]
        solution, *_ = lstsq(rows.reshape(-1, int(linear.sum())), rhs.ravel())
        return solution, (rows @ solution - rhs).ravel()

    current = NEUTRAL[1:]
    if "current_x" not in held:  # variable projection over the current (module docstring)
        current = least_squares(lambda c: solve(c)[1], np.zeros(2), x_scale=0.1).x
    theta = start.copy()
    theta[_CURRENT] = current
    theta[: _GAIN + 1][linear] = solve(current)[0]
    A, b = _stacked_regression(logs, vehicle, current)
    columns = [np.zeros_like(b)] * 2
    for axis in range(2 if "current_x" not in held else 0):
        step = CURRENT_STEP * np.eye(2)[axis]
        moved = [_stacked_regression(logs, vehicle, current + sign * step) for sign in (1, -1)]
        residuals = [rows @ theta[: _GAIN + 1] - rhs for rows, rhs in moved]
        columns[axis] = (residuals[0] - residuals[1]) / (2 * CURRENT_STEP)
    return theta, np.concatenate([A, np.stack(columns, axis=2)], axis=2), b


@dataclass
class _Model:
    """The simulated velocity model for one sample time: one RK4-integrated sample."""

    sample_time: float
    substeps: int
    iz_rb: float

    def __post_init__(self) -> None:
        nu, tau, theta = ca.SX.sym("nu", 3), ca.SX.sym("tau", 3), ca.SX.sym("theta", 9)

        def f(x, u):
            return velocity_rhs(x, u, theta, self.iz_rb, ca.fabs)

        x = nu
        for _ in range(self.substeps):
            x = rk4_step(f, x, tau, self.sample_time / self.substeps)
        self.step = ca.Function("step", [nu, tau, theta], [x])
        self._rollouts: dict[int, ca.Function] = {}

    def rollout(self, steps: int) -> ca.Function:
        """(nu0 (3,), tau (3, steps), theta (9, steps)) -> velocities at k = 1..steps."""
        if steps not in self._rollouts:
            self._rollouts[steps] = self.step.mapaccum("rollout", steps)
        return self._rollouts[steps]

    def simulate(self, nu0, tau: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Numeric rollout: (N+1, 3) from nu0 under tau (N, 3)."""
        steps = len(tau)
        out = self.rollout(steps)(nu0, tau.T, np.tile(theta[:, None], (1, steps)))
        return np.vstack([np.asarray(nu0, dtype=float)[None, :], np.asarray(out).T])


def model_substeps(sample_time: float, vehicle: VehicleParams, logs: list[VelocityLog]) -> int:
    """RK4 steps per sample: at most the plant's step (DEFAULT_PLANT_STEP_S) each, and
    stable for the start vehicle's damping at twice the logged speeds (the fit moves the
    parameters)."""
    top = 2.0 * np.max(np.vstack([np.abs(log.velocity) for log in logs]), axis=0)
    stable = RK4_STABLE_STEP / max(max(damping_rates(vehicle, *top)), 1e-9) / 2.0
    return substeps_for(sample_time, min(stable, DEFAULT_PLANT_STEP_S))


@dataclass
class _Fit:
    theta: np.ndarray  # (12,) UNKNOWNS
    half_width: np.ndarray  # (12,) 95 % half-widths, 0 for a fixed parameter, inf unknown
    residual_rms: np.ndarray  # (3,) RMS of the velocity residuals (m/s, m/s, rad/s)
    started_from: int  # which candidate
    iterations: int
    status: str


def _segments(log: VelocityLog, length: int) -> list[tuple[int, int]]:
    count = max(1, round(log.steps / length))
    edges = np.linspace(0, log.steps, count + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]


# The current's typical size (m/s) where neither the start nor the first estimate has one.
CURRENT_SCALE = 0.1


def _scales(start: np.ndarray, first: np.ndarray, vehicle: VehicleParams) -> np.ndarray:
    """Typical size per unknown (12,), so that IPOPT's variables are of order one."""
    axis_mass = {"X": vehicle.m11, "Y": vehicle.m22, "N": vehicle.Iz}
    masses = {"m11": vehicle.m11, "m22": vehicle.m22, "Iz_added": vehicle.Iz}
    floor = 0.01 * np.array([masses.get(name) or axis_mass[name[0]] for name in PARAMETERS])
    floor = np.concatenate([floor, [1.0, CURRENT_SCALE, CURRENT_SCALE]])
    return np.maximum.reduce([np.abs(start), np.abs(first), floor])


def output_error(
    logs: list[VelocityLog],
    vehicle: VehicleParams,
    candidates: list[np.ndarray],
    fixed: tuple[str, ...] = (),
    weight: np.ndarray | None = None,
    model: _Model | None = None,
) -> _Fit:
    """Output-error refinement (module docstring, steps 2 and 3) from whichever of the
    ``candidates`` (12,: :data:`UNKNOWNS`) simulates the log best; the ``fixed`` ones stay at
    that candidate's values. ``weight`` (3,): per velocity, 1 / its noise level (default:
    the filter's estimate). Each segment's free initial state is its velocity through the
    water; the current's body components at the logged headings are added to what it
    predicts (module docstring)."""
    sample_time = logs[0].sample_time
    model = model or _Model(sample_time, model_substeps(sample_time, vehicle, logs), vehicle.Iz_rb)
    start = start_unknowns(vehicle)
    scale = _scales(start, candidates[0], vehicle)
    weight = 1.0 / noise_levels(logs) if weight is None else np.asarray(weight, dtype=float)
    z = ca.MX.sym("z", _U)
    theta = z * scale
    parameters, gain, current = theta[:_P], theta[_GAIN], theta[_CURRENT]
    length = max(MIN_SAMPLES // 4, round(SEGMENT_S / sample_time))
    initial, starts, residuals = [], [], []
    for log in logs:
        tau = applied_force(log, vehicle)
        nu_smooth = smoothed(log)[0]
        psi = _heading(log)
        for a, b in _segments(log, length):
            x0 = ca.MX.sym(f"x0_{len(initial)}", 3)
            initial.append(x0)
            starts.append((nu_smooth[a], psi[a : a + 1]))
            steps = b - a
            relative = model.rollout(steps)(x0, gain * tau[a:b].T, ca.repmat(parameters, 1, steps))
            predicted = relative + current_rows(current, psi[a + 1 : b + 1])
            measured = log.velocity[a + 1 : b + 1].T
            residuals.append(ca.vec((predicted - measured) * weight))
            first = x0 + current_rows(current, psi[a : a + 1])
            residuals.append((first - log.velocity[a]) * weight)
    x = ca.vertcat(z, *initial)
    residual = ca.vertcat(*residuals)
    lower, upper = _bounds()
    is_fixed = np.array([name in fixed for name in UNKNOWNS])

    def guess(candidate: np.ndarray) -> np.ndarray:
        """The segments' initial velocities through the water under ``candidate``'s current."""
        return np.concatenate(
            [nu - current_rows(candidate[_CURRENT], psi)[:, 0] for nu, psi in starts]
        )

    cost = ca.Function("cost", [x], [0.5 * ca.sumsqr(residual)])
    costs = [float(cost(np.concatenate([c / scale, guess(c)]))) for c in candidates]
    best = min(range(len(costs)), key=lambda i: costs[i] if math.isfinite(costs[i]) else math.inf)
    z0 = np.clip(candidates[best] / scale, lower, upper)
    lower = np.where(is_fixed, z0, lower)
    upper = np.where(is_fixed, z0, upper)
    n_initial = 3 * len(initial)
    solver = ca.nlpsol(
        "output_error",
        "ipopt",
        {"x": x, "f": 0.5 * ca.sumsqr(residual)},
        {
            "print_time": False,
            "show_eval_warnings": False,  # a trial step may blow the model up: IPOPT backs off
            "ipopt": {
                "print_level": 0,
                "sb": "yes",
                "max_iter": 300,
                "tol": 1e-9,
                "hessian_approximation": HESSIAN,
            },
        },
    )
    solution = solver(
        x0=np.concatenate([z0, guess(candidates[best])]),
        lbx=np.concatenate([lower, np.full(n_initial, -np.inf)]),
        ubx=np.concatenate([upper, np.full(n_initial, np.inf)]),
    )
    stats = solver.stats()
    optimum = np.asarray(solution["x"]).ravel()
    # IPOPT may end a hair outside a bound (it relaxes them by ~1e-8 internally): a damping
    # of +2e-9 is not a damping the vehicle file accepts. The optimum is projected back.
    optimum[:_U] = np.clip(optimum[:_U], lower, upper)
    jacobian_of = ca.Function("J", [x], [residual, ca.jacobian(residual, x)])
    r_value, j_value = (np.asarray(value) for value in jacobian_of(optimum))
    r_value = r_value.ravel()
    free = np.concatenate([~is_fixed, np.ones(n_initial, dtype=bool)])
    J = j_value[:, free]
    dof = max(1, r_value.size - J.shape[1])
    variance = float(r_value @ r_value) / dof
    information = J.T @ J
    half_width = np.zeros(_U)
    try:
        covariance = variance * np.linalg.inv(information)
        std = np.sqrt(np.clip(np.diag(covariance)[: int((~is_fixed).sum())], 0.0, None))
    except np.linalg.LinAlgError:
        std = np.full(int((~is_fixed).sum()), np.inf)
    half_width[~is_fixed] = Z95 * std * scale[~is_fixed]
    residual_rms = np.sqrt(np.mean(r_value.reshape(-1, 3) ** 2, axis=0)) / weight
    return _Fit(
        theta=optimum[:_U] * scale,
        half_width=half_width,
        residual_rms=residual_rms,
        started_from=best,
        iterations=int(stats.get("iter_count", -1)),
        status=str(stats.get("return_status", "")),
    )


def _bounds() -> tuple[np.ndarray, np.ndarray]:
    """Physical bounds on the scaled unknowns: masses and the gain positive (added yaw
    inertia >= 0), damping <= 0, the current either way; every magnitude within a factor
    MAGNITUDE of its scale."""
    lower = np.full(_U, -MAGNITUDE)
    upper = np.zeros(_U)
    lower[:2], upper[:2] = 1.0 / MAGNITUDE, MAGNITUDE  # m11, m22
    lower[2], upper[2] = 0.0, MAGNITUDE  # Iz_added
    lower[_GAIN], upper[_GAIN] = 1.0 / MAGNITUDE, MAGNITUDE
    upper[_CURRENT] = MAGNITUDE
    return lower, upper


MAGNITUDE = 100.0
HESSIAN = "exact"


@dataclass(frozen=True)
class ParameterEstimate:
    name: str
    start: float
    equation_error: float  # the least-squares first estimate
    value: float  # what the vehicle file gets (the start value where not excited)
    ci95: tuple[float, float]
    excited: bool
    fixed: bool = False  # held at the start value as asked (``--fix``): not estimated


@dataclass
class Identification:
    """What :func:`identify` found and how well it predicts the held-out data."""

    parameters: list[ParameterEstimate]
    logs: list[str]
    sample_time: float
    fit_samples: int
    validation_samples: int
    noise_std: np.ndarray  # (3,) RMS of the fit's residuals: the noise of u, v, r
    equation_error_used: bool  # the fit started from it (else from the start file)
    validation_rms: np.ndarray  # (3,) identified model on the held-out parts
    validation_rms_start: np.ndarray  # (3,) the start model there
    iterations: int
    solver_status: str
    substeps: int
    traces: list[dict[str, np.ndarray]] = field(default_factory=list)  # per log, for figures
    # The EXTRAS asked for (thrust gain, current): estimated like the parameters, not
    # vehicle parameters themselves.
    extras: list[ParameterEstimate] = field(default_factory=list)

    @property
    def unexcited(self) -> list[str]:
        return [p.name for p in self.parameters + self.extras if not (p.excited or p.fixed)]

    @property
    def fixed(self) -> list[str]:
        return [p.name for p in self.parameters if p.fixed]

    def vehicle_values(self) -> dict[str, float]:
        return {p.name: p.value for p in self.parameters}

    def extra(self, name: str) -> ParameterEstimate | None:
        """The estimate of ``name`` in :data:`EXTRAS`, or None where it was not asked for."""
        return next((p for p in self.extras if p.name == name), None)


def _excited(theta, half_width, A, b) -> np.ndarray:
    """Module docstring, step 4."""
    relative = half_width <= RELATIVE_HALF_WIDTH * np.abs(theta)
    # Each equation's force: its terms' and its right-hand side's RMS together.
    force = np.sqrt(np.sum(np.mean((A * theta) ** 2, axis=1), axis=1) + np.mean(b**2, axis=1))
    column = np.sqrt(np.mean(A**2, axis=1))  # (3, 12) each regressor's RMS per axis
    moved = half_width[None, :] * column  # force the interval moves, per axis
    share = np.where(column > 0, moved / np.maximum(force[:, None], 1e-12), np.inf).min(axis=0)
    return relative | (share <= SENSITIVITY_SHARE)


def identify(
    logs: list[VelocityLog],
    vehicle: VehicleParams,
    holdout: float = 0.2,
    unknowns: Unknowns | None = None,
) -> Identification:
    """Identify :data:`PARAMETERS` (and the :data:`EXTRAS` ``unknowns`` asks for, holding
    the parameters it fixes) from ``logs`` starting from ``vehicle`` (module docstring); the
    last ``holdout`` share of each log validates."""
    unknowns = unknowns or Unknowns()
    if not logs:
        raise ConfigError("LOG", None, "give at least one log")
    sample_time = logs[0].sample_time
    for log in logs:
        if abs(log.sample_time - sample_time) > 1e-6 * sample_time:
            raise ConfigError(
                "LOG",
                log.name,
                f"sampled every {log.sample_time:g} s, the first log "
                f"every {sample_time:g} s: give logs of one sample time",
            )
        if log.thrust is not None and log.thrust.shape[1] != vehicle.n_thrusters:
            raise ConfigError(
                "LOG",
                log.name,
                f"has {log.thrust.shape[1]} thrusters, the start vehicle {vehicle.n_thrusters}",
            )
    unknowns.check(vehicle, logs)
    if not 0.0 < holdout < 0.5:
        raise ConfigError("--holdout", holdout, "must be in (0, 0.5)")
    fit_logs, check_logs = [], []
    for log in logs:
        cut = round((1.0 - holdout) * log.steps)
        if cut < MIN_SAMPLES or log.steps - cut < MIN_SAMPLES // 4:
            raise ConfigError(
                "LOG",
                log.name,
                f"has {log.steps} samples, too short: need "
                f"{math.ceil(MIN_SAMPLES / (1 - holdout))} to fit and validate",
            )
        fit_logs.append(log.part(0, cut))
        check_logs.append(log.part(cut, log.steps))

    start = start_unknowns(vehicle)
    held = unknowns.held()
    estimated = np.array([name not in held for name in UNKNOWNS])
    first, A, b = equation_error(fit_logs, vehicle, held)
    # A least-squares value outside the physics (a negative mass, a positive damping) is
    # noise's: the fit starts from the start file's value there.
    lower = np.array([1e-9, 1e-9, 0.0, *[-np.inf] * 6, 1e-9, -np.inf, -np.inf])
    upper = np.array([np.inf, np.inf, np.inf, *[0.0] * 6, np.inf, np.inf, np.inf])
    initial = np.where((first >= lower) & (first <= upper), first, start)
    model = _Model(sample_time, model_substeps(sample_time, vehicle, logs), vehicle.Iz_rb)
    # Weighted first by the filter's noise estimate, then again by the residuals' (the
    # filter also removes fast dynamics it cannot follow), all unknowns free; those the
    # second fit finds unexcited are then fixed at their start values for a third.
    first_fit = output_error(fit_logs, vehicle, [initial, start], fixed=held, model=model)
    weight = 1.0 / np.maximum(first_fit.residual_rms, 1e-9)
    fit = output_error(fit_logs, vehicle, [first_fit.theta], fixed=held, weight=weight, model=model)
    excited = _excited(fit.theta, fit.half_width, A, b) & estimated
    final = fit
    if not excited[estimated].all():
        fixed = tuple(name for name, ok in zip(UNKNOWNS, excited, strict=True) if not ok)
        final = output_error(
            fit_logs,
            vehicle,
            [np.where(excited, fit.theta, start)],
            fixed=fixed,
            weight=weight,
            model=model,
        )
    # An excited parameter's interval is the final fit's; an unexcited one's the fit that
    # judged it (the final one holds it fixed); a held one's is its value.
    center = np.where(excited, final.theta, fit.theta)
    half_width = np.where(excited, final.half_width, fit.half_width)
    estimates = [
        ParameterEstimate(
            name=name,
            start=float(start[i]),
            equation_error=float(first[i]),
            value=float(final.theta[i]) if excited[i] else float(start[i]),
            ci95=(float(center[i] - half_width[i]), float(center[i] + half_width[i])),
            excited=bool(excited[i]),
            fixed=name in unknowns.fixed,
        )
        for i, name in enumerate(UNKNOWNS)
    ]
    identified = np.array([p.value for p in estimates])
    traces, errors, errors_start = [], [], []
    for log in check_logs:
        tau = applied_force(log, vehicle)
        psi = _heading(log)
        nu0 = smoothed(log)[0][0] if log.steps > filter_window(sample_time) else log.velocity[0]
        simulated, simulated_start = (
            _simulated(model, nu0, tau, psi, theta) for theta in (identified, start)
        )
        errors.append(simulated - log.velocity)
        errors_start.append(simulated_start - log.velocity)
        traces.append(
            {
                "t": sample_time * np.arange(log.steps + 1),
                "measured": log.velocity,
                "identified": simulated,
                "start": simulated_start,
            }
        )
    return Identification(
        parameters=estimates[:_P],
        logs=[log.name for log in logs],
        sample_time=sample_time,
        fit_samples=sum(log.steps for log in fit_logs),
        validation_samples=sum(log.steps for log in check_logs),
        noise_std=final.residual_rms,
        equation_error_used=first_fit.started_from == 0,
        validation_rms=np.sqrt(np.mean(np.vstack(errors) ** 2, axis=0)),
        validation_rms_start=np.sqrt(np.mean(np.vstack(errors_start) ** 2, axis=0)),
        iterations=final.iterations,
        solver_status=final.status,
        substeps=model.substeps,
        traces=traces,
        extras=[p for p in estimates[_P:] if p.name not in held],
    )


def _simulated(model: _Model, nu0: np.ndarray, tau: np.ndarray, heading, theta) -> np.ndarray:
    """The velocities (N+1, 3) ``theta`` (12,) predicts from the measured ``nu0`` under
    ``tau`` (N, 3): the velocity through the water simulated, the current added back."""
    current = current_rows(theta[_CURRENT], heading).T
    relative = model.simulate(nu0 - current[0], theta[_GAIN] * tau, theta[:_P])
    return relative + current
