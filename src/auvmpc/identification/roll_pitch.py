"""Grey-box identification of what the 6-DOF model adds to the 3-DOF and heave models: roll
and pitch.

The roll and pitch rows of the 6-DOF equations (:mod:`auvmpc.models.six_dof`; Fossen 2021,
eqs. 2.40, 4.6, 6.45), diagonal in roll and pitch, NED body axes::

    phi'   = p + sin(phi) tan(theta) q + cos(phi) tan(theta) r        (T(phi, theta))
    theta' = cos(phi) q - sin(phi) r
    (Ix - K_pdot) p' = K_p p + K_pp |p| p - g_K(phi, theta) + K
    (Iy - M_qdot) q' = M_q q + M_qq |q| q - g_M(phi, theta) + M

with the restoring moments ``g_K``, ``g_M`` of :func:`auvmpc.models.six_dof.restoring_forces`
(W = m g, B = rho g V). The unknowns (:data:`PARAMETERS`) are the roll and pitch added
inertias ``K_pdot``, ``M_qdot`` (only the sums with the rigid-body Ix, Iy are observable, as
Iz_added in the 3-DOF model: Ix, Iy are kept from the start file), the dampings ``K_p``,
``K_pp``, ``M_q``, ``M_qq`` and the **righting moment** ``z_g W - z_b B`` (N m: the restoring
moment per radian of small tilt, the centre of buoyancy's height above the centre of
gravity times the weight when W = B), which the vehicle file holds as the centre of
buoyancy's z (x_g, y_g, x_b, y_b kept from the start file).

``K`` and ``M`` are the moments the model does not estimate, known from the log (the
model's input, held over each sample): the thrusters' (``T F``, rows
K and M) and the 6-DOF model's coupling terms, ``-[C_RB(nu) nu + C_A(nu) nu]`` and the
off-diagonal mass terms ``-M_(K,M),j nu_j'``, from the logged (smoothed) velocities and the
vehicle's translational and yaw values (:func:`coupling_moments`; the Munk moment
``(Z_wdot - X_udot) u w`` in pitch the largest of them). Assumed: no current (the log's
velocities are through the water) and those translational values right: identify the
3-DOF and heave models first (``auvmpc identify --dof six-dof`` does, on the same log).
The logged ``u, v, w, r`` enter the coupling as measured at each sample's two ends and go
linearly in between (:attr:`RollPitchGreyBox.linear_inputs`): held at their mean, they
left a model error that biased K_pdot, M_qdot and the righting moment by 1 to 3 % while the
vehicle turned at 2.5 rad/s, outside their intervals (docs/identification.md).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from auvmpc.errors import ConfigError
from auvmpc.identification.estimation import GreyBox, smoothed
from auvmpc.identification.logs import VelocityLog, log_from_table, run_table
from auvmpc.models.actuators import WRENCH
from auvmpc.models.layout import PLANAR_FORCE, WORLD_VECTOR, Layout
from auvmpc.models.six_dof import (
    ANGULAR_VELOCITY,
    BODY_VELOCITY,
    NX,
    SIX_DOF,
    TILT,
    Tzyx,
    coriolis_added_mass,
    coriolis_rigid_body,
    restoring_forces,
    six_dof_model,
)
from auvmpc.models.six_dof_params import SixDofParams
from auvmpc.models.vehicle import VehicleParams, load_vehicle

__all__ = [
    "OUTPUTS",
    "is_six_dof_log",
    "PARAMETERS",
    "SIX_DOF_FIELDS",
    "RollPitchGreyBox",
    "put_identified",
    "six_dof_fields",
]

SECTION = "six_dof"
# The unknowns, by the names identification.json and --fix use.
NAMES = ("K_pdot", "M_qdot", "K_p", "K_pp", "M_q", "M_qq", "righting_moment_Nm")
PARAMETERS = tuple(f"{SECTION}.{name}" for name in NAMES)
# The model's state [phi, theta, p, q], all of which the log measures (an AHRS's attitude
# and rates).
STATE = Layout(names=("phi", "theta", "p", "q"))
OUTPUTS = STATE.names
# The roll and pitch entries of the 6-DOF vectors: the wrench's K, M rows, which are nu's
# p, q (nu = [u, v, w, p, q, r] in the wrench's order).
_ROLL, _PITCH = WRENCH.index("K"), WRENCH.index("M")
# The vehicle file's field and index of each parameter (the righting moment: see
# six_dof_fields).
FIELD_OF = {
    "K_pdot": ("added_mass", _ROLL),
    "M_qdot": ("added_mass", _PITCH),
    "K_p": ("linear_damping", _ROLL),
    "K_pp": ("quadratic_damping", _ROLL),
    "M_q": ("linear_damping", _PITCH),
    "M_qq": ("quadratic_damping", _PITCH),
}
# The roll and pitch added inertias, which the coupling moments are linear in.
_ADDED_INERTIAS = ("K_pdot", "M_qdot")


def _section(vehicle: VehicleParams) -> SixDofParams:
    if vehicle.six_dof is None:
        raise ConfigError(
            "--vehicle", vehicle.name, "has no six_dof section: 6-DOF identification starts "
            "from one (the thruster poses, the inertia, a first guess of each parameter)",
        )  # fmt: skip
    if np.ndim(vehicle.six_dof.added_mass) != 1:
        raise ConfigError(
            "--vehicle", vehicle.name, "its six_dof added_mass is a 6x6 matrix: roll and "
            "pitch identification estimates the diagonal form [X_udot, ..., N_rdot]",
        )  # fmt: skip
    return vehicle.six_dof


def righting_moment(vehicle: VehicleParams) -> float:
    """z_g W - z_b B (N m) of the vehicle's six_dof section."""
    six = _section(vehicle)
    return six.center_of_gravity[2] * six.weight(vehicle.mass) - six.center_of_buoyancy[2] * (
        six.buoyancy
    )


