"""Grey-box identification of the 3-DOF velocity model from logged velocities and thrusts.

The model is the velocity part of :mod:`auvmpc.models.vehicle` (Fossen 2021, ch. 6)::

    m11 u' = Xu u + Xuu |u| u + m22 v r + tau_u
    m22 v' = Yv v + Yvv |v| v - m11 u r + tau_v
    Iz  r' = Nr r + Nrr |r| r + (m11 - m22) u v + tau_r,    Iz = Iz_rb + Iz_added

with ``tau = T F`` from the start vehicle's (known) thruster layout. The unknowns are
:data:`PARAMETERS`; ``Iz_rb`` is kept from the start file (only the sum Iz is observable).
Optionally (:class:`HorizontalGreyBox`'s ``current`` and ``thrust_gain``, :data:`EXTRAS`)
also:

- a **constant current** ``(V_x, V_y)`` in the world frame of the log's heading. The model
  then holds for the velocity through the water ``nu_r = nu - nu_c`` with
  ``(u_c, v_c) = body_from_world(V, psi)`` (Fossen 2021, sec. 6.5; ``models.vehicle.dynamics``):
  since ``u_c' = r v_c`` and ``v_c' = -r u_c``, the relative velocity obeys the equations
  above exactly, current-free, and what is measured is ``nu_r + nu_c(psi)``, psi being the
  logged heading: the current is added to the model's output;
- a **thrust gain** ``g``, one factor on every thrust (``tau = g T F``): it multiplies the
  model's input. A gain and the masses and dampings scale together (``g tau = M nu' - D nu
  ...`` is unchanged when all of them are multiplied by one factor; ``Iz_rb`` does not help,
  ``Iz_added`` takes it up), so the gain is only identifiable against a parameter held at its
  start value (``identify(fixed=...)``, ``--fix``): the estimates are then in that
  parameter's scale.

1. Equation error (:func:`equation_error`). The equations are linear in the parameters
   once the accelerations are known: ``A theta = b`` with rows per sample and axis. The
   velocities and their derivatives come from a Savitzky-Golay filter (Savitzky and Golay
   1964), each axis' rows are scaled by its force level, and ``scipy.linalg.lstsq`` solves
   it. The current and the gain enter through the data, not as columns (the current
   through |u_r|, nonlinearly): the least squares are solved for each trial value of them
   inside a trust-region Gauss-Newton search (``scipy.optimize.least_squares``) over them
   (variable projection, Golub and Pereyra 1973). Noise in the regressors biases this
   estimate; it is a start, not the answer.
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
   95 % intervals are +-1.96 standard deviations (Klein and Morelli 2006, sec. 6.2). That
   holds for white residuals; model error (an input noisier than assumed, a term left out)
   correlates them in time and the Fisher variance is then too small. So each variance is
   the larger of it and the sandwich ``(J'J)^-1 S (J'J)^-1``, S the long-run covariance of
   the per-sample scores ``J_t' r_t`` within each segment with Bartlett weights out to the
   last lag the residuals are correlated at (Newey and West 1987; for output error, Morelli
   and Klein 1997: :func:`_sandwich`).
4. Excitation. A parameter is *excited* if its interval is narrower than its value
   (half-width <= 0.5 |value|) or if its interval moves its equation's force by less than
   :data:`SENSITIVITY_SHARE` of that force's RMS (a parameter that is small but well
   determined, e.g. a zero linear damping; for the current and the gain, the force
   through the equations' derivative with respect to them), judged on the second fit.
   Parameters that are not are fixed at their start value (no current, gain 1) and the fit
   is repeated without them; the vehicle file keeps their start values and the report
   names them. A parameter held as asked (``fixed``) is not judged.
5. Validation: the held-out end of each log is simulated from its first measured
   velocity with the identified and with the start parameters (the start without a current
   and with gain 1); RMS of the differences.
6. Model error (``GreyBox.split_check``: the roll and pitch model). The final fit is
   repeated on each half of the fitted logs; an excited parameter whose two values are
   further apart than their intervals allow together is named (``model_error``): the
   intervals do not hold what dominates its fit.

The steps are written once over a :class:`GreyBox`: the model's parameters and bounds, its
state and what the log measures of it, its equations as a CasADi function of the
parameters, the regression they become, and the maps from the logged commands to its input
and from its state to the logged outputs, which may hold parameters of their own (the
gain, the current). :class:`HorizontalGreyBox` is the 3-DOF model above (the default);
:class:`~auvmpc.identification.heave.HeaveGreyBox` the heave model (no current or gain).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from types import SimpleNamespace

import casadi as ca
import numpy as np
from scipy.linalg import lstsq
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from auvmpc.errors import ConfigError
from auvmpc.identification.logs import MIN_SAMPLES, VELOCITY_NAMES, VelocityLog
from auvmpc.models.integrators import rk4_step, rk4_step_time_varying
from auvmpc.models.layout import HORIZONTAL_VELOCITY, PLANAR_FORCE
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
    "GreyBox",
    "HorizontalGreyBox",
    "Identification",
    "ParameterEstimate",
    "equation_error",
    "identify",
    "output_error",
    "regression",
    "velocity_rhs",
]

PARAMETERS = ("m11", "m22", "Iz_added", "Xu", "Xuu", "Yv", "Yvv", "Nr", "Nrr")
MASSES = ("m11", "m22", "Iz_added")
# The 3-DOF model's optional unknowns beside the vehicle's (module docstring): one factor
# on every thrust, and the world-frame current (m/s).
GAIN = "thrust_gain"
CURRENT = ("current_x", "current_y")
EXTRAS = (GAIN, *CURRENT)
# Each one's neutral value (where it starts, and what the start model holds), its bounds
# and its typical size (the current's where neither the start nor the first estimate has
# one).
EXTRA_START = {GAIN: 1.0, CURRENT[0]: 0.0, CURRENT[1]: 0.0}
EXTRA_BOUNDS = {GAIN: (1e-9, np.inf), CURRENT[0]: (-np.inf, np.inf), CURRENT[1]: (-np.inf, np.inf)}
EXTRA_SIZE = {GAIN: 1.0, CURRENT[0]: 0.1, CURRENT[1]: 0.1}
# Where each velocity and force sits in the model's state and input (the velocity model is
# [u, v, r]' = f([u, v, r], [X, Y, N])).
_U, _V, _R = (HORIZONTAL_VELOCITY.index(name) for name in HORIZONTAL_VELOCITY.names)
_X, _Y, _N = (PLANAR_FORCE.index(name) for name in PLANAR_FORCE.names)
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
# Central differences of the regression in a searched extra (its units: m/s for the
# current, 1 for the gain), for the excitation test only.
EXTRA_STEP = 1e-4


def velocity_rhs(nu, tau, theta, iz_rb: float, absolute=np.abs):
    """[u', v', r'] of the model above (models.vehicle.velocity_derivative) with the
    parameters ``theta`` in :data:`PARAMETERS` order (any further entries are not read).
    NumPy arrays (``nu`` [u, v, r], ``tau`` [X, Y, N] along the first axis) or CasADi columns
    (``absolute=ca.fabs``)."""
    values = dict(zip(PARAMETERS, (theta[i] for i in range(len(PARAMETERS))), strict=True))
    coefficients = SimpleNamespace(**values, Iz=iz_rb + values["Iz_added"])
    derivative = velocity_derivative(coefficients, nu[_U], nu[_V], nu[_R], tau, absolute)
    if isinstance(derivative[0], ca.SX | ca.MX):
        return ca.vertcat(*derivative)
    return np.array(derivative)


def start_vector(vehicle: VehicleParams) -> np.ndarray:
    return np.array([float(getattr(vehicle, name)) for name in PARAMETERS])


def current_rows(current, heading: np.ndarray):
    """The current's body components (u_c, v_c, 0) at each heading (n,), as rows (3, n):
    ``current`` (2,) NumPy or a CasADi column (then a CasADi matrix)."""
    u_c, v_c = body_from_world(current, np.asarray(heading, dtype=float)[None, :])
    if isinstance(u_c, ca.MX | ca.SX):
        return ca.vertcat(u_c, v_c, ca.DM.zeros(1, len(heading)))
    return np.vstack([u_c, v_c, np.zeros_like(u_c)])


def regression(nu: np.ndarray, nu_dot: np.ndarray, tau: np.ndarray, iz_rb: float):
    """The model as ``A theta = b``: per axis a block of rows, one per sample.

    Parameters
    ----------
    nu, nu_dot, tau : velocities [u, v, r] (N, HORIZONTAL_VELOCITY.size), their derivatives
        and the applied force [X, Y, N] (N, PLANAR_FORCE.size)
    iz_rb : kg m2, the rigid-body yaw inertia (known)

    Returns
    -------
    A : (axes, N, len(PARAMETERS)), b : (axes, N): block a is axis a (surge, sway, yaw).
    """
    u, v, r = nu.T
    du, dv, dr = nu_dot.T
    zero = np.zeros_like(u)
    surge = [-du, v * r, zero, u, np.abs(u) * u, zero, zero, zero, zero]
    sway = [-u * r, -dv, zero, zero, zero, v, np.abs(v) * v, zero, zero]
    yaw = [u * v, -u * v, -dr, zero, zero, zero, zero, r, np.abs(r) * r]
    A = np.stack([np.column_stack(block) for block in (surge, sway, yaw)])
    b = np.stack([-tau[:, _X], -tau[:, _Y], -tau[:, _N] + iz_rb * dr])
    return A, b


def filter_window(sample_time: float) -> int:
    window = max(7, round(FILTER_WINDOW_S / sample_time))
    return window + 1 - window % 2  # odd


def smoothed(log: VelocityLog) -> tuple[np.ndarray, np.ndarray]:
    """Savitzky-Golay smoothed velocities and their derivatives, (N+1, log columns) each."""
    window = filter_window(log.sample_time)
    nu = savgol_filter(log.velocity, window, FILTER_ORDER, axis=0)
    nu_dot = savgol_filter(
        log.velocity, window, FILTER_ORDER, deriv=1, delta=log.sample_time, axis=0
    )
    return nu, nu_dot


def applied_force(log: VelocityLog, vehicle: VehicleParams) -> np.ndarray:
    """The body force [X, Y, N] per command, (N, PLANAR_FORCE.size): the log's own, or
    tau = T F."""
    if log.force is not None:  # the log holds the body force itself: no allocation
        return log.force
    return log.thrust @ vehicle.T.T


def noise_levels(logs: list[VelocityLog]) -> np.ndarray:
    """Each velocity's noise standard deviation, from what the filter removes (per column), with a
    floor of 1 % of its RMS (a noise-free log still needs finite weights)."""
    removed = np.vstack([log.velocity - smoothed(log)[0] for log in logs])
    window = filter_window(logs[0].sample_time)
    # The filter passes a share (about its hat-matrix diagonal) of white noise through.
    passed = savgol_filter(np.eye(window)[window // 2], window, FILTER_ORDER)[window // 2]
    noise = removed.std(axis=0) / math.sqrt(max(1.0 - passed, 1e-6))
    level = np.sqrt(np.mean(np.vstack([log.velocity for log in logs]) ** 2, axis=0))
    return np.maximum(noise, 0.01 * np.maximum(level, 1e-6))


class GreyBox(ABC):
    """A model :func:`identify` fits, from a start vehicle (module docstring).

    Its state ``x`` (``state_size``) holds what the log measures (``log.velocity``'s columns,
    named ``outputs`` in ``units``) at the indices ``measured``, plus :meth:`offset`; its
    input is :meth:`input` of the force the log's commands apply (:meth:`applied`), held over
    each sample. ``extras`` are the parameters of those two maps (the rest are the vehicle
    file's fields, which :meth:`regression` is linear in).
    """

    parameters: tuple[str, ...]  # the unknowns, as the vehicle file names them, and extras
    lower: np.ndarray  # physical bounds of each (a mass > 0, a damping <= 0; +-inf: none)
    upper: np.ndarray
    outputs: tuple[str, ...]  # the logged signals (log.velocity's columns)
    units: tuple[str, ...]
    measured: tuple[int, ...]  # where each output sits in the state
    state_size: int
    title: str  # for the vehicle file's header and the report
    extras: tuple[str, ...] = ()  # of ``parameters``: not the vehicle's, in the maps only
    # The last ``linear_inputs`` entries of the model's input are measured signals that
    # change within a sample (a roll model's yaw rate): :meth:`applied` gives them at the
    # sample's start and, as further columns, at its end, then their rates times the sample
    # time at both; the model goes between them by the cubic through those (the rest is
    # held, as a thrust is).
    linear_inputs: int = 0
    # Whether identify checks the fit on each half of the logs (step 6): a model whose
    # intervals are known to miss some of what it leaves out (roll and pitch).
    split_check: bool = False

    @property
    @abstractmethod
    def thrusters(self) -> int:
        """How many thrusts a log of this model holds per command."""

    @abstractmethod
    def start(self) -> np.ndarray:
        """The start vehicle's parameters (p,), the extras at their neutral values."""

    @abstractmethod
    def rhs(self) -> ca.Function:
        """The model as a CasADi function of the parameters: (x, input, theta) -> x'."""

    @abstractmethod
    def applied(self, log: VelocityLog) -> np.ndarray:
        """The force the log's commands apply (N, ni)."""

    @abstractmethod
    def filtered(
        self, log: VelocityLog, theta: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The smoothed state and its derivative (N+1, state_size) each, from the log, as
        the output map of ``theta`` (p,; default the start) gives them."""

    @abstractmethod
    def regression(self, x: np.ndarray, x_dot: np.ndarray, inputs: np.ndarray):
        """The model as ``A theta = b`` on samples of the state, its derivative and the
        input: ``A`` (axes, N, p - extras) over the parameters but the extras, ``b`` (axes,
        N), a block of rows per equation."""

    @abstractmethod
    def scale_floor(self) -> np.ndarray:
        """The smallest typical size of each parameter (p,), for IPOPT's scaling."""

    @abstractmethod
    def damping_rate(self, logs: list[VelocityLog]) -> float:
        """How fast the start vehicle's damping acts at twice the logged speeds (1/s)."""

    def input(self, force, theta):
        """The model's input from the commands' ``force`` (any shape) under ``theta`` (p,),
        NumPy or CasADi: the force itself unless a parameter acts on it."""
        return force

    def offset(self, theta, log: VelocityLog, first: int, stop: int):
        """What the outputs hold beyond the state's measured components at samples
        ``first``..``stop`` - 1 of ``log`` under ``theta`` (p,), as rows (outputs, n), NumPy or
        CasADi; None: nothing."""
        return None

    def check(self, logs: list[VelocityLog], fixed: tuple[str, ...]) -> None:
        """One ConfigError line for a ``fixed`` name that is not a parameter (a model adds
        what its extras need of the logs)."""
        unknown = [name for name in fixed if name not in self.parameters]
        if unknown:
            raise ConfigError(
                "--fix", ",".join(unknown), f"not a parameter identify estimates: one of "
                f"{', '.join(self.parameters)}",
            )  # fmt: skip


class HorizontalGreyBox(GreyBox):
    """The 3-DOF velocity model (module docstring) of ``vehicle``'s thruster layout, with a
    constant world-frame ``current`` and a ``thrust_gain`` as further unknowns if asked."""

    outputs = VELOCITY_NAMES
    units = ("m/s", "m/s", "rad/s")
    measured = tuple(range(HORIZONTAL_VELOCITY.size))
    state_size = HORIZONTAL_VELOCITY.size
    title = "grey-box 3-DOF velocity model"

    def __init__(
        self, vehicle: VehicleParams, current: bool = False, thrust_gain: bool = False
    ) -> None:
        self.vehicle = vehicle
        self.extras = ((GAIN,) if thrust_gain else ()) + (CURRENT if current else ())
        self.parameters = PARAMETERS + self.extras
        lower, upper = ([EXTRA_BOUNDS[name][i] for name in self.extras] for i in (0, 1))
        self.lower = np.array([1e-9, 1e-9, 0.0, *[-np.inf] * 6, *lower])
        self.upper = np.array([np.inf, np.inf, np.inf, *[0.0] * 6, *upper])

    @property
    def thrusters(self) -> int:
        return self.vehicle.n_thrusters

    def start(self) -> np.ndarray:
        return np.array([*start_vector(self.vehicle), *(EXTRA_START[n] for n in self.extras)])

    def rhs(self) -> ca.Function:
        nu, tau = ca.SX.sym("nu", HORIZONTAL_VELOCITY.size), ca.SX.sym("tau", PLANAR_FORCE.size)
        theta = ca.SX.sym("theta", len(self.parameters))
        derivative = velocity_rhs(nu, tau, theta, self.vehicle.Iz_rb, ca.fabs)
        return ca.Function("velocity_rhs", [nu, tau, theta], [derivative])

    def applied(self, log: VelocityLog) -> np.ndarray:
        return applied_force(log, self.vehicle)

    def input(self, force, theta):
        """``tau = g T F`` with the thrust gain g, if it is an unknown."""
        if GAIN not in self.extras:
            return force
        return theta[self.parameters.index(GAIN)] * force

    def _current(self, theta):
        """theta's current (2,), or None where the model has none."""
        if CURRENT[0] not in self.extras:
            return None
        at = self.parameters.index(CURRENT[0])
        return theta[at : at + 2]

    def offset(self, theta, log: VelocityLog, first: int, stop: int):
        """The current's body components at the logged headings: the log measures the
        velocity over the ground, the model's state is the velocity through the water."""
        current = self._current(theta)
        if current is None:
            return None
        return current_rows(current, log.heading[first:stop])

    def filtered(
        self, log: VelocityLog, theta: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The smoothed velocities through the water and their derivatives: the current's
        body components at the (smoothed) heading and their rates ``u_c' = r v_c``,
        ``v_c' = -r u_c`` taken off."""
        nu, nu_dot = smoothed(log)
        current = None if theta is None else self._current(theta)
        if current is None:
            return nu, nu_dot
        psi = savgol_filter(log.heading, filter_window(log.sample_time), FILTER_ORDER)
        u_c, v_c, zero = current_rows(np.asarray(current, dtype=float), psi)
        r = nu[:, _R]
        return (
            nu - np.column_stack([u_c, v_c, zero]),
            nu_dot - np.column_stack([r * v_c, -r * u_c, zero]),
        )

    def regression(self, x: np.ndarray, x_dot: np.ndarray, inputs: np.ndarray):
        return regression(x, x_dot, inputs, self.vehicle.Iz_rb)

    def scale_floor(self) -> np.ndarray:
        vehicle = self.vehicle
        axis_mass = {"X": vehicle.m11, "Y": vehicle.m22, "N": vehicle.Iz}
        masses = {"m11": vehicle.m11, "m22": vehicle.m22, "Iz_added": vehicle.Iz}
        floor = [0.01 * (masses.get(name) or axis_mass[name[0]]) for name in PARAMETERS]
        return np.array(floor + [EXTRA_SIZE[name] for name in self.extras])

    def damping_rate(self, logs: list[VelocityLog]) -> float:
        top = 2.0 * np.max(np.vstack([np.abs(log.velocity) for log in logs]), axis=0)
        return max(damping_rates(self.vehicle, *top))

    def check(self, logs: list[VelocityLog], fixed: tuple[str, ...]) -> None:
        """Also a gain without a scale to be measured in (module docstring), and a current
        asked of a log without a heading."""
        super().check(logs, fixed)
        start = dict(zip(self.parameters, self.start(), strict=True))
        if GAIN in self.extras and not any(start[name] != 0 for name in fixed):
            raise ConfigError(
                "--thrust-gain", ",".join(fixed) or None,
                "a gain on every thrust and the masses and dampings scale together (the log "
                "cannot tell g tau = M nu' - D nu from tau = M/g nu' - D/g nu): hold one "
                "nonzero parameter at the start file's value, e.g. --fix m11",
            )  # fmt: skip
        for log in logs if CURRENT[0] in self.extras else ():
            if log.heading is None:
                raise ConfigError(
                    "LOG", log.name, "has no heading, which --current needs (a current fixed "
                    "in the world turns in the body as the vehicle turns)",
                )  # fmt: skip


def _observed(greybox: GreyBox, states, theta, log: VelocityLog, first: int):
    """The outputs (outputs, n) the model's ``states`` (state_size, n) at samples ``first``..
    give: their measured components plus the output map's offset."""
    seen = states[list(greybox.measured), :]
    offset = greybox.offset(theta, log, first, first + states.shape[1])
    return seen if offset is None else seen + offset


def _stacked_regression(logs: list[VelocityLog], greybox: GreyBox, theta: np.ndarray):
    """The regression rows of every log (``GreyBox.regression``) with its maps at ``theta``."""
    blocks_a, blocks_b = [], []
    for log in logs:
        x, x_dot = greybox.filtered(log, theta)
        tau = greybox.input(greybox.applied(log), theta)
        # The derivative at t_k spans the commands before and after it: their mean.
        tau_k = np.vstack([tau[:1], 0.5 * (tau[:-1] + tau[1:])])
        edge = filter_window(log.sample_time) // 2  # the filter's ends are extrapolations
        rows = slice(edge, log.steps - edge)
        A, b = greybox.regression(x[:-1][rows], x_dot[:-1][rows], tau_k[rows])
        blocks_a.append(A)
        blocks_b.append(b)
    return np.concatenate(blocks_a, axis=1), np.concatenate(blocks_b, axis=1)


def equation_error(
    logs: list[VelocityLog],
    vehicle: VehicleParams,
    greybox: GreyBox | None = None,
    fixed: tuple[str, ...] = (),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares parameters (p,) of ``greybox`` (default the 3-DOF model of
    ``vehicle``), the ``fixed`` ones at their start, and the regression ``A`` (axes, N, p),
    ``b`` (axes, N) at that estimate, each axis' rows scaled by its force RMS so that N and
    N m weigh alike. The extras are searched by variable projection (module docstring);
    ``A``'s columns of them are the rows' derivatives with respect to them."""
    greybox = greybox or HorizontalGreyBox(vehicle)
    start = greybox.start()
    names = greybox.parameters
    terms = np.array([name not in greybox.extras for name in names])
    searched = np.array([name in greybox.extras and name not in fixed for name in names])
    free = np.array([name not in fixed for name in names])[terms]
    held = np.where(free, 0.0, start[terms])
    A, b = _stacked_regression(logs, greybox, start)
    scale = np.sqrt(np.mean(b**2, axis=1)) + np.sqrt(np.mean((A @ start[terms]) ** 2, 1))
    scale = np.where(scale > 0, scale, 1.0)

    def with_extras(values) -> np.ndarray:
        theta = start.copy()
        theta[searched] = values
        return theta

    def solve(values) -> tuple[np.ndarray, np.ndarray]:
        """The free terms' least squares at the extras ``values``, and its residual."""
        rows, rhs = _stacked_regression(logs, greybox, with_extras(values))
        rhs = (rhs - rows @ held) / scale[:, None]
        rows = (rows[..., free] / scale[:, None, None]).reshape(-1, int(free.sum()))
        solution, *_ = lstsq(rows, rhs.ravel())
        return solution, rows @ solution - rhs.ravel()

    values = start[searched]
    if searched.any():  # variable projection over the extras (module docstring)
        size = np.maximum(np.abs(values), greybox.scale_floor()[searched])
        values = least_squares(lambda c: solve(c)[1], values, x_scale=size).x
    theta = with_extras(values)
    theta[np.flatnonzero(terms)[free]] = solve(values)[0]
    A, b = _stacked_regression(logs, greybox, theta)
    columns = np.zeros((*b.shape, len(names)))
    columns[..., terms] = A
    for i in np.flatnonzero(searched):
        residuals = []
        for sign in (1.0, -1.0):
            moved = theta.copy()
            moved[i] += sign * EXTRA_STEP
            rows, rhs = _stacked_regression(logs, greybox, moved)
            residuals.append(rows @ theta[terms] - rhs)
        columns[..., i] = (residuals[0] - residuals[1]) / (2 * EXTRA_STEP)
    return theta, columns, b


@dataclass
class _Model:
    """The simulated model (a :meth:`GreyBox.rhs`) for one sample time: one RK4-integrated
    sample, its input held over it but for the last ``linear`` entries, which follow the
    cubic Hermite curve through their values and rates at the sample's start and end
    (:attr:`GreyBox.linear_inputs`)."""

    sample_time: float
    substeps: int
    rhs: ca.Function  # (x, input, theta) -> x'
    linear: int = 0

    def __post_init__(self) -> None:
        size = self.rhs.size1_in(1)
        nu, tau = ca.SX.sym("x", self.rhs.size1_in(0)), ca.SX.sym("input", size + 3 * self.linear)
        theta = ca.SX.sym("theta", self.rhs.size1_in(2))
        h = self.sample_time / self.substeps

        def f(x, u):
            return self.rhs(x, u, theta)

        x = nu
        if self.linear == 0:
            for _ in range(self.substeps):
                x = rk4_step(f, x, tau, h)
        else:
            m = self.linear
            start, end = tau[size - m : size], tau[size : size + m]
            slope_a, slope_b = tau[size + m : size + 2 * m], tau[size + 2 * m :]

            def varying(t, x):  # t: s into the sample; cubic Hermite between its ends
                s = t / self.sample_time
                h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
                h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
                moving = h00 * start + h10 * slope_a + h01 * end + h11 * slope_b
                return self.rhs(x, ca.vertcat(tau[: size - m], moving), theta)

            for i in range(self.substeps):
                x = rk4_step_time_varying(varying, i * h, x, h)
        self.step = ca.Function("step", [nu, tau, theta], [x])
        self._rollouts: dict[int, ca.Function] = {}

    def rollout(self, steps: int) -> ca.Function:
        """(x0 (nx,), input (ni, steps), theta (p, steps)) -> states at k = 1..steps."""
        if steps not in self._rollouts:
            self._rollouts[steps] = self.step.mapaccum("rollout", steps)
        return self._rollouts[steps]

    def simulate(self, nu0, tau: np.ndarray, theta: np.ndarray) -> np.ndarray:
        """Numeric rollout: (N+1, nx) from nu0 under tau (N, ni)."""
        steps = len(tau)
        out = self.rollout(steps)(nu0, tau.T, np.tile(theta[:, None], (1, steps)))
        return np.vstack([np.asarray(nu0, dtype=float)[None, :], np.asarray(out).T])


def model_substeps(sample_time: float, greybox: GreyBox, logs: list[VelocityLog]) -> int:
    """RK4 steps per sample: at most the plant's step (DEFAULT_PLANT_STEP_S) each, and
    stable for the start vehicle's damping at twice the logged speeds (the fit moves the
    parameters)."""
    stable = RK4_STABLE_STEP / max(greybox.damping_rate(logs), 1e-9) / 2.0
    return substeps_for(sample_time, min(stable, DEFAULT_PLANT_STEP_S))


@dataclass
class _Fit:
    theta: np.ndarray  # (p,)
    half_width: np.ndarray  # (p,) 95 % half-widths, 0 for a fixed parameter, inf unknown
    residual_rms: np.ndarray  # (ny,) RMS of the output residuals (u, v, r: m/s, m/s, rad/s)
    started_from: int  # which candidate
    iterations: int
    status: str


def _segments(log: VelocityLog, length: int) -> list[tuple[int, int]]:
    count = max(1, round(log.steps / length))
    edges = np.linspace(0, log.steps, count + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]


def _scales(start: np.ndarray, first: np.ndarray, greybox: GreyBox) -> np.ndarray:
    """Typical size per parameter, so that IPOPT's variables are of order one."""
    return np.maximum.reduce([np.abs(start), np.abs(first), greybox.scale_floor()])


def output_error(
    logs: list[VelocityLog],
    vehicle: VehicleParams,
    candidates: list[np.ndarray],
    fixed: tuple[str, ...] = (),
    weight: np.ndarray | None = None,
    model: _Model | None = None,
    greybox: GreyBox | None = None,
) -> _Fit:
    """Output-error refinement (module docstring, steps 2 and 3) of ``greybox`` (default
    the 3-DOF model of ``vehicle``) from whichever of the ``candidates`` (p,) simulates the
    log best; the ``fixed`` parameters stay at that candidate's values. ``weight`` (ny,):
    per output, 1 / its noise level (default: the filter's estimate). Each segment's free
    initial state is the model's (the velocity through the water); the output map's offset
    (the current's body components at the logged headings) is added to what it predicts."""
    greybox = greybox or HorizontalGreyBox(vehicle)
    sample_time = logs[0].sample_time
    model = model or _Model(
        sample_time,
        model_substeps(sample_time, greybox, logs),
        greybox.rhs(),
        greybox.linear_inputs,
    )
    start = greybox.start()
    scale = _scales(start, candidates[0], greybox)
    weight = 1.0 / noise_levels(logs) if weight is None else np.asarray(weight, dtype=float)
    n_parameters, nx = len(greybox.parameters), greybox.state_size
    z = ca.MX.sym("z", n_parameters)
    theta = z * scale
    length = max(MIN_SAMPLES // 4, round(SEGMENT_S / sample_time))
    initial, starts, residuals, lengths = [], [], [], []
    for log in logs:
        tau = greybox.applied(log)
        for a, b in _segments(log, length):
            x0 = ca.MX.sym(f"x0_{len(initial)}", nx)
            initial.append(x0)
            starts.append((log, a))
            steps = b - a
            lengths.append(steps)
            inputs = greybox.input(tau[a:b].T, theta)
            predicted = model.rollout(steps)(x0, inputs, ca.repmat(theta, 1, steps))
            measured = log.velocity[a + 1 : b + 1].T
            observed = _observed(greybox, predicted, theta, log, a + 1)
            residuals.append(ca.vec((observed - measured) * weight))
            first = _observed(greybox, x0, theta, log, a)
            residuals.append((first - log.velocity[a]) * weight)
    x = ca.vertcat(z, *initial)
    residual = ca.vertcat(*residuals)
    lower, upper = _bounds(greybox)
    is_fixed = np.array([name in fixed for name in greybox.parameters])

    def guess(candidate: np.ndarray) -> np.ndarray:
        """The segments' initial states from the filtered logs under ``candidate``'s maps."""
        states = {id(log): greybox.filtered(log, candidate)[0] for log in logs}
        return np.concatenate([states[id(log)][a] for log, a in starts])

    cost = ca.Function("cost", [x], [0.5 * ca.sumsqr(residual)])
    costs = [float(cost(np.concatenate([c / scale, guess(c)]))) for c in candidates]
    best = min(range(len(costs)), key=lambda i: costs[i] if math.isfinite(costs[i]) else math.inf)
    z0 = np.clip(candidates[best] / scale, lower, upper)
    lower = np.where(is_fixed, z0, lower)
    upper = np.where(is_fixed, z0, upper)
    n_initial = nx * len(initial)
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
    optimum[:n_parameters] = np.clip(optimum[:n_parameters], lower, upper)
    jacobian_of = ca.Function("J", [x], [residual, ca.jacobian(residual, x)])
    r_value, j_value = (np.asarray(value) for value in jacobian_of(optimum))
    r_value = r_value.ravel()
    free = np.concatenate([~is_fixed, np.ones(n_initial, dtype=bool)])
    J = j_value[:, free]
    dof = max(1, r_value.size - J.shape[1])
    variance = float(r_value @ r_value) / dof
    information = J.T @ J
    half_width = np.zeros(n_parameters)
    outputs = len(greybox.measured)
    try:
        inverse = np.linalg.inv(information)
        fisher = variance * np.diag(inverse)
        # Colored residuals (model error) make the Fisher variance too small: the larger of
        # it and the sandwich's (step 3).
        sandwich = np.diag(_sandwich(J, r_value, inverse, lengths, outputs))
        variances = np.maximum(fisher, sandwich)[: int((~is_fixed).sum())]
        std = np.sqrt(np.clip(variances, 0.0, None))
    except np.linalg.LinAlgError:
        std = np.full(int((~is_fixed).sum()), np.inf)
    half_width[~is_fixed] = Z95 * std * scale[~is_fixed]
    residual_rms = np.sqrt(np.mean(r_value.reshape(-1, outputs) ** 2, axis=0)) / weight
    return _Fit(
        theta=optimum[:n_parameters] * scale,
        half_width=half_width,
        residual_rms=residual_rms,
        started_from=best,
        iterations=int(stats.get("iter_count", -1)),
        status=str(stats.get("return_status", "")),
    )


def _sandwich(
    J: np.ndarray, r: np.ndarray, inverse: np.ndarray, lengths: list[int], outputs: int
) -> np.ndarray:
    """The covariance of the output-error estimate with serially correlated residuals
    (step 3): ``H^-1 S H^-1`` with ``H = J'J`` (``inverse``: H^-1) and ``S`` the long-run
    covariance of the per-sample scores ``g_t = J_t' r_t`` within each segment, Bartlett
    weights out to :func:`correlated_lags` (Newey and West 1987; for output error, Morelli
    and Klein 1997). ``J``, ``r``: rows as output_error stacks them, per segment its
    ``steps`` samples (``lengths``) of ``outputs`` rows each, then its first sample."""
    scores, series, at = [], [], 0
    for steps in lengths:
        rows = (steps + 1) * outputs
        block_r, block_j = r[at : at + rows], J[at : at + rows]
        at += rows
        # in time order: the first sample's rows come last in the block
        order = np.r_[steps * outputs : rows, 0 : steps * outputs]
        block_r = block_r[order].reshape(steps + 1, outputs)
        block_j = block_j[order].reshape(steps + 1, outputs, -1)
        scores.append(np.einsum("tij,ti->tj", block_j, block_r))
        series.append(block_r)
    lags = correlated_lags(series)
    meat = np.zeros((J.shape[1], J.shape[1]))
    for g in scores:
        meat += g.T @ g
        for k in range(1, min(lags, len(g) - 1) + 1):
            cross = g[:-k].T @ g[k:]
            meat += (1.0 - k / (lags + 1)) * (cross + cross.T)
    return inverse @ meat @ inverse


def correlated_lags(series: list[np.ndarray]) -> int:
    """How many lags the residuals ``series`` (per segment, (n, outputs)) stay correlated:
    the last lag at which an output's autocorrelation, pooled over the segments, is outside
    the band white noise stays in (2 / sqrt(samples)), before :data:`QUIET_LAGS` lags in a
    row inside it; at most a quarter of the shortest segment. The last, not the first: a
    model error at the roll period swings its autocorrelation through zero within a quarter
    period and back."""
    samples = sum(len(x) for x in series)
    band = 2.0 / math.sqrt(samples)
    power = np.maximum(sum(np.sum(x**2, axis=0) for x in series), 1e-300)
    longest = max(1, min(len(x) for x in series) // 4)
    lags = 0
    for k in range(1, longest + 1):
        pooled = sum(np.sum(x[:-k] * x[k:], axis=0) for x in series) / power
        if np.any(np.abs(pooled) > band):
            lags = k
        elif k - lags >= QUIET_LAGS:
            break
    return lags


# Lags in a row inside the white-noise band that end the residuals' correlation.
QUIET_LAGS = 5


def _bounds(greybox: GreyBox) -> tuple[np.ndarray, np.ndarray]:
    """The physical bounds on the scaled parameters (a mass positive, an added yaw inertia
    >= 0, a damping <= 0: ``greybox.lower``, ``upper``); every magnitude within a factor
    MAGNITUDE of its scale."""
    low, high = greybox.lower, greybox.upper
    lower = np.where(low > 0, 1.0 / MAGNITUDE, np.where(low == 0, 0.0, -MAGNITUDE))
    upper = np.where(high < 0, -1.0 / MAGNITUDE, np.where(high == 0, 0.0, MAGNITUDE))
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
    # Excited, but the log's two halves give values further apart than their intervals
    # allow: something the model and its intervals do not hold dominates the fit (step 6).
    model_error: bool = False


@dataclass
class Identification:
    """What :func:`identify` found and how well it predicts the held-out data."""

    parameters: list[ParameterEstimate]
    logs: list[str]
    sample_time: float
    fit_samples: int
    validation_samples: int
    noise_std: np.ndarray  # (ny,) RMS of the fit's residuals: the noise of each output
    equation_error_used: bool  # the fit started from it (else from the start file)
    validation_rms: np.ndarray  # (ny,) identified model on the held-out parts
    validation_rms_start: np.ndarray  # (ny,) the start model there
    iterations: int
    solver_status: str
    substeps: int
    traces: list[dict[str, np.ndarray]] = field(default_factory=list)  # per log, for figures
    outputs: tuple[str, ...] = VELOCITY_NAMES  # what the logs measured (the RMS' order)
    units: tuple[str, ...] = HorizontalGreyBox.units
    model: str = HorizontalGreyBox.title
    # The model's extras (thrust gain, current: GreyBox.extras), estimated like the
    # parameters, not the vehicle file's fields.
    extras: list[ParameterEstimate] = field(default_factory=list)

    @property
    def unexcited(self) -> list[str]:
        return [p.name for p in self.parameters + self.extras if not (p.excited or p.fixed)]

    @property
    def model_error(self) -> list[str]:
        """The excited parameters the halves of the logs disagree on (step 6)."""
        return [p.name for p in self.parameters + self.extras if p.model_error]

    @property
    def fixed(self) -> list[str]:
        return [p.name for p in self.parameters + self.extras if p.fixed]

    def vehicle_values(self) -> dict[str, float]:
        return {p.name: p.value for p in self.parameters}

    def extra(self, name: str) -> ParameterEstimate | None:
        """The estimate of the extra ``name`` (:data:`EXTRAS`), or None where the model had
        none."""
        return next((p for p in self.extras if p.name == name), None)


def _excited(theta, half_width, A, b, terms) -> np.ndarray:
    """Module docstring, step 4. ``terms`` (p,): the parameters whose columns of ``A`` are
    terms of the equations (not the extras' derivatives), which make up each equation's
    force with ``b``."""
    relative = half_width <= RELATIVE_HALF_WIDTH * np.abs(theta)
    products = (A[..., terms] * theta[terms]) ** 2
    force = np.sqrt(np.mean(products, axis=(1, 2)) * products.shape[2] + np.mean(b**2, axis=1))
    column = np.sqrt(np.mean(A**2, axis=1))  # (axes, p) each regressor's RMS per axis
    moved = half_width[None, :] * column  # force the interval moves, per axis
    share = np.where(column > 0, moved / np.maximum(force[:, None], 1e-12), np.inf).min(axis=0)
    return relative | (share <= SENSITIVITY_SHARE)


def identify(
    logs: list[VelocityLog],
    vehicle: VehicleParams,
    holdout: float = 0.2,
    greybox: GreyBox | None = None,
    fixed: tuple[str, ...] = (),
) -> Identification:
    """Identify the parameters of ``greybox`` (default the 3-DOF model's, :data:`PARAMETERS`)
    from ``logs`` starting from ``vehicle`` (module docstring), the ``fixed`` ones held at
    their start values; the last ``holdout`` share of each log validates."""
    greybox = greybox or HorizontalGreyBox(vehicle)
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
        if log.thrust is not None and log.thrust.shape[1] != greybox.thrusters:
            raise ConfigError(
                "LOG",
                log.name,
                f"has {log.thrust.shape[1]} thrusters, the start vehicle {greybox.thrusters}",
            )
    greybox.check(logs, fixed)
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

    start = greybox.start()
    estimated = np.array([name not in fixed for name in greybox.parameters])
    first, A, b = equation_error(fit_logs, vehicle, greybox, fixed)
    # A least-squares value outside the physics (a negative mass, a positive damping) is
    # noise's: the fit starts from the start file's value there.
    lower, upper = greybox.lower, greybox.upper
    initial = np.where((first >= lower) & (first <= upper), first, start)
    model = _Model(
        sample_time,
        model_substeps(sample_time, greybox, logs),
        greybox.rhs(),
        greybox.linear_inputs,
    )
    # Weighted first by the filter's noise estimate, then again by the residuals' (the
    # filter also removes fast dynamics it cannot follow), all parameters free but the held
    # ones; those the second fit finds unexcited are then fixed at their start values for a
    # third.
    first_fit = output_error(
        fit_logs, vehicle, [initial, start], fixed, model=model, greybox=greybox
    )
    weight = 1.0 / np.maximum(first_fit.residual_rms, 1e-9)
    fit = output_error(
        fit_logs, vehicle, [first_fit.theta], fixed, weight=weight, model=model, greybox=greybox
    )
    terms = np.array([name not in greybox.extras for name in greybox.parameters])
    excited = _excited(fit.theta, fit.half_width, A, b, terms) & estimated
    final, fixed_now = fit, fixed
    if not excited[estimated].all():
        held = tuple(name for name, ok in zip(greybox.parameters, excited, strict=True) if not ok)
        fixed_now = held
        final = output_error(
            fit_logs,
            vehicle,
            [np.where(excited, fit.theta, start)],
            fixed=held,
            weight=weight,
            model=model,
            greybox=greybox,
        )
    inconsistent = np.zeros(len(greybox.parameters), dtype=bool)
    if greybox.split_check:
        inconsistent = (
            _halves_disagree(fit_logs, vehicle, final, fixed_now, weight, model, greybox) & excited
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
            fixed=name in fixed,
            model_error=bool(inconsistent[i]),
        )
        for i, name in enumerate(greybox.parameters)
    ]
    identified = np.array([p.value for p in estimates])
    traces, errors, errors_start = [], [], []
    for whole, log in zip(logs, check_logs, strict=True):
        simulated, simulated_start = (
            _held_out(greybox, model, whole, log, theta) for theta in (identified, start)
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
        parameters=[p for p in estimates if p.name not in greybox.extras],
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
        outputs=greybox.outputs,
        units=greybox.units,
        model=greybox.title,
        extras=[p for p in estimates if p.name in greybox.extras],
    )


def _halves_disagree(
    logs: list[VelocityLog],
    vehicle: VehicleParams,
    final: _Fit,
    fixed: tuple[str, ...],
    weight: np.ndarray,
    model: _Model,
    greybox: GreyBox,
) -> np.ndarray:
    """Step 6: the final fit repeated on each half of the fitted logs (from its values, the
    same parameters held); (p,) whether the halves' values are further apart than their
    95 % intervals allow together (|a - b| > sqrt(h_a^2 + h_b^2)). With a model that holds
    and intervals that carry its errors, that happens to 1 parameter in 20; model error
    (something the model leaves out or gets wrong, or an input noisier than the intervals
    assume) moves the halves apart."""
    halves = []
    for part in (0, 1):
        pieces = []
        for log in logs:
            cut = log.steps // 2
            pieces.append(log.part(0, cut) if part == 0 else log.part(cut, log.steps))
        halves.append(
            output_error(
                pieces, vehicle, [final.theta], fixed, weight=weight, model=model, greybox=greybox
            )  # fmt: skip
        )
    a, b = halves
    together = np.hypot(a.half_width, b.half_width)
    return np.abs(a.theta - b.theta) > together


def _held_out(
    greybox: GreyBox, model: _Model, whole: VelocityLog, log: VelocityLog, theta: np.ndarray
) -> np.ndarray:
    """The outputs (N+1, ny) ``theta`` predicts over the held-out end ``log`` of ``whole``
    from its first filtered state, under its commands."""
    seen = list(greybox.measured)
    if whole.steps > filter_window(log.sample_time):
        # From the filter over the whole log: at the cut an inner point, not the filter's
        # extrapolated end (a heave rate from the depth there drifts the simulated depth)
        x0 = greybox.filtered(whole, theta)[0][whole.steps - log.steps]
    else:  # too short to filter: the first measurement, the rest of the state at rest
        x0 = np.zeros(greybox.state_size)
        offset = greybox.offset(theta, log, 0, 1)
        x0[seen] = log.velocity[0] - (0.0 if offset is None else offset[:, 0])
    states = model.simulate(x0, greybox.input(greybox.applied(log), theta), theta)
    return _observed(greybox, states.T, theta, log, 0).T
