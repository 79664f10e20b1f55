"""Replay the QPs the MPC really solves through every backend and print one table.

    python benchmarks/qp_solvers.py [--cases ltv-nc2 ltv-nc30 mpc-nc2] [--repeats 1]

About 90 s of CPU with the defaults on a 2-core EPYC VM, three quarters of it OSQP
and ProxQP on the control-horizon-30 case (their failed solves run to the iteration
limit); each extra repeat adds about as much. ``--cases ltv-nc2 mpc-nc2`` takes ~15 s.

Each case runs the paper-obstacles scenario closed loop through auvmpc's own code
(``load_scenario`` -> ``simulate``, DAQP in the loop) and records every QP handed to
``QpSolver.solve`` together with the controller's warm start. The identical
sequence is then replayed through each backend exactly as the controller drives it:
one solver object for the whole run, ``update`` while the shape holds, a new setup
when obstacle rows come or go, the recorded warm start on every call.

Columns, per backend and case:

* solve time (ms): median, 99th percentile and maximum over the steps of the run,
  setup or update included; each step's time is the minimum over the repeats,
  which filters out preemption by other processes;
* fail: steps without a certified optimum (``solved=False``);
* max|dz|: largest ``|z - z_ref|`` over the solved steps, against a tight
  reference (DAQP set up from scratch for every QP, ``primal_tol`` 1e-10);
* cost gap: largest ``(J(z) - J(z_ref)) / max(1, |J(z_ref)|)``; a backend can be
  far from ``z_ref`` along a nearly flat direction of H at almost no cost;
* max viol: largest violation of a bound or row by a returned ``z``.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import importlib.metadata
import os
import platform
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from auvmpc.experiments.run import simulate
from auvmpc.scenario import load_scenario
from auvmpc.solvers.dense_qp import QpProblem, QpSolver, QpSolverName, make_qp_solver

SCENARIO = "paper-obstacles"
# Case name -> scenario overrides. DAQP is forced in the recording run so the recorded
# trajectory (and so the QP sequence) does not depend on the scenario file's choice.
CASES: dict[str, tuple[str, ...]] = {
    "ltv-nc2": ("controller.type=ltv-mpc", "controller.control_horizon=2"),
    "ltv-nc30": ("controller.type=ltv-mpc", "controller.control_horizon=30"),
    "mpc-nc2": ("controller.type=mpc", "controller.control_horizon=2"),
}
RECORDING_SOLVER = "controller.qp_solver=daqp"
REFERENCE_TOLERANCE = 1e-10  # DAQP primal_tol of the reference solves
LIBRARIES = ("numpy", "scipy", "casadi", "daqp", "osqp", "proxsuite")


@dataclass
class Recorded:
    """One QP as the controller posed it."""

    problem: QpProblem
    warm_start: np.ndarray | None


@dataclass
class Row:
    """One line of the table."""

    backend: str
    case: str
    times_ms: np.ndarray
    failures: int
    max_dz: float
    max_cost_gap: float
    max_violation: float


@contextlib.contextmanager
def recording(into: list[Recorded]) -> Iterator[None]:
    """Append a copy of every (problem, warm start) any QpSolver is asked to solve."""
    original = QpSolver.solve

    def solve(self: QpSolver, problem: QpProblem, warm_start: np.ndarray | None = None):
        warm = None if warm_start is None else np.array(warm_start, dtype=float)
        into.append(Recorded(copy.deepcopy(problem), warm))
        return original(self, problem, warm_start)

    QpSolver.solve = solve  # type: ignore[method-assign]
    try:
        yield
    finally:
        QpSolver.solve = original  # type: ignore[method-assign]


def record_case(case: str) -> list[Recorded]:
    """Run the scenario closed loop and return the QPs in the order they were solved."""
    recorded: list[Recorded] = []
    resolved = load_scenario(SCENARIO, [*CASES[case], RECORDING_SOLVER])
    with recording(recorded):
        simulate(resolved)
    return recorded


def reference_solutions(recorded: list[Recorded]) -> list[np.ndarray | None]:
    """Tight DAQP solve of every QP from a fresh setup (no warm start, no history)."""
    references = []
    for item in recorded:
        result = make_qp_solver(QpSolverName.DAQP, tolerance=REFERENCE_TOLERANCE).solve(
            item.problem
        )
        references.append(result.z)
    return references


def violation(problem: QpProblem, z: np.ndarray) -> float:
    """Largest violation of a simple bound or a row bound by ``z``."""
    rows = problem.A @ z
    return float(
        max(
            np.max(problem.bound_lower - z, initial=0.0),
            np.max(z - problem.bound_upper, initial=0.0),
            np.max(problem.lower - rows, initial=0.0),
            np.max(rows - problem.upper, initial=0.0),
        )
    )


def cost(problem: QpProblem, z: np.ndarray) -> float:
    """0.5 z' H z + f' z."""
    return float(0.5 * z @ problem.H @ z + problem.f @ z)


def replay(
    backend: QpSolverName,
    case: str,
    recorded: list[Recorded],
    references: list[np.ndarray | None],
    repeats: int,
) -> Row:
    """Solve the recorded sequence ``repeats`` times, each with a fresh solver object."""
    times = np.full((repeats, len(recorded)), np.inf)
    for repeat in range(repeats):
        solver = make_qp_solver(backend)
        results = []
        for k, item in enumerate(recorded):
            started = time.perf_counter()
            results.append(solver.solve(item.problem, item.warm_start))
            times[repeat, k] = time.perf_counter() - started
    # Accuracy from the last repeat (every repeat replays the same deterministic sequence).
    failures, max_dz, max_violation = 0, 0.0, 0.0
    gaps = []
    for item, result, reference in zip(recorded, results, references, strict=True):
        if not result.solved or result.z is None:
            failures += 1
            continue
        max_violation = max(max_violation, violation(item.problem, result.z))
        if reference is not None:
            max_dz = max(max_dz, float(np.max(np.abs(result.z - reference))))
            best = cost(item.problem, reference)
            gaps.append((cost(item.problem, result.z) - best) / max(1.0, abs(best)))
    return Row(
        backend=backend.value,
        case=case,
        times_ms=1e3 * times.min(axis=0),
        failures=failures,
        max_dz=max_dz,
        max_cost_gap=max(gaps, default=float("nan")),
        max_violation=max_violation,
    )


def machine_report() -> list[str]:
    """Processor, core count, Python and library versions, and the core affinity set."""
    cpu_model = "unknown"
    with contextlib.suppress(OSError):
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("model name"):
                    cpu_model = line.split(":", 1)[1].strip()
                    break
    versions = []
    for name in LIBRARIES:
        try:
            versions.append(f"{name} {importlib.metadata.version(name)}")
        except importlib.metadata.PackageNotFoundError:
            versions.append(f"{name} (not installed)")
    return [
        f"machine: {platform.machine()}, processor {platform.processor() or 'unknown'!r}, "
        f"CPU {cpu_model!r}, os.cpu_count() = {os.cpu_count()}",
        f"python {platform.python_version()} on {platform.system()} {platform.release()}",
        "libraries: " + ", ".join(versions),
    ]


def pin_to_one_core() -> str:
    """Pin this process to core 0 where the OS allows it; say what happened."""
    if not hasattr(os, "sched_setaffinity"):
        return "not pinned (os.sched_setaffinity unavailable on this platform)"
    try:
        os.sched_setaffinity(0, {0})
    except OSError as error:
        return f"not pinned ({error})"
    return f"pinned to core(s) {sorted(os.sched_getaffinity(0))}"


def describe(recorded: list[Recorded]) -> str:
    """Number, sizes and shape changes of a recorded sequence."""
    shapes = [item.problem.shape for item in recorded]
    sizes = np.array(shapes)
    setups = 1 + sum(a != b for a, b in zip(shapes, shapes[1:], strict=False))
    return (
        f"{len(recorded)} QPs, nz {sizes[:, 1].min()}..{sizes[:, 1].max()}, "
        f"rows {sizes[:, 0].min()}..{sizes[:, 0].max()}, {setups} shape changes (setups)"
    )


def format_table(rows: list[Row]) -> list[str]:
    """The table, one line per backend and case."""
    header = (
        f"{'backend':<10} {'case':<9} {'median':>8} {'p99':>8} {'max':>8} {'fail':>5} "
        f"{'max|dz|':>9} {'cost gap':>9} {'max viol':>9}"
    )
    lines = [header, f"{'':<20} {'(ms)':>8} {'(ms)':>8} {'(ms)':>8}", "-" * len(header)]
    for row in rows:
        lines.append(
            f"{row.backend:<10} {row.case:<9} {np.median(row.times_ms):8.3f} "
            f"{np.percentile(row.times_ms, 99):8.3f} {row.times_ms.max():8.3f} "
            f"{row.failures:5d} {row.max_dz:9.1e} {row.max_cost_gap:9.1e} "
            f"{row.max_violation:9.1e}"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    """Parse the arguments, record the cases, replay them and print the table."""
    run_started = time.perf_counter()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--cases", nargs="+", choices=list(CASES), default=list(CASES), help="cases to run"
    )
    parser.add_argument(
        "--repeats", type=int, default=1, help="replays per backend and case (minimum kept)"
    )
    parser.add_argument(
        "--backends",
        nargs="+",
        choices=[name.value for name in QpSolverName],
        default=[name.value for name in QpSolverName],
        help="backends to replay",
    )
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats must be >= 1, got {args.repeats}")

    affinity = pin_to_one_core()
    for line in machine_report():
        print(line)
    print(f"affinity: {affinity}")
    print(
        f"scenario {SCENARIO}; reference: DAQP from scratch per QP, primal_tol "
        f"{REFERENCE_TOLERANCE:g}; times are per-step minima over {args.repeats} repeat(s)"
    )
    rows = []
    for case in args.cases:
        started = time.perf_counter()
        recorded = record_case(case)
        references = reference_solutions(recorded)
        missing = sum(reference is None for reference in references)
        print(
            f"{case}: {describe(recorded)}; recorded in {time.perf_counter() - started:.1f} s"
            + (f"; reference failed on {missing} QPs (left out of max|dz|)" if missing else "")
        )
        for backend in args.backends:
            rows.append(replay(QpSolverName(backend), case, recorded, references, args.repeats))
        sys.stdout.flush()
    print()
    for line in format_table(rows):
        print(line)
    print(f"total {time.perf_counter() - run_started:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
