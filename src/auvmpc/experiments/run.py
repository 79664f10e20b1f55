"""From a resolved scenario to a run folder: build, simulate, measure, write atomically."""

from __future__ import annotations

import contextlib
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from threadpoolctl import threadpool_limits

from auvmpc import interrupts
from auvmpc.controllers.base import Controller
from auvmpc.errors import ConfigError, RunFailed
from auvmpc.experiments.kinds import (
    KINDS,
    DepthRunResult,
    Finished,
    RunResult,
    SixDofRunResult,
    kind_of,
)
from auvmpc.experiments.outputs import OutputKind, adding, atomic_write_text, staged_folder
from auvmpc.experiments.provenance import Stopwatch
from auvmpc.experiments.run_folder import read_run_folder
from auvmpc.models.vehicle import VehicleParams
from auvmpc.scenario import ResolvedDepthScenario, ResolvedScenario, Scenario
from auvmpc.scenario.depth import DepthScenario
from auvmpc.sim.divergence import likely_cause
from auvmpc.sim.log import SimLog
from auvmpc.sim.loop import PlantDiverged, Sensor, run_session
from auvmpc.sim.plant import Plant
from auvmpc.sim.session import Session

__all__ = [
    "DepthRunResult",
    "RunFailed",
    "RunResult",
    "RunSession",
    "SixDofRunResult",
    "atomic_write_text",
    "fill_run_folder",
    "make_controller",
    "read_run",
    "read_planar_run",
    "redraw",
    "run_plant",
    "simulate",
    "write_run",
]


def make_controller(scenario: Scenario | DepthScenario, model: VehicleParams) -> Controller:
    """The scenario's controller, built on the nominal (controller-side) vehicle model (a
    6-DOF scenario's horizontal one: its kind pairs it with the depth MPC)."""
    return kind_of(scenario).controller(scenario, model)


def simulate(
    resolved: ResolvedScenario | ResolvedDepthScenario,
    on_step: Callable[[int, int], None] | None = None,
    *,
    long_ok: bool = False,
) -> Finished:
    """Run the scenario once. Randomness comes from children of the scenario seed.

    Checked first (:mod:`auvmpc.scenario.sanity`): the sizes fit in memory, the estimated
    cost is within the limits of :mod:`auvmpc.scenario.cost` (or ``long_ok``: the caller
    confirmed it) and the scenario is physically possible; what is doubtful but possible
    becomes ``warnings``. A SIGINT or SIGTERM stops the loop after the current step
    (:mod:`auvmpc.interrupts`), even one a compiled solver swallowed or turned into another
    exception, so no result is ever built from an interrupted run. A plant whose state
    stops being finite ends the run there, verdict ``lost``, the likely cause named
    (:mod:`auvmpc.sim.divergence`).
    """
    from auvmpc.scenario.sanity import preflight

    stopwatch = Stopwatch()
    warnings = preflight(resolved, long_ok=long_ok)

    reached = [0]

    def step(k: int, n: int) -> None:
        reached[0] = k
        interrupts.check()
        if on_step is not None:
            on_step(k, n)

    with _failures_named(resolved.scenario, reached):
        return _simulate(resolved, step, stopwatch, warnings)


@contextlib.contextmanager
def _failures_named(scenario, reached: list[int]):
    try:
        yield
    except KeyboardInterrupt:
        raise
    except Exception as error:
        # A signal handler's exception raised inside CasADi's Python layer comes out as
        # another one (SWIG: NotImplementedError "Function_call", SystemError from
        # DM.__array__; measured: 1 SIGTERM in 10 on bluerov2-helix): the signal, not
        # the solver, ended the run.
        if interrupts.requested() is not None:
            raise interrupts.Interrupted(interrupts.requested()) from error
        if isinstance(error, (ConfigError, RunFailed)):
            raise
        k = reached[0]
        t = k * scenario.controller.sample_time
        text = str(error).strip().splitlines()
        what = f"{type(error).__name__}: {text[0]}" if text else type(error).__name__
        raise RunFailed(
            f"{scenario.name} with {scenario.controller.type} failed at t = {t:g} s "
            f"(step {k}): {what}"
        ) from error


