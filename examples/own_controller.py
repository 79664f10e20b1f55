"""A controller of your own in one file: registered as ``controller.type: pid-tracker``, then
flown by auvmpc like a built-in one (docs/extending.md).

The controller is a PID tracker with the model's own dynamics fed forward: it asks for the
body-frame acceleration ``3 wn^2 e + 3 wn e' + wn^3 integral(e)`` (e the position and
heading error, e' the velocity error; the integral kept in the world frame, where a current
is constant), cancels the drag, Coriolis and Munk terms the vehicle model predicts,
allocates the force by the thrusters' pseudo-inverse and clips it into the hard force and
rate limits. Every scenario field, the loop, the metrics, the run folder and
the figures are auvmpc's.

    python examples/own_controller.py OUT_DIR
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from pydantic import Field

import auvmpc
from auvmpc.controllers.base import Controller, ControlResult, ControlStatus, project_to_limits
from auvmpc.controllers.config import HorizontalControllerConfig
from auvmpc.controllers.registry import register_controller
from auvmpc.models.vehicle import dynamics


class PidTrackerConfig(HorizontalControllerConfig):
    """Its knobs: those every controller has (type, sample_time, ...) and one of its own."""

    natural_frequency: float = Field(
        default=0.5,  # well inside the Nyquist rate of a 0.5 s sample
        gt=0,
        description="every axis's closed loop has its three poles at -natural_frequency (rad/s)",
    )


class PidTracker(Controller):
    """A PID tracker with the vehicle model fed forward (module docstring)."""

    def __init__(self, model, config) -> None:
        self.model = model
        self.sample_time = config.sample_time  # filled in for the vehicle by auvmpc
        self.natural_frequency = config.natural_frequency  # its own knob
        self.preview_steps = 0  # it looks at the reference now only
        self._inertia = np.array([model.m11, model.m22, model.Iz])

    def reset(self, initial_state: np.ndarray, initial_thrust: np.ndarray) -> None:
        self._previous = np.asarray(initial_thrust, dtype=float).copy()
        self._integral = np.zeros(3)  # world x, y (m s) and heading (rad s)

    def compute(self, observation) -> ControlResult:
        state = np.asarray(observation.state, dtype=float)
        x, y, psi, u, v, r = state
        x_r, y_r, psi_r, u_r, v_r, r_r = observation.reference[0]
        c, s = math.cos(psi), math.sin(psi)
        heading_error = math.remainder(psi_r - psi, 2.0 * math.pi)
        error = np.array([c * (x_r - x) + s * (y_r - y), -s * (x_r - x) + c * (y_r - y),
                          heading_error])  # fmt: skip
        # The reference velocity seen in the vehicle's body frame.
        turn = psi_r - psi
        velocity_error = np.array(
            [u_r * math.cos(turn) - v_r * math.sin(turn) - u,
             u_r * math.sin(turn) + v_r * math.cos(turn) - v, r_r - r]
        )  # fmt: skip
        self._integral += self.sample_time * np.array([x_r - x, y_r - y, heading_error])
        ix, iy, iheading = self._integral
        integral = np.array([c * ix + s * iy, -s * ix + c * iy, iheading])
        wn = self.natural_frequency
        wanted = 3 * wn**2 * error + 3 * wn * velocity_error + wn**3 * integral
        # What the vehicle does with no thrust (drag, Coriolis, Munk), to be cancelled.
        unforced = np.asarray(dynamics(state, np.zeros(self.model.n_thrusters), self.model))[3:]
        force = self._inertia * (wanted - unforced)
        thrust, moved = project_to_limits(
            self.model.T_pinv @ force, self._previous, self.model, self.sample_time
        )
        self._previous = thrust
        status = ControlStatus.SATURATED if moved else ControlStatus.OK
        return ControlResult(thrust=thrust, status=status)


register_controller("pid-tracker", PidTracker, config=PidTrackerConfig)


def main(out: Path) -> None:
    scenario = auvmpc.load_scenario("paper-ideal", ["controller.type=pid-tracker"])
    run = auvmpc.simulate(scenario)
    auvmpc.save_run(run, out / "pid-tracker-run", figures=False)
    metrics = run.metrics
    print(
        f"pid-tracker on paper-ideal: RMS position error {metrics['rms_position_error_m']:.3f} m, "
        f"{metrics['thrust_limit_violations']} force and {metrics['thrust_rate_violations']} "
        f"rate limit violations"
    )


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "."))
