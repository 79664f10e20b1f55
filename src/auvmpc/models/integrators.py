"""Fixed-step Runge-Kutta integration, on NumPy arrays and CasADi symbols alike."""

from __future__ import annotations

from collections.abc import Callable

__all__ = ["rk4", "rk4_step", "rk4_step_time_varying"]


def rk4_step(f: Callable, x, u, dt: float):
    """One classical 4th-order Runge-Kutta step of x' = f(x, u), u held constant.

    Works for any types that support ``+`` and scalar ``*`` (NumPy arrays,
    CasADi SX/MX), so the plant and the controllers' prediction models share it.
    """
    k1 = f(x, u)
    k2 = f(x + (0.5 * dt) * k1, u)
    k3 = f(x + (0.5 * dt) * k2, u)
    k4 = f(x + dt * k3, u)
    return x + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def rk4(f: Callable, x, u, dt: float, substeps: int = 1):
    """Integrate over ``dt`` with ``substeps`` equal RK4 steps, u held constant."""
    if substeps < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    h = dt / substeps
    for _ in range(substeps):
        x = rk4_step(f, x, u, h)
    return x


def rk4_step_time_varying(f: Callable, t: float, x, h: float):
    """One RK4 step of the non-autonomous x' = f(t, x) (the plant under time-varying forces)."""
    k1 = f(t, x)
    k2 = f(t + 0.5 * h, x + (0.5 * h) * k1)
    k3 = f(t + 0.5 * h, x + (0.5 * h) * k2)
    k4 = f(t + h, x + h * k3)
    return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
