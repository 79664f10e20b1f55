"""The 3-DOF model in the paper's state-dependent-coefficient (SDC) form, and the exact RK4
step of a linear model (paper-model.md sections 3-4; the frozen-SDC MPC ``mpc`` predicts
with them).

    x' = A_c(x) x + B_c F + G_c d_b,   state [x, y, psi, u, v, r] (models/vehicle.py)

with A_c(x) x = f(x, 0) exactly (one factorisation among many), B_c = [0; M^-1 T] and
G_c = [0; M^-1] for a body-frame force d_b = [d_u, d_v, d_r].
"""

from __future__ import annotations

import math

import numpy as np

from auvmpc.models.layout import HORIZONTAL, PLANAR_FORCE
from auvmpc.models.vehicle import VehicleParams

__all__ = ["disturbance_matrix", "input_matrix", "rk4_discretize", "sdc_matrix"]

NX = HORIZONTAL.size


def sdc_matrix(state: np.ndarray, params: VehicleParams) -> np.ndarray:
    """A_c(x) with A_c(x) x = f(x, 0): the paper's state-dependent-coefficient form.

    Rows 1-2 hold the rotation, row 3 psi' = r, rows 4-6 the damping and Coriolis
    terms with the coupling velocities frozen (one factorisation among many; this
    one makes A_c(x) x exact).
    """
    _, _, psi, u, v, r = state
    p = params
    A = np.zeros((NX, NX))
    A[0, 3], A[0, 4] = math.cos(psi), -math.sin(psi)
    A[1, 3], A[1, 4] = math.sin(psi), math.cos(psi)
    A[2, 5] = 1.0
    A[3, 3] = (p.Xu + p.Xuu * abs(u)) / p.m11
    A[3, 4] = p.m22 * r / p.m11
    A[4, 3] = -p.m11 * r / p.m22
    A[4, 4] = (p.Yv + p.Yvv * abs(v)) / p.m22
    A[5, 3] = (p.m11 - p.m22) * v / p.Iz
    A[5, 5] = (p.Nr + p.Nrr * abs(r)) / p.Iz
    return A


def input_matrix(params: VehicleParams) -> np.ndarray:
    """B_c (6, n): thrust enters the velocity rows through M^-1 T."""
    B = np.zeros((NX, params.n_thrusters))
    B[3:] = np.diag([1.0 / params.m11, 1.0 / params.m22, 1.0 / params.Iz]) @ params.T
    return B


def disturbance_matrix(params: VehicleParams) -> np.ndarray:
    """G_c (6, 3): a body-frame force [d_u, d_v, d_r] enters the velocity rows through M^-1."""
    G = np.zeros((NX, PLANAR_FORCE.size))
    G[3:] = np.diag([1.0 / params.m11, 1.0 / params.m22, 1.0 / params.Iz])
    return G


def rk4_discretize(A: np.ndarray, B: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact result of one RK4 step on x' = A x + B u with u held (Ad, Bd).

    RK4 applied to a linear system equals the 4th-order Taylor polynomial of the
    matrix exponential: Ad = sum_{k<=4} (A dt)^k / k!, Bd = sum_{k<=3} A^k dt^(k+1)/(k+1)! B.
    """
    identity = np.eye(A.shape[0])
    Ah = A * dt
    Ah2 = Ah @ Ah
    Ah3 = Ah2 @ Ah
    Ad = identity + Ah + Ah2 / 2.0 + Ah3 / 6.0 + Ah3 @ Ah / 24.0
    Bd = dt * (identity + Ah / 2.0 + Ah2 / 6.0 + Ah3 / 24.0) @ B
    return Ad, Bd
