"""Dense convex QP backends behind one interface, each set up once and updated per step.

    minimize 0.5 z' H z + f' z   s.t.  lower <= A z <= upper,  bound_lower <= z <= bound_upper

The MPC builds a small dense condensed QP every sample. Its shape changes only when
obstacle rows (and their slacks) come and go, so each backend keeps its workspace,
updates the data in place while the shape holds and runs the full setup again when
it changes. Infinite bounds (``+-np.inf``) are allowed wherever a side is absent.

Every backend reports a failure the same way: ``QpResult(z=None, solved=False)``
with the reason in ``status``, never an exception and never a non-finite ``z``. A
failure is whatever is not a certified optimum: infeasible or non-finite data, the
iteration limit, a solver status other than "solved", an error raised by the
binding. What a failure means for the vehicle is the caller's decision (mpc.py
applies the previous plan). Inconsistent array shapes are a programming error and
raise ``ValueError`` instead.

Each backend reads ``tolerance`` in its own terms (see its class); the defaults were
chosen with ``benchmarks/qp_solvers.py`` on the QPs of the paper-obstacles scenario.
"""

from __future__ import annotations

import contextlib
import math
import sys
import threading
import time
from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass
from enum import StrEnum
from typing import Any, ClassVar, TextIO

import numpy as np

__all__ = ["QpProblem", "QpResult", "QpSolver", "QpSolverName", "make_qp_solver"]


class QpSolverName(StrEnum):
    """QP solvers a controller can use (benchmarks/qp_solvers.py compares them)."""

    DAQP = "daqp"
    OSQP = "osqp"
    PROXSUITE = "proxsuite"


@dataclass
class QpProblem:
    """One dense QP; the arrays are stored as C-contiguous float64.

    Attributes
    ----------
    H : np.ndarray
        (nz, nz) symmetric positive definite Hessian.
    f : np.ndarray
        (nz,) linear cost.
    A : np.ndarray
        (m, nz) general constraint rows; m may be 0.
    lower, upper : np.ndarray
        (m,) row bounds, ``-inf`` / ``+inf`` where a side is absent.
    bound_lower, bound_upper : np.ndarray
        (nz,) simple bounds on z, ``-inf`` / ``+inf`` where a side is absent.

    Raises
    ------
    ValueError
        If a shape does not match the others (named in the message).
    """

    H: np.ndarray
    f: np.ndarray
    A: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    bound_lower: np.ndarray
    bound_upper: np.ndarray

    def __post_init__(self) -> None:
        for name in ("H", "f", "A", "lower", "upper", "bound_lower", "bound_upper"):
            setattr(self, name, np.ascontiguousarray(getattr(self, name), dtype=float))
        if self.H.ndim != 2 or self.H.shape[0] != self.H.shape[1]:
            raise ValueError(f"QpProblem.H must be square (nz, nz), got shape {self.H.shape}")
        nz = self.H.shape[0]
        if self.A.ndim != 2 or self.A.shape[1] != nz:
            raise ValueError(f"QpProblem.A must have shape (m, {nz}), got {self.A.shape}")
        m = self.A.shape[0]
        expected = {"f": nz, "lower": m, "upper": m, "bound_lower": nz, "bound_upper": nz}
        for name, size in expected.items():
            if getattr(self, name).shape != (size,):
                raise ValueError(
                    f"QpProblem.{name} must have shape ({size},), got {getattr(self, name).shape}"
                )

    @property
    def shape(self) -> tuple[int, int]:
        """(m, nz): rows of A and number of variables; a change forces a new setup."""
        return self.A.shape


@dataclass
class QpResult:
    """Outcome of one solve.

    Attributes
    ----------
    z : np.ndarray or None
        (nz,) finite solution when ``solved``, else None.
    solved : bool
        True only for an optimum the backend certified within its tolerance.
    status : str
        The backend's status (or the reason for the failure), for logs.
    iterations : int
        Backend iterations (0 when the backend was not run).
    solve_time_s : float
        Wall time of setup or update plus solve (s).
    """

    z: np.ndarray | None
    solved: bool
    status: str
    iterations: int
    solve_time_s: float


