"""Grey-box identification of the heave model (the depth model auvmpc controls with).

The model is :mod:`auvmpc.models.heave`'s (docs/depth.md), z up::

    m_heave w' = Zw w + Zww |w| w + sum(F_z) + net_buoyancy_N,    z' = w

with the vertical thrusts ``F_z`` logged. The unknowns are :data:`PARAMETERS`, named as
the vehicle file's ``heave`` section holds them. :class:`HeaveGreyBox` states the model for
:func:`~auvmpc.identification.estimation.identify`, which fits it by the same steps as the
3-DOF model (equation error, output error, Fisher intervals, excitation, validation).

What a log gives (:func:`read_heave_log`, a run folder's log.csv):

- the depth alone (a pressure sensor): the state ``[z, w]`` is fitted to the measured z;
  the equation-error start takes w and w' as the first and second Savitzky-Golay
  derivatives of z;
- the depth and the heave rate (a DVL's w, or an estimator's): both are fitted;
- the heave rate alone (``RATE_ONLY``: a 6-DOF log's body heave velocity, whose depth also
  moves with the tilt, identification/six_dof_log.py): the state is ``[w]``, its equation
  the heave model's second row (the depth has no part in it).

A depth run's log.csv (``kind: depth``) holds the simulator's true ``z, w`` and the pressure
sensor's ``z_measured``: identification reads ``z_measured`` alone, what the vehicle
measured. A log.csv without ``z_measured`` (a log of your own in the run-folder format) is
taken as measured: its ``z`` and, if present, its ``w``.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import casadi as ca
import numpy as np
from scipy.signal import savgol_filter

from auvmpc.errors import ConfigError
from auvmpc.identification.estimation import (
    FILTER_ORDER,
    GreyBox,
    filter_window,
    smoothed,
)
from auvmpc.identification.logs import VelocityLog, log_from_table, run_table
from auvmpc.models.heave import heave_dynamics
from auvmpc.models.layout import DEPTH
from auvmpc.models.vehicle import VehicleParams

__all__ = ["PARAMETERS", "HeaveGreyBox", "is_heave_log", "read_heave_log"]

SECTION = "heave"
# The unknowns: the vehicle file's heave fields (HEAVE_MODEL_FIELDS but the thrust rate).
FIELDS = ("m_heave", "Zw", "Zww", "net_buoyancy_N")
PARAMETERS = tuple(f"{SECTION}.{name}" for name in FIELDS)
# The thrust columns of a depth log (sim/log.py, DEPTH_LOG's input prefix).
THRUST_PREFIX = "Fz"
# What the log's columns are called, by the outputs they give.
DEPTH_ONLY = ("z",)
DEPTH_AND_RATE = ("z", "w")
RATE_ONLY = ("w",)


class HeaveGreyBox(GreyBox):
    """The heave model (module docstring) of ``vehicle``'s heave section, fitted to the
    logged ``outputs``: the depth z alone, z and the heave rate w, or w alone (then the state
    is [w])."""

    parameters = PARAMETERS
    lower = np.array([1e-9, -np.inf, -np.inf, -np.inf])  # a mass > 0, damping <= 0
    upper = np.array([np.inf, 0.0, 0.0, np.inf])  # the net buoyancy either way
    title = "grey-box heave model"

    def __init__(self, vehicle: VehicleParams, outputs: tuple[str, ...] = DEPTH_ONLY) -> None:
        if vehicle.heave is None:
            raise ConfigError(
                "--vehicle", vehicle.name, "has no heave section: heave identification starts "
                "from one (the vertical thrusters, a first guess of each parameter)",
            )  # fmt: skip
        if outputs not in (DEPTH_ONLY, DEPTH_AND_RATE, RATE_ONLY):
            raise ValueError(
                f"outputs must be {DEPTH_ONLY}, {DEPTH_AND_RATE} or {RATE_ONLY}, got {outputs}"
            )
        self.vehicle, self.heave = vehicle, vehicle.heave
        self.outputs = outputs
        self.units = tuple({"z": "m", "w": "m/s"}[name] for name in outputs)
        self.states = RATE_ONLY if outputs == RATE_ONLY else DEPTH.names
        self.state_size = len(self.states)
        self.measured = tuple(self.states.index(name) for name in outputs)

    @property
    def thrusters(self) -> int:
        return self.heave.thruster_count

    def start(self) -> np.ndarray:
        return np.array([float(getattr(self.heave, name)) for name in FIELDS])

    def rhs(self) -> ca.Function:
        """[z', w'] (or [w']) by :func:`auvmpc.models.heave.heave_dynamics` itself, its
        parameters symbols: the model written once."""
        x, force = ca.SX.sym("x", self.state_size), ca.SX.sym("Fz")
        theta = ca.SX.sym("theta", len(FIELDS))
        coefficients = SimpleNamespace(**dict(zip(FIELDS, ca.vertsplit(theta), strict=True)))
        state = x if self.state_size == DEPTH.size else ca.vertcat(0.0, x)
        derivative = heave_dynamics(state, force, coefficients)[DEPTH.size - self.state_size :]
        return ca.Function("heave_rhs", [x, force, theta], [derivative])

    def applied(self, log: VelocityLog) -> np.ndarray:
        """The vertical force of the commands (N, 1): the thrusts' sum (or the log's own)."""
        return log.force if log.force is not None else log.thrust.sum(axis=1, keepdims=True)

    def filtered(
        self, log: VelocityLog, theta: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """[z, w] and [w, w'] smoothed (N+1, 2) each: w and w' from the logged w, or the
        first and second derivatives of z where the log has the depth alone; [w] and [w']
        where it has the rate alone (the output map has no parameters: ``theta`` is not
        read)."""
        signals, rates = smoothed(log)
        if self.outputs == RATE_ONLY:
            return signals, rates
        if self.outputs == DEPTH_AND_RATE:
            w = DEPTH_AND_RATE.index("w")
            return signals, np.column_stack([signals[:, w], rates[:, w]])
        z = DEPTH_ONLY.index("z")
        w = rates[:, z]
        w_dot = savgol_filter(
            log.velocity[:, z], filter_window(log.sample_time), FILTER_ORDER, deriv=2,
            delta=log.sample_time,
        )  # fmt: skip
        return np.column_stack([signals[:, z], w]), np.column_stack([w, w_dot])

    def regression(self, x: np.ndarray, x_dot: np.ndarray, inputs: np.ndarray):
        """One block, heave: ``-m w' + Zw w + Zww |w| w + B = -F`` (A (1, N, 4), b (1, N))."""
        w_index = self.states.index("w")  # [z, w] or [w]
        w, w_dot = x[:, w_index], x_dot[:, w_index]
        A = np.column_stack([-w_dot, w, np.abs(w) * w, np.ones_like(w)])[None]
        return A, -inputs[:, 0][None]

    def scale_floor(self) -> np.ndarray:
        """1 % of the heave mass for the mass and the dampings, 1 % of the vertical thrust
        for the net buoyancy."""
        thrust = self.heave.thruster_count * max(np.abs(self.heave.thrust_limits))
        return 0.01 * np.array([self.heave.m_heave] * 3 + [thrust])

    def damping_rate(self, logs: list[VelocityLog]) -> float:
        w_index = self.states.index("w")
        top = 2.0 * max(np.max(np.abs(self.filtered(log)[0][:, w_index])) for log in logs)
        return abs(self.heave.Zw + 2.0 * self.heave.Zww * top) / self.heave.m_heave


def read_heave_log(path: str | Path, n_vertical: int) -> VelocityLog:
    """The depth (and heave rate) and the vertical thrusts ``Fz1..Fzn`` of a run folder's
    log.csv (module docstring: which columns), checked as :func:`read_run_folder` checks a
    horizontal one."""
    where = Path(path)
    if where.is_file():
        raise ConfigError(
            "LOG", str(path), "heave identification reads auvmpc run folders (a depth run's "
            "log.csv); depth from ROS 2 bags and DataFlash logs is not read yet",
        )  # fmt: skip
    table, log_file = run_table(where)
    if "z_measured" in table.header:  # a simulated run: what the pressure sensor read
        signals, outputs = ("z_measured",), DEPTH_ONLY
    else:
        outputs = DEPTH_AND_RATE if "w" in table.header else DEPTH_ONLY
        signals = outputs
    return log_from_table(table, log_file, path, signals, THRUST_PREFIX, n_vertical, outputs)


# A log.csv header is one line of column names: far below this.
_HEADER_BYTES = 64 * 1024


def is_heave_log(path: str | Path) -> bool:
    """Whether ``path`` is a run folder whose log.csv has vertical thrusts (``Fz1``): a
    depth run's. Anything unreadable is not (its reader names what is wrong)."""
    try:
        with (Path(path) / "log.csv").open("rb") as handle:
            header = handle.readline(_HEADER_BYTES)
    except OSError:
        return False
    return f"{THRUST_PREFIX}1".encode() in [name.strip() for name in header.split(b",")]
