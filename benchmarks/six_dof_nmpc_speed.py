"""six-dof-nmpc interpreted and compiled (``controller.jit``) on the same closed loops: the
step time, the compile, and how far apart the two command sequences are.

    python benchmarks/six_dof_nmpc_speed.py [--steps 160] [--vehicles remus100 bluerov2-heavy]

Each vehicle flies a two-leg lawnmower at 10 m depth (REMUS 100: 1.5 m/s, legs 45 m apart,
0.3 m/s cross current; BlueROV2 Heavy: 0.3 m/s, 0.05 m/s) on the 6-DOF plant, the controller
at its defaults, once with ``jit=false`` and once with ``jit=true`` (the library built into an
empty cache folder, so the first build's time is printed). Prints a table; the machine's
CPU is named above it.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time

import numpy as np

from auvmpc.controllers.base import Observation
from auvmpc.controllers.channels import ReferenceWithDepth
from auvmpc.controllers.six_dof_nmpc import SixDofNmpc, SixDofNmpcConfig
from auvmpc.models.six_dof import integrate, plant_step_length, six_dof_model
from auvmpc.models.vehicle import load_vehicle
from auvmpc.references import LawnmowerConfig, make_reference
from auvmpc.sim.plant import substeps_for

# Per vehicle: speed (m/s), leg spacing (m), cross current (m/s), initial command.
CASES = {
    "remus100": (1.5, 45.0, 0.3, [900.0, 0.0, 0.0]),
    "bluerov2-heavy": (0.3, 4.0, 0.05, None),
}


def fly(name: str, jit: bool, steps: int) -> tuple[np.ndarray, list[float], float, float]:
    """Commands (steps, n), step times (s), build time (s), path RMS after 5 s (m)."""
    vehicle = load_vehicle(name)
    speed, spacing, cross, command = CASES[name]
    started = time.perf_counter()
    controller = SixDofNmpc(vehicle, SixDofNmpcConfig(jit=jit))
    built = time.perf_counter() - started
    lawnmower = LawnmowerConfig(leg_length=100.0 if speed > 1 else 12.0, spacing=spacing, legs=2,
                                speed=speed, depths_m=(10.0,))  # fmt: skip
    reference = ReferenceWithDepth(make_reference(lawnmower))
    model = six_dof_model(vehicle)
    current = np.array([0.0, cross, 0.0])
    state = np.zeros(12)
    state[2], state[6], state[7] = 10.0, speed, cross  # moving with the water
    inputs = vehicle.six_dof_actuators.size
    previous = np.zeros(inputs) if command is None else np.array(command)
    controller.reset(state, previous)
    sample, horizon = controller.sample_time, controller.preview_steps
    substeps = substeps_for(sample, plant_step_length(vehicle, sample))  # the plant's own rule
    commands, times, errors = [], [], []
    for k in range(steps):
        t = k * sample
        rows = reference.states(t + sample * np.arange(horizon + 1))
        result = controller.compute(Observation(k, t, state.copy(), rows))
        commands.append(result.thrust)
        times.append(result.solve_time_s)
        state = integrate(model, state, result.thrust, sample, substeps,
                          held_current=current)  # fmt: skip
        target = reference.states(np.array([t + sample]))[0]
        errors.append(np.hypot(state[0] - target[0], state[1] - target[1]))
    settled = int(5.0 / sample)
    return np.array(commands), times, built, float(np.sqrt(np.mean(np.square(errors[settled:]))))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=160)
    parser.add_argument("--vehicles", nargs="+", default=list(CASES))
    args = parser.parse_args()
    os.environ["AUVMPC_CACHE_DIR"] = tempfile.mkdtemp(prefix="auvmpc-bench-cache-")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs")
    print("| vehicle | jit | build s | median step ms | p95 step ms | path RMS m "
          "| max command gap |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for name in args.vehicles:
        runs = {jit: fly(name, jit, args.steps) for jit in (False, True)}
        ranges = load_vehicle(name).six_dof_actuators.limits
        span = np.asarray(ranges.upper - ranges.lower, dtype=float)
        gap = float(np.max(np.abs(runs[True][0] - runs[False][0]) / span))
        for jit, (_, times, built, rms) in runs.items():
            print(f"| {name} | {jit} | {built:.1f} | {1e3 * np.median(times):.1f} | "
                  f"{1e3 * np.percentile(times, 95):.1f} | {rms:.4f} | "
                  f"{gap if jit else 0.0:.2e} |")  # fmt: skip
    print("max command gap: largest |compiled - interpreted| over each input's range")


if __name__ == "__main__":
    main()
