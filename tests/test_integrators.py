"""RK4 against the exact solution of a linear ODE, and its order of accuracy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

import auvmpc.native as native
from auvmpc.environment.currents import WaterCurrentConfig
from auvmpc.environment.disturbances import DisturbanceConfig, WaveForceConfig, WorldDisturbance
from auvmpc.models.integrators import rk4, rk4_step_time_varying
from auvmpc.models.vehicle import body_from_world, dynamics
from auvmpc.sim.plant import PlantStepper, plant_step
from tests.conftest import PLANT_VS_SOLVE_IVP_TOL

A = np.array([[0.0, 1.0], [-4.0, -0.4]])  # lightly damped oscillator


def linear(x, u):
    return A @ x + np.array([0.0, u])


def test_rk4_matches_matrix_exponential():
    x0 = np.array([1.0, 0.0])
    exact = expm(A * 1.0) @ x0
    np.testing.assert_allclose(rk4(linear, x0, 0.0, 1.0, substeps=100), exact, atol=1e-9)


def test_rk4_is_fourth_order():
    x0 = np.array([1.0, -0.5])
    exact = expm(A * 2.0) @ x0
    errors = [
        np.linalg.norm(rk4(linear, x0, 0.0, 2.0, substeps=n) - exact) for n in (10, 20, 40, 80)
    ]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    # The observed order tends to 4 as the step shrinks.
    np.testing.assert_allclose(orders, 4.0, atol=0.15)


def test_time_varying_rk4_is_fourth_order():
    # x' = cos(t) x has the solution x0 exp(sin t).
    def f(t, x):
        return np.cos(t) * x

    exact = np.exp(np.sin(3.0))
    errors = []
    for n in (20, 40, 80, 160):
        x, h = np.array([1.0]), 3.0 / n
        for i in range(n):
            x = rk4_step_time_varying(f, i * h, x, h)
        errors.append(abs(x[0] - exact))
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    # Pre-asymptotic at coarse steps: the order approaches 4 from above as h shrinks.
    assert np.all(np.diff(np.abs(orders - 4.0)) < 0)
    assert orders[-1] == pytest.approx(4.0, abs=0.1)


@pytest.mark.parametrize(
    "waves", [None, WaveForceConfig(amplitude_N=4.0, period_s=3.0, direction_deg=30)]
)
def test_plant_step_matches_solve_ivp(jmse, waves):
    rng = np.random.default_rng(0)
    config = DisturbanceConfig(current_force_world=(10.0, 5.0), moment_N_m=0.3, waves=waves)
    disturbance = WorldDisturbance(config, 0.5, rng)
    state = np.array([7.5, -12.0, 1.57, 0.4, 0.1, 0.06])
    thrust = np.array([12.0, -3.0, 7.0, 15.0])

    def rhs(t, x):
        force = disturbance.force_world(t)
        d_u, d_v = body_from_world(force, x[2])
        return dynamics(x, thrust, jmse, (d_u, d_v, force[2]))

    reference = solve_ivp(rhs, (1.0, 1.5), state, method="DOP853", rtol=1e-11, atol=1e-13).y[:, -1]
    ours = plant_step(jmse, state, thrust, 1.0, 0.5, disturbance, substeps=10)
    np.testing.assert_allclose(ours, reference, atol=PLANT_VS_SOLVE_IVP_TOL)


# The compiled plant sample evaluates the same expressions as plant_step in C; they differ
# only by the order of a few floating-point operations (measured: below 1e-14 m, m/s, rad).
COMPILED_PLANT_TOL = 1e-12


@pytest.mark.parametrize(
    "waves", [None, WaveForceConfig(amplitude_N=4.0, period_s=3.0, direction_deg=30)]
)
@pytest.mark.parametrize("water", [None, WaterCurrentConfig(velocity_m_per_s=(0.2, -0.1, 0.0))])
def test_compiled_plant_sample_is_plant_step(jmse, waves, water):
    if not PlantStepper(jmse, 0.5, 10).compiled:
        pytest.skip("no C compiler on this machine")
    config = DisturbanceConfig(
        current_force_world=(10.0, 5.0), moment_N_m=0.3, waves=waves, water_current=water
    )
    disturbance = WorldDisturbance(config, 0.5, np.random.default_rng(0))
    state = np.array([7.5, -12.0, 1.57, 0.4, 0.1, 0.06])
    thrust = np.array([12.0, -3.0, 7.0, 15.0])
    compiled = PlantStepper(jmse, 0.5, 10)
    for k in range(5):
        ours = compiled(state, thrust, 0.5 * k, disturbance)
        expected = plant_step(jmse, state, thrust, 0.5 * k, 0.5, disturbance, 10)
        np.testing.assert_allclose(ours, expected, rtol=0, atol=COMPILED_PLANT_TOL)
        state = expected


def test_without_a_compiler_the_plant_sample_is_plant_step(jmse, monkeypatch):
    monkeypatch.setattr(native, "compiler", lambda: None)
    stepper = PlantStepper(jmse, 0.4, 7)  # a sample no other test has compiled
    assert not stepper.compiled
    disturbance = WorldDisturbance(DisturbanceConfig(), 0.4, np.random.default_rng(0))
    state, thrust = np.array([0.0, 0.0, 0.3, 0.5, 0.0, 0.0]), np.array([5.0, 5.0, 0.0, 0.0])
    expected = plant_step(jmse, state, thrust, 0.0, 0.4, disturbance, 7)
    np.testing.assert_array_equal(stepper(state, thrust, 0.0, disturbance), expected)


def test_a_compiled_function_shared_by_threads_gives_each_its_own_answer(jmse):
    """Compiled functions are cached per process and ctypes releases the GIL: four threads
    stepping the same plant must each get the answer of their own inputs (without the
    function's lock, 54 of 40 000 threaded calls came back with another thread's)."""
    import threading

    stepper = PlantStepper(jmse, 0.5, 10)
    if not stepper.compiled:
        pytest.skip("no C compiler on this machine")
    disturbance = WorldDisturbance(
        DisturbanceConfig(current_force_world=(1.0, 2.0)), 0.5, np.random.default_rng(0)
    )
    rng = np.random.default_rng(1)
    cases = [(rng.normal(size=6), 5.0 * rng.normal(size=4)) for _ in range(800)]
    alone = [stepper(x, thrust, 0.0, disturbance) for x, thrust in cases]
    wrong = []

    def work(indices):
        for i in indices:
            if not np.array_equal(stepper(*cases[i], 0.0, disturbance), alone[i]):
                wrong.append(i)

    for _ in range(3):
        threads = [threading.Thread(target=work, args=(range(j, 800, 4),)) for j in range(4)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
    assert wrong == []