# The 3-DOF and heave parameters' entries in the six_dof section (six_dof_params'
# horizontal_equivalent read backwards: m11 = m - X_udot, Iz_added = -N_rdot, m_heave =
# m - Z_wdot), each as (field, index, value -> entry given the rigid-body mass).
_TRANSLATIONAL = {
    "m11": ("added_mass", WRENCH.index("X"), lambda value, mass: mass - value),
    "m22": ("added_mass", WRENCH.index("Y"), lambda value, mass: mass - value),
    "heave.m_heave": ("added_mass", WRENCH.index("Z"), lambda value, mass: mass - value),
    "Iz_added": ("added_mass", WRENCH.index("N"), lambda value, mass: -value),
    "Xu": ("linear_damping", WRENCH.index("X"), None),
    "Xuu": ("quadratic_damping", WRENCH.index("X"), None),
    "Yv": ("linear_damping", WRENCH.index("Y"), None),
    "Yvv": ("quadratic_damping", WRENCH.index("Y"), None),
    "heave.Zw": ("linear_damping", WRENCH.index("Z"), None),
    "heave.Zww": ("quadratic_damping", WRENCH.index("Z"), None),
    "Nr": ("linear_damping", WRENCH.index("N"), None),
    "Nrr": ("quadratic_damping", WRENCH.index("N"), None),
}
NET_BUOYANCY = "heave.net_buoyancy_N"
# What six_dof_fields may write: four lists, then a number.
SIX_DOF_FIELDS = (
    "added_mass",
    "linear_damping",
    "quadratic_damping",
    "center_of_buoyancy",
    "displaced_volume",
)


def six_dof_fields(vehicle: VehicleParams, values: dict[str, float]) -> dict[str, object]:
    """The six_dof section's fields (added_mass, linear_damping, quadratic_damping,
    center_of_buoyancy, displaced_volume) of ``vehicle`` with the identified ``values`` (by
    identification.json's names) put in: roll and pitch's (:data:`PARAMETERS`) and, for a
    6-DOF log's identification, the 3-DOF and heave model's entries (:data:`_TRANSLATIONAL`);
    the net buoyancy B - W as the displaced volume, the righting moment R as
    z_b = (z_g W - R) / B (with the new B; without an identified R, the start's R kept)."""
    six = _section(vehicle)
    fields: dict[str, object] = {
        name: list(getattr(six, name))
        for name in ("added_mass", "linear_damping", "quadratic_damping")
    }
    for name, value in values.items():
        short = name.removeprefix(f"{SECTION}.")
        if short in FIELD_OF:
            field, index = FIELD_OF[short]
            fields[field][index] = float(value)  # type: ignore[index]
        elif name in _TRANSLATIONAL:
            field, index, entry = _TRANSLATIONAL[name]
            value = value if entry is None else entry(value, vehicle.mass)
            fields[field][index] = float(value)  # type: ignore[index]
    weight, buoyancy = six.weight(vehicle.mass), six.buoyancy
    if NET_BUOYANCY in values:
        buoyancy = weight + values[NET_BUOYANCY]
        fields["displaced_volume"] = float(buoyancy / (six.water_density * six.gravity))
    righting = values.get(PARAMETERS[-1], righting_moment(vehicle))
    centre = list(six.center_of_buoyancy)
    centre[2] = float((six.center_of_gravity[2] * weight - righting) / buoyancy)
    if PARAMETERS[-1] in values or NET_BUOYANCY in values:
        fields["center_of_buoyancy"] = centre
    return fields


