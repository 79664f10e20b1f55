"""The 6-DOF vehicle model in Fossen's matrix form, written once in CasADi.

Conventions (``shared/spec/six-dof.md``; equation numbers: Fossen, *Handbook of Marine Craft
Hydrodynamics and Motion Control*, 2nd ed., 2021):

- World frame NED (x north, y east, z down, so z is the depth below the surface); body frame
  x forward, y starboard, z down, origin CO. Depth scenarios elsewhere in auvmpc use z up:
  convert at the boundary, never here.
- State ``[x, y, z, phi, theta, psi, u, v, w, p, q, r]`` = [eta; nu]: position (m), zyx Euler
  angles (rad), body linear (m/s) and angular (rad/s) velocity. Input: one force per
  ``six_dof`` thruster (N), tau = T F; or each actuator's command in its own unit (rpm, deg),
  tau the sum of their wrenches (models/actuators). Actuator effectiveness e (faults: each
  actuator's share of its wrench that acts, 1 healthy, 0 dead) scales each wrench
  (``ActuatorSet.force``), never the command: a propeller's thrust goes with rpm squared.
- Current: water velocity v_c (m/s, world frame, irrotational) at the vehicle and v_c' its
  rate of change along the vehicle's path (m/s2; zero for a current uniform in space and
  constant in time). Body frame nu_c = [R^T v_c; 0]; relative velocity nu_r = nu - nu_c.

Equations (eqs. 2.40, 6.1, 6.45):

    eta' = J(eta) nu
    M_RB nu' + M_A nu_r' + C_RB(nu) nu + C_A(nu_r) nu_r + D(nu_r) nu_r + g(eta) = tau

with nu_c' = [-S(omega) R^T v_c + R^T v_c'; 0] (the body sees a fixed current turn as it
turns), solved for nu' as  M nu' = tau - C_RB(nu) nu - C_A(nu_r) nu_r - D(nu_r) nu_r - g(eta)
+ M_A nu_c'.  C_RB is the linear-velocity-independent form (eq. 3.56), for which Fossen's
property holds: with a constant current this equals M nu_r' + C(nu_r) nu_r + D nu_r + g = tau.
Forces of the fluid's own acceleration (Froude-Krylov) are left out, as in Fossen's models.

Pitch singularity: T(phi, theta) has 1/cos(theta), undefined at theta = +-90 deg. The
numeric evaluation and the plant refuse states with |theta| above
:data:`PITCH_LIMIT_RAD` (85 deg) with :class:`PitchSingularity`, rather than clamp (which
would change the dynamics silently); the vehicles here are passively stable in pitch and
never come near it. The symbolic expressions are valid for |theta| < 90 deg.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import casadi as ca
import numpy as np

from auvmpc.models.actuators import ActuatorSet
from auvmpc.models.integrators import rk4, rk4_step_time_varying
from auvmpc.models.layout import HORIZONTAL, Layout
from auvmpc.models.six_dof_params import SixDofParams, skew
from auvmpc.models.vehicle import RK4_STABLE_STEP, VehicleParams, stable_plant_step, steady_speed

__all__ = [
    "ANGULAR_VELOCITY",
    "BODY_VELOCITY",
    "HORIZONTAL_INDEX",
    "PITCH_LIMIT_RAD",
    "SIX_DOF",
    "SIX_DOF_MEASUREMENT",
    "PitchSingularity",
    "TILT",
    "SixDofModel",
    "Rzyx",
    "ground_velocity",
    "Tzyx",
    "check_pitch",
    "coriolis_added_mass",
    "coriolis_rigid_body",
    "depth_rate",
    "dynamics",
    "horizontal_state",
    "integrate",
    "plant_step_length",
    "restoring_forces",
    "six_dof_model",
    "top_surge_speed",
    "without_munk_moments",
    "wrench_authority",
]

SIX_DOF = Layout(names=("x", "y", "z", "phi", "theta", "psi", "u", "v", "w", "p", "q", "r"))
NX = SIX_DOF.size
# nu = [u, v, w, p, q, r] (m/s, rad/s) on its own, in the order of the wrench it answers
# (models/actuators, WRENCH: X, Y, Z, K, M, N); its angular part omega = [p, q, r].
BODY_VELOCITY = Layout(names=SIX_DOF.names[SIX_DOF.nu])
ANGULAR_VELOCITY = BODY_VELOCITY.span("p", "r")
# Roll and pitch [phi, theta] (rad): the angles the restoring forces g(eta) depend on.
TILT = Layout(names=("phi", "theta"))
# Where the horizontal model's [x, y, psi, u, v, r] sit in the 6-DOF state.
HORIZONTAL_INDEX = np.array([SIX_DOF.index(name) for name in HORIZONTAL.names])
# What the 6-DOF vehicle's controllers measure: the navigation solution's [x, y, psi, u, v, r]
# and a depth sensor's depth and depth rate (NED, m and m/s, down positive).
SIX_DOF_MEASUREMENT = Layout(names=(*HORIZONTAL.names, "z", "z_rate"))
# Refuse, don't clamp: 5 deg short of the singularity, where 1/cos(theta) is 11.5.
PITCH_LIMIT_RAD = math.radians(85.0)


class PitchSingularity(ArithmeticError):
    """The Euler-angle kinematics were asked for |theta| beyond PITCH_LIMIT_RAD."""


def six_dof_section(params: VehicleParams) -> SixDofParams:
    """The vehicle's six_dof section; ValueError naming the vehicle if it has none."""
    if params.six_dof is None:
        raise ValueError(f"vehicle {params.name!r} has no six_dof section")
    return params.six_dof


