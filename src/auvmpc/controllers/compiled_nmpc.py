"""The real-time ``nmpc`` run by its C controller: the very step ``export-c`` ships
(solvers/auvmpc_controller.c, built from controllers/c_sources.py), called through ctypes.

Where the configuration is one the C covers (:func:`runs_in_c`) and a C compiler and the casadi
wheel's HPIPM are present, ``nmpc`` is this class: estimator, SQP steps with their retries,
warm start and safety shell are the C's, so the compiled controller is one implementation,
not a Python twin of the exported one. The C asks back only for the last resort after every
real-time try failed: IPOPT on the same program (:class:`~auvmpc.controllers.nmpc.NonlinearMpc`
does the same in Python), through a callback. Elsewhere ``nmpc`` stays the Python
:class:`NonlinearMpc` (move blocking, a solve-time limit, an underactuated vehicle, the
robust tightening, or no compiler), whose real-time iteration is the reference the C is
tested against (tests/test_compiled_nmpc.py).
"""

from __future__ import annotations

import ctypes
import tempfile
import time
from pathlib import Path

import numpy as np

from auvmpc import native
from auvmpc.controllers.base import (
    Controller,
    ControlResult,
    ControlStatus,
    Observation,
    tracked_reference,
)
from auvmpc.controllers.c_sources import write_sources
from auvmpc.controllers.config import NmpcMode, QpStructure
from auvmpc.controllers.nmpc import NmpcConfig, rescue_solver
from auvmpc.controllers.shell import ESTIMATE_KEYS, SLACK_ACTIVE
from auvmpc.models.vehicle import VehicleParams
from auvmpc.ocp.multiple_shooting import ND, NX, MultipleShootingProgram
from auvmpc.ocp.stage_qp import stage_qp
from auvmpc.solvers.compiled_qp_step import hpipm_linking

__all__ = ["CompiledNmpc", "runs_in_c"]

_DOUBLE_P = ctypes.POINTER(ctypes.c_double)
# auvmpc_status (solvers/auvmpc_controller.h) by its number.
C_STATUS = (
    ControlStatus.OK,
    ControlStatus.RELAXED,
    ControlStatus.FALLBACK,
    ControlStatus.SATURATED,
    ControlStatus.RECOVERY,
)
_RESCUED, _RESUMABLE, _FAILED = 0, 1, -1  # what the rescue callback returns (the header's)
_OBSTACLE_FIELDS = 6  # auvmpc_obstacle: centre (2), velocity (2), radius, horizon_radius


class _Report(ctypes.Structure):
    _fields_ = [
        ("iterations", ctypes.c_int),
        ("spinning", ctypes.c_int),
        ("max_slack", ctypes.c_double),
        ("disturbance", ctypes.c_double * ND),
    ]


# auvmpc_rescue: (user, state, disturbance, previous, states, thrust, max_slack, iterations)
_RESCUE = ctypes.CFUNCTYPE(
    ctypes.c_int, ctypes.c_void_p, *[_DOUBLE_P] * 6, ctypes.POINTER(ctypes.c_int)
)


def runs_in_c(model: VehicleParams, config: NmpcConfig) -> bool:
    """Whether the C controller covers ``config`` (filled for ``model``): the real-time
    iteration on the sparse QP with every move free, compiled, for a fully actuated vehicle,
    without a solve-time limit (the C has no clock)."""
    every_move = config.move_schedule() == tuple(range(config.prediction_horizon))
    return (
        config.nmpc_mode is NmpcMode.REAL_TIME
        and config.qp_structure is not QpStructure.CONDENSED
        and every_move
        and config.jit
        and config.solver_time_limit_ms is None
        and model.unactuated_direction is None
        and native.compiler() is not None
        and hpipm_linking() is not None
    )


