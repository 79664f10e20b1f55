"""Benchmark: controllers x scenarios, timed on one CPU core, one row of numbers per pair.

Each row holds the per-step controller solve time (median, 99th percentile, max; ms), the
wall time of the whole closed-loop run (s), the number of control steps and every run
metric of ``shared/spec/interfaces.md``. Timings are only as honest as the machine they ran
on: :func:`machine_info` describes it and the process is pinned to a single CPU for the runs.

Two yardsticks. For speed, do-mpc (``pip install 'auvmpc[compare]'``): the ``do-mpc`` label
solves the same optimal control problem with do-mpc and IPOPT in the same process, and every
row of a scenario that has a ``do-mpc`` row gets ``speedup_vs_do_mpc``, the do-mpc median step
time over its own. For control, any controller named the ``yardstick`` (e.g. ``los-pid``, the
autopilot a torpedo AUV flies): it runs on every scenario beside the others, on the same seed,
and every row gets ``vs_yardstick``, its tracking errors and median step time over the
yardstick's. With ``out`` each run is kept as a run folder beside the table.
"""

from __future__ import annotations

import gc
import json
import os
import platform
import statistics
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from importlib.metadata import PackageNotFoundError, version
from importlib.util import find_spec
from pathlib import Path
from typing import Any

import numpy as np
from rich.table import Table

from auvmpc.controllers.config import CONTROLLER_PRESETS
from auvmpc.errors import ConfigError
from auvmpc.experiments.markdown_table import Column
from auvmpc.experiments.markdown_table import table as markdown_table
from auvmpc.experiments.outputs import (
    OutputKind,
    atomic_write_text,
    folder_name,
    mark_folder,
    staged_folder,
)
from auvmpc.experiments.run import fill_run_folder, simulate
from auvmpc.scenario import ControllerType, ResolvedScenario, builtin_scenarios, load_scenario
from auvmpc.solvers.blasfeo_target import BLASFEO_ENV

__all__ = [
    "BenchCase",
    "CONTROLLER_PRESETS",
    "DEFAULT_CONTROLLERS",
    "DEFAULT_SCENARIOS",
    "DO_MPC_LABEL",
    "SCENARIO_CONTROLLER_LABEL",
    "YARDSTICK_METRICS",
    "add_speedups",
    "add_yardstick_ratios",
    "bench_markdown",
    "resolve_controller",
    "run_benchmark",
    "machine_info",
    "format_table",
    "rows_to_json",
    "pinned_to_one_cpu",
]

DO_MPC_LABEL = "do-mpc"
# The scenario's own controller, as ``auvmpc run NAME`` flies it (its row is labelled by type).
SCENARIO_CONTROLLER_LABEL = "default"
# A 6-DOF run's distance to the path and depth error after the transient (run.json metrics).
CROSS_TRACK, DEPTH = "cross_track_rms_after_transient_m", "depth_rms_error_after_transient_m"
# What a row is measured against the yardstick's row by (its value over the yardstick's).
YARDSTICK_METRICS = ("solve_ms_median", "rms_position_error_after_transient_m", CROSS_TRACK, DEPTH)
# The files a benchmark folder (``out``) holds beside one run folder per scenario and label.
TABLE_FILE, ROWS_FILE = "bench.md", "bench.json"
# do-mpc joins the defaults where the ``compare`` extra is installed, on the same OCPs as
# the full-horizon and the move-blocked controllers.
DEFAULT_CONTROLLERS = (
    "mpc", "ltv-mpc", "ltv-mpc-nc30", "ltv-mpc-blocked", "nmpc", "nmpc-full", "baseline",
) + (("do-mpc", "do-mpc-blocked") if find_spec("do_mpc") is not None else ())  # fmt: skip
DEFAULT_SCENARIOS = ("paper-ideal", "paper-disturbed", "paper-obstacles")