def _skew(a):
    """S(a): S(a) b = a x b (eq. 2.9), on a CasADi 3-vector."""
    return ca.vertcat(
        ca.horzcat(0, -a[2], a[1]),
        ca.horzcat(a[2], 0, -a[0]),
        ca.horzcat(-a[1], a[0], 0),
    )


def Rzyx(phi, theta, psi):
    """Body-to-world rotation R(Theta) for zyx Euler angles (eq. 2.18)."""
    cphi, sphi = ca.cos(phi), ca.sin(phi)
    cth, sth = ca.cos(theta), ca.sin(theta)
    cpsi, spsi = ca.cos(psi), ca.sin(psi)
    return ca.vertcat(
        ca.horzcat(cpsi * cth, -spsi * cphi + cpsi * sth * sphi, spsi * sphi + cpsi * cphi * sth),
        ca.horzcat(spsi * cth, cpsi * cphi + sphi * sth * spsi, -cpsi * sphi + sth * spsi * cphi),
        ca.horzcat(-sth, cth * sphi, cth * cphi),
    )


def Tzyx(phi, theta):
    """Body angular velocity to Euler-angle rates, T(Theta) (eq. 2.28); singular at
    theta = +-90 deg."""
    cphi, sphi = ca.cos(phi), ca.sin(phi)
    cth, tth = ca.cos(theta), ca.tan(theta)
    return ca.vertcat(
        ca.horzcat(1, sphi * tth, cphi * tth),
        ca.horzcat(0, cphi, -sphi),
        ca.horzcat(0, sphi / cth, cphi / cth),
    )


def coriolis_rigid_body(mass: float, inertia: np.ndarray, r_g: np.ndarray, omega):
    """C_RB(nu), the linear-velocity-independent form (eq. 3.56): depends on omega only."""
    S_omega, S_rg = _skew(omega), ca.DM(skew(r_g))
    upper = ca.horzcat(mass * S_omega, -mass * ca.mtimes(S_omega, S_rg))
    lower = ca.horzcat(mass * ca.mtimes(S_rg, S_omega), -_skew(ca.mtimes(ca.DM(inertia), omega)))
    return ca.vertcat(upper, lower)