class CompiledNmpc(Controller):
    """``nmpc`` (real-time) as its C controller (module docstring)."""

    def __init__(self, model: VehicleParams, config: NmpcConfig, obstacle_slots: int) -> None:
        self.model = model
        self.config = config
        self.sample_time = config.sample_time
        self.horizon = config.prediction_horizon
        self.preview_steps = self.horizon
        self.program = MultipleShootingProgram(model, config, obstacle_slots)
        self._rescue: object | None = None  # IPOPT on the program, built when first needed
        library = _library(self.program, config)
        if library is None:
            raise RuntimeError("the C controller could not be built")
        self._c = library
        _declare(library)
        self._handle = library.auvmpc_create()
        if not self._handle:
            raise MemoryError("the C controller could not be allocated")
        N, n = self.horizon, model.n_thrusters
        self._state = np.zeros(NX)
        self._reference = np.zeros((N + 1, NX))
        self._obstacles = np.zeros((max(obstacle_slots, 1), _OBSTACLE_FIELDS))
        self._prediction_times = self.sample_time * np.arange(1, N + 1)  # as the program's
        self._command = np.zeros(n)
        self._healthy = np.ones(n)
        self._effectiveness = np.ones(n)  # what the C was told last (all ones after init)
        self._predicted = np.zeros((N + 1, NX))
        self._report = _Report()
        self._observation: Observation | None = None  # the sample the rescue is asked for
        self._rescue_error: Exception | None = None
        self._callback = _RESCUE(self._rescue_call)  # kept: the C holds its address
        library.auvmpc_controller_set_rescue(self._handle, self._callback, None)
        self.reset(np.zeros(NX), np.zeros(n))

    def __del__(self) -> None:
        handle, self._handle = getattr(self, "_handle", None), None
        if handle:
            self._c.auvmpc_destroy(handle)

    def reset(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        state = np.ascontiguousarray(initial_state, dtype=float)
        thrust = np.ascontiguousarray(initial_thrust, dtype=float)
        if self._c.auvmpc_controller_init(self._handle, state.ctypes.data, thrust.ctypes.data):
            raise MemoryError("the C controller's HPIPM workspace could not be allocated")
        self._effectiveness[:] = 1.0  # as the shell's reset: healthy until told otherwise

    def compute(self, observation: Observation) -> ControlResult:
        obstacles = observation.obstacles
        if len(obstacles) > len(self._obstacles):
            self._obstacles = np.zeros((len(obstacles), _OBSTACLE_FIELDS))
        for row, obstacle in zip(self._obstacles, obstacles, strict=False):
            radius = obstacle.horizon_radius(self._prediction_times)
            row[:] = [*obstacle.center, *obstacle.velocity, obstacle.radius, radius]
        told = self._healthy if observation.effectiveness is None else observation.effectiveness
        if not np.array_equal(told, self._effectiveness):
            np.copyto(self._effectiveness, told)
            if self._c.auvmpc_controller_set_effectiveness(
                self._handle, self._effectiveness.ctypes.data
            ):
                raise ValueError(f"effectiveness {told}: each in [0, 1]")
        np.copyto(self._state, observation.state)
        np.copyto(self._reference, observation.reference[: self.horizon + 1])
        self._observation = observation
        started = time.perf_counter()
        code = self._c.auvmpc_controller_step(
            self._handle, self._state.ctypes.data, self._reference.ctypes.data,
            self._obstacles.ctypes.data, len(obstacles), self._command.ctypes.data,
        )  # fmt: skip
        solve_time_s = time.perf_counter() - started
        self._observation = None
        if self._rescue_error is not None:  # raised in the callback, where the C is
            error, self._rescue_error = self._rescue_error, None
            raise error
        report = self._report
        self._c.auvmpc_controller_last(
            self._handle, ctypes.byref(report), self._predicted.ctypes.data
        )
        status = C_STATUS[code]
        fell_back = status in (ControlStatus.FALLBACK, ControlStatus.RECOVERY)
        return ControlResult(
            thrust=self._command.copy(),
            status=status,
            solve_time_s=solve_time_s,
            predicted_states=None if fell_back else self._predicted.copy(),
            info={
                "solver_iterations": float(report.iterations),
                "max_slack": float(report.max_slack),
                "solve_ms": 1e3 * solve_time_s,
                "relaxed": float(not fell_back and report.max_slack > SLACK_ACTIVE),
                "fallback": float(fell_back),
                **dict(zip(ESTIMATE_KEYS, map(float, report.disturbance), strict=True)),
                "recovery": float(status is ControlStatus.RECOVERY),
                "spinning": float(report.spinning),
            },
        )

    def _rescue_call(self, _user, state, disturbance, previous, states, thrust, slack, iterations):
        """The C's last resort: IPOPT on the program from the vehicle at rest where it is
        (NonlinearMpc.propose, step 3). An exception must not cross into the C: the rescue
        fails there and :meth:`compute` raises it once the C has returned, as the Python
        controller would."""
        try:
            return self._rescued(
                np.ctypeslib.as_array(state, (NX,)).copy(),
                np.ctypeslib.as_array(disturbance, (ND,)).copy(),
                np.ctypeslib.as_array(previous, (self.model.n_thrusters,)).copy(),
                np.ctypeslib.as_array(states, (self.horizon + 1, NX)),
                np.ctypeslib.as_array(thrust, (self.horizon, self.model.n_thrusters)),
                slack, iterations,
            )  # fmt: skip
        except Exception as error:  # noqa: BLE001 -- re-raised by compute
            self._rescue_error = error
            return _FAILED

    def _rescued(self, state, disturbance, previous, states, thrust, slack, iterations) -> int:
        observation = self._observation
        reference = tracked_reference(
            self.model, state, disturbance, observation.reference[: self.horizon + 1],
            self.sample_time,
        )  # fmt: skip
        program = self.program
        sample = program.sample(
            state, previous, reference, disturbance, observation.obstacles, self._effectiveness
        )
        if self._rescue is None:
            self._rescue = rescue_solver(program, self.config)
        solution = self._rescue.solve(program.resting_guess(sample), sample, 0, True)
        iterations[0] = solution.iterations
        point = solution.iterate if solution.iterate is not None else solution.resume
        if point is None:
            return _FAILED
        states[:] = point.states
        thrust[:] = program.plan(point)
        slack[0] = float(point.slack.max(initial=0.0))
        return _RESCUED if solution.iterate is not None else _RESUMABLE


def _declare(library: ctypes.CDLL) -> None:
    """The C functions' signatures (solvers/auvmpc_controller.h)."""
    pointer = ctypes.c_void_p
    library.auvmpc_create.restype = pointer
    library.auvmpc_create.argtypes = []
    library.auvmpc_destroy.argtypes = [pointer]
    library.auvmpc_controller_init.restype = ctypes.c_int
    library.auvmpc_controller_init.argtypes = [pointer] * 3
    library.auvmpc_controller_step.restype = ctypes.c_int
    library.auvmpc_controller_step.argtypes = [pointer] * 4 + [ctypes.c_int, pointer]
    library.auvmpc_controller_set_effectiveness.restype = ctypes.c_int
    library.auvmpc_controller_set_effectiveness.argtypes = [pointer, pointer]
    library.auvmpc_controller_set_rescue.argtypes = [pointer, _RESCUE, pointer]
    library.auvmpc_controller_last.argtypes = [pointer, ctypes.POINTER(_Report), pointer]


def _library(program: MultipleShootingProgram, config: NmpcConfig) -> ctypes.CDLL | None:
    """The C controller for ``program``, built into the cache folder unless it is there."""
    options, salt = hpipm_linking()
    with tempfile.TemporaryDirectory(prefix="auvmpc-nmpc-") as scratch:
        sources = write_sources(program, stage_qp(program), config, Path(scratch))
        return native.shared_library("nmpc", sources, [f"-I{scratch}", *options], salt=salt)
