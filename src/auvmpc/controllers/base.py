"""What every controller implements, and what the closed loop gives it each sample."""

from __future__ import annotations

import math
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from auvmpc.environment.obstacles import ObstacleState
from auvmpc.models.actuators import ActuatorLimits
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.vehicle import VehicleParams
from auvmpc.ocp.underactuated_reference import crab_reference

__all__ = [
    "ActuatorLimits",
    "align_heading",
    "next_planned_move",
    "ControlResult",
    "ControlStatus",
    "Controller",
    "MemoryNeed",
    "nlp_memory_need",
    "Observation",
    "ObstacleState",
    "feasible_thrust_box",
    "horizontal_limits",
    "project_to_limits",
    "timed_command",
    "tracked_reference",
]


@dataclass(frozen=True)
class Observation:
    """What the closed loop hands a controller at sample k."""

    k: int
    t: float  # s
    state: np.ndarray  # measured, possibly noisy: [x, y, psi, u, v, r] (HORIZONTAL); depth: [z]
    reference: np.ndarray  # (preview_steps + 1, nx): reference at t_k + i * Te, i = 0..
    obstacles: tuple[ObstacleState, ...] = ()
    # (n,) each input's actuator effectiveness as the controller should assume it, in input
    # order (1 healthy, 0 dead, 0.5 half force; ActuatorSet.force): what its prediction
    # model and its allocation use this sample. None: all healthy.
    effectiveness: np.ndarray | None = None
    # (n,) the value each stuck input holds whatever it is commanded, in its own unit (rpm,
    # deg, N), NaN where the input is free; None: none stuck. A stuck input's effectiveness
    # above is 0 (a controller that does not read this takes it as not acting, its fixed
    # force left to its disturbance estimate); one that reads it (six-dof-nmpc) predicts
    # with the input fixed at this value, acting in full.
    stuck_at: np.ndarray | None = None


class ControlStatus(StrEnum):
    """Outcome of one controller step, as logged."""

    OK = "ok"
    RELAXED = "relaxed"  # obstacle constraints softened by slack to stay feasible
    FALLBACK = "fallback"  # solver failed or timed out: previous plan's next move applied
    RECOVERY = "recovery"  # the shell's stabilising feedback applied (plan used up, or a spin)
    SATURATED = "saturated"  # command clipped to the thrust or rate limits


@dataclass
class ControlResult:
    """One step's command and how it was obtained."""

    thrust: np.ndarray  # (n,) N, applied over [t_k, t_k+1)
    status: ControlStatus = ControlStatus.OK
    solve_time_s: float = 0.0  # the optimiser's own time (the loop also times the whole call)
    predicted_states: np.ndarray | None = None  # (N + 1, nx) if the controller predicts
    info: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class MemoryNeed:
    """The largest allocation building a controller's problem takes, what it is, and the
    scenario field that sets its size (for a one-line refusal: scenario/sanity.py)."""

    field: str
    value: object
    n_bytes: float
    what: str  # e.g. "building the nmpc problem with ny=30"


# Peak memory of building a CasADi/IPOPT problem grows about as ny^2: measured with
# `/usr/bin/time -f %M` around make_controller for nmpc on jmse2210 (paper-ideal,
# control_horizon null): ny = 500 -> 0.18 GB, ny = 2000 -> 1.16 GB.
NLP_BYTES_PER_STAGE_SQUARED = 270
FLOAT_BYTES = 8  # float64


def nlp_memory_need(config) -> MemoryNeed:
    """Building the CasADi nonlinear program of ``config`` (nmpc, do-mpc)."""
    ny = config.prediction_horizon
    return MemoryNeed(
        "controller.prediction_horizon", ny, NLP_BYTES_PER_STAGE_SQUARED * ny * ny,
        f"building the {config.type} problem with ny={ny}",
    )  # fmt: skip