def coriolis_added_mass(added_mass: np.ndarray, nu_r):
    """C_A(nu_r) = [[0, -S(A11 nu1 + A12 nu2)], [-S(A11 nu1 + A12 nu2), -S(A21 nu1 + A22 nu2)]]
    (eq. 6.43), M_A = [[A11, A12], [A21, A22]] (numbers, or a CasADi matrix of symbols:
    identification's roll and pitch model estimates two of its entries)."""
    M_A = added_mass if isinstance(added_mass, ca.SX | ca.MX) else ca.DM(added_mass)
    momentum = ca.mtimes(M_A, nu_r)
    linear, angular = _skew(momentum[0:3]), _skew(momentum[3:6])
    return ca.vertcat(ca.horzcat(ca.DM.zeros(3, 3), -linear), ca.horzcat(-linear, -angular))


# C_A's entries MSS remus100.m (l. 202-206) sets to zero, in pairs (i, j) and (j, i) so that
# C_A stays skew-symmetric: pitch with heave and surge, yaw with surge and sway.
MUNK_ENTRIES = ((4, 2), (2, 4), (4, 0), (0, 4), (5, 0), (0, 5), (5, 1), (1, 5))


def without_munk_moments(C_A):
    """C_A(nu_r) without its Munk-moment entries (:data:`MUNK_ENTRIES`); a CasADi matrix."""
    kept = ca.DM.ones(6, 6)
    for row, column in MUNK_ENTRIES:
        kept[row, column] = 0.0
    return C_A * kept


def restoring_forces(weight: float, buoyancy: float, r_g, r_b, phi, theta):
    """g(eta) from weight, buoyancy and their centres (eq. 4.6)."""
    W, B = weight, buoyancy
    x_g, y_g, z_g = r_g
    x_b, y_b, z_b = r_b
    cphi, sphi = ca.cos(phi), ca.sin(phi)
    cth, sth = ca.cos(theta), ca.sin(theta)
    return ca.vertcat(
        (W - B) * sth,
        -(W - B) * cth * sphi,
        -(W - B) * cth * cphi,
        -(y_g * W - y_b * B) * cth * cphi + (z_g * W - z_b * B) * cth * sphi,
        (z_g * W - z_b * B) * sth + (x_g * W - x_b * B) * cth * cphi,
        -(x_g * W - x_b * B) * cth * sphi - (y_g * W - y_b * B) * sth,
    )


def dynamics(state, thrust, params: VehicleParams, current_world=None, current_rate_world=None):
    """x' of the 6-DOF model (module docstring) for a vehicle with a ``six_dof`` section.

    Parameters
    ----------
    state : (12,) array or CasADi column, [eta; nu]
    thrust : (n,) array or CasADi column, one force per ``six_dof`` thruster (N)
    params : VehicleParams with ``six_dof``
    current_world : (3,) water velocity at the vehicle, world NED (m/s), or None (still water)
    current_rate_world : (3,) its rate along the vehicle's path (m/s2), or None (zero)

    Returns
    -------
    (12,) NumPy array for numeric input (evaluated through the model's compiled CasADi
    Function, refusing |theta| > PITCH_LIMIT_RAD), CasADi column for symbolic input.
    """
    symbolic = any(isinstance(a, ca.SX | ca.MX) for a in (state, thrust, current_world))
    if not symbolic:
        return six_dof_model(params).evaluate(state, thrust, current_world, current_rate_world)
    zero = ca.DM.zeros(3)
    return _expression(
        params,
        state,
        thrust,
        zero if current_world is None else ca.vertcat(*_entries(current_world)),
        zero if current_rate_world is None else ca.vertcat(*_entries(current_rate_world)),
    )


def _entries(vector):
    return [vector[i] for i in range(3)]


