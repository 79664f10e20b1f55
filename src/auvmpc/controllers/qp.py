"""Dense convex QP backends behind one interface, each set up once and updated per step.

    minimize 0.5 z' H z + f' z   s.t.  lower <= A z <= upper,  bound_lower <= z <= bound_upper

The MPC builds a small dense condensed QP every sample with the same shape (it
changes only when obstacles appear or vanish), so each backend keeps its
workspace and re-runs the full setup only when the shape changes.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

__all__ = ["QpProblem", "QpResult", "QpSolver", "QpSolverName", "make_qp_solver"]


class QpSolverName(StrEnum):
    """QP solvers a controller can use (benchmarks/qp_solvers.py compares them)."""

    DAQP = "daqp"
    OSQP = "osqp"
    PROXSUITE = "proxsuite"


@dataclass
class QpProblem:
    H: np.ndarray  # (nz, nz) symmetric positive definite
    f: np.ndarray  # (nz,)
    A: np.ndarray  # (m, nz)
    lower: np.ndarray  # (m,)
    upper: np.ndarray  # (m,)
    bound_lower: np.ndarray  # (nz,)
    bound_upper: np.ndarray  # (nz,)

    @property
    def shape(self) -> tuple[int, int]:
        return self.A.shape


@dataclass
class QpResult:
    z: np.ndarray | None  # None when the solver did not produce a usable solution
    solved: bool
    status: str
    iterations: int
    solve_time_s: float


class QpSolver(ABC):
    """One backend; ``solve`` reuses the workspace when the problem shape is unchanged."""

    def __init__(self, iteration_limit: int | None = None, tolerance: float = 1e-7) -> None:
        self.iteration_limit = iteration_limit
        self.tolerance = tolerance
        self._shape: tuple[int, int] | None = None

    def solve(self, problem: QpProblem, warm_start: np.ndarray | None = None) -> QpResult:
        started = time.perf_counter()
        if problem.shape != self._shape:
            self._setup(problem)
            self._shape = problem.shape
        else:
            self._update(problem)
        z, solved, status, iterations = self._solve(warm_start)
        return QpResult(z, solved, status, iterations, time.perf_counter() - started)

    @abstractmethod
    def _setup(self, problem: QpProblem) -> None: ...

    @abstractmethod
    def _update(self, problem: QpProblem) -> None: ...

    @abstractmethod
    def _solve(self, warm_start: np.ndarray | None) -> tuple[np.ndarray | None, bool, str, int]: ...


class DaqpSolver(QpSolver):
    """DAQP: dual active-set, dense; warm-started by keeping the last active set."""

    def _setup(self, problem: QpProblem) -> None:
        import daqp

        self._model = daqp.Model()
        upper, lower = self._bounds(problem)
        flag, _ = self._model.setup(problem.H, problem.f, problem.A, upper, lower)
        if flag < 0:
            self._shape = None
        settings = {"primal_tol": self.tolerance}
        if self.iteration_limit is not None:
            settings["iter_limit"] = self.iteration_limit
        for key, value in settings.items():
            self._model.settings[key] = value
        self._setup_failed = flag < 0

    def _update(self, problem: QpProblem) -> None:
        upper, lower = self._bounds(problem)
        flag = self._model.update(H=problem.H, f=problem.f, A=problem.A, bupper=upper, blower=lower)
        self._setup_failed = flag < 0

    @staticmethod
    def _bounds(problem: QpProblem) -> tuple[np.ndarray, np.ndarray]:
        # DAQP reads the first nz entries of the bound vectors as simple bounds on z.
        upper = np.concatenate([problem.bound_upper, problem.upper])
        lower = np.concatenate([problem.bound_lower, problem.lower])
        return upper, lower

    def _solve(self, warm_start):
        if self._setup_failed:
            self._shape = None
            return None, False, "setup failed", 0
        z, _, flag, info = self._model.solve()
        solved = flag == 1
        return (np.array(z) if solved else None), solved, f"exitflag {flag}", int(info["iterations"])


class OsqpSolver(QpSolver):
    """OSQP: ADMM, sparse; the dense matrices are stored with a fixed full pattern."""

    def _setup(self, problem: QpProblem) -> None:
        import osqp
        import scipy.sparse as sparse

        nz = problem.H.shape[0]
        m = problem.A.shape[0]
        # Upper triangle of H, column-major, every entry stored so that updates keep the pattern.
        self._p_rows, self._p_cols = np.triu_indices(nz)
        order = np.lexsort((self._p_rows, self._p_cols))
        self._p_rows, self._p_cols = self._p_rows[order], self._p_cols[order]
        p_indptr = np.concatenate([[0], np.cumsum(np.arange(1, nz + 1))])
        P = sparse.csc_matrix((problem.H[self._p_rows, self._p_cols], self._p_rows, p_indptr), shape=(nz, nz))
        full = self._stacked(problem)
        a_indices = np.tile(np.arange(nz + m), nz)
        a_indptr = (nz + m) * np.arange(nz + 1)
        A = sparse.csc_matrix((full.ravel(order="F"), a_indices, a_indptr), shape=(nz + m, nz))
        self._model = osqp.OSQP()
        settings = dict(
            verbose=False, eps_abs=self.tolerance, eps_rel=self.tolerance, polishing=True,
            warm_starting=True, max_iter=self.iteration_limit or 20000,
        )  # fmt: skip
        self._model.setup(P, problem.f, A, *self._limits(problem), **settings)

    def _update(self, problem: QpProblem) -> None:
        lower, upper = self._limits(problem)
        self._model.update(
            Px=problem.H[self._p_rows, self._p_cols],
            Ax=self._stacked(problem).ravel(order="F"),
            q=problem.f,
            l=lower,
            u=upper,
        )

    @staticmethod
    def _stacked(problem: QpProblem) -> np.ndarray:
        return np.vstack([np.eye(problem.H.shape[0]), problem.A])

    @staticmethod
    def _limits(problem: QpProblem) -> tuple[np.ndarray, np.ndarray]:
        lower = np.concatenate([problem.bound_lower, problem.lower])
        upper = np.concatenate([problem.bound_upper, problem.upper])
        return lower, upper

    def _solve(self, warm_start):
        import osqp

        if warm_start is not None:
            self._model.warm_start(x=warm_start)
        result = self._model.solve()
        solved = result.info.status_val == osqp.SolverStatus.OSQP_SOLVED
        return (np.array(result.x) if solved else None), solved, result.info.status, result.info.iter


class ProxsuiteSolver(QpSolver):
    """ProxQP (proxsuite), dense backend with box constraints; warm-started from the last result."""

    def _setup(self, problem: QpProblem) -> None:
        import proxsuite

        nz, m = problem.H.shape[0], problem.A.shape[0]
        self._qp = proxsuite.proxqp.dense.QP(nz, 0, m, box_constraints=True)
        self._qp.settings.eps_abs = self.tolerance
        self._qp.settings.verbose = False
        if self.iteration_limit is not None:
            self._qp.settings.max_iter = self.iteration_limit
        self._qp.init(
            problem.H, problem.f, None, None, problem.A, problem.lower, problem.upper,
            problem.bound_lower, problem.bound_upper,
        )  # fmt: skip
        self._qp.settings.initial_guess = proxsuite.proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT

    def _update(self, problem: QpProblem) -> None:
        self._qp.update(
            problem.H, problem.f, None, None, problem.A, problem.lower, problem.upper,
            problem.bound_lower, problem.bound_upper,
        )  # fmt: skip

    def _solve(self, warm_start):
        import proxsuite

        self._qp.solve()
        status = self._qp.results.info.status
        solved = status == proxsuite.proxqp.QPSolverOutput.PROXQP_SOLVED
        z = np.array(self._qp.results.x) if solved else None
        return z, solved, str(status), int(self._qp.results.info.iter)


def make_qp_solver(
    name: QpSolverName, iteration_limit: int | None = None, tolerance: float = 1e-7
) -> QpSolver:
    backends = {
        QpSolverName.DAQP: DaqpSolver,
        QpSolverName.OSQP: OsqpSolver,
        QpSolverName.PROXSUITE: ProxsuiteSolver,
    }
    return backends[QpSolverName(name)](iteration_limit, tolerance)