class QpSolver(ABC):
    """One backend; ``solve`` reuses the workspace while the problem shape is unchanged.

    Parameters
    ----------
    iteration_limit : int or None
        Cap on the backend's iterations; reaching it is a failure. None: the
        backend's ``default_iteration_limit``.
    tolerance : float or None
        Accuracy target, read by each backend as its class docstring says. None:
        the backend's ``default_tolerance``.

    Raises
    ------
    ValueError
        If ``iteration_limit`` < 1 or ``tolerance`` is not a positive finite number.
    ImportError
        If the backend's package is not installed.
    """

    default_tolerance: ClassVar[float]
    default_iteration_limit: ClassVar[int]

    def __init__(self, iteration_limit: int | None = None, tolerance: float | None = None) -> None:
        if iteration_limit is not None and (
            isinstance(iteration_limit, bool) or not isinstance(iteration_limit, int | np.integer)
            or iteration_limit < 1
        ):  # fmt: skip
            raise ValueError(f"iteration_limit must be an integer >= 1, got {iteration_limit!r}")
        if tolerance is not None and not (math.isfinite(tolerance) and tolerance > 0):
            raise ValueError(f"tolerance must be a positive finite number, got {tolerance!r}")
        self.iteration_limit = (
            self.default_iteration_limit if iteration_limit is None else int(iteration_limit)
        )
        self.tolerance = self.default_tolerance if tolerance is None else float(tolerance)
        self._shape: tuple[int, int] | None = None  # shape of the live workspace, None: none

    def solve(self, problem: QpProblem, warm_start: np.ndarray | None = None) -> QpResult:
        """Solve ``problem``, updating the workspace in place if the shape is unchanged.

        Parameters
        ----------
        problem : QpProblem
            The QP.
        warm_start : np.ndarray or None
            (nz,) guess of the solution, used where the backend can use one.

        Returns
        -------
        QpResult
            ``z`` finite and ``solved`` True, or ``z`` None and ``solved`` False.

        Raises
        ------
        ValueError
            If ``warm_start`` is not a finite (nz,) array (a programming error).
        """
        started = time.perf_counter()
        nz = problem.H.shape[0]
        if warm_start is not None:
            warm_start = np.asarray(warm_start, dtype=float)
            if warm_start.shape != (nz,) or not np.all(np.isfinite(warm_start)):
                raise ValueError(f"warm_start must be a finite ({nz},) array, got {warm_start!r}")

        defect = _data_defect(problem)
        if defect is not None:  # never hand NaN or an empty box to compiled code
            return QpResult(None, False, defect, 0, time.perf_counter() - started)
        try:
            if problem.shape == self._shape:
                failure = self._update(problem)
            else:
                self._shape = None
                failure = self._setup(problem, warm_start)
                if failure is None:
                    self._shape = problem.shape
            if failure is None:
                z, solved, status, iterations = self._solve(warm_start)
            else:
                z, solved, status, iterations = None, False, failure, 0
        except Exception as error:  # noqa: BLE001
            # The bindings raise ValueError, RuntimeError, TypeError or their own types
            # (osqp.OSQPException); any of them is a failed solve to the caller.
            z, solved, status, iterations = None, False, f"{type(error).__name__}: {error}", 0
        if solved and (z is None or z.shape != (nz,) or not np.all(np.isfinite(z))):
            solved, status = False, f"{status}, but the solution is not a finite ({nz},) array"
        if not solved:
            # Nothing of a failed attempt (active set, iterates, half-updated data) may
            # seed the next solve: the next call sets the backend up afresh.
            self._shape, z = None, None
        return QpResult(z, solved, status, iterations, time.perf_counter() - started)

    @abstractmethod
    def _setup(self, problem: QpProblem, warm_start: np.ndarray | None) -> str | None:
        """Build the workspace for ``problem``; return a failure reason or None."""

    @abstractmethod
    def _update(self, problem: QpProblem) -> str | None:
        """Replace all data of a same-shape problem; return a failure reason or None."""

    @abstractmethod
    def _solve(self, warm_start: np.ndarray | None) -> tuple[np.ndarray | None, bool, str, int]:
        """Run the backend: (z, solved, status, iterations)."""


def _data_defect(problem: QpProblem) -> str | None:
    """Why the data cannot be solved as given (non-finite, empty bound interval), or None."""
    for name in ("H", "f", "A"):
        if not np.all(np.isfinite(getattr(problem, name))):
            return f"non-finite entries in {name}"
    for kind, low, high in (
        ("row", problem.lower, problem.upper),
        ("variable", problem.bound_lower, problem.bound_upper),
    ):
        if np.any(np.isnan(low)) or np.any(np.isnan(high)):
            return f"NaN in the {kind} bounds"
        empty = (low > high) | (low == np.inf) | (high == -np.inf)
        if np.any(empty):
            return f"infeasible: empty {kind} bound interval at index {int(np.argmax(empty))}"
    return None