def _expression(
    params: VehicleParams, state, thrust, current_world, current_rate_world, effectiveness=None
):
    six = six_dof_section(params)
    r_g = np.array(six.center_of_gravity, dtype=float)
    r_b = np.array(six.center_of_buoyancy, dtype=float)
    phi, theta, psi = state[3], state[4], state[5]
    nu = state[6:12]
    linear, omega = nu[0:3], nu[3:6]
    R = Rzyx(phi, theta, psi)

    current_body = ca.mtimes(R.T, current_world)
    nu_r = ca.vertcat(linear - current_body, omega)
    # d/dt (R^T v_c) along the path: the body turns under the current, and the current
    # itself may change (in time, or with depth as the vehicle dives).
    current_body_rate = -ca.mtimes(_skew(omega), current_body) + ca.mtimes(R.T, current_rate_world)
    nu_c_rate = ca.vertcat(current_body_rate, ca.DM.zeros(3))

    M_A = six.added_mass_matrix
    M = six.mass_matrix(params.mass)
    C_RB = coriolis_rigid_body(params.mass, six.inertia_matrix, r_g, omega)
    C_A = coriolis_added_mass(M_A, nu_r)
    if six.without_munk_moments:
        C_A = without_munk_moments(C_A)
    damping = (
        -ca.DM(np.array(six.linear_damping)) * nu_r
        - ca.DM(np.array(six.quadratic_damping)) * ca.fabs(nu_r) * nu_r
    )  # D(nu_r) nu_r, diagonal: element-wise
    g = restoring_forces(six.weight(params.mass), six.buoyancy, r_g, r_b, phi, theta)
    tau = params.six_dof_actuators.force(nu_r, thrust, effectiveness=effectiveness)
    if six.hull_lift is not None:
        tau = tau + hull_lift(six.hull_lift, nu_r)

    forces = (
        tau
        - ca.mtimes(C_RB, nu)
        - ca.mtimes(C_A, nu_r)
        - damping
        - g
        + ca.mtimes(ca.DM(M_A), nu_c_rate)
    )
    nu_dot = ca.mtimes(ca.DM(np.linalg.inv(M)), forces)
    eta_dot = ca.vertcat(ca.mtimes(R, linear), ca.mtimes(Tzyx(phi, theta), omega))
    return ca.vertcat(eta_dot, nu_dot)


def hull_lift(derivatives, nu_r):
    """The hull's lift and its moment at relative velocity ``nu_r`` (Prestero's body lift,
    SixDofParams.hull_lift): [0, Y_uv u v, Z_uw u w, 0, M_uw u w, N_uv u v]."""
    y_uv, z_uw, m_uw, n_uv = derivatives
    sideslip, attack = nu_r[0] * nu_r[1], nu_r[0] * nu_r[2]
    return ca.vertcat(0, y_uv * sideslip, z_uw * attack, 0, m_uw * attack, n_uv * sideslip)