# The per-step solve statistics, computed as auvmpc.sim.metrics does (numpy's linear percentile).
SOLVE_STATS = {"solve_ms_median": 50.0, "solve_ms_p99": 99.0}
PACKAGES = ("numpy", "scipy", "casadi", "daqp", "osqp", "do-mpc")


@dataclass(frozen=True)
class BenchCase:
    """A labelled controller configuration, expressed as scenario overrides.

    Attributes
    ----------
    controller : str
        Label shown in the table and the JSON rows, e.g. ``"ltv-mpc-nc30"``.
    overrides : tuple of str
        ``field=value`` overrides applied to each scenario, e.g.
        ``("controller.type=ltv-mpc", "controller.control_horizon=30")``.
    """

    controller: str
    overrides: tuple[str, ...]


def resolve_controller(label: str) -> BenchCase:
    """The case for a preset label or a bare controller type name, with its own overrides.

    Parameters
    ----------
    label : str
        A key of :data:`CONTROLLER_PRESETS`, ``do-mpc`` (type do-mpc, control horizon 30),
        any ``controller.type`` value (the scenario's other controller settings are
        then kept), or ``default`` (:data:`SCENARIO_CONTROLLER_LABEL`: the scenario's own
        controller, unchanged); optionally followed by ``@field=value`` overrides for this
        row only, e.g. ``ltv-mpc-nc30@controller.disturbance_bound.force_N=10`` (the whole
        string is the row's label).

    Returns
    -------
    BenchCase

    Raises
    ------
    ConfigError
        If ``label`` is neither, naming the ``--controllers`` option.
    """
    name, *row_overrides = label.split("@")
    for override in row_overrides:
        if "=" not in override:
            raise ConfigError("--controllers", label, f"{override!r} is not field=value")
    presets = CONTROLLER_PRESETS
    if name == SCENARIO_CONTROLLER_LABEL:
        return BenchCase(label, tuple(row_overrides))
    if name in presets:
        return BenchCase(label, (*presets[name], *row_overrides))
    if name in {kind.value for kind in ControllerType}:
        return BenchCase(label, (f"controller.type={name}", *row_overrides))
    known = sorted(set(presets) | {kind.value for kind in ControllerType})
    known.append(SCENARIO_CONTROLLER_LABEL)
    raise ConfigError("--controllers", name, f"unknown controller; choose from {known}")