_DAQP_INFINITY = 1e30  # DAQP_INF in daqp's constants.h


class DaqpSolver(QpSolver):
    """DAQP: dual active-set, dense; warm-started by keeping the last active set.

    After a shape change the new workspace starts from the active set of the
    caller's warm start.

    ``tolerance`` is DAQP's ``primal_tol`` (accepted constraint violation). Exact
    active-set: the solution is optimal to round-off once the active set is right.
    Accepted status: exitflag 1 (optimal).
    """

    default_tolerance = 1e-6  # DAQP's own default
    default_iteration_limit = 10_000  # DAQP's own default; the MPC QPs need < 200
    _EXITFLAGS: ClassVar[dict[int, str]] = {
        1: "optimal",
        2: "soft optimal",
        -1: "infeasible",
        -2: "cycling",
        -3: "unbounded",
        -4: "iteration limit",
        -5: "nonconvex",
        -6: "overdetermined initial active set",
        -7: "time limit",
    }

    def __init__(self, iteration_limit: int | None = None, tolerance: float | None = None) -> None:
        super().__init__(iteration_limit, tolerance)
        import daqp

        self._daqp = daqp

    def _setup(self, problem: QpProblem, warm_start: np.ndarray | None) -> str | None:
        self._model = self._daqp.Model()
        # Settings are a property returning a copy: assign the dict, item assignment is lost.
        self._model.settings = {"primal_tol": self.tolerance, "iter_limit": self.iteration_limit}
        upper, lower = self._bounds(problem)
        # After a shape change the caller's guess seeds the active set (the constraints
        # nearly active at it): ~3 iterations instead of ~20 on the MPC's QPs.
        flag, _ = self._model.setup(
            problem.H, problem.f, problem.A, upper, lower, primal_start=warm_start
        )
        return None if flag >= 0 else f"setup: {self._describe(flag)}"

    def _update(self, problem: QpProblem) -> str | None:
        upper, lower = self._bounds(problem)
        flag = self._model.update(H=problem.H, f=problem.f, A=problem.A, bupper=upper, blower=lower)
        return None if flag >= 0 else f"update: {self._describe(flag)}"

    @staticmethod
    def _bounds(problem: QpProblem) -> tuple[np.ndarray, np.ndarray]:
        # DAQP reads the first nz entries of the bound vectors as simple bounds on z.
        upper = np.concatenate([problem.bound_upper, problem.upper])
        lower = np.concatenate([problem.bound_lower, problem.lower])
        # +-inf is fine in setup but turns the whole solution into NaN after an update
        # (daqp 0.11, still with exitflag 1); DAQP's own infinity is 1e30.
        return np.minimum(upper, _DAQP_INFINITY), np.maximum(lower, -_DAQP_INFINITY)

    def _solve(self, warm_start: np.ndarray | None) -> tuple[np.ndarray | None, bool, str, int]:
        z, _, flag, info = self._model.solve()
        return z, flag == 1, self._describe(flag), int(info["iterations"])

    @classmethod
    def _describe(cls, flag: int) -> str:
        return f"{cls._EXITFLAGS.get(flag, 'unknown')} (exitflag {flag})"


