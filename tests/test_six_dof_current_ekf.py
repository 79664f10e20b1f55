"""The EKF of the 6-DOF state and the horizontal current (estimation/six_dof_current.py) on a
linear case where Kalman's steady state is known in closed form."""

from __future__ import annotations

import casadi as ca
import numpy as np
import scipy.linalg

from auvmpc.estimation.six_dof_current import SixDofCurrentEkf

NX, NC, TE = 12, 2, 0.25
# A still vehicle that the current carries: x and y move by the current, nothing else moves.
MEASUREMENT_STD = np.full(NX, 0.01)
MEASUREMENT_STD[:2] = 0.1  # a USBL-grade fix
PROCESS_STD = np.full(NX, 0.01)
CURRENT_RATE_STD, INITIAL_CURRENT_STD = 0.02, 0.5


def _drift_step() -> ca.Function:
    x, u, current, share = (
        ca.SX.sym(name, n) for name, n in (("x", NX), ("u", 1), ("c", 3), ("e", 1))
    )
    carried = ca.vertcat(x[0] + TE * current[0], x[1] + TE * current[1], x[2:])
    return ca.Function("step", [x, u, current, share], [carried])


def _steady_state() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(A, H, Q, R, P): the linear system and the a-posteriori covariance of its Kalman filter
    in steady state, from the discrete algebraic Riccati equation."""
    A = np.eye(NX + NC)
    A[0, NX], A[1, NX + 1] = TE, TE
    H = np.eye(NX, NX + NC)
    Q = np.diag(np.concatenate([PROCESS_STD**2, np.full(NC, CURRENT_RATE_STD**2 * TE)]))
    R = np.diag(MEASUREMENT_STD**2)
    prior = scipy.linalg.solve_discrete_are(A.T, H.T, Q, R)
    posterior = prior - prior @ H.T @ np.linalg.solve(H @ prior @ H.T + R, H @ prior)
    return A, H, Q, R, posterior


def _filter() -> SixDofCurrentEkf:
    return SixDofCurrentEkf(
        _drift_step(), TE, MEASUREMENT_STD, PROCESS_STD, CURRENT_RATE_STD, INITIAL_CURRENT_STD
    )


def test_its_covariance_settles_on_the_riccati_solution():
    """On a linear model the EKF is Kalman's filter: its covariance after the update settles
    on the discrete Riccati equation's (to 1e-6 relative: round-off over 400 samples)."""
    *_, posterior = _steady_state()
    ekf = _filter()
    ekf.reset(np.zeros(NX))
    for _ in range(400):
        ekf.correct(np.zeros(NX))
        ekf.predict(np.zeros(1), np.ones(1))
    ekf.correct(np.zeros(NX))
    np.testing.assert_allclose(ekf.filter.covariance, posterior, rtol=1e-6, atol=1e-12)


def test_its_errors_are_as_large_as_its_covariance_says():
    """Simulated with the noise the filter assumes, the estimate's errors in steady state have
    the spread of the Riccati covariance: position and current each within 20 % (3000 samples
    after 200 of settling, one fixed seed: the errors are correlated over ~20 samples, so some
    150 independent ones, and a variance from 150 samples is off by sqrt(2/150) = 12 % (1 sd)
    in a std by half that)."""
    A, H, Q, R, posterior = _steady_state()
    rng = np.random.default_rng(3)
    truth = np.zeros(NX + NC)
    truth[NX:] = (0.3, -0.2)
    ekf = _filter()
    ekf.reset(np.zeros(NX))
    errors = []
    for k in range(3200):
        measured = H @ truth + rng.normal(0.0, MEASUREMENT_STD)
        state, current = ekf.correct(measured)
        if k >= 200:
            errors.append(np.concatenate([state, current]) - truth)
        ekf.predict(np.zeros(1), np.ones(1))
        truth = A @ truth + rng.multivariate_normal(np.zeros(NX + NC), Q)
    spread = np.std(errors, axis=0)
    expected = np.sqrt(np.diag(posterior))
    for index in (0, 1, NX, NX + 1):
        assert abs(spread[index] / expected[index] - 1.0) < 0.2, index
    # and the fix's noise is filtered: the position is known better than it is measured
    assert spread[0] < 0.5 * MEASUREMENT_STD[0]
