"""The torpedo's two controllers on the same cases: ``los-pid`` (the LOS + PID yardstick) and
``six-dof-nmpc`` (default configurations), flying the remus100 preset on the 6-DOF plant in
a hand-built loop (no scenario kind flies the torpedo yet).

    python benchmarks/torpedo_autopilots.py [--cases survey helix depth-change]
                                            [--controllers los-pid six-dof-nmpc]
                                            [--model-error 1.2] [--set KEY=VALUE ...]

Cases, each in a 0.3 m/s current across the first leg (world +y), no noise, no model error
unless ``--model-error`` scales the plant's inertia, added mass and damping, the vehicle
starting on the path at 1.5 m/s:

- survey: a lawnmower of three 100 m legs 45 m apart at 10 m depth, 1.5 m/s (234 s);
- helix: 20 m radius at 1.5 m/s from 10 m depth, 5 m deeper per turn (120 s);
- depth-change: a straight line at 1.5 m/s, 10 m to 20 m deep over 60 s from t = 20 s
  (120 s).

Columns: cross-track RMS after 20 s (the distance to the path, not to the moving point),
depth RMS after 20 s, samples with a command outside its box or moved faster than its rate,
median time of one controller step.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import dataclass

import numpy as np

from auvmpc.controllers.base import Controller, Observation
from auvmpc.controllers.channels import ReferenceWithDepth
from auvmpc.controllers.los_pid import LosPid, LosPidConfig
from auvmpc.controllers.six_dof_nmpc import SixDofNmpc, SixDofNmpcConfig
from auvmpc.models.six_dof import SIX_DOF, integrate, plant_step_length, six_dof_model
from auvmpc.models.vehicle import VehicleParams, load_vehicle, scaled
from auvmpc.references import (
    DepthChangeConfig,
    DepthScheduleConfig,
    HelixConfig,
    LawnmowerConfig,
    LineConfig,
    make_reference,
)
from auvmpc.sim.metrics import cross_track_error
from auvmpc.sim.plant import substeps_for

SPEED_M_PER_S = 1.5
CURRENT = np.array([0.0, 0.3, 0.0])  # world NED (m/s): across the survey's legs
TRANSIENT_S = 20.0
# The path is sampled this finely (s of reference) for the distance to it.
PATH_SAMPLE_S = 0.02
# A command beyond its box or rate by more than this (its own units) is a violation.
TOLERANCE = 1e-6
CASES = {
    "survey": (
        LawnmowerConfig(leg_length=100.0, spacing=45.0, legs=3, speed=SPEED_M_PER_S,
                        depths_m=(10.0,)),
        None,  # its end
    ),
    "helix": (
        HelixConfig(radius=20.0, speed=SPEED_M_PER_S, descent_per_turn_m=5.0,
                    start_depth_m=10.0),
        120.0,
    ),
    "depth-change": (
        LineConfig(speed=SPEED_M_PER_S, depth=DepthScheduleConfig(
            start_m=10.0, changes=(DepthChangeConfig(time_s=20.0, depth_m=20.0,
                                                     duration_s=60.0),))),
        120.0,
    ),
}  # fmt: skip
# What --model-error scales in the plant (as a scenario's plant.scale would).
MODEL_ERROR_FIELDS = ("inertia", "added_mass", "linear_damping", "quadratic_damping")
CONTROLLERS = {
    "los-pid": lambda vehicle, knobs: LosPid(vehicle, LosPidConfig(**knobs)),
    "six-dof-nmpc": lambda vehicle, knobs: SixDofNmpc(vehicle, SixDofNmpcConfig(**knobs)),
}


@dataclass
class Flight:
    t: np.ndarray  # (N + 1,) s
    states: np.ndarray  # (N + 1, 12)
    commands: np.ndarray  # (N, nu)
    step_s: np.ndarray  # (N,) each controller step's time


def fly(vehicle: VehicleParams, controller: Controller, reference, seconds: float) -> Flight:
    """The controller on the 6-DOF plant of ``vehicle`` (RK4 steps short enough for the fins
    at the top speed) for ``seconds``, from the path's start at SPEED_M_PER_S."""
    te = controller.sample_time
    model = six_dof_model(vehicle)
    substeps = substeps_for(te, plant_step_length(vehicle, te))
    rows = ReferenceWithDepth(reference)
    first = rows.states(np.array([0.0]))[0]
    state = np.zeros(SIX_DOF.size)
    state[[0, 1, 2, 5]] = first[[0, 1, 6, 2]]
    state[SIX_DOF.index("u")] = SPEED_M_PER_S
    limits = vehicle.six_dof_actuators.limits
    command = np.zeros(vehicle.six_dof_actuators.size)
    command[0] = float(np.clip(900.0, limits.lower[0], limits.upper[0]))
    controller.reset(state, command)
    steps = round(seconds / te)
    states, commands, times = [state], [], []
    for k in range(steps):
        t = k * te
        preview = rows.states(t + te * np.arange(controller.preview_steps + 1))
        started = time.perf_counter()
        result = controller.compute(Observation(k, t, state.copy(), preview))
        times.append(time.perf_counter() - started)
        command = np.asarray(result.thrust, dtype=float)
        state = integrate(model, state, command, te, substeps, held_current=CURRENT)
        states.append(state)
        commands.append(command)
    return Flight(te * np.arange(steps + 1), np.array(states), np.array(commands),
                  np.array(times))  # fmt: skip


