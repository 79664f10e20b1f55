"""One run, a sample at a time: the controller's side of the closed loop.

A :class:`Session` is the one place where an observation is built: the measured state, the
reference's preview from the sample's time on, and the obstacles as the controller knows
them (exactly, or as its obstacle sensor detects them). It calls the controller inside its
safety shell and records the sample in the run's log. The batch loop (sim/loop.py) is a
plain loop over it with the built-in plant, which hands it the truth as well; a user's own
simulator, rig or vehicle steps it with its measurements (``auvmpc.session``,
docs/session.md). What a caller hands over is checked first: a bad value is one line
naming it (ConfigError), never a traceback from deep inside a solver.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from auvmpc.controllers.base import (
    Controller,
    ControlStatus,
    Observation,
    ObstacleState,
    timed_command,
)
from auvmpc.environment.obstacle_sensor import ObstaclePerception
from auvmpc.environment.obstacles import ObstacleConfig, clearance, visible_obstacles
from auvmpc.errors import ConfigError
from auvmpc.estimation.fault_detection import FaultDetector, FaultFound
from auvmpc.models.layout import Layout
from auvmpc.sim.log import LiveLog, Row, SimLog

__all__ = ["Session", "StateReference", "StepResult", "Truth"]


@dataclass(frozen=True)
class StepResult:
    """What one sample gave: the command to hold until the next sample and how it came."""

    k: int  # the sample's index, from 0
    u: np.ndarray  # the command, in the session's ``input_names`` order (N)
    status: ControlStatus  # ok, saturated, relaxed, fallback, recovery (docs/safety.md)
    solve_ms: float  # wall time of the controller call
    info: dict[str, float] = field(default_factory=dict)  # the controller's diagnostics


@dataclass(frozen=True)
class Truth:
    """What a simulator knows beyond the measurement: the true state (in the log's layout)
    and what the environment does at the sample, in the log's ``environment_names``: a
    horizontal run's world force and moment, a depth run's wave force, a 6-DOF run's water
    velocity at the vehicle."""

    state: np.ndarray
    environment: np.ndarray


class StateReference(Protocol):
    """The reference in the plant's state layout, vectorised over time."""

    def states(self, t: np.ndarray) -> np.ndarray: ...


class Session:
    """The controller of one run, stepped sample by sample, and the run's log.

    Each :meth:`step` appends its row to ``log`` (an empty log to begin with), :meth:`finish`
    the final state row, and :attr:`stepped_log` is the run of the rows so far; ``steps``
    is the run's length in commands (the scenario's duration), past which :meth:`step` is
    refused. Without :class:`Truth` the log's state columns hold the measurement and
    the vehicle-to-obstacle gap is the measured position's; a session whose measurement is
    not its whole state (6-DOF, depth) needs the truth. ``live_log``: a new file that
    gets each row of log.csv as soon as it is complete (sim/log.py, LiveLog).
    ``fault_detector``: watches the horizontal thrusters (the first inputs; a 6-DOF
    detector every input) from the measurements (estimation/fault_detection.py); what it
    finds is assumed from the sample that finds it on, with whatever :attr:`effectiveness`
    and :attr:`stuck_at` say, and kept in :attr:`faults_found`.
    """

    def __init__(
        self,
        controller: Controller,
        reference: StateReference,
        log: SimLog,
        steps: int,
        *,
        initial_state: Sequence[float],
        initial_thrust: np.ndarray | None = None,
        obstacles: Sequence[ObstacleConfig] = (),
        perception: ObstaclePerception | None = None,
        vehicle_radius: float = 0.0,
        fault_detector: FaultDetector | None = None,
        live_log: str | Path | None = None,
    ) -> None:
        self.controller = controller
        self.reference = reference
        self.log = log
        self.steps = steps
        self.sample_time = controller.sample_time
        self.obstacles = tuple(obstacles)
        self.perception = perception
        self.vehicle_radius = vehicle_radius
        self.n_inputs = log.n_thrusters
        self.input_names = log.input_names
        self.state_names = log.layout.names
        self.measurement_names = log.format.measured_names
        # What Truth.environment holds, in order (the log's environment columns).
        self.environment_names = log.format.environment_names
        self.k = 0  # samples stepped so far
        self._previous_t: float | None = None  # the last stepped sample's time
        self.finished = False  # the final state row is in
        self.closed = False  # filed as a run: nothing more may be stepped
        # Where the position sits in the state: obstacle gaps and detections need it.
        self.position = log.layout.position if obstacles or perception is not None else None
        # The measured position, where the obstacle sensor looks from (by the measurement's
        # own names: they need not be the state's).
        self._measured_position = (
            None if self.position is None else Layout(log.format.measured_names).position
        )
        previous = (
            np.zeros(self.n_inputs) if initial_thrust is None else np.asarray(initial_thrust, float)
        )
        log.initial_thrust = previous.copy()
        self._initial_state = np.asarray(initial_state, dtype=float).copy()
        self._effectiveness: np.ndarray | None = None  # all healthy
        self._stuck_at: np.ndarray | None = None  # none stuck
        self.fault_detector = fault_detector
        self._healthy = np.ones(self.n_inputs)  # what "all healthy" assumes (never written)
        self._healthy.setflags(write=False)
        self._found = np.ones(self.n_inputs)  # the detector's effectiveness of each input
        self._found_stuck = np.full(self.n_inputs, np.nan)  # ... and what it found stuck
        #: What the detector found: (sample k, time, FaultFound), in order.
        self.faults_found: list[tuple[int, float, FaultFound]] = []
        # Where the state the detector reads sits in the measurement (by its names).
        self._watched_measured = [
            list(log.format.measured_names).index(name) for name in fault_detector.state_names
        ] if fault_detector is not None else []  # fmt: skip
        controller.reset(self._initial_state.copy(), previous.copy())
        self._preview_offsets = self.sample_time * np.arange(controller.preview_steps + 1)
        # Created last: a session that could not be set up leaves no file behind.
        self.live_log = None if live_log is None else LiveLog(live_log, log)

    @property
    def effectiveness(self) -> np.ndarray | None:
        """Each input's actuator effectiveness the controller assumes from the next sample on,
        in ``input_names`` order (1 healthy, 0 dead, 0.5 half force), or None: all healthy.
        Set it when you learn of a fault (a detector, a mission's declared faults): the
        controller's prediction model and allocation use it from the next :meth:`step`, with
        nothing rebuilt."""
        return None if self._effectiveness is None else self._effectiveness.copy()

    @effectiveness.setter
    def effectiveness(self, values: Any) -> None:
        checked = self._per_input("effectiveness", values, "")
        if checked is not None and not np.all((checked >= 0.0) & (checked <= 1.0)):
            raise ConfigError("effectiveness", values, "must be between 0 and 1 (1 healthy)")
        self._effectiveness = checked

    @property
    def stuck_at(self) -> np.ndarray | None:
        """The value each input is stuck at whatever it is commanded, in ``input_names`` order
        and each input's own unit, NaN where it is free, or None: none stuck. Set it when
        you learn of a jammed actuator (a mission's declared faults): a controller that reads
        it (``Observation.stuck_at``: six-dof-nmpc) predicts with the input fixed there from
        the next :meth:`step`; the others take the input as not acting (its effectiveness 0)."""
        return None if self._stuck_at is None else self._stuck_at.copy()

    @stuck_at.setter
    def stuck_at(self, values: Any) -> None:
        checked = self._per_input("stuck_at", values, " (NaN where free)")
        if checked is not None and np.isinf(checked).any():
            raise ConfigError("stuck_at", values, "must be finite (NaN where free)")
        self._stuck_at = checked

    def _per_input(self, name: str, values: Any, free: str) -> np.ndarray | None:
        """``values`` as a read-only array of one number per input (None stays None), or
        one ConfigError line naming ``name``; ``free`` says how a free input is written."""
        if values is None:
            return None
        try:
            checked = np.array(values, dtype=float)
        except (TypeError, ValueError):
            raise ConfigError(name, values, f"must be numbers{free}") from None
        if checked.shape != (self.n_inputs,):
            raise ConfigError(name, values, f"must have one value per input ({self.n_inputs})")
        checked.setflags(write=False)
        return checked

    @property
    def initial_state(self) -> np.ndarray:
        """The scenario's start, in ``state_names`` order (a copy: yours to change)."""
        return self._initial_state.copy()

    def step(
        self,
        t: float,
        measurement: np.ndarray,
        detections: Sequence[ObstacleState] | None = None,
        truth: Truth | None = None,
        *,
        trusted: bool = False,
    ) -> StepResult:
        """One sample at time ``t`` (s): the command to hold until the next sample.

        ``measurement`` is what the controller sees (``measurement_names``, in that order);
        ``detections`` the obstacles as the caller perceives them (default: the scenario's,
        through its obstacle sensor if it has one, else exactly); ``truth`` what a simulator
        knows beyond the measurement. A failed solve does not raise: the result's status says
        so and ``u`` is the safety shell's command. ``trusted``: the values come from
        auvmpc's own plant and sensor (run_session) and are not checked; a plant that
        diverges is the run's failure (experiments/run.py), not the caller's bad input.
        """
        k = self.k
        self._check_open("step")
        if self.finished or k >= self.steps:
            raise ConfigError(
                "step", k, f"the run has {self.steps} samples ({self._duration_text()})"
            )
        if not trusted:
            t, measurement, truth = self._checked(t, measurement, truth)
            if detections is not None:
                detections = _checked_detections(detections)
        row = self._sample(t, measurement, truth)
        t = row["t"]
        self._detect_faults(k, t, measurement)
        assumed, stuck = self._assumed(), self._stuck()
        observation = Observation(
            k=k,
            t=t,
            state=measurement,
            reference=self._preview,
            obstacles=self._detections(t, measurement) if detections is None else detections,
            effectiveness=assumed,
            stuck_at=stuck,
        )
        result, thrust, solve_ms = timed_command(self.controller, observation, self.n_inputs)
        acting = self._healthy if assumed is None else assumed
        if self.fault_detector is not None:
            watched = self.fault_detector.n_inputs
            self.fault_detector.held(
                thrust[:watched], acting[:watched], None if stuck is None else stuck[:watched]
            )
        command = self.log.format.command(result, thrust, solve_ms)
        self._append(row | command | {"effectiveness": acting})
        self.k = k + 1
        return StepResult(k, thrust.copy(), result.status, solve_ms, result.info)

    def finish(
        self,
        t: float,
        measurement: np.ndarray,
        truth: Truth | None = None,
        *,
        trusted: bool = False,
    ) -> None:
        """The state after the last command (the log's final row, which has no command);
        ``trusted`` as for :meth:`step`."""
        self._check_open("finish")
        if self.finished:
            raise ConfigError("finish", self.k, "the run is finished already")
        if not trusted:
            t, measurement, truth = self._checked(t, measurement, truth)
        self._append(self._sample(t, measurement, truth))
        self.finished = True
        if self.live_log is not None:
            self.live_log.close()

    def end_live_log(self) -> None:
        """Close the live log (if any) where the run stands; :meth:`finish` closes it after
        the final row."""
        if self.live_log is not None:
            self.live_log.close()

    @property
    def stepped_log(self) -> SimLog:
        """The log of the samples stepped so far: all of it after :meth:`finish`; before it,
        the last stepped sample's state is the final row (its command is not in the log)."""
        rows = self.k + 1 if self.finished else self.k
        if rows < 2:
            raise ConfigError("step", self.k, "a run needs at least two samples stepped")
        return self.log if self.finished else self.log.first(rows)

    def _detect_faults(self, k: int, t: float, measurement: np.ndarray) -> None:
        """The detector's look at this sample's measurement; what it finds is kept."""
        if self.fault_detector is None:
            return
        found = self.fault_detector.check(measurement[self._watched_measured])
        if found is not None:
            # taken as keeping what the detector says of the wrench assumed so far (none for
            # a thruster of the horizontal detector: fault_detection.py says why), or as
            # acting at the value found
            self._found[found.index] *= found.remaining
            if found.stuck_at is not None:
                self._found_stuck[found.index] = found.stuck_at
            self.faults_found.append((k, float(t), found))

    def _assumed(self) -> np.ndarray | None:
        """Each input's effectiveness the controller is to assume now: what it was told
        (:attr:`effectiveness`, 0 where :attr:`stuck_at` says stuck) times what the detector
        found; None: all healthy."""
        if self._effectiveness is None and self._stuck_at is None and not self.faults_found:
            return None
        told = self._healthy if self._effectiveness is None else self._effectiveness
        if self._stuck_at is not None:
            told = np.where(np.isnan(self._stuck_at), told, 0.0)
        return told * self._found

    def _stuck(self) -> np.ndarray | None:
        """Each input's stuck value the controller is to assume now: what it was told
        (:attr:`stuck_at`), else what the detector found; None: none stuck."""
        found = self._found_stuck
        if self._stuck_at is None:
            return None if np.isnan(found).all() else found.copy()
        return np.where(np.isnan(self._stuck_at), found, self._stuck_at)

    def _check_open(self, what: str) -> None:
        if self.closed:
            raise ConfigError(what, self.k, "the session is closed (its run is filed)")

    # -- one row of the log ------------------------------------------------------------
    def _checked(
        self, t: Any, measurement: Any, truth: Truth | None
    ) -> tuple[float, np.ndarray, Truth | None]:
        """A caller's time, measurement and truth for the next row, as checked floats, or one
        line naming the first that is wrong."""
        log = self.log
        t = _finite_time(t, self._previous_t)
        names = log.format.measured_names
        measured = _finite_vector("measurement", measurement, len(names), names)
        if truth is None and names != log.layout.names:
            raise ConfigError(
                "truth", None, f"needed: the measurement ({', '.join(names)}) is not the whole "
                f"state ({', '.join(log.layout.names)}); pass Truth(state, environment) with "
                "your simulator's or navigation filter's full state",
            )  # fmt: skip
        if truth is not None:
            truth = Truth(
                _finite_vector("truth.state", truth.state, log.layout.size, log.layout.names),
                _finite_vector(
                    "truth.environment", truth.environment, len(log.format.environment_names),
                    log.format.environment_names,
                ),
            )  # fmt: skip
        return t, measured, truth

    def _sample(self, t: float, measured: np.ndarray, truth: Truth | None) -> Row:
        """The next row's sample: its time (the log's float64), reference, state (the
        truth's if given, else the measurement), environment, obstacle gap and measurement;
        the reference's preview from t is kept for the observation."""
        # Its first row is the reference at t; the whole preview is the observation's.
        self._preview = self.reference.states(t + self._preview_offsets)
        state = measured if truth is None else truth.state
        format = self.log.format
        gap = math.inf  # no obstacles
        if self.position is not None:
            position = np.asarray(state, float)[self.position]
            gap = clearance(position, t, self.obstacles, self.vehicle_radius)
        return {
            "t": np.float64(t),
            "state": state,
            "reference": self._preview[0],
            "environment": (
                np.zeros(len(format.environment_names)) if truth is None else truth.environment
            ),
            "clearance_m": gap,
            "measured": measured,
        }

    def _append(self, row: Row) -> None:
        """The row to the log, and to the live log if there is one."""
        self.log.append(row)
        self._previous_t = float(row["t"])
        if self.live_log is not None:
            self.live_log.append(row)

    def _detections(self, t: float, measured: np.ndarray) -> Sequence[ObstacleState]:
        """The obstacles as the controller knows them at t: through the obstacle sensor
        (from the measured position) where there is one, else the scenario's exactly."""
        if self.perception is None:
            return visible_obstacles(self.obstacles, t)
        return self.perception.observe(t, measured[self._measured_position])

    def _duration_text(self) -> str:
        return f"{self.steps * self.sample_time:g} s at {self.sample_time:g} s"


def _finite_time(t: Any, previous: float | None) -> float:
    """``t`` as a float: finite, and later than the previous sample's."""
    try:
        value = float(t)
    except (TypeError, ValueError):
        raise ConfigError("t", t, "must be a number of seconds") from None
    if not math.isfinite(value):
        raise ConfigError("t", t, "must be finite")
    if previous is not None and value <= previous:
        raise ConfigError("t", value, f"must be later than the previous sample's {previous:g} s")
    return value


def _finite_vector(name: str, values: Any, size: int, names: Sequence[str]) -> np.ndarray:
    """``values`` as ``size`` finite real floats, or one line naming ``name``."""
    try:
        array = np.asarray(values)
        if np.iscomplexobj(array):
            raise TypeError
        array = array.astype(float)
    except (TypeError, ValueError):
        raise ConfigError(name, values, "must be real numbers") from None
    if size == 1 and array.ndim == 0:  # one value handed over as a number
        array = array.reshape(1)
    if array.shape != (size,):
        count = f"{size} value{'s' * (size != 1)}"
        shown = np.ravel(array)[:12].tolist()
        raise ConfigError(name, shown, f"needs {count} ({', '.join(names)})")
    if not np.all(np.isfinite(array)):
        raise ConfigError(name, array.tolist(), "must be finite")
    return array


def _checked_detections(detections: Any) -> tuple[ObstacleState, ...]:
    """The caller's obstacles as a tuple of ObstacleState, or one line saying what they are."""
    try:
        items = tuple(detections)
    except TypeError:
        raise ConfigError("detections", detections, "must be a sequence of ObstacleState") from None
    for item in items:
        if not isinstance(item, ObstacleState):
            raise ConfigError(
                "detections", type(item).__name__, "must hold ObstacleState (controllers.base)"
            )
    return items
