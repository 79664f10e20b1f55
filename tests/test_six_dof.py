"""The 6-DOF plant against analytic physics, an independent solver, the 3-DOF model and an
independently written relative-velocity form (shared/spec/six-dof.md)."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp

from auvmpc.models.integrators import rk4
from auvmpc.models.six_dof import (
    PITCH_LIMIT_RAD,
    PitchSingularity,
    dynamics,
    integrate,
    plant_step_length,
    six_dof_model,
)
from auvmpc.models.six_dof_params import horizontal_equivalent, skew
from auvmpc.models.vehicle import VehicleParams, load_vehicle
from auvmpc.models.vehicle import dynamics as dynamics_3dof
from tests.conftest import (
    DRIFT_VELOCITY_TOL,
    NATURAL_FREQUENCY_REL_TOL,
    PLANT_VS_SOLVE_IVP_TOL,
    ROUND_OFF_TOL,
    SIX_DOF_REDUCTION_TOL,
)

PRESETS = ("bluerov2-heavy", "jmse2210")


def variant(name: str, *, neutral: bool = True, **six_dof_changes) -> VehicleParams:
    """A preset with W = B (``neutral``) and other ``six_dof`` fields replaced."""
    data = load_vehicle(name).model_dump()
    six = data["six_dof"]
    if neutral:  # B = rho g V = m g
        six["displaced_volume"] = data["mass"] / six["water_density"]
    six.update(six_dof_changes)
    return VehicleParams.model_validate(data)


def Rzyx(phi, theta, psi) -> np.ndarray:
    """Fossen 2021 eq. 2.18, written out again with NumPy."""

    def Rx(a):
        return np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])

    def Ry(a):
        return np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])

    def Rz(a):
        return np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])

    return Rz(psi) @ Ry(theta) @ Rx(phi)


def relative_form_derivative(params: VehicleParams, state, thrust, current) -> np.ndarray:
    """Fossen's relative form for a constant, irrotational current, independently of
    auvmpc.models.six_dof: M nu_r' + C_RB(nu_r) nu_r + C_A(nu_r) nu_r + D nu_r + g = tau,
    nu' = nu_r' + nu_c' with nu_c' = [-S(omega) R^T v_c; 0]."""
    six = params.six_dof
    m = params.mass
    phi, theta, psi = state[3:6]
    nu = state[6:]
    R = Rzyx(phi, theta, psi)
    omega = nu[3:]
    v_c = R.T @ current
    nu_r = np.concatenate([nu[:3] - v_c, omega])
    r_g, r_b = np.array(six.center_of_gravity), np.array(six.center_of_buoyancy)
    I_b = six.inertia_matrix
    # eq. 3.56 on nu_r: the rigid-body Coriolis in the frame moving with the water.
    C_RB = np.block(
        [
            [m * skew(omega), -m * skew(omega) @ skew(r_g)],
            [m * skew(r_g) @ skew(omega), -skew(I_b @ omega)],
        ]
    )
    M_A = six.added_mass_matrix
    a = M_A @ nu_r
    C_A = np.block([[np.zeros((3, 3)), -skew(a[:3])], [-skew(a[:3]), -skew(a[3:])]])
    D = -np.diag(six.linear_damping) - np.diag(np.array(six.quadratic_damping) * np.abs(nu_r))
    W, B = six.weight(m), six.buoyancy
    s, c = math.sin, math.cos
    g = np.array(
        [
            (W - B) * s(theta),
            -(W - B) * c(theta) * s(phi),
            -(W - B) * c(theta) * c(phi),
            -(r_g[1] * W - r_b[1] * B) * c(theta) * c(phi)
            + (r_g[2] * W - r_b[2] * B) * c(theta) * s(phi),
            (r_g[2] * W - r_b[2] * B) * s(theta) + (r_g[0] * W - r_b[0] * B) * c(theta) * c(phi),
            -(r_g[0] * W - r_b[0] * B) * c(theta) * s(phi) - (r_g[1] * W - r_b[1] * B) * s(theta),
        ]
    )
    M = six.mass_matrix(m)
    tau = six.T @ thrust
    nu_r_dot = np.linalg.solve(M, tau - C_RB @ nu_r - C_A @ nu_r - D @ nu_r - g)
    nu_dot = nu_r_dot + np.concatenate([-skew(omega) @ v_c, np.zeros(3)])
    T = np.array(
        [
            [1, s(phi) * math.tan(theta), c(phi) * math.tan(theta)],
            [0, c(phi), -s(phi)],
            [0, s(phi) / c(theta), c(phi) / c(theta)],
        ]
    )
    return np.concatenate([R @ nu[:3], T @ omega, nu_dot])


angles = st.floats(-0.6, 0.6)
speeds = st.floats(-1.0, 1.0)
rates = st.floats(-0.5, 0.5)
states = st.tuples(
    st.floats(-5, 5), st.floats(-5, 5), st.floats(0, 20), angles, angles, st.floats(-3.2, 3.2),
    speeds, speeds, speeds, rates, rates, rates,
).map(np.array)  # fmt: skip
currents = st.tuples(st.floats(-0.8, 0.8), st.floats(-0.8, 0.8), st.floats(-0.2, 0.2)).map(np.array)


@pytest.mark.parametrize("preset", PRESETS)
@settings(max_examples=40, deadline=None)
@given(state=states, current=currents, thrust_scale=st.floats(-20, 20))
def test_general_form_equals_fossens_relative_form(preset, state, current, thrust_scale):
    # six-dof.md: for a constant irrotational current, M_RB nu' + C_RB(nu) nu + M_A nu_r' + ...
    # is the same as M nu_r' + C(nu_r) nu_r + ... (Fossen sec. 6.5). A second, NumPy-only
    # writing of the equations also cross-checks C_RB, C_A, D, g and J term by term.
    params = load_vehicle(preset)
    thrust = thrust_scale * np.linspace(-1.0, 1.0, params.six_dof.n_thrusters)
    got = dynamics(state, thrust, params, current)
    expected = relative_form_derivative(params, state, thrust, current)
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize("preset", PRESETS)
def test_symbolic_and_numeric_evaluation_agree(preset):
    params = load_vehicle(preset)
    n = params.six_dof.n_thrusters
    x, F, c = ca.SX.sym("x", 12), ca.SX.sym("F", n), ca.SX.sym("c", 3)
    symbolic = ca.Function("f", [x, F, c], [dynamics(x, F, params, c)])
    rng = np.random.default_rng(3)
    for _ in range(5):
        state = rng.uniform(-0.5, 0.5, 12)
        thrust, current = rng.uniform(-10, 10, n), rng.uniform(-0.5, 0.5, 3)
        np.testing.assert_allclose(
            np.asarray(symbolic(state, thrust, current)).ravel(),
            dynamics(state, thrust, params, current),
            atol=ROUND_OFF_TOL,
        )


def energy_relative_to_water(params: VehicleParams, state, current) -> float:
    """1/2 nu_r^T M nu_r plus the restoring potential W BG (1 - cos phi cos theta) of a
    neutral vehicle with CG and CB on its z axis."""
    six = params.six_dof
    R = Rzyx(*state[3:6])
    nu_r = np.concatenate([state[6:9] - R.T @ current, state[9:]])
    kinetic = 0.5 * nu_r @ six.mass_matrix(params.mass) @ nu_r
    metacentric = six.center_of_gravity[2] - six.center_of_buoyancy[2]
    potential = (
        six.weight(params.mass) * metacentric * (1 - math.cos(state[3]) * math.cos(state[4]))
    )
    return kinetic + potential


@pytest.mark.parametrize("preset", PRESETS)
@settings(max_examples=8, deadline=None)
@given(state=states, current=currents)
def test_unpowered_neutral_vehicle_only_loses_energy_relative_to_the_water(preset, state, current):
    # dE/dt = -nu_r^T D(nu_r) nu_r <= 0: the Coriolis terms do no work (skew-symmetric),
    # gravity and buoyancy only trade kinetic for potential energy. Kinetic energy alone
    # may rise while a tilted vehicle rights itself, so the sum is what must not.
    params = variant(preset)
    model = six_dof_model(params)
    zero = np.zeros(model.n_thrusters)

    def current_at(t, x):
        return current, np.zeros(3)

    energies = [energy_relative_to_water(params, state, current)]
    for _ in range(150):  # 15 s at 0.1 s, RK4 at 0.01 s
        state = integrate(model, state, zero, 0.1, 10, current_at)
        energies.append(energy_relative_to_water(params, state, current))
    energies = np.array(energies)
    # RK4 at 0.01 s changes the energy by O(h^5) per step: 1e-10 of the start is far above.
    assert np.all(np.diff(energies) <= 1e-10 * max(energies[0], 1e-3))
    assert energies[-1] < energies[0] or energies[0] == 0.0


def steady_speed(linear: float, quadratic: float, force: float) -> float:
    """Root of |linear| s + |quadratic| s^2 = force (force > 0)."""
    a, b = -quadratic, -linear
    return force / b if a == 0 else (-b + math.sqrt(b * b + 4 * a * force)) / (2 * a)


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("current", [(0.0, 0.0, 0.0), (0.2, -0.1, 0.0)])
def test_steady_surge_speed_through_the_water_is_the_damping_balance_root(preset, current):
    params = variant(preset)
    six = params.six_dof
    surge_force = 8.0
    # Thrust along the surge row: no sway force or yaw moment but round-off. jmse2210 is
    # directionally unstable in open loop (Munk moment, m22 > m11, growth ~0.6/s): 1e-15 N m
    # of yaw moment turns it off a straight line within a minute, not within 20 s.
    thrust = surge_force * six.T[0] / (six.T[0] @ six.T[0])
    np.testing.assert_allclose(six.T[1:] @ thrust, 0.0, atol=1e-14)
    model = six_dof_model(params)
    current = np.array(current)
    state = np.zeros(12)
    state[6:9] = current  # heading 0: at rest relative to the water, so no Munk moment
    for _ in range(200):  # 20 s: at speed, surge settles at 1.1/s (jmse2210) or faster
        state = integrate(model, state, thrust, 0.1, 2, lambda t, x: (current, np.zeros(3)))
    expected = steady_speed(six.linear_damping[0], six.quadratic_damping[0], surge_force)
    relative = state[6:9] - Rzyx(*state[3:6]).T @ current
    assert relative[0] == pytest.approx(expected, abs=1e-9)
    # Straight on: no sway or heave through the water, no rotation.
    np.testing.assert_allclose([*relative[1:], *state[3:6], *state[9:]], 0.0, atol=1e-9)


def zero_crossing_period(times: np.ndarray, signal: np.ndarray) -> float:
    """Mean period from the sign changes of an oscillation (linear interpolation)."""
    crossings = []
    for k in np.flatnonzero(np.sign(signal[1:]) != np.sign(signal[:-1])):
        t0, t1, s0, s1 = times[k], times[k + 1], signal[k], signal[k + 1]
        crossings.append(t0 - s0 * (t1 - t0) / (s1 - s0))
    return 2.0 * float(np.mean(np.diff(crossings)))


@pytest.mark.parametrize("preset", PRESETS)
@pytest.mark.parametrize("axis", ["roll", "pitch"])
def test_small_roll_and_pitch_oscillate_at_the_metacentric_frequency(preset, axis):
    # six-dof.md: omega = sqrt((z_g W - z_b B) / (I - K_pdot)) for W = B. Damping in the
    # oscillating axis is set to zero so that the natural frequency is what is measured.
    index = 3 if axis == "roll" else 4
    base = load_vehicle(preset).six_dof
    linear, quadratic = list(base.linear_damping), list(base.quadratic_damping)
    linear[index] = quadratic[index] = 0.0
    params = variant(preset, linear_damping=linear, quadratic_damping=quadratic)
    six = params.six_dof
    W = six.weight(params.mass)
    stiffness = six.center_of_gravity[2] * W - six.center_of_buoyancy[2] * six.buoyancy
    inertia = six.mass_matrix(params.mass)[index, index]  # I + added, CG at CO
    omega = math.sqrt(stiffness / inertia)

    model = six_dof_model(params)
    state = np.zeros(12)
    state[index] = 0.01
    h = 0.01
    steps = int(round(8 * 2 * math.pi / omega / h))  # eight periods
    trace = np.empty(steps + 1)
    trace[0] = state[index]
    zero = np.zeros(model.n_thrusters)
    for k in range(steps):
        state = integrate(model, state, zero, h, 1)
        trace[k + 1] = state[index]
    measured = 2 * math.pi / zero_crossing_period(h * np.arange(steps + 1), trace)
    assert measured == pytest.approx(omega, rel=NATURAL_FREQUENCY_REL_TOL)


@pytest.mark.parametrize("preset", PRESETS)
def test_presets_six_dof_sections_agree_with_their_3dof_and_heave_values(preset):
    params = load_vehicle(preset)
    implied = horizontal_equivalent(params.mass, params.six_dof)
    for name, value in implied.items():
        stated = (
            getattr(params, name)
            if name in VehicleParams.model_fields
            else getattr(params.heave, name)
        )
        # net buoyancy: the file states it to 0.01 N; the rest to their printed digits.
        assert value == pytest.approx(stated, abs=0.01 if name == "net_buoyancy_N" else 1e-12), name
    n = params.n_thrusters  # the horizontal thrusters come first, in the same order
    np.testing.assert_allclose(params.six_dof.T[[0, 1, 5], :n], params.T, atol=1e-8)
    np.testing.assert_allclose(params.six_dof.T[[2, 3, 4], :n], 0.0, atol=1e-12)


def horizontal_rows(state6: np.ndarray) -> np.ndarray:
    return state6[[0, 1, 5, 6, 7, 11]]


@pytest.mark.parametrize("preset", PRESETS)
@settings(max_examples=30, deadline=None)
@given(
    planar=st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-3.2, 3.2), speeds, speeds,
                     rates).map(np.array),
    current=st.tuples(st.floats(-0.8, 0.8), st.floats(-0.8, 0.8)).map(np.array),
    thrust_scale=st.floats(-15, 15),
)  # fmt: skip
def test_in_the_horizontal_plane_the_6dof_model_is_the_3dof_model(
    preset, planar, current, thrust_scale
):
    # six-dof.md "Reduction": w = p = q = 0, z = phi = theta = 0 and W = B leave the surge,
    # sway and yaw rows of the 3-DOF model (also under a horizontal current).
    params = variant(preset)
    n = params.n_thrusters
    thrust = np.zeros(params.six_dof.n_thrusters)
    thrust[:n] = thrust_scale * np.linspace(-1, 1, n)
    state = np.zeros(12)
    state[[0, 1, 5, 6, 7, 11]] = planar
    six = dynamics(state, thrust, params, np.array([*current, 0.0]))
    three = dynamics_3dof(planar, thrust[:n], params, current_world=current)
    np.testing.assert_allclose(horizontal_rows(six), three, rtol=0, atol=SIX_DOF_REDUCTION_TOL)
    np.testing.assert_array_equal(six[[2, 3, 4, 8, 9, 10]], 0.0)  # nothing leaves the plane


@pytest.mark.parametrize("preset", PRESETS)
def test_a_horizontal_trajectory_of_the_6dof_plant_is_the_3dof_plants(preset):
    params = variant(preset)
    model = six_dof_model(params)
    n = params.n_thrusters
    thrust = np.zeros(model.n_thrusters)
    thrust[:n] = [4.0, -2.0, 3.0, 1.0][:n]
    current = np.array([0.3, -0.2])
    planar = np.array([1.0, -2.0, 0.4, 0.3, -0.1, 0.05])
    state = np.zeros(12)
    state[[0, 1, 5, 6, 7, 11]] = planar

    def planar_f(x, u):
        return dynamics_3dof(x, u, params, current_world=current)

    current_6 = np.array([*current, 0.0])
    for _ in range(40):  # 20 s, 0.5 s samples of 10 RK4 steps each
        planar = rk4(planar_f, planar, thrust[:n], 0.5, 10)
        state = integrate(model, state, thrust, 0.5, 10, lambda t, x: (current_6, np.zeros(3)))
    np.testing.assert_allclose(horizontal_rows(state), planar, atol=SIX_DOF_REDUCTION_TOL)
    np.testing.assert_allclose(state[[2, 3, 4, 8, 9, 10]], 0.0, atol=SIX_DOF_REDUCTION_TOL)


def test_unpowered_vehicle_ends_up_drifting_with_the_current():
    # jmse2210 has linear damping in every axis, so its velocity relative to the water dies
    # out exponentially; it starts turning, so the body-frame current keeps changing.
    params = variant("jmse2210")
    model = six_dof_model(params)
    current = np.array([0.3, -0.2, 0.0])
    state = np.array([0, 0, 5.0, 0.1, -0.1, 0.5, 0.4, 0.2, 0.1, 0.2, -0.1, 0.6])
    zero = np.zeros(model.n_thrusters)
    for _ in range(240):  # 240 s: 40 surge time constants
        state = integrate(model, state, zero, 1.0, 20, lambda t, x: (current, np.zeros(3)))
    world_velocity = Rzyx(*state[3:6]) @ state[6:9]
    np.testing.assert_allclose(world_velocity, current, atol=DRIFT_VELOCITY_TOL)
    np.testing.assert_allclose(state[9:], 0.0, atol=DRIFT_VELOCITY_TOL)


def test_the_3dof_plant_drifts_with_the_current_too(jmse):
    current = np.array([0.3, -0.2])
    state = np.array([0.0, 0.0, 0.5, 0.4, 0.2, 0.6])
    zero = np.zeros(jmse.n_thrusters)
    for _ in range(240):
        state = rk4(lambda x, u: dynamics_3dof(x, u, jmse, current_world=current), state, zero,
                    1.0, 20)  # fmt: skip
    c, s = math.cos(state[2]), math.sin(state[2])
    world = np.array([c * state[3] - s * state[4], s * state[3] + c * state[4]])
    np.testing.assert_allclose(world, current, atol=DRIFT_VELOCITY_TOL)
    assert state[5] == pytest.approx(0.0, abs=DRIFT_VELOCITY_TOL)


@pytest.mark.parametrize("preset", PRESETS)
def test_plant_matches_solve_ivp(preset):
    # The plant's RK4 at its step length (plant_step_length) against DOP853 at rtol 1e-11,
    # over 10 s of thrust in every axis, a current and a buoyancy that is not neutral: the
    # 3-DOF plant's accuracy (PLANT_VS_SOLVE_IVP_TOL).
    params = load_vehicle(preset)
    model = six_dof_model(params)
    n = model.n_thrusters
    # Horizontal thrusts, then vertical ones that lift with a little roll moment: the
    # BlueROV2's 4.9 cm metacentric height rights it against 6.4 N m at most.
    thrust = np.array([3.0, 1.0, -1.0, 2.0, -2.0, -2.2, -1.9, -2.1][:n])
    current = np.array([0.2, 0.1, 0.0])
    start = np.array([1.0, 2.0, 3.0, 0.1, -0.05, 0.3, 0.3, -0.1, 0.05, 0.1, 0.05, -0.2])

    def rhs(t, x):  # unchecked: the solver's trial steps may try any pitch
        return np.asarray(model.derivative(x, thrust, current, np.zeros(3))).ravel()

    reference = solve_ivp(rhs, (0.0, 10.0), start, method="DOP853", rtol=1e-11, atol=1e-12,
                          t_eval=np.arange(1, 11) * 1.0)  # fmt: skip
    substeps = math.ceil(1.0 / plant_step_length(params, 0.05))
    state = start
    for k in range(10):
        state = integrate(model, state, thrust, 1.0, substeps, lambda t, x: (current, np.zeros(3)))
        np.testing.assert_allclose(state, reference.y[:, k], atol=PLANT_VS_SOLVE_IVP_TOL)
    # The compiled RK4 step (still water) and the time-varying one agree.
    still = integrate(model, start, thrust, 1.0, 20)
    moving = integrate(model, start, thrust, 1.0, 20, lambda t, x: (np.zeros(3), np.zeros(3)))
    np.testing.assert_allclose(still, moving, atol=ROUND_OFF_TOL)


def test_pitch_near_the_euler_singularity_is_refused(bluerov):
    model = six_dof_model(bluerov)
    state = np.zeros(12)
    state[4] = PITCH_LIMIT_RAD + 1e-6
    zero = np.zeros(model.n_thrusters)
    with pytest.raises(PitchSingularity, match="pitch theta = 85.0 deg"):
        model.evaluate(state, zero)
    state[4] = PITCH_LIMIT_RAD - 0.01
    state[10] = 2.0  # pitching up fast: the step leaves the allowed range
    with pytest.raises(PitchSingularity, match="singularity"):
        integrate(model, state, zero, 0.5, 10)


def test_a_vehicle_without_a_six_dof_section_has_no_6dof_model():
    params = load_vehicle("rexrov")
    assert params.six_dof is None
    with pytest.raises(ValueError, match="no six_dof section"):
        six_dof_model(params)