class SixDofModel:
    """The 6-DOF model of one vehicle as compiled CasADi functions, built once.

    ``derivative(x, F, v_c, v_c')`` is the model; ``step(x, F, v_c, h)`` is one RK4 step of
    length h under a current uniform in space and constant over the step. Their
    ``..._with_effectiveness`` forms take each actuator's effectiveness ``e`` (n,) last: the
    share of its wrench that acts (module docstring); the plain forms are all healthy.
    """

    layout = SIX_DOF

    def __init__(self, params: VehicleParams) -> None:
        six_dof_section(params)
        self.params = params
        self.n_thrusters = params.six_dof_actuators.size  # inputs: thrusts, or rpm and angles
        state, thrust = ca.SX.sym("x", NX), ca.SX.sym("F", self.n_thrusters)
        current, current_rate = ca.SX.sym("v_c", 3), ca.SX.sym("v_c_rate", 3)
        share, h = ca.SX.sym("e", self.n_thrusters), ca.SX.sym("h")
        still = ca.DM.zeros(3)

        def functions(acting, suffix: str) -> tuple[ca.Function, ca.Function]:
            """The derivative and the RK4 step, with ``acting`` (the effectiveness symbol)
            their last input, or all healthy (None: the wrenches unscaled)."""
            extra, extra_names = ([], []) if acting is None else ([acting], ["e"])
            expression = _expression(params, state, thrust, current, current_rate, acting)
            derivative = ca.Function(
                "six_dof" + suffix, [state, thrust, current, current_rate, *extra], [expression],
                ["x", "F", "v_c", "v_c_rate", *extra_names], ["x_dot"],
            )  # fmt: skip

            def f(x, u):
                return derivative(x, u, current, still, *extra)

            step = ca.Function(
                "six_dof_rk4" + suffix, [state, thrust, current, h, *extra],
                [rk4(f, state, thrust, h)], ["x", "F", "v_c", "h", *extra_names], ["x_next"],
            )  # fmt: skip
            return derivative, step

        self.derivative, self.step = functions(None, "")
        self.derivative_with_effectiveness, self.step_with_effectiveness = functions(
            share, "_with_effectiveness"
        )

    def evaluate(self, state, thrust, current_world=None, current_rate_world=None) -> np.ndarray:
        """x' (12,) on NumPy input; refuses |theta| > PITCH_LIMIT_RAD."""
        state = np.asarray(state, dtype=float)
        check_pitch(state)
        value = self.derivative(
            state,
            np.asarray(thrust, dtype=float),
            np.zeros(3) if current_world is None else np.asarray(current_world, dtype=float),
            np.zeros(3)
            if current_rate_world is None
            else np.asarray(current_rate_world, dtype=float),
        )
        return np.asarray(value, dtype=float).ravel()


def check_pitch(state: np.ndarray) -> None:
    """Raise PitchSingularity if the state's pitch is beyond PITCH_LIMIT_RAD (or not finite)."""
    theta = float(state[4])
    if not abs(theta) <= PITCH_LIMIT_RAD:
        raise PitchSingularity(
            f"pitch theta = {math.degrees(theta):.1f} deg is beyond +-"
            f"{math.degrees(PITCH_LIMIT_RAD):.0f} deg, where the zyx Euler-angle kinematics "
            "(1/cos theta) are near their singularity"
        )


def horizontal_state(state: np.ndarray) -> np.ndarray:
    """``[x, y, psi, u, v, r]`` (6,) of a 6-DOF state (12,) (or rows of them)."""
    return np.asarray(state)[..., HORIZONTAL_INDEX]


def ground_velocity(state: np.ndarray) -> np.ndarray:
    """(2,) the world-frame horizontal velocity [x', y'] (m/s) of a 6-DOF state: the first two
    rows of R(Theta) [u, v, w] (Fossen 2021, eq. 2.18)."""
    phi, theta, psi = (float(state[i]) for i in (3, 4, 5))
    u, v, w = (float(state[i]) for i in (6, 7, 8))
    cphi, sphi, cth, sth = math.cos(phi), math.sin(phi), math.cos(theta), math.sin(theta)
    cpsi, spsi = math.cos(psi), math.sin(psi)
    north = cpsi * cth * u + (cpsi * sth * sphi - spsi * cphi) * v
    east = spsi * cth * u + (cpsi * cphi + sphi * sth * spsi) * v
    north += (spsi * sphi + cpsi * cphi * sth) * w
    east += (spsi * sth * cphi - cpsi * sphi) * w
    return np.array([north, east])


def depth_rate(state: np.ndarray) -> float:
    """z' (m/s, down positive): the third row of R(Theta) times [u, v, w]."""
    phi, theta = state[3], state[4]
    u, v, w = state[6], state[7], state[8]
    return float(
        -math.sin(theta) * u
        + math.cos(theta) * math.sin(phi) * v
        + math.cos(theta) * math.cos(phi) * w
    )


