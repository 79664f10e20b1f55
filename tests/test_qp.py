"""QP backends against independent solutions, each other, and their failure contract."""

from __future__ import annotations

import importlib.util
import itertools

import numpy as np
import pytest
from scipy.optimize import Bounds, LinearConstraint, minimize

from auvmpc.solvers.dense_qp import QpProblem, QpResult, QpSolver, QpSolverName, make_qp_solver

# proxsuite is an optional backend (not among the core dependencies).
INSTALLED = [
    name.value
    for name in QpSolverName
    if name is not QpSolverName.PROXSUITE or importlib.util.find_spec("proxsuite") is not None
]
BACKENDS = [
    pytest.param(name.value, marks=pytest.mark.skipif(
        name.value not in INSTALLED, reason="proxsuite is not installed"
    ))
    for name in QpSolverName
]  # fmt: skip

# How far from the exact optimum each backend may land at its default settings, on the
# test QPs below (lambda(H) in [0.5, 5], |f| ~ 10, |z| <~ 10):
# * DAQP, active set: exact once the active set is right; a constraint violated by less
#   than primal_tol = 1e-6 may stay out of it. Observed <= 2e-14.
# * ProxQP stops at residuals and duality gap <= eps_abs = 1e-6: ~eps / lambda_min = 2e-6.
#   Observed <= 6e-6 on 300 QPs; 2e-5 for margin.
# * OSQP, eps_abs = eps_rel = 1e-5: polished results are exact, but when polishing finds
#   no active constraint the ADMM point stands, with a dual residual up to
#   1e-5 * (1 + ~20) = 2e-4, i.e. up to 4e-4 in z. Observed <= 2.2e-5 on 300 QPs.
ACCURACY = {"daqp": 1e-6, "proxsuite": 2e-5, "osqp": 4e-4}
# Two backends each within its ACCURACY of the optimum: the loosest pair sets the bound.
BACKENDS_AGREE_TOL = ACCURACY["osqp"] + ACCURACY["proxsuite"]
# Reference: a constraint within this of its bound at the SLSQP point is taken as active
# (SLSQP lands within ~1e-8; inactive constraints of the test QPs are much farther off).
ACTIVE_SET_GAP = 1e-6
# Round-off allowance of the reference's KKT certificate (feasibility, multiplier signs).
CERTIFICATE_TOL = 1e-9
# Constraint violation a "solved" result may show: the backends' feasibility tolerances
# (DAQP primal_tol 1e-6, OSQP eps 1e-5 scaled by |Az| <= ~10, ProxQP eps_abs 1e-6).
FEASIBILITY_TOL = 1e-4


def random_qp(rng: np.random.Generator, nz: int, m: int, p_infinite: float = 0.25) -> QpProblem:
    """Strictly convex QP, feasible by construction, some bounds infinite.

    H has eigenvalues in [0.5, 5]; the bounds enclose a random interior point z0 and
    the linear cost is large enough that the unconstrained optimum usually lies
    outside, so several constraints are active at the solution.
    """
    basis, _ = np.linalg.qr(rng.standard_normal((nz, nz)))
    H = basis @ np.diag(rng.uniform(0.5, 5.0, nz)) @ basis.T
    H = 0.5 * (H + H.T)
    f = rng.normal(0.0, 5.0, nz)
    A = rng.standard_normal((m, nz))
    z0 = rng.uniform(-0.5, 0.5, nz)
    lower = A @ z0 - rng.uniform(0.1, 1.0, m)
    upper = A @ z0 + rng.uniform(0.1, 1.0, m)
    bound_lower = z0 - rng.uniform(0.2, 1.5, nz)
    bound_upper = z0 + rng.uniform(0.2, 1.5, nz)
    for values, side in ((lower, -1), (upper, 1), (bound_lower, -1), (bound_upper, 1)):
        values[rng.random(values.size) < p_infinite] = side * np.inf
    return QpProblem(H, f, A, lower, upper, bound_lower, bound_upper)