class OsqpSolver(QpSolver):
    """OSQP: ADMM, sparse; the dense matrices are stored with a fixed full pattern.

    ``tolerance`` is both ``eps_abs`` and ``eps_rel``; solutions are polished, rho is
    adaptive and the data Ruiz-scaled (10 passes). ADMM converges slowly on the MPC's
    ill-conditioned Hessians (condition up to 1e10): 1e-6 or 1e-7 mostly buy more
    iteration-limit failures. Accepted status: ``OSQP_SOLVED`` only;
    ``SOLVED_INACCURATE`` (residuals within 10x the tolerance when the limit is hit)
    is rejected, because even "solved" points can be a few newtons off along the
    Hessian's nearly flat directions when polishing finds no active set (see the
    benchmark). The caller's warm start sets the primal iterate before each solve.
    """

    default_tolerance = 1e-5
    # OSQP's own 4000 fails 1 paper-obstacles QP in 3 and the vehicle hits an obstacle;
    # 20000 halves the failures, none hits, at <= 200 ms per solve (control horizon 2).
    default_iteration_limit = 20_000

    def __init__(self, iteration_limit: int | None = None, tolerance: float | None = None) -> None:
        super().__init__(iteration_limit, tolerance)
        import osqp

        self._osqp = osqp
        self._infinity = float(osqp.constant("OSQP_INFTY"))

    def _setup(self, problem: QpProblem, warm_start: np.ndarray | None) -> str | None:
        import scipy.sparse as sparse

        nz, m = problem.H.shape[0], problem.A.shape[0]
        # Upper triangle of H, column-major, every entry stored so that updates keep the pattern.
        rows, cols = np.triu_indices(nz)
        order = np.lexsort((rows, cols))
        self._p_rows, self._p_cols = rows[order], cols[order]
        p_indptr = np.concatenate([[0], np.cumsum(np.arange(1, nz + 1))])
        P = sparse.csc_matrix(
            (problem.H[self._p_rows, self._p_cols], self._p_rows, p_indptr), shape=(nz, nz)
        )
        # [I; A] with every entry stored (the identity carries the simple bounds).
        self._stacked = np.vstack([np.eye(nz), problem.A])
        a_indices = np.tile(np.arange(nz + m), nz)
        a_indptr = (nz + m) * np.arange(nz + 1)
        A = sparse.csc_matrix(
            (self._stacked.ravel(order="F"), a_indices, a_indptr), shape=(nz + m, nz)
        )
        self._model = self._osqp.OSQP()
        self._model.setup(
            P, problem.f, A, *self._limits(problem),
            verbose=False, eps_abs=self.tolerance, eps_rel=self.tolerance,
            polishing=True, warm_starting=True, adaptive_rho=True, scaling=10,
            max_iter=self.iteration_limit,
        )  # fmt: skip
        return None

    def _update(self, problem: QpProblem) -> str | None:
        lower, upper = self._limits(problem)
        self._stacked[problem.H.shape[0] :] = problem.A
        self._model.update(
            Px=problem.H[self._p_rows, self._p_cols],
            Ax=self._stacked.ravel(order="F"),
            q=problem.f,
            l=lower,
            u=upper,
        )
        return None

    def _limits(self, problem: QpProblem) -> tuple[np.ndarray, np.ndarray]:
        lower = np.concatenate([problem.bound_lower, problem.lower])
        upper = np.concatenate([problem.bound_upper, problem.upper])
        return np.maximum(lower, -self._infinity), np.minimum(upper, self._infinity)

    def _solve(self, warm_start: np.ndarray | None) -> tuple[np.ndarray | None, bool, str, int]:
        if warm_start is not None:
            self._model.warm_start(x=warm_start)
        with _osqp_polish_note_dropped():
            result = self._model.solve(raise_error=False)
        info = result.info
        solved = info.status_val == self._osqp.SolverStatus.OSQP_SOLVED
        z = np.array(result.x, dtype=float) if solved else None
        return z, solved, str(info.status), int(info.iter)


_OSQP_POLISH_NOTE = "Polishing not needed - no active set detected at optimal point"
_STDOUT_LOCK = threading.Lock()


class _WithoutPolishNote:
    """A text stream that forwards everything to ``stream`` except OSQP's polishing note."""

    def __init__(self, stream: TextIO) -> None:
        self._stream = stream

    def write(self, text: str) -> int:
        if text.strip() == _OSQP_POLISH_NOTE:
            return len(text)
        return self._stream.write(text)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)


@contextlib.contextmanager
def _osqp_polish_note_dropped() -> Iterator[None]:
    """Drop OSQP's "Polishing not needed" note from stdout for the duration.

    OSQP 1.1 prints it (through ``sys.stdout``) on every polished solve that ends with
    no active constraint, whatever ``verbose`` says. Anything else written meanwhile,
    by any thread, passes through; the lock keeps concurrent solves from restoring
    each other's stream.
    """
    with _STDOUT_LOCK:
        original = sys.stdout
        if original is None:
            yield
            return
        sys.stdout = _WithoutPolishNote(original)  # type: ignore[assignment]
        try:
            yield
        finally:
            sys.stdout = original


