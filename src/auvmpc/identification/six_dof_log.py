"""One 6-DOF log, every model: the 3-DOF, heave and roll and pitch grey boxes in turn.

A 6-DOF log (a ``kind: six-dof`` run folder's log.csv, or a real vehicle's AHRS, DVL and
thruster commands) holds the body velocities ``u, v, w, p, q, r``, the attitude and every
``six_dof`` thruster's force. The 6-DOF model's thruster matrix maps those forces to the
body wrench ``tau = T F`` (Fossen 2021, eq. 6.1), whose X, Y, N rows drive the 3-DOF model
and whose Z row the heave model. What the 6-DOF equations hold beyond those reduced models
(:func:`remainder`) is known from the log and the vehicle's other values, and is added to
their input as a force:

- the Coriolis and centripetal terms with w, p or q in them, ``-[C_RB(nu) + C_A(nu)] nu``
  less the reduced models' own (3-DOF: ``m22 v r``, ``-m11 u r``, ``(m11 - m22) u v``; heave:
  none), e.g. the surge force ``-(m - Z_wdot) w q`` of a pitching, heaving vehicle;
- the restoring forces' change with the tilt, ``-[g(phi, theta) - g(0, 0)]`` (the reduced
  models hold the level values: no horizontal force, the net buoyancy in heave);
- the mass matrix's off-diagonal terms ``-M_ij nu_j'`` (a centre of gravity off CO).

The heave model is fitted to the body heave velocity ``w`` alone (a DVL's; z up: ``-w``):
the 6-DOF Z row is written in the body, and a tilted vehicle moving forward changes its
depth by ``-u sin(theta)`` too, which the heave model's ``z' = w`` does not hold.

The terms above depend on the other models' values (the surge force on Z_wdot, the heave
force on X_udot, roll and pitch on all of them), so the models are identified in turn, each
with the others' best values so far: 3-DOF (from the start file's heave and roll and pitch
values), heave, roll and pitch, and all three once more (:data:`ROUNDS`; on the BlueROV2
Heavy's 25 s test log from a start 30 % off, the 3-DOF and heave models alone repeated left
7 of 20 intervals missing the truth, all three repeated 2). The start values reported are
the start file's. Assumed: no current (the
logged velocities are through the water). The log is a ``kind: six-dof`` run folder, a ROS 2
bag (the odometry's whole pose and twist, every thruster's force) or an ArduSub DataFlash log
(ATT, the EKF's position and velocity, IMU's rates, RCOU): :func:`read_six_dof_samples`.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import casadi as ca
import numpy as np

from auvmpc.errors import ConfigError
from auvmpc.identification.estimation import (
    GreyBox,
    HorizontalGreyBox,
    Identification,
    identify,
    smoothed,
)
from auvmpc.identification.heave import RATE_ONLY, HeaveGreyBox
from auvmpc.identification.logs import LogKind, LogOptions, VelocityLog, log_kind
from auvmpc.identification.roll_pitch import (
    RollPitchGreyBox,
    put_identified,
    read_six_dof_state,
    roll_pitch_log,
)
from auvmpc.models.actuators import WRENCH
from auvmpc.models.layout import HORIZONTAL_VELOCITY, PLANAR_FORCE
from auvmpc.models.six_dof import (
    ANGULAR_VELOCITY,
    BODY_VELOCITY,
    SIX_DOF,
    TILT,
    coriolis_added_mass,
    coriolis_rigid_body,
    restoring_forces,
)
from auvmpc.models.six_dof_params import horizontal_equivalent
from auvmpc.models.vehicle import VehicleParams, load_vehicle, velocity_derivative

__all__ = [
    "MODELS",
    "offset_vehicle",
    "parameter_values",
    "ROUNDS",
    "heave_log",
    "horizontal_log",
    "identify_six_dof",
    "merged",
    "model_of",
    "read_six_dof_samples",
    "remainder",
]

_NU = SIX_DOF.nu
_PLANAR_ROWS = [WRENCH.index(name) for name in PLANAR_FORCE.names]
_HEAVE_ROW = WRENCH.index("Z")
# The models in the order they are identified, and how many times each is (module
# docstring: a second round has the others' identified values in its coupling).
MODELS = ("horizontal", "heave", "roll-pitch")
ROUNDS = 2


def remainder(vehicle: VehicleParams) -> ca.Function:
    """(nu [u, v, w, p, q, r], [phi, theta], nu') -> the wrench [X, Y, Z, K, M, N] the 6-DOF
    equations of
    ``vehicle`` hold beyond the 3-DOF and heave models (module docstring), NED body axes; its
    K and M rows are not used (the roll and pitch model has its own, roll_pitch.py)."""
    six = vehicle.six_dof
    nu, nu_dot = ca.SX.sym("nu", BODY_VELOCITY.size), ca.SX.sym("nu_dot", BODY_VELOCITY.size)
    angles = ca.SX.sym("angles", TILT.size)
    r_g = np.array(six.center_of_gravity, dtype=float)
    r_b = np.array(six.center_of_buoyancy, dtype=float)
    C_RB = coriolis_rigid_body(vehicle.mass, six.inertia_matrix, r_g, nu[ANGULAR_VELOCITY])
    C_A = coriolis_added_mass(six.added_mass_matrix, nu)
    weight, buoyancy = six.weight(vehicle.mass), six.buoyancy
    phi, theta = (angles[TILT.index(name)] for name in TILT.names)
    tilted = restoring_forces(weight, buoyancy, r_g, r_b, phi, theta)
    level = restoring_forces(weight, buoyancy, r_g, r_b, 0.0, 0.0)
    mass = np.array(six.mass_matrix(vehicle.mass))
    off_diagonal = mass - np.diag(np.diag(mass))
    wrench = -ca.mtimes(C_RB + C_A, nu) - (tilted - level) - ca.mtimes(ca.DM(off_diagonal), nu_dot)
    # The 3-DOF model's own coupling, by its equations (zero damping and force, times the
    # masses), with the values the section implies: what is left is the 6-DOF's surplus.
    reduced = horizontal_equivalent(vehicle.mass, six)
    coefficients = SimpleNamespace(
        m11=reduced["m11"], m22=reduced["m22"], Iz=reduced["Iz_rb"] + reduced["Iz_added"],
        Xu=0.0, Xuu=0.0, Yv=0.0, Yvv=0.0, Nr=0.0, Nrr=0.0,
    )  # fmt: skip
    u, v, r = (nu[BODY_VELOCITY.index(name)] for name in HORIZONTAL_VELOCITY.names)
    derivative = velocity_derivative(coefficients, u, v, r, (0.0, 0.0, 0.0), ca.fabs)
    planar = [coefficients.m11, coefficients.m22, coefficients.Iz]
    for row, rate, inertia in zip(_PLANAR_ROWS, derivative, planar, strict=True):
        wrench[row] -= inertia * rate
    return ca.Function("remainder", [nu, angles, nu_dot], [wrench])


def _wrench(
    state: np.ndarray, thrust: np.ndarray, sample_time: float, vehicle: VehicleParams
) -> np.ndarray:
    """The known body wrench over each sample (N, WRENCH.size): the thrusters' ``T F`` and the
    :func:`remainder` at the mean of the sample's two ends (the accelerations from the
    Savitzky-Golay filter, as the equation error's)."""
    nu = state[:, _NU]
    unused = np.zeros((len(thrust), PLANAR_FORCE.size))  # smoothed reads the velocities alone
    nu_dot = smoothed(VelocityLog("six", sample_time, nu, None, unused))[1]
    angles = state[:, [SIX_DOF.index(name) for name in TILT.names]]
    function = remainder(vehicle).map(len(nu))
    rest = np.asarray(function(nu.T, angles.T, nu_dot.T)).T
    return thrust @ np.asarray(vehicle.six_dof.T).T + 0.5 * (rest[:-1] + rest[1:])


def horizontal_log(
    name: str, sample_time: float, state: np.ndarray, thrust: np.ndarray, vehicle: VehicleParams
) -> VelocityLog:
    """The 3-DOF model's log of 6-DOF samples ``state`` (N+1, SIX_DOF.size; in SIX_DOF order,
    what was measured) and every six_dof thruster's ``thrust`` (N, n): ``u, v, r``, the
    heading, and the body force ``[X, Y, N]`` of :func:`_wrench`."""
    force = _wrench(state, thrust, sample_time, vehicle)[:, _PLANAR_ROWS]
    velocity = state[:, [SIX_DOF.index(n) for n in HORIZONTAL_VELOCITY.names]]
    heading = np.unwrap(state[:, SIX_DOF.index("psi")])
    return VelocityLog(name, sample_time, velocity, None, force, heading=heading)


def heave_log(
    name: str, sample_time: float, state: np.ndarray, thrust: np.ndarray, vehicle: VehicleParams
) -> VelocityLog:
    """The heave model's log (z up) of the same: the body heave velocity ``-w`` and the
    upward force ``-Z`` of :func:`_wrench` (module docstring: why not the depth)."""
    force = -_wrench(state, thrust, sample_time, vehicle)[:, [_HEAVE_ROW]]
    w_up = -state[:, [SIX_DOF.index("w")]]
    return VelocityLog(name, sample_time, w_up, None, force, outputs=RATE_ONLY)


def model_of(which: str, vehicle: VehicleParams, first: bool = True, last: bool = True) -> GreyBox:
    """The grey box of ``which`` (:data:`MODELS`) fitted to a 6-DOF log; ``first``: its first
    round, whose vehicle is the start file (the log's sampling is checked against it);
    ``last``: its last round, the one reported (the halves are checked in it alone)."""
    if which == "horizontal":
        return HorizontalGreyBox(vehicle)
    if which == "heave":
        return HeaveGreyBox(vehicle, RATE_ONLY)
    greybox = RollPitchGreyBox(vehicle, period_check=first)
    greybox.split_check = last
    return greybox


# How each model's log is made of the 6-DOF samples.
LOG_OF = {"horizontal": horizontal_log, "heave": heave_log, "roll-pitch": roll_pitch_log}


def parameter_values(vehicle: VehicleParams) -> dict[str, float]:
    """Every model's parameters at ``vehicle``'s values, by identification.json's names."""
    values = {}
    for which in MODELS:
        greybox = model_of(which, vehicle)
        values |= dict(zip(greybox.parameters, greybox.start(), strict=True))
    return values


def offset_vehicle(vehicle: VehicleParams, fraction: float) -> VehicleParams:
    """``vehicle`` with every model's parameter ``fraction`` off, alternately up and down, in
    the 3-DOF fields, the heave section and the six_dof section alike: a wrong start file."""
    values = parameter_values(vehicle)
    signs = np.where(np.arange(len(values)) % 2 == 0, 1.0, -1.0)
    wrong = {name: value * (1 + fraction * sign)
             for (name, value), sign in zip(values.items(), signs, strict=True)}  # fmt: skip
    return load_vehicle(put_identified(vehicle.model_dump(mode="json"), wrong, six_dof=True))


def _checked(vehicle: VehicleParams) -> VehicleParams:
    for section in ("six_dof", "heave"):
        if getattr(vehicle, section) is None:
            raise ConfigError(
                "--vehicle", vehicle.name, f"has no {section} section: a 6-DOF log's "
                "identification starts from one (docs/identification.md)",
            )  # fmt: skip
    return vehicle


def identify_six_dof(
    samples: list[tuple[str, float, np.ndarray, np.ndarray]],
    vehicle: VehicleParams,
    holdout: float = 0.2,
    fixed: tuple[str, ...] = (),
) -> Identification:
    """The 3-DOF, heave and roll and pitch models of ``vehicle`` (the start) from 6-DOF logs
    ``samples`` (name, sample time, state (N+1, SIX_DOF.size), thrust (N, n)), in turn (module
    docstring); the ``fixed`` parameters (any model's) held at their start values. One
    :class:`Identification` of all three, in that order."""
    start = _checked(vehicle)
    known = {name for which in MODELS for name in model_of(which, start).parameters}
    unknown = [name for name in fixed if name not in known]
    if unknown:
        raise ConfigError(
            "--fix", ",".join(unknown), f"not a parameter identify estimates: one of "
            f"{', '.join(sorted(known))}",
        )  # fmt: skip
    order = [*MODELS] * ROUNDS
    found: dict[str, Identification] = {}
    current = start
    for round_index, which in enumerate(order):
        last = round_index >= len(order) - len(MODELS)
        greybox = model_of(which, current, first=which not in found, last=last)
        logs = [
            LOG_OF[which](name, te, state, thrust, current) for name, te, state, thrust in samples
        ]
        held = tuple(name for name in fixed if name in greybox.parameters)
        result = identify(logs, current, holdout, greybox, held)
        if which in found:  # a later round: the start file's values and model as the first's
            first = found[which]
            starts = {p.name: p.start for p in first.parameters}
            traces = [
                trace | {"start": before["start"]}
                for trace, before in zip(result.traces, first.traces, strict=True)
            ]
            result = replace(
                result,
                parameters=[replace(p, start=starts[p.name]) for p in result.parameters],
                validation_rms_start=first.validation_rms_start,
                traces=traces,
            )
        found[which] = result
        values = {p.name: p.value for p in result.parameters if p.excited}
        current = load_vehicle(
            put_identified(current.model_dump(mode="json"), values, six_dof=True)
        )
    return merged([found[which] for which in MODELS])


def merged(parts: list[Identification]) -> Identification:
    """Several models' identifications from the same logs as one: their parameters, outputs
    and RMS side by side, the held-out traces joined by column."""
    first = parts[0]

    def joined(key: str) -> np.ndarray:
        return np.concatenate([getattr(part, key) for part in parts])

    traces = [
        {"t": trace["t"]} | {
            key: np.column_stack([part.traces[i][key] for part in parts])
            for key in ("measured", "identified", "start")
        }
        for i, trace in enumerate(first.traces)
    ]  # fmt: skip
    statuses = dict.fromkeys(part.solver_status for part in parts)
    return Identification(
        parameters=[p for part in parts for p in part.parameters],
        logs=first.logs,
        sample_time=first.sample_time,
        fit_samples=first.fit_samples,
        validation_samples=first.validation_samples,
        noise_std=joined("noise_std"),
        equation_error_used=all(part.equation_error_used for part in parts),
        validation_rms=joined("validation_rms"),
        validation_rms_start=joined("validation_rms_start"),
        iterations=sum(part.iterations for part in parts),
        solver_status=", ".join(statuses),
        substeps=max(part.substeps for part in parts),
        traces=traces,
        outputs=tuple(name for part in parts for name in part.outputs),
        units=tuple(unit for part in parts for unit in part.units),
        model=" + ".join(part.model for part in parts),
        extras=[p for part in parts for p in part.extras],
    )


def read_six_dof_samples(
    path: str | Path, vehicle: VehicleParams, options: LogOptions | None = None
):
    """(name, sample time, state (N+1, 12) in SIX_DOF order, thrust (N, n)) of a 6-DOF log:
    a ``kind: six-dof`` run folder (roll_pitch.py's reader), a ROS 2 bag or an ArduSub
    DataFlash log (their readers' ``six_dof`` functions), read by what ``path`` is."""
    n_thrusters = _checked(vehicle).six_dof.n_thrusters
    options = options or LogOptions()
    kind = log_kind(path)
    if kind is LogKind.ROSBAG:
        from auvmpc.identification.rosbag import read_six_dof_rosbag

        return read_six_dof_rosbag(path, n_thrusters, options)
    if kind is LogKind.DATAFLASH:
        from auvmpc.identification.dataflash import read_six_dof_dataflash

        return read_six_dof_dataflash(path, n_thrusters, options)
    state, thrust, sample_time = read_six_dof_state(path, n_thrusters)
    return str(path), sample_time, state, thrust