# RK4's local error on a mode of rate lambda is ~ (h |lambda|)^5 / 120. At h |lambda| = 0.1 the
# 6-DOF plant meets the 3-DOF plant's accuracy (1e-6 against solve_ivp at rtol 1e-11 over 10 s,
# tests/test_six_dof.py); the 3-DOF plant's own rule (stability, 2.5) is far looser.
ACCURATE_RATE_STEP = 0.1


def plant_step_length(params: VehicleParams, longest: float) -> float:
    """The longest RK4 step (at most ``longest``) with h |lambda| <= ACCURATE_RATE_STEP for
    the 6-DOF model's fastest rate: the modes at rest (roll and pitch oscillations, linear
    damping) and the damping of surge, sway, heave and yaw at the speed their full authority
    reaches. (Roll and pitch never reach theirs: the restoring moment holds them.)

    Fixed thrusters: each axis's authority is every thruster at whichever limit helps, and
    the step is no longer than the 3-DOF plant's :func:`auvmpc.models.vehicle.stable_plant_step`.
    Actuators whose wrench depends on the flow (a propeller and fins): the same, at the top
    surge speed the actuators reach (:func:`top_surge_speed`), and also the modes about that
    cruise (the fins' lift damps sway, heave, pitch and yaw in proportion to the speed)."""
    six = six_dof_section(params)
    model = six_dof_model(params)
    x = ca.SX.sym("x", NX)
    u = ca.SX.sym("u", model.n_thrusters)
    jacobian = ca.Function("A", [x, u], [ca.jacobian(model.derivative(x, u, 0, 0), x)])

    def fastest_mode(state: np.ndarray, command: np.ndarray) -> float:
        return float(np.max(np.abs(np.linalg.eigvals(np.asarray(jacobian(state, command))))))

    inputs = params.six_dof_actuators
    rates = [fastest_mode(np.zeros(NX), np.zeros(model.n_thrusters))]
    inertia = np.diag(six.mass_matrix(params.mass))
    if inputs.linear:
        low, high = params.thrust_limits
        authority = np.maximum(six.T * high, six.T * low).sum(axis=1)
        longest = stable_plant_step(params, longest)
    else:
        cruise = np.zeros(NX)
        cruise[SIX_DOF.index("u")] = top_surge_speed(params)
        nu_r = cruise[SIX_DOF.nu]
        authority = wrench_authority(inputs, nu_r)
        for command in (inputs.limits.lower, inputs.limits.upper):
            rates.append(fastest_mode(cruise, np.asarray(command, dtype=float)))
    for axis in (0, 1, 2, 5):
        linear, quadratic = six.linear_damping[axis], six.quadratic_damping[axis]
        top = steady_speed(linear, quadratic, float(authority[axis]))
        if math.isfinite(top):
            rates.append(abs(linear + 2.0 * quadratic * top) / inertia[axis])
    return min(longest, ACCURATE_RATE_STEP / max(rates))


def wrench_authority(inputs: ActuatorSet, nu_r: np.ndarray) -> np.ndarray:
    """The largest [X, Y, Z, K, M, N] (6,) each axis gets on its own at relative velocity
    ``nu_r`` (6,), each actuator at whichever end of its command box, or at zero, helps that
    axis most (a fin's drag is least at zero angle; the set's wrench is the sum of its
    actuators')."""
    limits = inputs.limits
    best = [
        np.max(
            [
                actuator.wrench(nu_r, float(command))
                for command in (low, np.clip(0.0, low, high), high)
            ],
            axis=0,
        )
        for actuator, low, high in zip(inputs.actuators, limits.lower, limits.upper, strict=True)
    ]
    return np.sum(best, axis=0)