def run_benchmark(
    controllers: Sequence[str],
    scenarios: Sequence[str],
    repeats: int = 1,
    on_run: Callable[[int, int, str], None] | None = None,
    overrides: Sequence[str] = (),
    *,
    yardstick: str | None = None,
    out: Path | str | None = None,
    figures: bool = True,
    overwrite: bool = False,
) -> list[dict[str, Any]]:
    """Run every controller on every scenario, pinned to one CPU, and time it.

    Every name is checked and every scenario loaded before the first run, so a typo fails
    at once and no YAML parsing is timed.

    Parameters
    ----------
    controllers : sequence of str
        Controller labels, see :func:`resolve_controller`.
    scenarios : sequence of str
        Built-in scenario names or paths to scenario files.
    repeats : int
        Closed-loop runs per (controller, scenario) pair, at least 1.
    on_run : callable, optional
        ``on_run(done, total, name)`` before each run and once more with ``"done"``;
        ``total`` counts single runs (pairs x repeats).
    overrides : sequence of str
        Extra ``field=value`` overrides applied to every run after the controller's,
        e.g. ``("duration=5",)``.
    yardstick : str, optional
        A controller label (not ``default``) that every other row is measured against, on
        each scenario (:func:`add_yardstick_ratios`); run as its last controller unless
        ``controllers`` names it already.
    out : path, optional
        A benchmark folder to write: one run folder per row, ``SCENARIO/LABEL/`` (the
        scenario's name; the first repeat's run, as ``auvmpc run`` writes it), the table
        as ``bench.md`` (:func:`bench_markdown`) and the rows as ``bench.json``
        (:func:`rows_to_json`). New or empty, or an earlier benchmark folder with
        ``overwrite``; it appears only when every run is written.
    figures : bool
        Draw each run folder's figures (with ``out``).

    Returns
    -------
    list of dict
        One row per pair, scenarios in the outer loop. Keys: ``controller`` (the label;
        ``default`` becomes the scenario's controller type, with the label's ``@``
        overrides), ``scenario``, ``solve_ms_median``, ``solve_ms_p99``, ``solve_ms_max``
        (per controller step, over all steps of all repeats; ms), ``wall_s`` (wall time of
        one :func:`simulate` call, i.e. controller construction, closed loop and metrics;
        median over repeats; s), ``steps`` (control steps per run), ``repeats``,
        ``pinned_cpu`` (the CPU the runs were pinned to, None if pinning was not
        possible), ``speedup_vs_do_mpc`` (see :func:`add_speedups`), ``yardstick`` and
        ``vs_yardstick`` (see :func:`add_yardstick_ratios`), then every run metric.
        The metrics other than the solve times are those of the first repeat: runs are
        seeded and repeat exactly unless a solver time limit makes them timing dependent.

    Raises
    ------
    ConfigError
        Unknown controller (``--controllers``, ``--yardstick``), unknown scenario
        (``--scenarios``), no names at all, a label named twice, ``repeats`` below 1, an
        invalid override, or an ``out`` that may not be written.
    """
    if not controllers:
        raise ConfigError("--controllers", list(controllers), "name at least one controller")
    if not scenarios:
        raise ConfigError("--scenarios", list(scenarios), "name at least one scenario")
    if isinstance(repeats, bool) or not isinstance(repeats, int) or repeats < 1:
        raise ConfigError("--repeats", repeats, "need a whole number of at least 1")
    cases = [resolve_controller(label) for label in controllers]
    if yardstick is not None:
        cases += _yardstick_case(yardstick, cases)
    builtins = builtin_scenarios()
    for name in scenarios:
        if name not in builtins and not Path(name).is_file():
            raise ConfigError(
                "--scenarios", name, f"unknown scenario (not a file); built-ins: {list(builtins)}"
            )
    planned: list[tuple[str, str, ResolvedScenario]] = []
    for name in scenarios:
        for case in cases:
            resolved = load_scenario(name, (*case.overrides, *overrides))
            planned.append((name, _row_label(case, resolved), resolved))
    folders = _run_folders(planned) if out is not None else None
    total = len(planned) * repeats
    rows = []
    writing = (
        staged_folder(out, OutputKind.BENCH, overwrite=overwrite)
        if out is not None
        else nullcontext(None)
    )
    machine = machine_info()  # before pinning, which would show one CPU allowed
    with writing as staging, pinned_to_one_cpu() as cpu:
        for index, (name, label, resolved) in enumerate(planned):
            solve_ms: list[np.ndarray] = []
            wall_s: list[float] = []
            metrics: dict[str, Any] = {}
            steps = 0
            for repeat in range(repeats):
                if on_run is not None:
                    on_run(index * repeats + repeat, total, f"{name} / {label}")
                gc.collect()  # a collection left over from the previous run is not this run's
                started = time.perf_counter()
                result = simulate(resolved)
                wall_s.append(time.perf_counter() - started)
                solve_ms.append(result.log.solve_ms.copy())
                if repeat == 0:
                    metrics, steps = result.metrics, result.log.steps
                    if staging is not None:  # after the clock: writing is not the run's time
                        folder = staging / folders[index]
                        fill_run_folder(result, folder, figures=figures)
                        mark_folder(folder, OutputKind.RUN)
            row = _row(label, name, np.concatenate(solve_ms), wall_s, steps, cpu, metrics)
            controller = resolved.scenario.controller
            row["controller_type"] = str(controller.type)
            row["move_steps"] = list(getattr(controller, "move_schedule", tuple)())
            rows.append(row)
        rows = add_yardstick_ratios(add_speedups(rows), yardstick)
        if staging is not None:
            atomic_write_text(staging / TABLE_FILE, bench_markdown(rows, machine))
            atomic_write_text(staging / ROWS_FILE, rows_to_json(rows))
    if on_run is not None:
        on_run(total, total, "done")
    return rows


