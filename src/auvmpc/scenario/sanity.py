"""Checks before a run: does it fit in memory, and can the vehicle do what is asked?

Each finding is an error (:class:`~auvmpc.errors.ConfigError`: one line, exit 2, nothing
run) when the run could not mean anything, and a warning (printed, stored in run.json
``warnings``) when the run is possible but probably not what was meant. The decisions,
with their reasons, are in ``docs/safety.md`` (Physical sanity checks):

- sizes beyond the available memory: error (the run could only crash);
- a run estimated beyond the cost limits (plant steps, hours: :mod:`auvmpc.scenario.cost`):
  error unless the caller confirms it (``--yes-long``);
- start inside an obstacle's keep-out disc (radius + ``vehicle_radius``): warning (the
  run starts in contact; the MPCs relax the constraint and leave, a recovery that is
  worth simulating, e.g. an obstacle appearing on top of the vehicle);
- a reference faster than the vehicle's steady top speed: error (no controller can
  track it; the tracking metrics would measure the thrust limits, not the controller);
- a reference that needs more thrust than the limits allow somewhere else (a turn too
  tight for its speed): warning (a steady-turn estimate; sideslip can help);
- a reference whose thrust needs change faster than ``thrust_rate_limit`` allows within
  one sample: warning (a minimum-norm allocation estimate; the vehicle lags there).
- a reference whose depth changes in a horizontal-plane scenario: warning (the 3-DOF
  plant follows its horizontal path only);
- a sample time over which the largest yaw moment can turn the vehicle by over half a turn
  (any controller), or over 8 yaw turn-up times (ltv-mpc, mpc): warning (it may spin);
- ltv-mpc or mpc on a path with corners (turns of 45 degrees or more): warning (measured
  on the hard survey);
- the real-time nmpc given fewer SQP steps per sample than the vehicle's surge and sway
  agility call for: warning.

The thrust the reference needs is the 3-DOF model solved for the force (inverse
dynamics, :mod:`auvmpc.models.vehicle`) along the reference at the controller's samples, for
the simulated plant, with no disturbance.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from auvmpc.controllers.base import FLOAT_BYTES
from auvmpc.controllers.config import (
    AGILITY_SPEED_M_PER_S,
    HEADING_PER_SAMPLE_RAD,
    ControllerType,
    NmpcMode,
    default_sample_time,
    default_sqp_iterations,
    velocity_change_time,
)
from auvmpc.controllers.registry import class_of
from auvmpc.errors import ConfigError
from auvmpc.models.layout import DEPTH_PROFILE, HORIZONTAL, PLANAR_FORCE
from auvmpc.models.vehicle import VehicleParams, heading_turn_time, top_yaw_rate, turn_up_time
from auvmpc.scenario import (
    ResolvedDepthScenario,
    ResolvedScenario,
    Scenario,
)
from auvmpc.scenario.cost import readable_bytes

__all__ = [
    "available_memory_bytes",
    "check_memory",
    "memory_needs",
    "feasible_forces",
    "largest_surge_thrust",
    "preflight",
    "reference_thrust_needs",
    "steady_top_speed",
]

# Speeds and forces within this relative margin of a limit count as at the limit
# (finite differences and the top-speed formula agree to about 1e-9 relative).
_RELATIVE_MARGIN = 1e-6
# Memory a run may plan to use, as a share of what the machine has available now.
_MEMORY_SHARE = 0.8
# The surge force's row of an allocation matrix (PLANAR_FORCE).
_SURGE = PLANAR_FORCE.index("X")


def available_memory_bytes() -> int:
    """Memory a new allocation can get now: the least of Linux MemAvailable (else physical
    memory), what this process's address-space limit leaves (``ulimit -v``: the build of
    a 3000-step nmpc passed a check on MemAvailable alone and died with MemoryError under
    it) and what its cgroup's memory.max leaves."""
    limits = [_meminfo_available()]
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            limits.append(max(0, soft - _status_bytes("VmSize:")))
    except (ImportError, OSError, ValueError):
        pass
    try:
        cgroup = Path("/sys/fs/cgroup")
        limit = (cgroup / "memory.max").read_text().strip()
        if limit != "max":
            limits.append(max(0, int(limit) - int((cgroup / "memory.current").read_text())))
    except (OSError, ValueError):
        pass
    return min(limits)