def top_surge_speed(params: VehicleParams) -> float:
    """The surge speed through the water (m/s) where the 6-DOF inputs' largest forward
    force, at that speed, equals the surge damping: a propeller's thrust falls as the
    advance ratio grows, so the speed is found by bisection on the force balance."""
    six = six_dof_section(params)
    inputs = params.six_dof_actuators
    linear, quadratic = six.linear_damping[0], six.quadratic_damping[0]

    def surplus(speed: float) -> float:
        nu_r = np.array([speed, 0.0, 0.0, 0.0, 0.0, 0.0])
        return float(wrench_authority(inputs, nu_r)[0]) + linear * speed + quadratic * speed**2

    if surplus(0.0) <= 0.0:
        return 0.0
    high = 1.0
    while surplus(high) > 0.0:
        if high > _FASTEST_VEHICLE_M_S:
            return math.inf  # no damping holds it: no finite top speed
        high *= 2.0
    low = 0.0
    for _ in range(60):  # to round-off
        middle = 0.5 * (low + high)
        low, high = (middle, high) if surplus(middle) > 0.0 else (low, middle)
    return 0.5 * (low + high)


# Beyond this (m/s) a vehicle's top speed is taken as unbounded (no surge damping).
_FASTEST_VEHICLE_M_S = 1e3


def stable_substeps(params: VehicleParams, sample_time: float) -> int:
    """The fewest RK4 steps per ``sample_time`` that keep a prediction stable on the 6-DOF
    model's fastest mode (h |lambda| <= RK4_STABLE_STEP; :func:`plant_step_length` finds the
    rate, with the accuracy rule the plant needs)."""
    fastest = ACCURATE_RATE_STEP / plant_step_length(params, sample_time)
    return max(1, math.ceil(sample_time * fastest / RK4_STABLE_STEP))


CurrentAt = Callable[[float, np.ndarray], tuple[np.ndarray, np.ndarray]]


def integrate(
    model: SixDofModel,
    state: np.ndarray,
    thrust: np.ndarray,
    duration: float,
    substeps: int,
    current_at: CurrentAt | None = None,
    t0: float = 0.0,
    held_current: np.ndarray | None = None,
    effectiveness: np.ndarray | None = None,
) -> np.ndarray:
    """The plant over one zero-order-hold sample: ``substeps`` RK4 steps (as the 3-DOF plant).

    ``current_at(t, x) -> (v_c, v_c')`` gives the water velocity at the vehicle and its rate
    along the path (world frame), e.g. from :class:`auvmpc.environment.currents.WaterCurrent`;
    without it the water velocity ``held_current`` (3,) is held over the sample (the compiled
    RK4 step), still water if None. ``effectiveness`` (n,): each actuator's share of its
    wrench that acts (None: all healthy). The pitch is checked after every step.
    """
    thrust = np.asarray(thrust, dtype=float)
    state = np.asarray(state, dtype=float)
    if effectiveness is None:
        step, derivative, extra = model.step, model.derivative, ()
    else:
        step, derivative = model.step_with_effectiveness, model.derivative_with_effectiveness
        extra = (np.asarray(effectiveness, dtype=float),)
    h = duration / substeps
    check_pitch(state)
    if current_at is None:
        held = np.zeros(3) if held_current is None else held_current
        for _ in range(substeps):
            state = np.asarray(step(state, thrust, held, h, *extra), dtype=float).ravel()
            check_pitch(state)
        return state

    def rhs(t: float, x: np.ndarray) -> np.ndarray:
        current, rate = current_at(t, x)
        return np.asarray(derivative(x, thrust, current, rate, *extra), dtype=float).ravel()

    for i in range(substeps):
        state = rk4_step_time_varying(rhs, t0 + i * h, state, h)
        check_pitch(state)
    return state


@functools.lru_cache(maxsize=16)
def _cached(params_json: str) -> SixDofModel:
    return SixDofModel(VehicleParams.model_validate_json(params_json))


def six_dof_model(params: VehicleParams) -> SixDofModel:
    """The compiled 6-DOF model of ``params``, built once per process."""
    return _cached(params.model_dump_json())
