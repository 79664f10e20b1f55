"""Step auvmpc's controller from your own simulator: a session against a plant written here.

The plant is the paper vehicle's 3-DOF equations of motion (Fossen 2021, ch. 6; the
equations of docs/model.md) integrated by SciPy's ``solve_ivp``, not auvmpc's RK4: the same
shape of loop drives a hardware-in-the-loop rig or a live vehicle, where ``measure`` reads
the navigation solution and ``apply`` sends the thrusts. The session builds every
observation, runs the controller in its safety shell and writes the usual run folder.

    python examples/own_simulator.py OUT_DIR
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

import auvmpc
from auvmpc.sim.session import Truth


def equations_of_motion(vehicle):
    """dx/dt of [x, y, psi, u, v, r] under thrusts F (N), for the vehicle's coefficients."""
    T = vehicle.T  # thrust allocation: [f_u, f_v, M_r] = T F

    def f(_t, state, thrust):
        _, _, psi, u, v, r = state
        f_u, f_v, m_r = T @ thrust
        return [
            u * np.cos(psi) - v * np.sin(psi),
            u * np.sin(psi) + v * np.cos(psi),
            r,
            (vehicle.Xu * u + vehicle.Xuu * abs(u) * u + vehicle.m22 * v * r + f_u) / vehicle.m11,
            (vehicle.Yv * v + vehicle.Yvv * abs(v) * v - vehicle.m11 * u * r + f_v) / vehicle.m22,
            (vehicle.Nr * r + vehicle.Nrr * abs(r) * r + (vehicle.m11 - vehicle.m22) * u * v + m_r)
            / vehicle.Iz,
        ]

    return f


def main(out: Path) -> auvmpc.api.RunResult:
    scenario = auvmpc.load_scenario("paper-obstacles", {"duration": 40})
    session = auvmpc.session(scenario)
    print("states:", session.state_names, "inputs:", session.input_names)
    f = equations_of_motion(scenario.plant)  # the simulated vehicle of the scenario
    state = session.initial_state
    calm = np.zeros(len(session.environment_names))  # this simulator has no current or force
    steps = round(session.duration / session.sample_time)
    for k in range(steps):
        t = k * session.sample_time
        # The true state is known here (a simulator): hand it over for the log and metrics.
        result = session.step(t, state, truth=Truth(state, calm))
        held = solve_ivp(
            f, (t, t + session.sample_time), state, args=(result.u,), rtol=1e-9, atol=1e-9
        )
        state = held.y[:, -1]
    session.finish(steps * session.sample_time, state, truth=Truth(state, calm))
    run = session.close(out / "own-simulator-run", figures=False)
    rms = run.metrics["rms_position_error_m"]
    print(f"RMS position error {rms:.4f} m, fallbacks {run.metrics['fallback_steps']}")
    return run


if __name__ == "__main__":
    folder = Path(sys.argv[1] if len(sys.argv) > 1 else "own-simulator")
    folder.mkdir(parents=True, exist_ok=True)
    main(folder)
