"""The fastest straight and level flight a 6-DOF vehicle can hold as it is now.

A torpedo whose stern planes jam at an angle can still hold its depth, but only at one
speed: the jammed fin's lift and moment grow with the speed squared, the hull's weight and
buoyancy do not, so there is one speed (for each jam) at which the pitch trim that balances
the fin leaves the flight path level (REMUS 100's nominal model, planes at 5 deg: 1.01 m/s,
at 10 deg: 0.83 m/s, against the survey's 1.5 m/s; tests/test_level_flight.py). Flown faster
it climbs or dives whatever the propeller does, which is why a controller told only to keep
the mission's speed loses the depth (docs/faults.md).

A level flight here is a steady state of the model with no angular rate and no vertical
velocity over ground, in still water: over the body velocities (u, v, w), the roll and pitch
and every free input c (a stuck one held at its value),

    nu' (x, c) = 0,  z' (x) = 0,  0.1 cap <= u <= cap,  |phi|, |theta| <= bound,
    lower <= c <= upper,

with u as large as that allows. Seven equations: a healthy torpedo holds a level flight at
any speed (its propeller sets the speed), a jammed one only at isolated speeds. Solved as
bounded least squares (SciPy's trust-region reflective, the model's Jacobian from CasADi)
from a few starting speeds, each first pulled weakly towards the cap, then solved without
the pull; the fastest that solves the equations wins. A neutrally buoyant vehicle at rest
is a level flight too (no flow, no force): below a tenth of the cap it is not flying the
mission, and not looked at. The answer is the speed to fly the mission at, not the inputs
to fly it with: the controller finds those on the way. A vehicle with no such flight (a
rudder jammed over: no sideslip balances both its side force and its yaw moment) has none.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import casadi as ca
import numpy as np
from scipy.optimize import least_squares

from auvmpc.models.six_dof import SIX_DOF

__all__ = ["LevelFlight", "fastest_level_flight"]

_NX = SIX_DOF.size
_PHI, _THETA = SIX_DOF.index("phi"), SIX_DOF.index("theta")
_BODY = SIX_DOF.span("u", "r")  # nu: what must not change
_Z = SIX_DOF.index("z")
# The slowest flight looked at, as a share of the cap (module docstring).
_SLOWEST = 0.1
# The starting speeds, as shares of the cap: a jammed vehicle's flights are isolated, and
# least squares finds the one nearest its start.
_STARTS = (1.0, 0.75, 0.5, 0.3)
# The first pass's pull of the speed towards the cap (a residual of this times the speed's
# shortfall, m/s): weak against the equations (m/s2), strong enough to lean towards the
# fastest flight where there are many.
_PULL = 1e-2
# How close to steady a flight must be: the largest rate left (m/s2, rad/s2, m/s). 1e-5 m/s
# of depth is 3.6 cm an hour; the planes held at exactly 0 deg leave 3.6e-7 at 1.5 m/s
# (their exact trim is a hair off 0), a 5 deg jam flown at 1.5 m/s 1e-2.
_STEADY = 1e-5


@dataclass(frozen=True)
class LevelFlight:
    """A steady straight and level flight: the speed through the water (m/s), the pitch
    (rad) it is flown at, every input that holds it (each in its own unit), and how the
    steady flight's depth rate moves with the speed there (m/s per m/s, down positive):
    flown a little faster, a torpedo with its planes jammed nose down dives (positive)."""

    speed: float
    pitch: float
    inputs: np.ndarray
    sinking_per_speed: float


def fastest_level_flight(
    flow: ca.Function,
    lower: np.ndarray,
    upper: np.ndarray,
    cap: float,
    tilt_bound: float,
    start: np.ndarray | None = None,
) -> LevelFlight | None:
    """The fastest level flight (module docstring) no faster than ``cap`` (m/s); None where
    there is none.

    ``flow(x, c)``: the model's state derivative (12,) in still water for the inputs ``c``
    as the vehicle is now (its faults in it); ``lower``, ``upper``: each input's bounds,
    equal for an input held at a value; ``tilt_bound``: the largest roll and pitch (rad);
    ``start``: inputs to start from besides the middle of their ranges (a command held in a
    turn, its rudder hard over, starts the least squares far from a straight flight)."""
    lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
    free = upper > lower
    velocity, attitude = ca.SX.sym("nu_linear", 3), ca.SX.sym("phi_theta", 2)
    moved = ca.SX.sym("c_free", int(free.sum()))
    inputs = ca.vertcat(*(moved[int(free[:i].sum())] if free[i] else lower[i]
                          for i in range(lower.size)))  # fmt: skip
    state = ca.vertcat(
        ca.SX.zeros(_PHI), attitude, ca.SX.zeros(_BODY.start - _THETA - 1), velocity,
        ca.SX.zeros(_NX - _BODY.start - 3),
    )  # fmt: skip
    derivative = flow(state, inputs)
    unknowns = ca.vertcat(velocity, attitude, moved)
    steady = ca.vertcat(derivative[_BODY.start : _BODY.stop], derivative[_Z])
    equations = ca.Function("level", [unknowns], [steady, ca.jacobian(steady, unknowns)])
    low = np.concatenate([[_SLOWEST * cap, -cap, -cap], [-tilt_bound] * 2, lower[free]])
    high = np.concatenate([[cap, cap, cap], [tilt_bound] * 2, upper[free]])
    middle = 0.5 * (lower + upper)
    guesses = [middle] if start is None else [np.asarray(start, dtype=float), middle]
    scale = np.maximum(high - low, 1e-3)  # rpm and radians alike, over their ranges

    def residual(z, pull):
        values = np.asarray(equations(z)[0], dtype=float).ravel()
        return np.append(values, pull * (z[0] - cap))

    def jacobian(z, pull):
        rows = np.asarray(equations(z)[1], dtype=float)
        return np.vstack([rows, pull * np.eye(1, z.size)])

    best: np.ndarray | None = None
    for share, guess in itertools.product(_STARTS, guesses):
        z = np.concatenate(
            [[share * cap, 0.0, 0.0], [0.0, 0.0], np.clip(guess, lower, upper)[free]]
        )
        for pull in (_PULL, 0.0):
            z = least_squares(residual, np.clip(z, low, high), jacobian, (low, high),
                              x_scale=scale, args=(pull,), xtol=1e-14, ftol=1e-14,
                              gtol=1e-14).x  # fmt: skip
        left = np.abs(np.asarray(equations(z)[0], dtype=float)).max()
        if left <= _STEADY and (best is None or z[0] > best[0] + _STEADY):
            best = z
    if best is None:
        return None
    held = lower.copy()
    held[free] = best[5:]
    jacobian_at = np.asarray(equations(best)[1], dtype=float)
    return LevelFlight(float(best[0]), float(best[4]), held, _sinking_per_speed(jacobian_at))


def _sinking_per_speed(jacobian: np.ndarray) -> float:
    """d z'/d u along the steady flights through a level one, by the implicit function
    theorem on the Jacobian (7, unknowns) of [nu'; z'] in [u, the rest]: the rest follow u
    as -(dnu'/drest)^+ dnu'/du (least norm where several inputs hold the same flight)."""
    body, depth = jacobian[:-1], jacobian[-1]
    follows = -np.linalg.lstsq(body[:, 1:], body[:, 0], rcond=None)[0]
    return float(depth[0] + depth[1:] @ follows)