def reference_solution(problem: QpProblem) -> np.ndarray:
    """The optimum, independently of the backends, certified by the KKT conditions.

    SciPy's SLSQP (a sequential least-squares method) finds the active set; the
    equality-constrained KKT system on that set is then solved exactly, and the
    point is accepted only if it is feasible and every multiplier has the right
    sign, which for a strictly convex QP makes it the unique optimum.
    """
    nz = problem.f.size
    bounded = np.isfinite(problem.lower) | np.isfinite(problem.upper)  # SciPy rejects free rows
    constraints = []
    if np.any(bounded):
        constraints.append(
            LinearConstraint(problem.A[bounded], problem.lower[bounded], problem.upper[bounded])
        )
    guess = minimize(
        lambda z: 0.5 * z @ problem.H @ z + problem.f @ z,
        np.clip(np.zeros(nz), problem.bound_lower, problem.bound_upper),
        jac=lambda z: problem.H @ z + problem.f,
        method="SLSQP",
        bounds=Bounds(problem.bound_lower, problem.bound_upper),
        constraints=constraints,
        options={"ftol": 1e-12, "maxiter": 1000},
    ).x
    G = np.vstack([np.eye(nz), problem.A])  # every constraint as lo <= G z <= hi
    lo = np.concatenate([problem.bound_lower, problem.lower])
    hi = np.concatenate([problem.bound_upper, problem.upper])
    at_lo = np.isfinite(lo) & (G @ guess - lo < ACTIVE_SET_GAP)
    at_hi = np.isfinite(hi) & (hi - G @ guess < ACTIVE_SET_GAP) & ~at_lo
    active = at_lo | at_hi
    n_active = int(active.sum())
    # H z + f = G_a' lam, with lam >= 0 on lower-active and lam <= 0 on upper-active rows.
    kkt = np.block([[problem.H, -G[active].T], [G[active], np.zeros((n_active, n_active))]])
    rhs = np.concatenate([-problem.f, np.where(at_lo, lo, hi)[active]])
    solution = np.linalg.solve(kkt, rhs)
    z, lam = solution[:nz], solution[nz:]
    assert np.all(G @ z >= lo - CERTIFICATE_TOL) and np.all(G @ z <= hi + CERTIFICATE_TOL)
    assert np.all(lam[at_lo[active]] >= -CERTIFICATE_TOL)
    assert np.all(lam[at_hi[active]] <= CERTIFICATE_TOL)
    return z


def violation(problem: QpProblem, z: np.ndarray) -> float:
    rows = problem.A @ z
    return float(
        max(
            np.max(problem.bound_lower - z, initial=0.0),
            np.max(z - problem.bound_upper, initial=0.0),
            np.max(problem.lower - rows, initial=0.0),
            np.max(rows - problem.upper, initial=0.0),
        )
    )


def check_contract(result: QpResult, nz: int) -> None:
    """solved <=> z is a finite (nz,) array; z is None otherwise."""
    if result.solved:
        assert result.z is not None and result.z.shape == (nz,)
        assert np.all(np.isfinite(result.z))
    else:
        assert result.z is None
    assert result.solve_time_s >= 0.0


def solved_z(result: QpResult, nz: int) -> np.ndarray:
    check_contract(result, nz)
    assert result.solved, result.status
    return result.z


def with_setup_counter(monkeypatch: pytest.MonkeyPatch, solver: QpSolver) -> list[int]:
    """Count calls of the backend's full setup (as opposed to an in-place update)."""
    calls: list[int] = []
    original = type(solver)._setup

    def counting(self, problem, warm_start):
        calls.append(problem.shape[0])
        return original(self, problem, warm_start)

    monkeypatch.setattr(type(solver), "_setup", counting)
    return calls


# Sizes like the MPC's smallest QPs (8 moves) and smaller, with and without rows.
SIZES = [(2, 0), (3, 2), (5, 4), (8, 8), (8, 12)]
SEEDS = range(4)