def _yardstick_case(label: str, cases: Sequence[BenchCase]) -> list[BenchCase]:
    """The yardstick's case to add to ``cases`` (none if they name it already)."""
    if label.split("@")[0] == SCENARIO_CONTROLLER_LABEL:
        raise ConfigError(
            "--yardstick", label, "name the controller to measure against (e.g. los-pid)"
        )
    try:
        case = resolve_controller(label)
    except ConfigError as error:
        raise ConfigError("--yardstick", label, error.reason) from None
    return [] if any(c.controller == label for c in cases) else [case]


def _row_label(case: BenchCase, resolved: ResolvedScenario) -> str:
    """The case's label, the scenario's own controller named by its type."""
    name, at, rest = case.controller.partition("@")
    if name != SCENARIO_CONTROLLER_LABEL:
        return case.controller
    return f"{resolved.scenario.controller.type}{at}{rest}"


def _run_folders(planned: Sequence[tuple[str, str, ResolvedScenario]]) -> list[Path]:
    """``SCENARIO/LABEL`` of each planned run, checked to be folder names and distinct."""
    folders = []
    for _, label, resolved in planned:
        folder = Path(
            folder_name(resolved.scenario.name, "scenario.name"),
            folder_name(label, "--controllers"),
        )
        if folder in folders:
            raise ConfigError(
                "--controllers", label, f"runs twice on {resolved.scenario.name}: name it once"
            )
        folders.append(folder)
    return folders


