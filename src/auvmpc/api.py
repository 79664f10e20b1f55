"""The public Python API: what a script or a notebook needs, in a few stable names.

>>> import auvmpc
>>> scenario = auvmpc.load_scenario("paper-obstacles", {"duration": 20}, controller="ltv-mpc-nc30")
>>> run = auvmpc.simulate(scenario)
>>> frame = auvmpc.log_dataframe(run)          # pandas, the columns of log.csv
>>> run.metrics["rms_position_error_m"]        # doctest: +SKIP
>>> figures = auvmpc.figures(run)              # matplotlib Figures, keyed by name
>>> auvmpc.save_run(run, "runs/obs")           # the same folder as `auvmpc run --out`
>>> s = auvmpc.session(scenario)               # step it yourself: s.step(t, measured).u

Everything here is also reachable from the command line; the names are kept stable
(new keyword arguments may be added, none removed without a deprecation period).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd
import yaml
from matplotlib.figure import Figure

import auvmpc  # noqa: E402 -- the package names the public API once (re-exported lazily)
from auvmpc.controllers.base import Controller
from auvmpc.errors import ConfigError
from auvmpc.experiments.run import DepthRunResult, RunResult, RunSession, make_controller
from auvmpc.scenario import ResolvedDepthScenario, ResolvedScenario
from auvmpc.sim.log import SimLog

__all__ = list(auvmpc._API)

Overrides = Mapping[str, Any] | Sequence[str] | None
Scenario = ResolvedScenario | ResolvedDepthScenario
Run = RunResult | DepthRunResult


def load_scenario(
    source: str | Path, overrides: Overrides = None, *, controller: str | None = None
) -> Scenario:
    """A built-in scenario by name, or a scenario YAML file, with overrides applied.

    Parameters
    ----------
    source : str or Path
        Built-in name (``auvmpc scenarios`` lists them) or a path to a YAML file.
    overrides : mapping or sequence of str, optional
        ``{"controller.control_horizon": 30, "obstacles.0.radius": 2}`` or the command
        line's ``["controller.control_horizon=30"]``; any field of
        ``docs/scenario-reference.md``.
    controller : str, optional
        A controller type or a bench label (``ltv-mpc-nc30``), as ``run --controller``;
        ``overrides`` are applied after it.

    Returns
    -------
    ResolvedScenario or ResolvedDepthScenario
        ``.scenario`` (validated fields), ``.model`` (the controller's vehicle) and, for a
        horizontal scenario, ``.plant`` (the simulated vehicle); a ``kind: six-dof`` one is a
        ``ResolvedSixDofScenario`` (a ResolvedScenario with ``.reference``).

    Raises
    ------
    auvmpc.errors.ConfigError
        A bad name, file, field or value; the message names it.
    """
    from auvmpc.scenario import load_scenario as load

    return load(source, [*controller_overrides(controller), *_override_strings(overrides)])


def override(scenario: Scenario, overrides: Overrides) -> Scenario:
    """A copy of a loaded scenario with more fields changed (the original is untouched)."""
    from auvmpc.scenario.loader import apply_overrides, resolve_document

    # The scenario as written, not as filled in for its vehicle (a new vehicle or sample time
    # must get its own defaults): only the fields its file set.
    given = scenario.given
    data = given.model_dump(mode="json", exclude_unset=True)
    notes = apply_overrides(data, _override_strings(overrides))
    return resolve_document(data, scenario.base_dir, notes)


def build_controller(scenario: Scenario) -> Controller:
    """The scenario's controller on its nominal vehicle model, ready for ``reset``/``compute``
    (to step it yourself; :func:`simulate` builds its own); a depth scenario's is the depth
    MPC, which sees ``[z]`` measured and ``[z, w]`` reference rows."""
    if not isinstance(scenario, ResolvedScenario | ResolvedDepthScenario):
        raise TypeError(f"build_controller takes a loaded scenario, got {type(scenario).__name__}")
    return make_controller(scenario.scenario, scenario.model)


def simulate(scenario: Scenario | str, on_step: Callable[[int, int], None] | None = None) -> Run:
    """Run the closed loop once; a name or path is loaded first.

    Returns
    -------
    RunResult or DepthRunResult
        ``.log`` (time-major arrays), ``.metrics`` (the names of run.json) and
        ``.scenario``.
    """
    from auvmpc.experiments.run import simulate as run

    if isinstance(scenario, str | Path):
        scenario = load_scenario(scenario)
    return run(scenario, on_step)


def session(scenario: Scenario | str | Path, live_log: str | Path | None = None) -> RunSession:
    """The scenario's controller, to step yourself sample by sample against your own
    simulator, rig or vehicle; a name or path is loaded first.

    >>> s = auvmpc.session("paper-obstacles")   # doctest: +SKIP
    >>> s.state_names, s.input_names            # ('x', 'y', 'psi', 'u', 'v', 'r'), ('F1', ...)
    >>> r = s.step(0.0, s.initial_state)        # r.u: the command, in input_names order
    >>> s.close("runs/mine")                    # the run folder of what was stepped

    ``step(t, measurement, detections=None, truth=None)``: ``measurement`` in
    ``measurement_names`` order (a horizontal scenario's are its ``state_names``; a 6-DOF
    one's the horizontal states, the depth and the depth rate; a depth one's the pressure
    sensor's depth); ``detections`` the obstacles
    you perceive (default: the scenario's, through its obstacle sensor if it has one);
    ``truth`` (sim.session.Truth) the true state and the environment (the log's
    ``environment_names``) if your simulator knows them, for the log and the metrics. A
    failed solve never raises: the result's ``status`` says so and ``u`` is the safety
    shell's command. ``auvmpc run`` is a loop over the same session with the built-in plant
    (docs/session.md). ``live_log``: a new file (never an existing one) that gets each row
    of log.csv as soon as it is stepped, flushed, so a crash keeps what was stepped.

    Raises
    ------
    auvmpc.errors.ConfigError
        A bad name, file, field or value, or something that is not a scenario.
    """
    if isinstance(scenario, str | Path):
        scenario = load_scenario(scenario)
    if not isinstance(scenario, ResolvedScenario | ResolvedDepthScenario):
        raise ConfigError(
            "scenario", type(scenario).__name__, "must be a preset name, a path or a scenario "
            "from auvmpc.load_scenario",
        )  # fmt: skip
    return RunSession(scenario, live_log=live_log)


def log_dataframe(run: Run | SimLog) -> pd.DataFrame:
    """The log as a DataFrame with the columns of ``log.csv`` (one row per sample k).

    The thrust of the last row is NaN (the command on row k is applied over
    [t_k, t_k+1)); numbers are exactly the simulated ones.
    """
    log = run.log if isinstance(run, RunResult | DepthRunResult) else run
    return log.dataframe()


def figures(run: RunResult) -> dict[str, Figure]:
    """The standard figures of a run (``trajectory``, ``errors``, ``velocities``, ``thrusts``,
    ``solve_times``; ``depth`` for a depth run; plus ``trajectory_3d``, ``tracking_errors``,
    ``depth_attitude`` for a 6-DOF run), titled with the controller and vehicle."""
    return run.figures()


def save_run(run: Run, folder: str | Path, figures: bool = True) -> Path:
    """Write the run folder (``log.csv``, ``run.json``, PNG figures), as ``auvmpc run --out``."""
    from auvmpc.experiments.run import write_run

    return write_run(run, Path(folder), figures=figures)


def load_run(folder: str | Path) -> tuple[dict[str, Any], pd.DataFrame]:
    """``run.json`` (as a dict) and ``log.csv`` (as a DataFrame) of a saved run folder."""
    from auvmpc.experiments.run_folder import read_run_tables

    tables = read_run_tables(Path(folder))
    return tables.info, tables.log


def controller_overrides(label: str | None) -> tuple[str, ...]:
    """The overrides ``run --controller LABEL`` stands for.

    A ``controller.type`` value sets the type only (the scenario's tuning is kept, as
    before); any other label of the bench (``CONTROLLER_PRESETS``, e.g. ``ltv-mpc-nc30``)
    applies that preset's overrides.
    """
    from auvmpc.controllers.config import CONTROLLER_PRESETS, ControllerType

    if label is None:
        return ()
    types = {kind.value for kind in ControllerType}
    if label in types:
        return (f"controller.type={label}",)
    if label in CONTROLLER_PRESETS:
        return CONTROLLER_PRESETS[label]
    known = sorted(types | set(CONTROLLER_PRESETS))
    reason = f"not a controller.type or bench label; one of {known}"
    raise ConfigError("--controller", label, reason)


def _override_strings(overrides: Overrides) -> list[str]:
    if overrides is None:
        return []
    if isinstance(overrides, Mapping):
        return [f"{key}={_yaml_value(value)}" for key, value in overrides.items()]
    if isinstance(overrides, str):
        return [overrides]
    return list(overrides)


def _yaml_value(value: Any) -> str:
    """The value as one line of YAML, which apply_override reads back."""
    if isinstance(value, tuple):
        value = list(value)
    return (
        yaml.safe_dump(value, default_flow_style=True, width=10**9)
        .strip()
        .removesuffix("...")
        .strip()
    )