class ProxsuiteSolver(QpSolver):
    """ProxQP (proxsuite), dense backend with box constraints; warm-started from the last result.

    ``tolerance`` is ``eps_abs`` on the primal and dual residuals and on the duality
    gap; ``eps_rel`` is 0 because the MPC's gradients reach 1e5, so a relative test
    stops up to 5 N away from the optimum along the Hessian's nearly flat directions
    (eigenvalue ~0.01, set by the thrust weight R alone). With the default 1e-6, z is
    within 1e-4 of the optimum on the paper MPC's QPs; on the LTV-MPC's (condition
    up to 1e10) it can still be ~1 N off along those directions at a relative cost
    gap < 1e-5, while 1e-8 roughly doubles the iterations. Infinite bounds are passed
    as they are (ProxQP accepts them). Each solve after the first starts from the
    previous primal and dual solution; the caller's (primal-only) warm start is not
    used: with it the MPC QPs took ~6x the iterations. Accepted status:
    ``PROXQP_SOLVED``.
    """

    default_tolerance = 1e-6
    default_iteration_limit = 10_000  # ProxQP's default

    def __init__(self, iteration_limit: int | None = None, tolerance: float | None = None) -> None:
        super().__init__(iteration_limit, tolerance)
        import proxsuite

        self._proxqp = proxsuite.proxqp

    def _setup(self, problem: QpProblem, warm_start: np.ndarray | None) -> str | None:
        nz, m = problem.H.shape[0], problem.A.shape[0]
        self._qp = self._proxqp.dense.QP(nz, 0, m, True)
        settings = self._qp.settings
        settings.eps_abs = self.tolerance
        settings.eps_rel = 0.0
        settings.verbose = False
        settings.max_iter = self.iteration_limit
        # Without the duality-gap test ProxQP can stop at a feasible, stationary but
        # non-complementary point (up to 0.1 away from the optimum on random QPs).
        settings.check_duality_gap = True
        settings.eps_duality_gap_abs = self.tolerance
        settings.eps_duality_gap_rel = 0.0
        # First solve from the equality-constrained guess; WARM_START_WITH_PREVIOUS_RESULT
        # is switched on only after it (see _solve). Selected before the first solve it
        # either segfaults (proxsuite 0.8.0, when set after init) or starts from zeros
        # and can report a feasible problem primal infeasible (when set before init).
        settings.initial_guess = self._proxqp.InitialGuess.EQUALITY_CONSTRAINED_INITIAL_GUESS
        self._qp.init(*self._data(problem))
        return None

    def _update(self, problem: QpProblem) -> str | None:
        self._qp.update(*self._data(problem))
        return None

    @staticmethod
    def _data(problem: QpProblem) -> tuple[Any, ...]:
        # No equality rows: None for (A, b); no general rows: None for (C, l, u).
        rows = (problem.A, problem.lower, problem.upper) if problem.A.shape[0] else (None,) * 3
        return (problem.H, problem.f, None, None, *rows, problem.bound_lower, problem.bound_upper)

    def _solve(self, warm_start: np.ndarray | None) -> tuple[np.ndarray | None, bool, str, int]:
        self._qp.solve()
        info = self._qp.results.info
        solved = info.status == self._proxqp.QPSolverOutput.PROXQP_SOLVED
        z = np.array(self._qp.results.x, dtype=float) if solved else None
        if solved:  # from now on each solve starts at the last primal and dual solution
            guess = self._proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
            self._qp.settings.initial_guess = guess
        return z, solved, str(info.status), int(info.iter)


_BACKENDS: dict[QpSolverName, type[QpSolver]] = {
    QpSolverName.DAQP: DaqpSolver,
    QpSolverName.OSQP: OsqpSolver,
    QpSolverName.PROXSUITE: ProxsuiteSolver,
}


def make_qp_solver(
    name: QpSolverName | str, iteration_limit: int | None = None, tolerance: float | None = None
) -> QpSolver:
    """The backend called ``name``.

    Parameters
    ----------
    name : QpSolverName or str
        "daqp", "osqp" or "proxsuite".
    iteration_limit : int or None
        Cap on iterations (reaching it is a failure); None: the backend's default.
    tolerance : float or None
        Accuracy target in the backend's terms; None: the backend's default.

    Raises
    ------
    ValueError
        For an unknown name or an invalid limit or tolerance.
    """
    try:
        backend = _BACKENDS[QpSolverName(name)]
    except ValueError:
        known = ", ".join(item.value for item in QpSolverName)
        raise ValueError(f"unknown QP solver {name!r}; known: {known}") from None
    return backend(iteration_limit, tolerance)