def put_identified(
    data: dict[str, Any], values: dict[str, float], six_dof: bool = False
) -> dict[str, Any]:
    """A vehicle file's mapping ``data`` with the identified ``values`` put in (a copy; the
    sections it changes copied too): a 3-DOF name (``m11``) as its field, a heave one
    (``heave.Zw``) in its section; with ``six_dof`` (a 6-DOF log's identification), or where
    roll and pitch are among them, every value also in the six_dof section
    (:func:`six_dof_fields`)."""
    data = dict(data)
    for name, value in values.items():
        if name not in PARAMETERS:
            _put(data, name, value)
    if six_dof or any(name in PARAMETERS for name in values):
        start = load_vehicle(data, "--vehicle")
        data[SECTION] = dict(data[SECTION]) | six_dof_fields(start, values)
    return data


def _put(data: dict[str, Any], name: str, value: float) -> None:
    """Set a vehicle file's field ``name`` (``m11``, or in a section: ``heave.Zw``) in
    ``data``, copying the sections it changes."""
    *sections, key = name.split(".")
    for section in sections:
        data[section] = dict(data[section])
        data = data[section]
    data[key] = float(value)


def _coupling_function(vehicle: VehicleParams) -> ca.Function:
    """(nu [u, v, w, p, q, r], a) -> the roll and pitch moments [K, M] of the Coriolis and
    centripetal terms ``-[C_RB(nu) nu + C_A(nu) nu]`` (module docstring) by the 6-DOF model's
    own C_RB and C_A, with the roll and pitch added inertias ``a`` = [K_pdot, M_qdot] symbols
    (C_A is linear in them) and the rest of M_A the vehicle's."""
    six = _section(vehicle)
    nu, derivatives = ca.SX.sym("nu", BODY_VELOCITY.size), ca.SX.sym("a", len(_ADDED_INERTIAS))
    r_g = np.array(six.center_of_gravity, dtype=float)
    added = ca.SX(ca.DM(six.added_mass_matrix))
    k_pdot, m_qdot = (derivatives[_ADDED_INERTIAS.index(name)] for name in _ADDED_INERTIAS)
    added[_ROLL, _ROLL], added[_PITCH, _PITCH] = -k_pdot, -m_qdot
    C_RB = coriolis_rigid_body(vehicle.mass, six.inertia_matrix, r_g, nu[ANGULAR_VELOCITY])
    C_A = coriolis_added_mass(added, nu)
    moments = -(ca.mtimes(C_RB, nu) + ca.mtimes(C_A, nu))
    return ca.Function("coupling", [nu, derivatives], [moments[_ROLL : _PITCH + 1]])


def _off_diagonal_moments(vehicle: VehicleParams, nu_dot: np.ndarray) -> np.ndarray:
    """``-M_(K,M),j nu_j'`` (N, 2) over j other than roll and pitch: the mass matrix's coupling
    (a centre of gravity off CO, a full added-mass matrix; zero for a diagonal one)."""
    mass = np.array(_section(vehicle).mass_matrix(vehicle.mass))
    rows = mass[_ROLL : _PITCH + 1].copy()
    rows[:, [_ROLL, _PITCH]] = 0.0
    return -nu_dot @ rows.T


# Fewer samples per natural period of roll or pitch cannot follow the oscillation.
SAMPLES_PER_PERIOD = 8

# The model's input: the known roll and pitch moments, then the logged u, v, w and r.
_INPUT_VELOCITIES = ("u", "v", "w", "r")
INPUT = Layout(names=("K", "M", *_INPUT_VELOCITIES))


