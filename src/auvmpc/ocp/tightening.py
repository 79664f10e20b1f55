"""Constraint tightening for a bounded disturbance: robust back-offs along the plan.

A zero-order robust (zoRO-like) tightening (Zanelli, Frey, Messerer, Diehl 2021, "Zero-order
robust nonlinear model predictive control with ellipsoidal uncertainty sets"; here with the
exact support of a bounded set instead of an ellipsoid). The disturbance the prediction does
not know is, at every sample and in any sequence, inside

    W = {(X, Y, N): |(X, Y)| <= w_F, |N| <= w_M}      (world-frame force (N) and moment (N m))

With an ancillary feedback u_n = u_plan_n + K_n e_n on the deviation e_n of the true state from
the plan, the deviation follows the linearisation the plan was solved on:

    e_{n+1} = (A_n + B_n K_n) e_n + G_n w_n,    e_0 = 0,   w_n in W
    e_n = sum_{j<n} Phi(n, j+1) G_j w_j,
    Phi(n, j) = (A_{n-1} + B_{n-1} K_{n-1}) ... (A_j + B_j K_j)

and its largest component in a direction c (the support function of its reachable set) is

    max c . e_n = sum_{j<n} h_W(G_j' Phi(n, j+1)' c),    h_W(l) = w_F |(l_X, l_Y)| + w_M |l_N|

An obstacle half-plane ``a . p_n >= b`` becomes ``a . p_n >= b + max a . e_n``, and a thrust
limit ``lower_i <= u_n,i <= upper_i`` becomes ``lower_i + max K_n,i e_n <= u_n,i <= upper_i -
max K_n,i e_n``; so the plan keeps room for the feedback to hold the true vehicle on the safe
side of every constraint of the linearised problem. The back-offs are computed from the
Jacobians the step already has and enter the QP as changed bounds: its structure is the
nominal one. docs/tightening.md states the assumptions and what is not guaranteed.

K_n is the LQR gain of the vehicle's linearisation in straight motion at the plan's surge
speed at step n (a table over speeds, computed once), rotated to the plan's heading: the model
is the same at every heading (the world frame only rotates the position), so the gain rotated
is the gain of the rotated model. One gain at rest is not enough: moving, the heading steers
the position, and the gain at rest left the loop at 0.6 m/s with a spectral radius of 0.98
(0.60 with its own gain; jmse2210), which made the back-offs metres wide.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from auvmpc.models.layout import HORIZONTAL, PLANAR_FORCE, PLANAR_MOMENT

__all__ = [
    "Backoffs",
    "OBSTACLE_BACKOFF_LIMIT_M",
    "THRUST_BACKOFF_LIMIT",
    "Tightening",
    "error_responses",
    "rotated_gains",
    "tightened_box",
    "tube_gain",
]

# Bryson's rule for the ancillary feedback (largest acceptable deviation per state entry, on
# [x, y, psi, u, v, r], and the half thrust range per input): a gain that spends half the
# thrust range on a 0.25 m position error.
_TUBE_STATE_SCALE = HORIZONTAL.vector(
    {"x": 0.25, "y": 0.25, "psi": 0.2, "u": 0.25, "v": 0.25, "r": 0.2}
)
# Thrust back-offs are capped at this fraction of the half range, so the tightened box never
# closes and an avoidance manoeuvre keeps most of the thrust in its plan (a bound that would
# need more is reported by max_thrust_backoff_fraction reaching it). Measured: at 0.5, run 164
# of the first encounter-robust campaign (herded off the track by a crossing obstacle) planned
# its escape with half the thrust, needed obstacle slack and touched (-0.57 m); at 0.25 it
# keeps 0.37 m.
THRUST_BACKOFF_LIMIT = 0.25
# Obstacle back-offs are capped at this (m): a wider tube means the linearisation it is
# propagated on has diverged (the nominal step falls back there too), not a real deviation.
OBSTACLE_BACKOFF_LIMIT_M = 2.0
# Surge speeds of the gain table (m/s): this step, from the top reverse to the top forward speed.
GAIN_SPEED_STEP = 0.1
# Where a gain's position columns and the surge speed sit in the state, and the
# world force's components in the disturbance.
_X, _Y, _SURGE = (HORIZONTAL.index(name) for name in ("x", "y", "u"))
_FORCE_X, _FORCE_Y = (PLANAR_FORCE.index(name) for name in ("X", "Y"))


@dataclass(frozen=True)
class Backoffs:
    """What one sample's tightening took away: per soft row (m) and per step and input (N)."""

    rows: np.ndarray  # (r,) added to each soft row's lower bound
    thrust: np.ndarray  # (ny, nu) taken from both ends of each step's thrust box


def tube_gain(A: np.ndarray, B: np.ndarray, half_range: np.ndarray) -> np.ndarray:
    """K (nu, nx), u = K e: the discrete LQR gain of (A, B) with Bryson's weights
    (_TUBE_STATE_SCALE, the half thrust range ``half_range`` (nu,))."""
    Q = np.diag(1.0 / _TUBE_STATE_SCALE**2)
    R = np.diag(1.0 / np.asarray(half_range, dtype=float) ** 2)
    P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    return -np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)


def rotated_gains(gains: np.ndarray, headings: np.ndarray) -> np.ndarray:
    """(n, nu, nx): ``gains`` (n, nu, nx) of the model at heading 0 acting on errors at each
    heading: K(psi) e = K [R(psi)' e_p; e_psi; e_nu], the position error seen in the body frame.
    """
    cos, sin = np.cos(headings)[:, None], np.sin(headings)[:, None]
    rotated = gains.copy()
    kx, ky = gains[:, :, _X], gains[:, :, _Y]
    rotated[:, :, _X] = cos * kx - sin * ky
    rotated[:, :, _Y] = sin * kx + cos * ky
    return rotated