def _simulate(resolved, step, stopwatch: Stopwatch, warnings: list[str]) -> Finished:
    # One BLAS thread: a controller step works on small matrices, where a second thread only
    # adds hand-over latency (measured: p99 2 ms -> 16 ms for ltv-mpc at nc 30), and
    # campaigns run one process per core anyway.
    with threadpool_limits(limits=1, user_api="blas"):
        session = RunSession(resolved, warnings, stopwatch)
        plant, sensor = run_plant(resolved)
        try:
            run_session(session, plant, sensor, step, resolved.faults)
        except PlantDiverged as diverged:
            return _lost(session, resolved, diverged)
    return session.result()


def _lost(session: RunSession, resolved, diverged: PlantDiverged) -> Finished:
    """The run up to the last finite state, verdict ``lost`` with the likely cause; with
    fewer than two samples to keep, a failed run saying the same."""
    scenario = resolved.scenario
    t = diverged.k * scenario.controller.sample_time
    reason = (
        f"the plant diverged at t = {t:g} s (step {diverged.k}: {diverged.what}); "
        f"likely cause: {likely_cause(resolved)}"
    )
    if session.k < 2:
        raise RunFailed(f"{scenario.name} with {scenario.controller.type} lost: {reason}")
    result = session.result()
    result.metrics["verdict"], result.metrics["verdict_reason"] = "lost", reason
    return result


def run_plant(resolved: ResolvedScenario | ResolvedDepthScenario) -> tuple[Plant, Sensor]:
    """The simulated vehicle of a scenario in its environment, and its sensors: what
    ``auvmpc run`` steps a :class:`RunSession` against (tests step one by hand with them)."""
    return kind_of(resolved.scenario).plant(resolved)


class RunSession(Session):
    """A scenario's controller, stepped sample by sample (``auvmpc.session``): its names,
    timing and start, and :meth:`close`, which files what was stepped as a run. What differs
    between a horizontal, a depth and a 6-DOF scenario comes from its kind
    (experiments/kinds.py): a 6-DOF scenario's controller is its horizontal controller and
    depth MPC on the 6-DOF thrusters (controllers/channels.py).

    The batch run (:func:`simulate`) steps the same session against the scenario's plant.
    ``warnings``: the scenario's pre-run checks, when the caller has run them already;
    ``live_log``: a new file that gets log.csv row by row as the session is stepped.
    """

    def __init__(
        self,
        resolved: ResolvedScenario | ResolvedDepthScenario,
        warnings: list[str] | None = None,
        stopwatch: Stopwatch | None = None,
        live_log: str | Path | None = None,
    ) -> None:
        from auvmpc.scenario.sanity import preflight

        self.resolved = resolved
        self.kind = kind_of(resolved.scenario)
        self._stopwatch = stopwatch or Stopwatch()
        # long_ok: a session's caller steps it as long as it likes; the cost limits are for
        # the batch run (simulate).
        warnings = preflight(resolved, long_ok=True) if warnings is None else warnings
        controller = make_controller(resolved.scenario, resolved.model)
        # getattr: a controller need not derive from base.Controller (a user's own, a test's).
        self.warnings = [*warnings, *getattr(controller, "build_warnings", ())]
        super().__init__(**self.kind.start(resolved, controller).arguments(), live_log=live_log)
        self.duration = self.steps * self.sample_time

    def result(self) -> Finished:
        """What was stepped, as a finished run: its log, metrics, warnings and provenance."""
        libraries = self.kind.libraries(self.resolved.scenario)
        provenance = self._stopwatch.record(libraries)
        finished = self.kind.finished(self.resolved, self.stepped_log, provenance, self.warnings)
        if self.fault_detector is not None:
            finished.fault_detections = [
                {"actuator": self.input_names[found.index], "t_s": t, "lost": found.lost,
                 "remaining": found.remaining, "score": found.sigmas,
                 **({} if found.stuck_at is None else {"stuck_at": found.stuck_at})}
                for _, t, found in self.faults_found
            ]  # fmt: skip
        return finished

    def close(
        self, out_dir: str | Path | None = None, figures: bool = True, *, overwrite: bool = False
    ) -> Finished:
        """The run of the samples stepped so far, written as a run folder into ``out_dir``
        when given (as ``auvmpc run --out``: new or empty, or with ``overwrite`` an earlier
        run folder of auvmpc's). The session is closed then: nothing more may be stepped."""
        self._check_open("close")
        self.end_live_log()
        result = self.result()
        if out_dir is not None:
            write_run(result, Path(out_dir), figures=figures, overwrite=overwrite)
        self.closed = True
        return result