def roll_pitch_log(
    name: str,
    sample_time: float,
    state: np.ndarray,
    thrust: np.ndarray,
    vehicle: VehicleParams,
) -> VelocityLog:
    """The log the roll and pitch model is fitted to, from 6-DOF samples ``state`` (N+1, NX)
    in :data:`~auvmpc.models.six_dof.SIX_DOF` order (what was measured: attitude and rates,
    velocities) and every ``six_dof`` thruster's force ``thrust`` (N, n) held over each
    sample: ``velocity`` holds [phi, theta, p, q]; ``force`` the model's input over each
    sample, [K, M] (the thrusters' moments and the mass matrix's coupling, held), the logged
    u, v, w, r at the sample's start and then at its end (the model goes linearly between
    them)."""
    six = _section(vehicle)
    if state.shape[1] != NX:
        raise ValueError(f"state must have {NX} columns, got {state.shape}")
    unused = np.zeros((len(thrust), PLANAR_FORCE.size))  # smoothed reads the velocities alone
    body = VelocityLog(name, sample_time, state[:, SIX_DOF.nu], None, unused)
    nu_dot = smoothed(body)[1]
    coupled = _off_diagonal_moments(vehicle, nu_dot)
    moments = thrust @ np.asarray(six.T)[_ROLL : _PITCH + 1].T + 0.5 * (coupled[:-1] + coupled[1:])
    velocities = state[:, [SIX_DOF.index(n) for n in _INPUT_VELOCITIES]]
    # Their rates just after the sample's start and just before its end (per sample: times
    # Te), by the 6-DOF model of ``vehicle`` under the sample's thrust: the thrust steps at
    # the sample's edges, so the velocities have a kink there that differences across it
    # would smooth away.
    rates = [sample_time * rate for rate in _velocity_rates(vehicle, state, thrust)]
    inputs = np.column_stack([moments, velocities[:-1], velocities[1:], *rates])
    measured = state[:, [SIX_DOF.index(n) for n in OUTPUTS]]
    return VelocityLog(name, sample_time, measured, None, inputs, outputs=OUTPUTS)