@pytest.fixture(scope="module")
def random_cases() -> list[tuple[QpProblem, np.ndarray]]:
    rng = np.random.default_rng(20240601)
    cases = []
    for nz, m in SIZES:
        for _ in SEEDS:
            problem = random_qp(rng, nz, m)
            cases.append((problem, reference_solution(problem)))
    return cases


@pytest.mark.parametrize("backend", BACKENDS)
def test_backend_matches_independent_reference(backend, random_cases):
    for problem, reference in random_cases:
        nz = problem.f.size
        z = solved_z(make_qp_solver(backend).solve(problem), nz)
        np.testing.assert_allclose(z, reference, rtol=0.0, atol=ACCURACY[backend])
        assert violation(problem, z) <= FEASIBILITY_TOL


def test_random_cases_have_active_constraints(random_cases):
    """The comparison above means little if every optimum were unconstrained."""
    active = 0
    for problem, reference in random_cases:
        unconstrained = np.linalg.solve(problem.H, -problem.f)
        active += not np.allclose(unconstrained, reference, atol=1e-6)
    assert active >= 0.8 * len(random_cases)


def test_backends_agree_with_each_other(random_cases):
    for problem, _ in random_cases:
        nz = problem.f.size
        solutions = {name: solved_z(make_qp_solver(name).solve(problem), nz) for name in INSTALLED}
        for first, second in itertools.combinations(INSTALLED, 2):
            np.testing.assert_allclose(
                solutions[first], solutions[second], rtol=0.0, atol=BACKENDS_AGREE_TOL,
                err_msg=f"{first} vs {second}",
            )  # fmt: skip


@pytest.mark.parametrize("backend", BACKENDS)
def test_unconstrained_equals_newton_step(backend):
    rng = np.random.default_rng(1)
    nz = 6
    problem = random_qp(rng, nz, 3, p_infinite=1.0)  # every bound infinite
    expected = np.linalg.solve(problem.H, -problem.f)
    z = solved_z(make_qp_solver(backend).solve(problem), nz)
    np.testing.assert_allclose(z, expected, rtol=0.0, atol=ACCURACY[backend])


@pytest.mark.parametrize("backend", BACKENDS)
def test_equality_rows_solve_the_kkt_system(backend):
    """Rows with lower == upper are equalities: [H A'; A 0] [z; y] = [-f; b]."""
    rng = np.random.default_rng(2)
    nz, m = 6, 2
    template = random_qp(rng, nz, m)
    b = rng.normal(0.0, 1.0, m)
    problem = QpProblem(
        template.H, template.f, template.A, b, b, np.full(nz, -np.inf), np.full(nz, np.inf)
    )
    kkt = np.block([[problem.H, problem.A.T], [problem.A, np.zeros((m, m))]])
    expected = np.linalg.solve(kkt, np.concatenate([-problem.f, b]))[:nz]
    z = solved_z(make_qp_solver(backend).solve(problem), nz)
    np.testing.assert_allclose(z, expected, rtol=0.0, atol=ACCURACY[backend])


@pytest.mark.parametrize("backend", BACKENDS)
def test_update_with_new_data_gives_the_new_optimum(backend, monkeypatch):
    rng = np.random.default_rng(3)
    nz, m = 8, 8
    solver = make_qp_solver(backend)
    setups = with_setup_counter(monkeypatch, solver)
    first = random_qp(rng, nz, m)
    solved_z(solver.solve(first), nz)
    # Same shape, every array different (H, f, A and all bounds): an in-place update.
    second = random_qp(rng, nz, m)
    z = solved_z(solver.solve(second, warm_start=np.zeros(nz)), nz)
    np.testing.assert_allclose(z, reference_solution(second), rtol=0.0, atol=ACCURACY[backend])
    assert setups == [m]
    # Changing only the cost or only the bounds must be picked up as well.
    third = QpProblem(
        second.H, -second.f, second.A, second.lower, second.upper,
        second.bound_lower, second.bound_upper,
    )  # fmt: skip
    z = solved_z(solver.solve(third, warm_start=z), nz)
    np.testing.assert_allclose(z, reference_solution(third), rtol=0.0, atol=ACCURACY[backend])
    # Rows dropped (infinite bounds) and a box that cuts off the last optimum: feasible
    # (z = 0 is inside) and with a different optimum.
    assert np.max(np.abs(z)) > 0.2
    tightened = QpProblem(
        third.H, third.f, third.A, np.full(m, -np.inf), np.full(m, np.inf),
        np.full(nz, -0.1), np.full(nz, 0.1),
    )  # fmt: skip
    z = solved_z(solver.solve(tightened, warm_start=z), nz)
    np.testing.assert_allclose(z, reference_solution(tightened), rtol=0.0, atol=ACCURACY[backend])
    assert np.max(np.abs(z)) <= 0.1 + FEASIBILITY_TOL
    assert setups == [m]


