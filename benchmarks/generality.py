"""Vehicle-generality benchmark: the default controller on every preset, four tracks, two
conditions, one table.

    python benchmarks/generality.py [--vehicles jmse2210 rexrov ...] [--workers 2]
        [--set controller.type=nmpc ...]

Every run uses the scenario defaults and the default controller (no controller settings)
unless ``--set`` says otherwise. Tracks are scaled to the vehicle (length scale
s = max(1, (mass / 13.5 kg)^(1/3)), the BlueROV2 being 1) and run at 0.3 m/s:

* ``oval``: a 12 s x 8 s loop with 4 s corner arcs (the paper's semi-oval, closed);
* ``circle``: radius 4 s;
* ``eight``: a figure-eight 6 s wide;
* ``lawnmower``: three 20 s legs 4 s apart, 90 deg corners rounded at 2 s.

Conditions: ``ideal`` (exact model, no current, no noise) and ``disturbed``: a constant
world current force equal to the vehicle's drag at 0.2 m/s (from 30 deg), the plant's
inertia and damping 30 % off the controller's model (up or down by axis), and sensor noise
(1 cm, 0.3 deg, 1 cm/s, 0.3 deg/s). The columns are the run metrics of
``run.json`` after the scenario's transient (30 s).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from auvmpc.experiments.run import simulate
from auvmpc.models.vehicle import VehicleParams, load_vehicle, thruster_preset_names
from auvmpc.references import FigureEightConfig, make_reference
from auvmpc.scenario import ResolvedScenario, apply_override, validate_scenario

SPEED_M_PER_S = 0.3
DURATION_S = 150.0
TRANSIENT_S = 30.0
CURRENT_SPEED_M_PER_S = 0.2
CURRENT_DIRECTION_DEG = 30.0
# 30 % model error, alternating in sign so that no axis is simply "heavier".
PLANT_SCALE = {"m11": 1.3, "m22": 0.7, "Iz_rb": 0.7, "Iz_added": 1.3,
               "Xu": 1.3, "Xuu": 0.7, "Yv": 0.7, "Yvv": 1.3, "Nr": 1.3, "Nrr": 0.7}  # fmt: skip
SENSOR_STD = [0.01, 0.01, 0.005, 0.01, 0.01, 0.005]
TRACKS = ("oval", "circle", "eight", "lawnmower")
CONDITIONS = ("ideal", "disturbed")


def length_scale(mass: float) -> float:
    return max(1.0, (mass / 13.5) ** (1.0 / 3.0))


def _eight_period(size: float) -> float:
    """The period that runs a figure-eight of half-width ``size`` at SPEED_M_PER_S on average."""
    reference = make_reference(FigureEightConfig(size=size, period=1.0))
    points = reference.states(np.linspace(0.0, 1.0, 4001))[:, :2]
    length = float(np.sum(np.hypot(*np.diff(points, axis=0).T)))
    return length / SPEED_M_PER_S


def track(name: str, s: float) -> dict:
    if name == "oval":
        points = [[0, 0], [12 * s, 0], [12 * s, 8 * s], [0, 8 * s], [0, 0.5 * s]]
        return {"type": "waypoints", "points": points, "speed": SPEED_M_PER_S,
                "corner_radius": 4 * s}  # fmt: skip
    if name == "circle":
        return {"type": "circle", "center": [0, 0], "radius": 4 * s, "speed": SPEED_M_PER_S}
    if name == "eight":
        return {"type": "figure-eight", "size": 6 * s, "period": _eight_period(6 * s)}
    if name == "lawnmower":
        points = [[0, 0], [20 * s, 0], [20 * s, 4 * s], [0, 4 * s], [0, 8 * s], [20 * s, 8 * s]]
        return {"type": "waypoints", "points": points, "speed": SPEED_M_PER_S,
                "corner_radius": 2 * s}  # fmt: skip
    raise ValueError(name)


def scenario(
    vehicle: str | dict, track_name: str, condition: str, overrides: list[str], name: str = ""
) -> dict:
    """The run of ``vehicle`` (a preset, or a vehicle's fields named ``name``) on a track."""
    params = load_vehicle(vehicle)
    data = {
        "name": f"{name or vehicle}-{track_name}-{condition}",
        "duration": DURATION_S,
        "vehicle": vehicle,
        "reference": track(track_name, length_scale(params.mass)),
        "transient_s": TRANSIENT_S,
        "seed": 1,
        "initial_state": [0.0] * 6,  # replaced by the reference's start below
    }
    start = make_reference(validate_scenario(data).reference).states(np.array([0.0]))[0]
    data["initial_state"] = [float(v) for v in start]
    if condition == "disturbed":
        disturb(data, params)
    for override in overrides:
        apply_override(data, override)
    return data


def disturb(data: dict, params: VehicleParams) -> None:
    """Make a scenario the ``disturbed`` condition: current, model error, sensor noise."""
    v = CURRENT_SPEED_M_PER_S
    drag = abs(params.Xu * v + params.Xuu * v * abs(v))
    angle = math.radians(CURRENT_DIRECTION_DEG)
    data["disturbance"] = {"current_force_world": [drag * math.cos(angle),
                                                   drag * math.sin(angle)]}  # fmt: skip
    data["plant"] = {"scale": dict(PLANT_SCALE)}
    data["sensing"] = {"std": SENSOR_STD}


def run_one(job: tuple[str, str, str, list[str]]) -> dict:
    vehicle, track_name, condition, overrides = job
    started = time.perf_counter()
    result = simulate(
        ResolvedScenario(validate_scenario(scenario(*job[:3], overrides)), Path.cwd())
    )
    m = result.metrics
    return {
        "vehicle": vehicle, "track": track_name, "condition": condition,
        "rms": m["rms_position_error_after_transient_m"],
        "max": m["max_position_error_after_transient_m"],
        "heading": m["max_heading_error_after_transient_rad"],
        "fallbacks": m["fallback_steps"], "verdict": m["verdict"],
        "wall_s": time.perf_counter() - started,
    }  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", nargs="+", default=thruster_preset_names())
    parser.add_argument("--tracks", nargs="+", default=list(TRACKS), choices=TRACKS)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    args = parser.parse_args(argv)
    jobs = [
        (v, t, c, args.overrides) for v in args.vehicles for t in args.tracks for c in CONDITIONS
    ]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(run_one, jobs, chunksize=1))
    settings = " ".join(args.overrides) or "default controller"
    print(f"{settings}; {SPEED_M_PER_S} m/s, {DURATION_S:.0f} s, after {TRANSIENT_S:.0f} s")
    print(
        f"{'vehicle':16s} {'track':10s} {'condition':10s} {'RMS m':>8s} {'max m':>8s} "
        f"{'max hdg rad':>11s} {'fallb.':>6s} {'verdict':9s} {'wall s':>6s}"
    )
    for r in rows:
        print(
            f"{r['vehicle']:16s} {r['track']:10s} {r['condition']:10s} {r['rms']:8.4f} "
            f"{r['max']:8.4f} {r['heading']:11.4f} {r['fallbacks']:6d} {r['verdict']:9s} "
            f"{r['wall_s']:6.1f}"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