class Controller(ABC):
    """A discrete-time controller run every ``sample_time`` seconds.

    The closed loop calls ``reset`` once, then ``compute`` at every sample with
    the measured state and a reference preview of ``preview_steps + 1`` rows.
    A controller owns its internal model (built from the *nominal* vehicle), so
    plant-model mismatch is a property of the scenario, not of the controller.
    """

    sample_time: float
    preview_steps: int
    # Whether it commands every input of the 6-DOF vehicle on the whole measured 6-DOF state
    # (kind: six-dof only), rather than the horizontal thrusters on [x, y, psi, u, v, r].
    whole_vehicle: bool = False
    # What a run should record about how this controller was built (e.g. a slower path
    # taken because the machine lacks something); the run adds them to its warnings.
    build_warnings: tuple[str, ...] = ()

    @classmethod
    def libraries(cls, config) -> tuple[str, ...]:
        """Distributions beyond numpy, scipy and casadi it uses with ``config`` (run.json's
        provenance names their versions)."""
        return ()

    @classmethod
    def memory_need(cls, config, n_inputs: int, n_states: int) -> MemoryNeed | None:
        """What building its problem for ``config`` allocates at most, with ``n_inputs``
        thrusters and ``n_states`` states; None where that is small."""
        return None

    @abstractmethod
    def reset(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        """Forget all history; ``initial_thrust`` is F(-1) for the first rate limit."""

    @abstractmethod
    def compute(self, observation: Observation) -> ControlResult:
        """The thrust to apply over the next sample."""


def timed_command(
    controller: Controller, observation: Observation, size: int, who: str = "controller"
) -> tuple[ControlResult, np.ndarray, float]:
    """``(result, thrust, solve ms)`` of one controller call; an invalid command (wrong size
    or not finite) raises RuntimeError naming ``who`` and the sample."""
    started = time.perf_counter()
    result = controller.compute(observation)
    solve_ms = 1e3 * (time.perf_counter() - started)
    thrust = np.asarray(result.thrust, dtype=float)
    if thrust.shape != (size,) or not np.all(np.isfinite(thrust)):
        raise RuntimeError(f"{who} returned an invalid command at k={observation.k}: {thrust!r}")
    return result, thrust, solve_ms


def align_heading(state: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """The reference preview with its (continuous) heading shifted by 2 pi k to the turn
    the vehicle is on, so that heading errors stay within (-pi, pi] of the truth."""
    aligned = np.array(reference, dtype=float)
    heading = HORIZONTAL.heading
    turns = np.round((state[heading] - aligned[0, heading]) / (2.0 * math.pi))
    aligned[:, heading] += 2.0 * math.pi * turns
    return aligned


def tracked_reference(
    model: VehicleParams,
    state: np.ndarray,
    disturbance: np.ndarray,
    reference: np.ndarray,
    sample_time: float,
) -> np.ndarray:
    """The reference preview a horizontal controller's cost tracks: for an underactuated
    vehicle with the heading it can hold (ocp/underactuated_reference.py), and aligned to
    the turn the vehicle is on."""
    heading = float(state[HORIZONTAL.heading])
    crabbed = crab_reference(model, reference, disturbance, sample_time, heading)
    return align_heading(state, crabbed)


def next_planned_move(plan: np.ndarray | None, previous: np.ndarray):
    """What a fallback applies: the previous plan's next move, and the plan shifted on.

    Returns ``(wanted command, shifted plan)``; without a plan the previous command is held.
    """
    if plan is None or len(plan) < 2:
        return previous, plan
    return plan[1], np.vstack([plan[1:], plan[-1:]])


def horizontal_limits(params: VehicleParams) -> ActuatorLimits:
    """The horizontal thrusters' hard limits."""
    return params.actuators.limits


def feasible_thrust_box(
    previous_thrust: np.ndarray, params: VehicleParams, sample_time: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per-thruster [lower, upper] reachable in one sample under both hard limits."""
    return horizontal_limits(params).box(previous_thrust, sample_time)


def project_to_limits(
    thrust: np.ndarray, previous_thrust: np.ndarray, params: VehicleParams, sample_time: float
) -> tuple[np.ndarray, bool]:
    """Clip a command into the hard-limit box; also say whether it had to move."""
    return horizontal_limits(params).project(thrust, previous_thrust, sample_time)