@pytest.mark.parametrize("backend", BACKENDS)
def test_shape_change_sets_up_again(backend, monkeypatch):
    """Obstacle rows and slacks come and go in the MPC: (m, nz) changes between steps."""
    rng = np.random.default_rng(4)
    solver = make_qp_solver(backend)
    setups = with_setup_counter(monkeypatch, solver)
    sequence = [(8, 8), (8, 8), (9, 13), (9, 13), (8, 8)]
    for nz, m in sequence:
        problem = random_qp(rng, nz, m)
        z = solved_z(solver.solve(problem, warm_start=np.zeros(nz)), nz)
        np.testing.assert_allclose(z, reference_solution(problem), rtol=0.0, atol=ACCURACY[backend])
    assert setups == [8, 13, 8]


def contradictory_rows(nz: int = 3) -> QpProblem:
    """z0 + z1 >= 1 and z0 + z1 <= -1: each row feasible alone, together empty."""
    A = np.zeros((2, nz))
    A[:, :2] = 1.0
    return QpProblem(
        H=np.eye(nz),
        f=np.ones(nz),
        A=A,
        lower=np.array([1.0, -np.inf]),
        upper=np.array([np.inf, -1.0]),
        bound_lower=np.full(nz, -10.0),
        bound_upper=np.full(nz, 10.0),
    )


@pytest.mark.parametrize("backend", BACKENDS)
def test_contradictory_rows_report_failure_without_raising(backend):
    solver = make_qp_solver(backend)
    infeasible = contradictory_rows()
    result = solver.solve(infeasible)
    check_contract(result, 3)
    assert not result.solved
    # The same solver recovers on a feasible problem of the same shape.
    feasible = QpProblem(
        infeasible.H, infeasible.f, infeasible.A, np.array([1.0, -np.inf]),
        np.array([np.inf, 5.0]), infeasible.bound_lower, infeasible.bound_upper,
    )  # fmt: skip
    z = solved_z(solver.solve(feasible), 3)
    np.testing.assert_allclose(z, reference_solution(feasible), rtol=0.0, atol=ACCURACY[backend])


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("where", ["row", "variable"])
def test_empty_bound_interval_reports_failure(backend, where):
    problem = random_qp(np.random.default_rng(5), 4, 3, p_infinite=0.0)
    if where == "row":
        problem.lower[1], problem.upper[1] = 1.0, -1.0
    else:
        problem.bound_lower[2], problem.bound_upper[2] = 0.5, 0.4
    result = make_qp_solver(backend).solve(problem)
    check_contract(result, 4)
    assert not result.solved
    assert "infeasible" in result.status


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("field", ["H", "f", "A", "lower"])
def test_non_finite_data_reports_failure(backend, field):
    problem = random_qp(np.random.default_rng(6), 4, 3, p_infinite=0.0)
    getattr(problem, field).flat[0] = np.nan
    result = make_qp_solver(backend).solve(problem)
    check_contract(result, 4)
    assert not result.solved