def write_run(
    result: Finished,
    out_dir: Path,
    figures: bool = True,
    figure_format: str = "png",
    dpi: int = 120,
    *,
    overwrite: bool = False,
) -> Path:
    """Write log.csv, run.json and figures into ``out_dir``, all or nothing.

    ``out_dir`` must be new, empty, or an earlier run folder of auvmpc's and then only
    with ``overwrite`` (:mod:`auvmpc.experiments.outputs`); it is written in a hidden staging folder
    renamed into place when complete, so an interrupted write leaves nothing that looks done.
    """
    with staged_folder(out_dir, OutputKind.RUN, overwrite=overwrite) as staging:
        fill_run_folder(result, staging, figures, figure_format, dpi)
    return Path(out_dir)


def fill_run_folder(
    result: Finished,
    folder: Path,
    figures: bool,
    figure_format: str = "png",
    dpi: int = 120,
) -> None:
    """Write a run's files into ``folder`` (a staging folder the caller owns)."""
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(folder / "log.csv", result.csv_text())
    atomic_write_text(
        folder / "run.json", json.dumps(result.run_json(), indent=2, allow_nan=False) + "\n"
    )
    if figures:
        result.draw(folder, figure_format, dpi)


def redraw(run_dir: Path, fmt: str = "png", dpi: int = 120) -> None:
    """Re-draw the figures of a saved run folder (of any kind) as ``fmt`` files, listed in
    its marker; a file of the same name that auvmpc did not write is refused, not replaced."""
    from auvmpc.plots import save_figures

    run_dir = Path(run_dir)
    folder = read_run_folder(run_dir, ("scenario", "model", "plant"))
    figures = folder.kind.figures(
        folder.log(), folder.scenario(), folder.vehicle("model"), folder.vehicle("plant")
    )
    with adding(run_dir, [f"{name}.{fmt}" for name in figures], "RUN_DIR"):
        save_figures(figures, run_dir, dpi=dpi, fmt=fmt)


def read_planar_run(
    run_dir: Path, command: str
) -> tuple[dict[str, Any], Scenario, VehicleParams, SimLog]:
    """A saved run as ``command`` (animate, compare) reads it: run.json, its scenario and
    nominal model, and the horizontal log (a 6-DOF run's horizontal view). A folder that is
    not a run, a damaged one (:mod:`auvmpc.experiments.run_folder`), or a depth run, is
    refused with one line."""
    folder = read_run_folder(run_dir, ("scenario", "model"))
    kind = folder.kind
    if not kind.has_horizontal:
        raise ConfigError(
            "RUN_DIR", str(run_dir), f"a {kind.name} run; {command} takes horizontal and 6-DOF runs"
        )
    scenario, model = folder.scenario(), folder.vehicle("model")
    return folder.info, scenario, model, folder.log().horizontal()


def read_run(run_dir: Path) -> tuple[dict[str, Any], SimLog]:
    """run.json contents and the horizontal columns of a saved run folder's log (a 6-DOF
    run's with every thruster), both checked (:mod:`auvmpc.experiments.run_folder`)."""
    folder = read_run_folder(run_dir)
    return folder.info, folder.log(KINDS["horizontal"])