def _meminfo_available() -> int:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, AttributeError):
        return 2**63


def _status_bytes(key: str) -> int:
    """A size from /proc/self/status (kB there), 0 where there is none."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(key):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return 0


def memory_needs(
    resolved: ResolvedScenario | ResolvedDepthScenario,
) -> list[tuple[str, object, float, str]]:
    """``(field, value, bytes, what)`` of the run's largest allocations: the log
    (duration / sample_time samples) and what building the controller's problem takes
    (``memory_need`` of its class: the condensed QP of the linear MPCs grows as
    ny x nc x n^2, the nonlinear program as ny^2)."""
    scenario = resolved.scenario
    config = scenario.controller
    steps = scenario.duration / config.sample_time
    n, nx = resolved.controlled_inputs.size, resolved.controlled_layout.size
    # log: state, reference, disturbance, thrust, clearance, solve time, status per sample
    log_bytes = steps * (FLOAT_BYTES * (3 * nx + n + 4) + 64)
    needs = [
        (
            "duration",
            scenario.duration,
            log_bytes,
            f"{steps:.3g} samples of {config.sample_time} s need about "
            f"{readable_bytes(log_bytes)} of log",
        )
    ]
    need = class_of(config).memory_need(config, n, nx)
    if need is not None:
        needs.append(
            (
                need.field,
                need.value,
                need.n_bytes,
                f"{need.what} needs about {readable_bytes(need.n_bytes)}",
            )
        )
    return needs


def check_memory(
    resolved: ResolvedScenario | ResolvedDepthScenario, available: int | None = None
) -> None:
    """Refuse sizes that cannot fit (:func:`memory_needs`) in a share of the memory
    available (:func:`available_memory_bytes`)."""
    budget = _MEMORY_SHARE * (available_memory_bytes() if available is None else available)
    for field, value, n_bytes, what in memory_needs(resolved):
        if n_bytes > budget:
            raise ConfigError(
                field, value, f"{what}, more than the {readable_bytes(budget)} of memory available"
            )


def preflight(
    resolved: ResolvedScenario | ResolvedDepthScenario, long_ok: bool = False
) -> list[str]:
    """All checks of the module docstring; returns the warnings, raises the errors.
    ``long_ok``: the caller confirmed a run beyond the cost limits (:mod:`.cost`)."""
    from auvmpc.scenario.cost import check_cost

    check_memory(resolved)
    check_cost(resolved, confirmed=long_ok)
    if not resolved.has_horizontal_path:
        return list(resolved.notes)
    return (
        resolved.notes
        + _check_start(resolved.scenario)
        + _check_sample_time(resolved)
        + _check_sqp_steps(resolved)
        + _check_reference(resolved)
    )


# Linearised controllers (ltv-mpc, mpc) predict a sample with the model linearised at its
# start; a yaw that turns up faster than a sample's 1/LINEARISED_TURN_UP_SAMPLES leaves that
# linearisation within the sample. Measured at 0.5 s (docs/recovery.md): ltv-mpc spun and
# was lost on hard-survey vehicles with turn-up times of 0.006-0.059 s (8.5-83 per sample);
# it tracks the BlueROV2 Heavy (0.082 s, 6.1 per sample) on every generality run.
LINEARISED_TURN_UP_SAMPLES = 8.0
_LINEARISED = ("mpc", "ltv-mpc")


def _check_sample_time(resolved: ResolvedScenario) -> list[str]:
    """A sample long against the vehicle's yaw response: one over which the largest yaw
    moment can turn it by more than HEADING_PER_SAMPLE_RAD (any controller; only a sample
    time the scenario gives, the default keeping below it where the grid allows), and for a
    linearised controller one over LINEARISED_TURN_UP_SAMPLES turn-up times."""
    config = resolved.scenario.controller
    model = resolved.model
    if not model.has_thrusters:  # a propeller and fins make no yaw moment at rest
        return []
    warnings = []
    spin = heading_turn_time(model, HEADING_PER_SAMPLE_RAD)
    if resolved.given.controller.sample_time is not None and config.sample_time > spin:
        warnings.append(
            f"controller.sample_time: {config.sample_time:g} s is longer than the {spin:.3g} s "
            f"{model.name}'s largest yaw moment needs to turn it by half a turn (top yaw rate "
            f"{top_yaw_rate(model):.3g} rad/s): a held thrust can spin it within the sample; "
            f"omit it for {default_sample_time(model):g} s, or use <= {spin:.3g} s"
        )
    turn_up = turn_up_time(model)
    if (
        str(config.type) in _LINEARISED
        and config.sample_time > LINEARISED_TURN_UP_SAMPLES * turn_up
    ):
        warnings.append(
            f"controller.sample_time: {config.sample_time:g} s is more than "
            f"{LINEARISED_TURN_UP_SAMPLES:g} x {model.name}'s yaw turn-up time "
            f"{turn_up:.3g} s (Iz r_top / M_max): {config.type} linearises once per sample and "
            f"may spin on it; use nmpc (the default) or a sample time <= "
            f"{LINEARISED_TURN_UP_SAMPLES * turn_up:.3g} s"
        )
    return warnings


# Hard-survey cases (of those where the converged OCP is not lost) each linearised
# controller was lost on or fell short of the converged OCP's bar on, at this release
# (docs/recovery.md, `auvmpc campaign hard-survey --controller ...`); the default missed none.
CORNERED_MISSES = {"ltv-mpc": "53 of 196", "mpc": "131 of 196"}


def _check_sqp_steps(resolved: ResolvedScenario) -> list[str]:
    """The real-time nmpc given fewer SQP steps per sample than the vehicle's surge and sway
    agility call for (default_sqp_iterations): one step oscillated at full thrust beside a
    disc on such hard-survey vehicles and touched it."""
    config = resolved.scenario.controller
    if config.type is not ControllerType.NMPC or config.nmpc_mode is not NmpcMode.REAL_TIME:
        return []
    wanted = default_sqp_iterations(resolved.model)
    if config.linearisation_iterations >= wanted:
        return []
    change = velocity_change_time(resolved.model)
    return [
        f"controller.linearisation_iterations: {config.linearisation_iterations} SQP step "
        f"per sample on {resolved.model.name}, whose full thrust changes its speed by "
        f"{AGILITY_SPEED_M_PER_S:g} m/s in {change:.3g} s: one step oscillated beside discs "
        f"on such vehicles (docs/recovery.md); omit it for {wanted}"
    ]


def _check_corners(corners: int, controller: str) -> list[str]:
    """A linearised controller on a path with corners: the hard survey's lost cases. Not
    predicted per vehicle (the turn-up rule above catches part of them), so said of the
    mission, with the count measured in docs/recovery.md."""
    if corners == 0 or controller not in _LINEARISED:
        return []
    return [
        f"controller.type: {controller} on a path with {corners} corner{'s' * (corners != 1)}: "
        f"it linearises once per sample and was lost or fell short of the converged OCP on "
        f"{CORNERED_MISSES[controller]} cornered hard-survey cases (docs/recovery.md); nmpc "
        "(the default) follows corners"
    ]


def _check_start(scenario: Scenario) -> list[str]:
    x, y = scenario.initial_state[HORIZONTAL.position]
    margin = scenario.controller.vehicle_radius
    warnings = []
    for index, obstacle in enumerate(scenario.obstacles):
        if not obstacle.exists_at(0.0):
            continue
        cx, cy = obstacle.center_at(0.0)
        distance = math.hypot(x - cx, y - cy)
        if distance < obstacle.radius + margin:
            warnings.append(
                f"obstacles.{index}: the start position ({x:g}, {y:g}) is {distance:.3g} m from "
                f"its centre, inside its keep-out disc (radius {obstacle.radius:g} + "
                f"vehicle_radius {margin:g} m): the run starts in contact (negative clearance) "
                "and the MPCs relax that constraint until the vehicle is out"
            )
    return warnings


def steady_top_speed(params: VehicleParams) -> float:
    """Fastest steady straight surge (m/s): the largest pure surge force the thrusters can
    make within their limits (:func:`largest_surge_thrust`) against Xu u + Xuu u|u|."""
    force = float(params.T[_SURGE] @ largest_surge_thrust(params))
    a, b = -params.Xuu, -params.Xu  # both >= 0: damping force a u^2 + b u
    if a > 0:
        return (-b + math.sqrt(b * b + 4.0 * a * force)) / (2.0 * a)
    return force / b if b > 0 else math.inf


def largest_surge_thrust(params: VehicleParams) -> np.ndarray:
    """Thrusts (n,) within the limits that make the largest surge force with no sway force
    and no yaw moment (a linear program); zeros if the layout cannot push straight ahead."""
    from scipy.optimize import linprog

    T = params.T
    others = [i for i in range(PLANAR_FORCE.size) if i != _SURGE]  # sway force, yaw moment
    result = linprog(
        -T[_SURGE],
        A_eq=T[others],
        b_eq=np.zeros(len(others)),
        bounds=[params.thrust_limits] * params.n_thrusters,
        method="highs",
    )
    return np.asarray(result.x) if result.status == 0 else np.zeros(params.n_thrusters)


def reference_thrust_needs(
    params: VehicleParams, states: np.ndarray, sample_time: float
) -> np.ndarray:
    """Generalised force [f_u, f_v, M_r] (k, PLANAR_FORCE.size) that moves the model along
    ``states`` [x, y, psi, u, v, r] (k, HORIZONTAL.size) sampled every ``sample_time`` with
    no disturbance (the model solved for tau; accelerations by central differences)."""
    u, v, r = (states[:, HORIZONTAL.index(name)] for name in ("u", "v", "r"))
    if len(states) > 1:
        du, dv, dr = (np.gradient(q, sample_time) for q in (u, v, r))
    else:
        du = dv = dr = np.zeros(len(states))
    p = params
    return np.column_stack(
        (
            p.m11 * du - p.Xu * u - p.Xuu * np.abs(u) * u - p.m22 * v * r,
            p.m22 * dv - p.Yv * v - p.Yvv * np.abs(v) * v + p.m11 * u * r,
            p.Iz * dr - p.Nr * r - p.Nrr * np.abs(r) * r - (p.m11 - p.m22) * u * v,
        )
    )


def feasible_forces(params: VehicleParams, tau: np.ndarray) -> np.ndarray:
    """For each generalised force [X, Y, N] (k, PLANAR_FORCE.size), whether thrusts within
    the limits make it exactly.

    The minimum-norm allocation decides most rows; the others are decided exactly by the
    interval of the null-space coordinate when the null space is one-dimensional (four
    thrusters), else by a linear program each.
    """
    low, high = params.thrust_limits
    slack = _RELATIVE_MARGIN * max(abs(low), abs(high))
    base = tau @ params.T_pinv.T  # (k, n) minimum-norm thrusts
    inside = np.all((base >= low - slack) & (base <= high + slack), axis=1)
    if inside.all():
        return inside
    _, singular, vt = np.linalg.svd(params.T)
    null = vt[int(np.sum(singular > 1e-9 * singular[0])) :]
    result = inside.copy()
    rows = np.flatnonzero(~inside)
    if len(null) == 0:
        return result
    if len(null) == 1:  # F = base + a n: each thruster bounds a to an interval
        n = null[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            a1 = (low - slack - base[rows]) / n
            a2 = (high + slack - base[rows]) / n
        lower = np.where(np.abs(n) > 1e-12, np.minimum(a1, a2), -np.inf).max(axis=1)
        upper = np.where(np.abs(n) > 1e-12, np.maximum(a1, a2), np.inf).min(axis=1)
        fixed_ok = np.all(
            (np.abs(n) > 1e-12) | ((base[rows] >= low - slack) & (base[rows] <= high + slack)),
            axis=1,
        )
        result[rows] = (lower <= upper) & fixed_ok
        return result
    from scipy.optimize import linprog

    for k in rows:
        solved = linprog(
            np.zeros(params.n_thrusters),
            A_eq=params.T,
            b_eq=tau[k],
            bounds=[(low - slack, high + slack)] * params.n_thrusters,
            method="highs",
        )
        result[k] = solved.status == 0
    return result


def _check_mission_end(end: float | None, duration: float, sample_time: float) -> list[str]:
    """A reference that ends (waypoints, a lawnmower) more than half a sample before the run
    does, or after it: the vehicle holds the end point, or never gets there (issue 30: a
    200 s survey ended at 177.5 s and held still without a word)."""
    if end is None or abs(end - duration) <= 0.5 * sample_time:
        return []
    if end < duration:
        return [
            f"reference: the path ends at t = {end:.4g} s, {duration - end:.4g} s before the "
            f"run's duration {duration:g} s; the vehicle is asked to hold the end point after it"
        ]
    return [
        f"duration: {duration:g} s ends the run before the path does (at t = {end:.4g} s, "
        f"{100.0 * duration / end:.0f} % of the way)"
    ]


def _check_reference(resolved: ResolvedScenario) -> list[str]:
    from auvmpc.references import make_reference

    scenario = resolved.scenario
    plant = resolved.plant
    sample_time = scenario.controller.sample_time
    steps = int(round(scenario.duration / sample_time))
    t = sample_time * np.arange(steps + 1)
    reference = make_reference(scenario.reference, resolved.base_dir)
    states = reference.states(t)
    warnings = _check_mission_end(reference.end_time, scenario.duration, sample_time)
    if reference.has_depth and not resolved.follows_depth:
        depths = reference.depths(t)[:, DEPTH_PROFILE.index("z")]
        if np.ptp(depths) > 0.0:
            warnings.append(
                f"reference: its depth changes ({depths.min():.3g} to {depths.max():.3g} m) "
                "but a horizontal-plane scenario tracks only its horizontal path; give "
                "kind: six-dof to follow the depth too"
            )
    if not plant.has_thrusters:  # what follows weighs the reference against thrust (N)
        return warnings
    speed = np.hypot(*states[:, HORIZONTAL.body_velocity].T)
    top = steady_top_speed(plant)
    fastest = int(np.argmax(speed))
    warnings += _check_corners(reference.corners, str(scenario.controller.type))
    if speed[fastest] > top * (1.0 + _RELATIVE_MARGIN):
        config = scenario.reference
        field, value = (
            ("reference.speed", config.speed)
            if hasattr(config, "speed")
            else (
                "reference",
                config.type,
            )
        )
        raise ConfigError(
            field,
            value,
            f"the reference moves at {speed[fastest]:.3g} m/s (t = {t[fastest]:g} s), faster "
            f"than {plant.name}'s steady top speed {top:.3g} m/s (thrust limits "
            f"{list(plant.thrust_limits)} N against its surge damping)",
        )
    tau = reference_thrust_needs(plant, states, sample_time)
    infeasible = np.flatnonzero(~feasible_forces(plant, tau))
    if len(infeasible):
        k = int(infeasible[0])
        yaw_rate = abs(states[k, HORIZONTAL.index("r")])
        radius = speed[k] / yaw_rate if yaw_rate > 1e-12 else math.inf
        warnings.append(
            f"reference: needs more thrust than {plant.name}'s limits {list(plant.thrust_limits)}"
            f" N at {len(infeasible)} of {len(t)} samples, first at t = {t[k]:g} s "
            f"(speed {speed[k]:.3g} m/s, turn radius {radius:.3g} m): the vehicle cannot "
            "follow it there"
        )
    if len(t) > 1:
        change = np.abs(np.diff(tau @ plant.T_pinv.T, axis=0)).max(axis=1)
        allowed = plant.thrust_rate_limit * sample_time
        worst = int(np.argmax(change))
        if change[worst] > allowed * (1.0 + _RELATIVE_MARGIN):
            warnings.append(
                f"vehicle.thrust_rate_limit: the reference's thrust needs change by "
                f"{change[worst]:.3g} N in one sample at t = {t[worst]:g} s, more than "
                f"thrust_rate_limit x sample_time = {allowed:.3g} N: the vehicle lags there"
            )
    return warnings