@pytest.mark.parametrize("backend", BACKENDS)
def test_iteration_limit_one_reports_failure(backend):
    rng = np.random.default_rng(7)
    problem = random_qp(rng, 8, 8, p_infinite=0.0)
    unlimited = make_qp_solver(backend).solve(problem)
    solved_z(unlimited, 8)
    assert unlimited.iterations > 1  # the limit below really cuts the solve short
    result = make_qp_solver(backend, iteration_limit=1).solve(problem)
    check_contract(result, 8)
    assert not result.solved
    assert result.iterations <= 1


def test_osqp_prints_nothing(capfd):
    """OSQP 1.1 writes a polishing note from C when no constraint is active."""
    problem = random_qp(np.random.default_rng(8), 4, 2, p_infinite=1.0)
    solved_z(make_qp_solver(QpSolverName.OSQP).solve(problem), 4)
    assert capfd.readouterr().out == ""


def test_unknown_backend_is_rejected():
    with pytest.raises(ValueError, match="unknown QP solver 'gurobi'"):
        make_qp_solver("gurobi")


@pytest.mark.parametrize("limit", [0, -3, 2.5])
def test_bad_iteration_limit_is_rejected(limit):
    with pytest.raises(ValueError, match="iteration_limit must be an integer >= 1"):
        make_qp_solver(QpSolverName.DAQP, iteration_limit=limit)


@pytest.mark.parametrize("tolerance", [0.0, -1e-6, float("nan"), float("inf")])
def test_bad_tolerance_is_rejected(tolerance):
    with pytest.raises(ValueError, match="tolerance must be a positive finite number"):
        make_qp_solver(QpSolverName.DAQP, tolerance=tolerance)


def test_inconsistent_problem_shapes_are_rejected():
    with pytest.raises(ValueError, match=r"QpProblem.f must have shape \(3,\)"):
        QpProblem(np.eye(3), np.zeros(2), np.zeros((1, 3)), *np.zeros((2, 1)), *np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"QpProblem.A must have shape \(m, 3\)"):
        QpProblem(np.eye(3), np.zeros(3), np.zeros((1, 2)), *np.zeros((2, 1)), *np.zeros((2, 3)))


def test_warm_start_of_the_wrong_size_is_rejected():
    problem = random_qp(np.random.default_rng(9), 4, 2)
    with pytest.raises(ValueError, match=r"warm_start must be a finite \(4,\) array"):
        make_qp_solver(QpSolverName.DAQP).solve(problem, warm_start=np.zeros(5))


def test_a_non_finite_solution_claimed_optimal_is_a_failure(monkeypatch):
    """daqp 0.11 once returned NaN with exitflag 1 (inf bounds after an update)."""
    solver = make_qp_solver(QpSolverName.DAQP)
    monkeypatch.setattr(
        solver, "_solve", lambda warm_start: (np.full(4, np.nan), True, "optimal", 3)
    )
    result = solver.solve(random_qp(np.random.default_rng(10), 4, 2))
    check_contract(result, 4)
    assert not result.solved
    assert "not a finite" in result.status


def test_an_exception_in_the_binding_is_a_failure_and_the_next_solve_starts_afresh(monkeypatch):
    rng = np.random.default_rng(11)
    solver = make_qp_solver(QpSolverName.DAQP)
    setups = with_setup_counter(monkeypatch, solver)
    solved_z(solver.solve(random_qp(rng, 4, 2)), 4)

    def broken_update(problem):
        raise RuntimeError("workspace corrupted")

    monkeypatch.setattr(solver, "_update", broken_update)
    result = solver.solve(random_qp(rng, 4, 2))
    check_contract(result, 4)
    assert not result.solved
    assert result.status == "RuntimeError: workspace corrupted"
    problem = random_qp(rng, 4, 2)
    z = solved_z(solver.solve(problem), 4)  # set up again, not updated
    np.testing.assert_allclose(z, reference_solution(problem), rtol=0.0, atol=ACCURACY["daqp"])
    assert setups == [2, 2]
