"""A vehicle from its size, flown against the published one (issue 30's floor).

    python benchmarks/vehicle_from_size.py [--out DIR]

For bluerov2-heavy, jmse2210 and videoray-pro3, ``auvmpc vehicle new`` is given only the
preset's mass, size (its ``size`` block), hull shape and thruster layout and limits, and
writes a vehicle file. Then the default controller flies a figure-eight (16 m, period 160 s)
in a 0.11 m/s water current twice: with the published preset as its model, and with the
estimated file as its model; the plant is the published preset both times (scenario field
``plant.vehicle``). The table gives both RMS position errors after the transient, the bound
max(2 x published, 0.05 m), the verdicts, and whether the estimate passes.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from auvmpc.experiments.run import simulate
from auvmpc.models.vehicle import load_vehicle
from auvmpc.scenario import ResolvedScenario, validate_scenario

# Hull shapes: the BlueROV2 is an open frame (box); the paper's AUV a slender hull and the
# VideoRay a closed, rounded float block (ellipsoid; as a box its surge drag is 4x the
# measured one and the run is lost: docs/vehicles.md).
SHAPES = {"bluerov2-heavy": "box", "jmse2210": "ellipsoid", "videoray-pro3": "ellipsoid"}
BOUND_FACTOR = 2.0
BOUND_FLOOR_M = 0.05


def figure_eight(model: str, plant: str) -> dict:
    """bluerov2-figure-eight's path and noise, with a water current instead of a current
    force (a force of 11 N would exceed the VideoRay's thrust)."""
    return {
        "name": "from-size-figure-eight",
        "duration": 200.0,
        "vehicle": model,
        "plant": {"vehicle": plant},
        "reference": {"type": "figure-eight", "center": [0, 0], "size": 8.0, "period": 160.0},
        "initial_state": [0.0, 0.0, 0.7853982, 0.0, 0.0, 0.0],
        "disturbance": {"water_current": {"velocity_m_per_s": [0.1, 0.05, 0.0]}},
        "sensing": {"std": [0.01, 0.01, 0.005, 0.01, 0.01, 0.005]},
        "transient_s": 30.0,
        "seed": 0,
    }


def vehicle_new_command(preset: str, out: Path) -> list[str]:
    """The ``auvmpc vehicle new`` arguments from the preset's mass, size and thrusters."""
    vehicle = load_vehicle(preset)
    size = vehicle.size
    low, high = vehicle.thrust_limits
    command = [
        "vehicle", "new", f"{preset}-from-size", f"--mass={vehicle.mass:g}",
        f"--length={size.length:g}", f"--width={size.width:g}", f"--height={size.height:g}",
        f"--shape={SHAPES[preset]}", f"--thrust-limits={low:g},{high:g}",
        f"--thrust-rate-limit={vehicle.thrust_rate_limit:g}", f"--out={out}",
    ]  # fmt: skip
    for thruster in vehicle.thrusters:
        x, y = thruster.position
        command.append(f"--thruster={x:g},{y:g},{thruster.angle_deg:g}")
    return command


def rms_after_transient(model: str, plant: str) -> tuple[float, str]:
    resolved = ResolvedScenario(validate_scenario(figure_eight(model, plant)), Path.cwd())
    metrics = simulate(resolved).metrics
    return float(metrics["rms_position_error_after_transient_m"]), str(metrics["verdict"])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, help="keep the written vehicle files here")
    args = parser.parse_args()
    folder = args.out or Path(tempfile.mkdtemp(prefix="vehicle-from-size-"))
    folder.mkdir(parents=True, exist_ok=True)
    rows, passed = [], True
    started = time.perf_counter()
    for preset in SHAPES:
        path = folder / f"{preset}-from-size.yaml"
        command = [sys.executable, "-m", "auvmpc.cli", *vehicle_new_command(preset, path),
                   "--overwrite"]  # fmt: skip
        subprocess.run(command, check=True, capture_output=True, text=True)
        load_vehicle(path)  # loads as-is
        published, verdict_published = rms_after_transient(preset, preset)
        estimated, verdict_estimated = rms_after_transient(str(path), preset)
        bound = max(BOUND_FACTOR * published, BOUND_FLOOR_M)
        ok = verdict_estimated != "lost" and estimated <= bound
        passed &= ok
        rows.append((preset, published, verdict_published, estimated, verdict_estimated, bound,
                     ok))  # fmt: skip
    print("| plant (published) | shape | RMS, published model (m) | verdict | RMS, model from "
          "size (m) | verdict | bound (m) | pass |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for preset, published, vp, estimated, ve, bound, ok in rows:
        print(f"| {preset} | {SHAPES[preset]} | {published:.4f} | {vp} | {estimated:.4f} | {ve} "
              f"| {bound:.4f} | {'yes' if ok else 'NO'} |")  # fmt: skip
    print(f"\nvehicle files in {folder}; {time.perf_counter() - started:.0f} s")
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