def violations(vehicle: VehicleParams, flight: Flight, initial: np.ndarray, te: float):
    """Samples with some command outside its box, and moved beyond its rate."""
    limits = vehicle.six_dof_actuators.limits
    commands = flight.commands
    outside = (commands < limits.lower - TOLERANCE) | (commands > limits.upper + TOLERANCE)
    moves = np.abs(np.diff(np.vstack([initial, commands]), axis=0))
    fast = moves > limits.rate * te + TOLERANCE
    return int(np.any(outside, axis=1).sum()), int(np.any(fast, axis=1).sum())


def measure(vehicle: VehicleParams, name: str, controller_name: str,
            model_error: float = 1.0, knobs: dict | None = None) -> dict[str, float]:  # fmt: skip
    """One case flown by one controller (built on ``vehicle`` with ``knobs``) on the plant
    whose inertia, added mass and damping are ``model_error`` times the controller's."""
    config, seconds = CASES[name]
    reference = make_reference(config)
    seconds = seconds or float(reference.end_time)
    controller = CONTROLLERS[controller_name](vehicle, knobs or {})
    plant = scaled(vehicle, dict.fromkeys(MODEL_ERROR_FIELDS, model_error))
    flight = fly(plant, controller, reference, seconds)
    path_t = np.arange(0.0, seconds + PATH_SAMPLE_S, PATH_SAMPLE_S)
    path = reference.positions(path_t)
    late = flight.t >= TRANSIENT_S
    cross = cross_track_error(flight.states[late][:, :2], path)
    depth_error = flight.states[late, 2] - reference.depths(flight.t[late])[:, 0]
    initial = np.zeros(flight.commands.shape[1])
    initial[0] = 900.0
    box, rate = violations(vehicle, flight, initial, controller.sample_time)
    return {
        "cross_track_rms_m": math.sqrt(float(np.mean(cross**2))),
        "cross_track_max_m": float(np.max(cross)),
        "depth_rms_m": math.sqrt(float(np.mean(depth_error**2))),
        "box": box,
        "rate": rate,
        "median_step_ms": 1e3 * float(np.median(flight.step_s)),
        "sample_s": controller.sample_time,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES))
    parser.add_argument("--controllers", nargs="+", choices=list(CONTROLLERS),
                        default=list(CONTROLLERS))  # fmt: skip
    parser.add_argument("--model-error", type=float, default=1.0,
                        help="the plant's inertia, added mass and damping over the "
                        "controllers' (e.g. 1.2)")  # fmt: skip
    parser.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE",
                        help="knobs of the controllers' configurations (JSON values), e.g. "
                        "integral_los=true; with one --controllers")  # fmt: skip
    arguments = parser.parse_args()
    knobs = {key: json.loads(value) for key, _, value in (k.partition("=") for k in arguments.set)}
    vehicle = load_vehicle("remus100")
    print(
        "| case | controller | Te (s) | cross-track RMS after 20 s (m) | max (m) | "
        "depth RMS after 20 s (m) | box / rate violations | median step (ms) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for name in arguments.cases:
        for controller_name in arguments.controllers:
            m = measure(vehicle, name, controller_name, arguments.model_error, knobs)
            print(f"| {name} | {controller_name} | {m['sample_s']:g} | "
                  f"{m['cross_track_rms_m']:.3f} | {m['cross_track_max_m']:.3f} | "
                  f"{m['depth_rms_m']:.4f} | {m['box']} / {m['rate']} | "
                  f"{m['median_step_ms']:.2f} |", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