def error_responses(A: np.ndarray, B: np.ndarray, G: np.ndarray, K: np.ndarray) -> np.ndarray:
    """M (ny + 1, nx, ny, nw): M[n, :, j] = Phi(n, j + 1) G_j, the deviation at step n caused
    by the disturbance over sample j (zero for j >= n). A (ny, nx, nx), B (ny, nx, nu),
    G (ny, nx, nw), K (ny, nu, nx)."""
    ny, nx, nw = G.shape
    closed = A + np.matmul(B, K)
    # Step n's responses side by side, (nx, ny nw): one product per step advances them all.
    M = np.zeros((ny + 1, nx, ny * nw))
    for n in range(ny):  # the columns j >= n of M[n] are zero, and stay so in the product
        np.matmul(closed[n], M[n], out=M[n + 1])
        M[n + 1, :, n * nw : (n + 1) * nw] = G[n]
    return M.reshape(ny + 1, nx, ny, nw)


class Tightening:
    """The back-offs of one controller's constraints for a disturbance set W (module doc).

    ``force`` w_F (N), ``moment`` w_M (N m); ``gains`` (s, nu, nx) the ancillary K at heading
    0 for each surge speed of ``speeds`` (s,) (m/s, increasing; one speed: one gain for all),
    ``half_range`` (nu,) half of each input's force range (N).
    """

    def __init__(
        self,
        force: float,
        moment: float,
        speeds: np.ndarray,
        gains: np.ndarray,
        half_range: np.ndarray,
    ) -> None:
        self.force = float(force)
        self.moment = float(moment)
        self.speeds = np.asarray(speeds, dtype=float)
        self.gains = np.asarray(gains, dtype=float)
        self.half_range = np.asarray(half_range, dtype=float)

    def feedback(self, nominal: np.ndarray) -> np.ndarray:
        """K_n (n, nu, nx) along nominal states (n, nx) (HORIZONTAL): the gain of the
        nearest tabled surge speed, rotated to the heading."""
        nearest = np.abs(nominal[:, _SURGE, None] - self.speeds[None, :]).argmin(axis=1)
        return rotated_gains(self.gains[nearest], nominal[:, HORIZONTAL.heading])

    def support(self, directions: np.ndarray) -> np.ndarray:
        """h_W of the last axis (X, Y, N) of ``directions``, summed over the axis before it."""
        force = np.hypot(directions[..., _FORCE_X], directions[..., _FORCE_Y])
        moment = np.abs(directions[..., PLANAR_MOMENT])
        return (self.force * force + self.moment * moment).sum(axis=-1)

    def backoffs(
        self,
        A: np.ndarray,
        B: np.ndarray,
        G: np.ndarray,
        nominal: np.ndarray,
        row_steps: np.ndarray,
        row_coefficients: np.ndarray,
    ) -> Backoffs:
        """Back-offs along one linearisation: A (ny, nx, nx), B (ny, nx, nu), G (ny, nx, nd)
        (the world force and moment, nd = PLANAR_FORCE.size), the plan's states at steps
        0..ny-1 (ny, nx), and the soft rows ``row_coefficients[r] . x_{row_steps[r]} >= b_r``
        (steps in 1..ny)."""
        K = self.feedback(nominal)
        M = error_responses(A, B, G, K)  # (ny + 1, nx, ny, nd)
        # Soft rows: sum_j h_W(G_j' Phi' a) = sum_j h_W(a' M[n, :, j]).
        rows = self.support(np.einsum("rk,rkjw->rjw", row_coefficients, M[row_steps]))
        # fmin: a NaN (an overflow on a diverged linearisation) becomes the cap, too.
        rows = np.fmin(rows, OBSTACLE_BACKOFF_LIMIT_M)
        # Thrust at step n (n = 1..ny-1; u_0 is applied before any deviation): K_n e_n.
        ny, nx = len(nominal), A.shape[1]
        thrust = np.zeros((ny, len(self.half_range)))
        responses = M[1:-1].reshape(ny - 1, nx, -1)
        feedback = np.matmul(K[1:], responses).reshape(ny - 1, -1, ny, M.shape[-1])
        thrust[1:] = self.support(feedback)
        thrust = np.fmin(thrust, THRUST_BACKOFF_LIMIT * self.half_range)
        return Backoffs(rows=rows, thrust=thrust)


def tightened_box(
    lower: np.ndarray,
    upper: np.ndarray,
    backoff: np.ndarray,
    move_steps: np.ndarray,
    previous: np.ndarray,
    max_move: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-step force limits (ny, nu) with ``backoff`` (ny, nu) taken from both ends.

    A held input must keep the room of every step it is held over, so each move step gets
    the largest back-off until the next move. The tightened box is widened back to what the
    rate limit can reach from ``previous`` by then (a command at a limit can only leave it at
    ``max_move`` per sample): the QP stays feasible, and the tightening is soft at the start.
    """
    ny = len(backoff)
    held = np.maximum.reduceat(backoff, move_steps, axis=0)  # (nc, nu)
    per_step = np.zeros_like(backoff)
    per_step[move_steps] = held
    reach = (np.arange(ny) + 1)[:, None] * max_move
    tight_lower = np.minimum(lower + per_step, previous + reach)
    tight_upper = np.maximum(upper - per_step, previous - reach)
    return tight_lower, tight_upper