def _velocity_rates(
    vehicle: VehicleParams, state: np.ndarray, thrust: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The rates of u, v, w, r (N, 4) at each sample's start and end under its thrust, by
    the vehicle's 6-DOF model at the logged states (still water)."""
    derivative = six_dof_model(vehicle).derivative.map(len(thrust))
    columns = [SIX_DOF.index(n) for n in _INPUT_VELOCITIES]
    still = np.zeros((WORLD_VECTOR.size, len(thrust)))  # no water velocity, nor its rate
    at = [np.asarray(derivative(x.T, thrust.T, still, still)).T[:, columns]
          for x in (state[:-1], state[1:])]  # fmt: skip
    return at[0], at[1]


class RollPitchGreyBox(GreyBox):
    """The roll and pitch model (module docstring) of ``vehicle``'s six_dof section, fitted
    to the logged attitude and rates [phi, theta, p, q]."""

    parameters = PARAMETERS
    # added inertias and dampings <= 0, the righting moment > 0 (the section's validation:
    # the centre of buoyancy above the centre of gravity)
    lower = np.array([-np.inf] * 6 + [1e-9])
    upper = np.array([0.0] * 6 + [np.inf])
    outputs = OUTPUTS
    units = ("rad", "rad", "rad/s", "rad/s")
    measured = tuple(range(STATE.size))
    state_size = STATE.size
    title = "grey-box roll and pitch model"
    linear_inputs = len(_INPUT_VELOCITIES)  # u, v, w, r: linear over each sample
    split_check = True  # the logged inputs' noise is model error its intervals do not hold

    def __init__(self, vehicle: VehicleParams, period_check: bool = True) -> None:
        """``period_check``: refuse a log sampled too slowly for the start model's roll and
        pitch (:meth:`check`); off where a log was checked against an earlier start (a later
        round of identification/six_dof_log.py)."""
        self.period_check = period_check
        self.six = _section(vehicle)
        self.vehicle = vehicle
        inertia = self.six.inertia_matrix
        self.ix, self.iy = float(inertia[0, 0]), float(inertia[1, 1])
        self.weight, self.buoyancy = self.six.weight(vehicle.mass), self.six.buoyancy
        self.coupling = _coupling_function(vehicle)

    @property
    def thrusters(self) -> int:
        return self.six.n_thrusters

    def start(self) -> np.ndarray:
        added, linear, quadratic = (
            np.asarray(self.six.added_mass, dtype=float),
            self.six.linear_damping,
            self.six.quadratic_damping,
        )
        return np.array(
            [added[_ROLL], added[_PITCH], linear[_ROLL], quadratic[_ROLL], linear[_PITCH],
             quadratic[_PITCH], righting_moment(self.vehicle)]
        )  # fmt: skip

    def _restoring(self, righting, phi, theta):
        """g_K, g_M with the righting moment ``righting`` (z_b from it, the rest the start
        file's), by the 6-DOF model's own restoring_forces."""
        r_g = self.six.center_of_gravity
        x_b, y_b, _ = self.six.center_of_buoyancy
        z_b = (r_g[2] * self.weight - righting) / self.buoyancy
        g = restoring_forces(self.weight, self.buoyancy, r_g, (x_b, y_b, z_b), phi, theta)
        return g[_ROLL], g[_PITCH]

    def _known_restoring(self, phi: np.ndarray, pitch: np.ndarray) -> np.ndarray:
        """g_K, g_M (2, N) at zero righting moment (the x and y offsets' part)."""
        angles = ca.SX.sym("angles", TILT.size)
        g = ca.vertcat(*self._restoring(0.0, *(angles[TILT.index(n)] for n in TILT.names)))
        function = ca.Function("known_restoring", [angles], [g]).map(len(phi))
        return np.asarray(function(np.vstack([phi, pitch])))

    @staticmethod
    def _nu(state, inputs) -> list:
        """[u, v, w, p, q, r]: p, q of the state, the rest the logged input (CasADi columns,
        or NumPy arrays of samples, one row per entry)."""
        return [state[STATE.index(name)] if name in STATE.names
                else inputs[INPUT.index(name)] for name in BODY_VELOCITY.names]  # fmt: skip

    def rhs(self) -> ca.Function:
        x, inputs = ca.SX.sym("x", STATE.size), ca.SX.sym("input", INPUT.size)
        theta = ca.SX.sym("theta", len(PARAMETERS))
        k_pdot, m_qdot, k_p, k_pp, m_q, m_qq, righting = ca.vertsplit(theta)
        phi, pitch, p, q = ca.vertsplit(x)
        r = inputs[INPUT.index("r")]
        phi_dot, theta_dot, _ = ca.vertsplit(ca.mtimes(Tzyx(phi, pitch), ca.vertcat(p, q, r)))
        g_k, g_m = self._restoring(righting, phi, pitch)
        coupling = self.coupling(ca.vertcat(*self._nu(x, inputs)), ca.vertcat(k_pdot, m_qdot))
        roll_moment = inputs[INPUT.index("K")] + coupling[0]
        pitch_moment = inputs[INPUT.index("M")] + coupling[1]
        p_dot = (k_p * p + k_pp * ca.fabs(p) * p - g_k + roll_moment) / (self.ix - k_pdot)
        q_dot = (m_q * q + m_qq * ca.fabs(q) * q - g_m + pitch_moment) / (self.iy - m_qdot)
        derivative = ca.vertcat(phi_dot, theta_dot, p_dot, q_dot)
        return ca.Function("roll_pitch_rhs", [x, inputs, theta], [derivative])

    def applied(self, log: VelocityLog) -> np.ndarray:
        """[K, M, u, v, w, r] at each sample's start, then u, v, w, r at its end
        (:func:`roll_pitch_log`)."""
        return log.force

    def filtered(
        self, log: VelocityLog, theta: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        return smoothed(log)

    def regression(self, x: np.ndarray, x_dot: np.ndarray, inputs: np.ndarray):
        """Two blocks, roll and pitch: the equations of the module docstring with every term
        in a parameter on the left (the coupling's through C_A's linearity in K_pdot and
        M_qdot), the rest on the right: ``b = Ix p' - K - c0_K + g_K(R = 0)``, likewise in
        pitch with Iy, q', M."""
        phi, pitch, p, q = x.T
        p_dot, q_dot = x_dot[:, STATE.index("p")], x_dot[:, STATE.index("q")]
        zero = np.zeros_like(p)
        # The coupling moments c0 + K_pdot c1 + M_qdot c2 (C_A is linear in them), (2, N) each.
        nu = np.column_stack(self._nu(x.T, inputs.T)).T
        coupling = self.coupling.map(len(p))
        c0, c1, c2 = (np.asarray(coupling(nu, np.tile(a, (len(p), 1)).T))
                      for a in ([0.0, 0.0], [1.0, 0.0], [0.0, 1.0]))  # fmt: skip
        c1, c2 = c1 - c0, c2 - c0
        roll = [p_dot - c1[0], -c2[0], p, np.abs(p) * p, zero, zero,
                -np.cos(pitch) * np.sin(phi)]  # fmt: skip
        pitch_row = [-c1[1], q_dot - c2[1], zero, zero, q, np.abs(q) * q, -np.sin(pitch)]
        A = np.stack([np.column_stack(roll), np.column_stack(pitch_row)])
        # g at zero righting moment: the x and y offsets' part, known
        g_k, g_m = np.asarray(self._known_restoring(phi, pitch))
        b = np.stack(
            [self.ix * p_dot - inputs[:, INPUT.index("K")] - c0[0] + g_k,
             self.iy * q_dot - inputs[:, INPUT.index("M")] - c0[1] + g_m]
        )  # fmt: skip
        return A, b

    def scale_floor(self) -> np.ndarray:
        """1 % of the rigid-body inertia for the added inertias and the dampings, 1 % of the
        weight times 1 cm for the righting moment."""
        return np.array(
            [0.01 * self.ix, 0.01 * self.iy, 0.01 * self.ix, 0.01 * self.ix, 0.01 * self.iy,
             0.01 * self.iy, 1e-4 * self.weight]
        )  # fmt: skip

    def natural_period(self) -> float:
        """The start model's shorter small-angle period of roll and pitch (s)."""
        start = self.start()
        inertia = min(self.ix - start[0], self.iy - start[1])
        return 2.0 * math.pi / math.sqrt(max(start[6], 1e-12) / inertia)

    def check(self, logs: list[VelocityLog], fixed: tuple[str, ...]) -> None:
        """Also a log sampled too slowly to see the roll and pitch oscillation: more than
        SAMPLES_PER_PERIOD samples per natural period are needed (a 6-DOF run's default
        0.5 s on the BlueROV2 Heavy's 1.7 s roll period identified nothing true)."""
        super().check(logs, fixed)
        period = self.natural_period()
        for log in logs if self.period_check else ():
            if log.sample_time > period / SAMPLES_PER_PERIOD:
                raise ConfigError(
                    "LOG", log.name, f"sampled every {log.sample_time:g} s: roll and pitch "
                    f"oscillate with a period of {period:.3g} s (the start file's), need "
                    f"{SAMPLES_PER_PERIOD} samples in it (--sample-time at most "
                    f"{period / SAMPLES_PER_PERIOD:.3g} s)",
                )  # fmt: skip

    def damping_rate(self, logs: list[VelocityLog]) -> float:
        """The fastest of the start model's roll and pitch rates: damping at twice the logged
        rates, and the natural frequency of the righting moment."""
        start = self.start()
        rates = STATE.span("p", "q")
        top = 2.0 * np.max(np.vstack([np.abs(log.velocity[:, rates]) for log in logs]), axis=0)
        inertia = np.array([self.ix - start[0], self.iy - start[1]])
        damping = np.abs(start[[2, 4]] + 2.0 * start[[3, 5]] * top) / inertia
        natural = np.sqrt(max(start[6], 0.0) / inertia)
        return float(max(np.max(damping), np.max(natural)))


def read_six_dof_state(path: str | Path, n_thrusters: int) -> tuple[np.ndarray, np.ndarray, float]:
    """A 6-DOF run folder's log.csv (``kind: six-dof``): the state (N+1, NX) in SIX_DOF order
    and every ``six_dof`` thruster's force ``F1..Fn`` (N, n), and the sample time (s); checked
    as :func:`~auvmpc.identification.logs.read_run_folder` checks a horizontal log."""
    log = log_from_table(*run_table(path), path, SIX_DOF.names, "F", n_thrusters,
                         outputs=SIX_DOF.names)  # fmt: skip
    return log.velocity, log.thrust, log.sample_time


# A log.csv header is one line of column names: far below this.
_HEADER_BYTES = 64 * 1024


def is_six_dof_log(path: str | Path) -> bool:
    """Whether ``path`` is a run folder whose log.csv has the attitude and rates (``phi``,
    ``p``): a 6-DOF run's. Anything unreadable is not (its reader names what is wrong)."""
    try:
        with (Path(path) / "log.csv").open("rb") as handle:
            header = handle.readline(_HEADER_BYTES)
    except OSError:
        return False
    names = [name.strip() for name in header.split(b",")]
    return all(name.encode() in names for name in OUTPUTS)