def add_speedups(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Rows with ``speedup_vs_do_mpc`` set: do-mpc's median step time over the row's own.

    Parameters
    ----------
    rows : sequence of dict
        Benchmark rows (``controller``, ``scenario``, ``solve_ms_median`` at least).

    Returns
    -------
    list of dict
        New rows, in order. The ratio is taken against the do-mpc row that solves the same
        OCP: same scenario and same move schedule (1.0 on that row itself); it is None
        where there is no such row or a median is zero.
    """

    def problem(row: dict[str, Any]) -> tuple:
        return row["scenario"], tuple(row.get("move_steps") or ())

    reference = {
        problem(row): row["solve_ms_median"]
        for row in rows
        if row.get("controller_type", row["controller"]) == DO_MPC_LABEL
    }
    result = []
    for row in rows:
        do_mpc_ms, own_ms = reference.get(problem(row)), row["solve_ms_median"]
        speedup = do_mpc_ms / own_ms if do_mpc_ms and own_ms > 0 else None
        result.append({**row, "speedup_vs_do_mpc": speedup})  # keeps the key's place
    return result


def add_yardstick_ratios(
    rows: Sequence[dict[str, Any]], yardstick: str | None
) -> list[dict[str, Any]]:
    """Rows with ``yardstick`` and ``vs_yardstick`` set: each of :data:`YARDSTICK_METRICS`
    over the yardstick row's, on the same scenario (so the same seed).

    Parameters
    ----------
    rows : sequence of dict
        Benchmark rows (``controller``, ``scenario`` and the metrics).
    yardstick : str or None
        The label of the yardstick's rows.

    Returns
    -------
    list of dict
        New rows, in order. ``yardstick`` is the label and ``vs_yardstick`` a dict of
        ratios (1.0 on the yardstick's row; None where either value is missing or the
        yardstick's is zero) where the scenario has a yardstick row; both None where not.
    """
    reference = {row["scenario"]: row for row in rows if row["controller"] == yardstick}
    result = []
    for row in rows:
        bar = reference.get(row["scenario"])
        ratios = None
        if bar is not None:
            ratios = {key: _ratio(row.get(key), bar.get(key)) for key in YARDSTICK_METRICS}
        result.append(
            {**row, "yardstick": None if bar is None else yardstick, "vs_yardstick": ratios}
        )  # keeps the keys' places
    return result


def _ratio(value: float | None, reference: float | None) -> float | None:
    if value is None or reference is None or not reference:
        return None
    return float(value) / float(reference)


def _row(
    controller: str,
    scenario: str,
    solve_ms: np.ndarray,
    wall_s: Sequence[float],
    steps: int,
    cpu: int | None,
    metrics: dict[str, Any],
) -> dict[str, Any]:
    head: dict[str, Any] = {"controller": controller, "scenario": scenario}
    for key, q in SOLVE_STATS.items():
        head[key] = float(np.percentile(solve_ms, q)) if len(solve_ms) else 0.0
    head["solve_ms_max"] = float(solve_ms.max()) if len(solve_ms) else 0.0
    head["wall_s"] = float(statistics.median(wall_s))
    head["steps"] = int(steps)
    head["repeats"] = len(wall_s)
    head["pinned_cpu"] = cpu
    head["speedup_vs_do_mpc"] = None  # set by add_speedups once every row is known
    head["yardstick"] = None  # these two by add_yardstick_ratios
    head["vs_yardstick"] = None
    return {**head, **{key: value for key, value in metrics.items() if key not in head}}


@contextmanager
def pinned_to_one_cpu() -> Iterator[int | None]:
    """Run the body on the first CPU this process may use; restore the affinity afterwards.

    On Linux an affinity belongs to a thread, so every thread of the process is pinned
    (math libraries start worker threads at import), and threads started inside the body
    are returned to the process's previous CPU set at exit.

    Yields
    ------
    int or None
        The CPU pinned to, or None where affinity cannot be set (not Linux, or refused).
    """
    if not hasattr(os, "sched_setaffinity"):
        yield None
        return
    allowed = os.sched_getaffinity(0)
    cpu = min(allowed)
    previous: dict[int, set[int]] = {}
    try:
        os.sched_setaffinity(0, {cpu})
    except OSError:
        yield None
        return
    previous[threading.get_native_id()] = allowed
    try:
        for tid in _thread_ids():
            if tid in previous:
                continue
            try:
                previous[tid] = os.sched_getaffinity(tid)
                os.sched_setaffinity(tid, {cpu})
            except OSError:  # the thread ended meanwhile, or is not ours to move
                previous.pop(tid, None)
        yield cpu
    finally:
        for tid in _thread_ids():
            try:
                os.sched_setaffinity(tid, previous.get(tid, allowed))
            except OSError:
                pass


def _thread_ids() -> list[int]:
    try:
        return [int(entry) for entry in os.listdir("/proc/self/task")]
    except OSError:
        return [threading.get_native_id()]


def machine_info() -> dict[str, Any]:
    """What the timings ran on.

    Returns
    -------
    dict
        ``cpu_model`` (from /proc/cpuinfo, else ``platform.processor()``, else None),
        ``platform``, ``machine``, ``python``, ``cpu_count`` (``os.cpu_count()``),
        ``cpus_allowed`` (CPUs this process may use, None if unknown) and ``packages``
        (installed versions of numpy, scipy, casadi, daqp, osqp, do-mpc; None if missing).
    """
    allowed = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    return {
        "cpu_model": _cpu_model(),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "python": platform.python_version(),
        "cpu_count": os.cpu_count(),
        "cpus_allowed": allowed,
        "packages": {name: _version(name) for name in PACKAGES},
    }


def _cpu_model() -> str | None:
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        text = ""
    for line in text.splitlines():
        key, separator, value = line.partition(":")
        if separator and key.strip() in ("model name", "Model", "Hardware", "cpu model"):
            return value.strip()
    return platform.processor() or None


def _version(package: str) -> str | None:
    try:
        return version(package)
    except PackageNotFoundError:
        return None


@dataclass(frozen=True)
class _Column:
    """One column of the table: its title, alignment and cell text of a row."""

    title: str
    justify: str
    text: Callable[[dict[str, Any]], str]


def _columns(rows: Sequence[dict[str, Any]]) -> list[_Column]:
    """The table's columns, written once for the terminal and for ``bench.md``: the
    per-step times, then the planar tracking columns, or, when every row is a 6-DOF run
    (it has a cross-track error), the path, depth and actuator ones; ``vs do-mpc`` where
    a do-mpc row exists; each error and the median followed by its ratio to the yardstick."""

    def number(key: str, spec: str, ratio: bool = False) -> Callable[[dict[str, Any]], str]:
        def text(row: dict[str, Any]) -> str:
            shown = _number(row.get(key), spec)
            over = (row.get("vs_yardstick") or {}).get(key) if ratio else None
            if over is None or row["controller"] == row.get("yardstick"):
                return shown
            return f"{shown} ({over:.3g}x)"

        return text

    def pair(first: str, second: str) -> Callable[[dict[str, Any]], str]:
        return lambda row: "/".join(
            "-" if row.get(k) is None else str(row[k]) for k in (first, second)
        )

    def speedup(row: dict[str, Any]) -> str:
        value = row.get("speedup_vs_do_mpc")
        return "-" if value is None else f"{value:.1f}x"

    columns = [
        _Column("controller", "left", lambda row: row["controller"]),
        _Column("scenario", "left", lambda row: row["scenario"]),
        _Column("median ms", "right", number("solve_ms_median", ".2f", ratio=True)),
        _Column("p99 ms", "right", number("solve_ms_p99", ".2f")),
        _Column("max ms", "right", number("solve_ms_max", ".2f")),
        _Column("wall s", "right", number("wall_s", ".2f")),
    ]
    if any(row.get("speedup_vs_do_mpc") is not None for row in rows):
        columns.append(_Column("vs do-mpc", "right", speedup))
    if _whole_vehicle_view(rows):
        columns += [
            _Column("x-track>tr m", "right", number(CROSS_TRACK, ".4f", ratio=True)),
            _Column("depth>tr m", "right", number(DEPTH, ".4f", ratio=True)),
            _Column("viol. lim/rate", "right",
                    pair("actuator_limit_violations", "actuator_rate_violations")),
            _Column("fallb./streak", "right", pair("fallback_steps", "longest_fallback_streak")),
        ]  # fmt: skip
    else:
        columns += [
            _Column("RMS err m", "right", number("rms_position_error_m", ".3f")),
            _Column("RMS>tr m", "right",
                    number("rms_position_error_after_transient_m", ".4f", ratio=True)),
            _Column("final err m", "right", number("final_position_error_m", ".3f")),
            _Column("min clear. m", "right", number("min_obstacle_clearance_m", ".3f")),
            _Column("viol. F/dF", "right",
                    pair("thrust_limit_violations", "thrust_rate_violations")),
            _Column("fallb./relax.", "right", lambda row: (
                f"{row.get('fallback_steps', row['solver_failures'])}/"
                f"{row.get('relaxed_steps', '-')}"
            )),
        ]  # fmt: skip
    columns.append(_Column("verdict", "left", lambda row: str(row.get("verdict", "-"))))
    return columns


def _whole_vehicle_view(rows: Sequence[dict[str, Any]]) -> bool:
    """Every row a 6-DOF run's (with a distance to the path): the path and actuator view."""
    return bool(rows) and all(row.get(CROSS_TRACK) is not None for row in rows)


def format_table(rows: Sequence[dict[str, Any]], machine: dict[str, Any] | None = None) -> Table:
    """A rich table of benchmark rows, the machine (if given) in the caption.

    The ``vs do-mpc`` column (do-mpc's median step time over the row's) is shown when at
    least one row has a do-mpc row to compare with; a row measured against a yardstick
    shows its ratios beside its errors and median (:func:`add_yardstick_ratios`). Rows of
    6-DOF runs only get the path, depth and actuator columns (:func:`_columns`).

    Parameters
    ----------
    rows : sequence of dict
        Rows from :func:`run_benchmark`.
    machine : dict, optional
        From :func:`machine_info`.

    Returns
    -------
    rich.table.Table
    """
    table = Table(
        title="auvmpc benchmark (solve times per controller step)",
        caption=_caption(rows, machine),
    )
    columns = _columns(rows)
    for column in columns:
        table.add_column(column.title, justify=column.justify)
    for row in rows:
        table.add_row(*(column.text(row) for column in columns))
    return table


def bench_markdown(rows: Sequence[dict[str, Any]], machine: dict[str, Any] | None = None) -> str:
    """The table of :func:`format_table` as Markdown, its caption below it (``bench.md``)."""
    columns = _columns(rows)
    shown = [{column.title: column.text(row) for column in columns} for row in rows]
    lines = markdown_table(shown, [Column(column.title, "") for column in columns])
    caption = _caption(rows, machine)
    notes = [part for line in (caption or "").splitlines() for part in ("", line)]
    return "\n".join([*lines, *notes]) + "\n"


def _caption(rows: Sequence[dict[str, Any]], machine: dict[str, Any] | None) -> str | None:
    parts = []
    if machine is not None:
        packages = ", ".join(f"{name} {ver}" for name, ver in machine["packages"].items() if ver)
        parts.append(
            f"{machine['cpu_model'] or 'unknown CPU'}, {machine['cpu_count']} CPUs "
            f"({machine['cpus_allowed']} allowed); {machine['platform']}; "
            f"Python {machine['python']}; {packages}"
        )
    blasfeo = os.environ.get(BLASFEO_ENV)
    if blasfeo:
        parts.append(f"nmpc's QP step on the BLASFEO in {blasfeo} ({BLASFEO_ENV})")
    pinned = {row.get("pinned_cpu") for row in rows}
    if pinned and None not in pinned:
        parts.append("pinned to CPU " + ", ".join(str(cpu) for cpu in sorted(pinned)))
    elif rows:
        parts.append("not pinned to one CPU")
    repeats = {row.get("repeats") for row in rows}
    if repeats - {None, 1}:
        parts.append(f"repeats {', '.join(str(n) for n in sorted(repeats))}: wall s is the median")
    transients = {row.get("transient_s") for row in rows} - {None}
    if transients:
        listed = ", ".join(f"{value:g}" for value in sorted(transients))
        if _whole_vehicle_view(rows):
            parts.append(
                f"x-track>tr, depth>tr: RMS distance to the path and RMS depth error after the "
                f"scenario's transient ({listed} s); viol. lim/rate: commands outside an "
                "input's limits / beyond its rate; fallb./streak: fallback steps / longest run"
            )
        else:
            parts.append(f"RMS>tr: RMS position error after the scenario's transient ({listed} s)")
    if any(row.get("speedup_vs_do_mpc") is not None for row in rows):
        parts.append(
            "vs do-mpc: do-mpc median ms / this median ms, same OCP (scenario and move schedule)"
        )
    yardsticks = sorted({row["yardstick"] for row in rows if row.get("yardstick")})
    if yardsticks:
        parts.append(
            f"(r x): this row's value over the yardstick's ({', '.join(yardsticks)}), "
            "same scenario and seed"
        )
    return "\n".join(parts) or None


def _number(value: float | int | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def rows_to_json(rows: Sequence[dict[str, Any]]) -> str:
    """The rows as a JSON list of objects (the ``--json FILE`` contract), keys as in the rows.

    Parameters
    ----------
    rows : sequence of dict
        Rows from :func:`run_benchmark`.

    Returns
    -------
    str
        Indented JSON; ``null`` for missing values (e.g. clearance without obstacles).
    """
    return json.dumps(list(rows), indent=2, allow_nan=False) + "\n"
