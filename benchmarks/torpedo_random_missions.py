"""The torpedo's default controller against its yardstick on random missions with corners:
``auvmpc bench --yardstick los-pid`` over scenario files drawn here.

    python benchmarks/torpedo_random_missions.py --missions 6 [--seed 0] [--out DIR]
        [--controllers default los-pid@...] [--set FIELD=VALUE ...]

Each mission is a ``kind: six-dof`` scenario of the ``remus100`` preset, drawn from one
``np.random.Generator`` (``--seed``, mission i from its i-th child): five 3-D waypoints,
legs of 60-110 m joined by corners that turn 45-110 deg either way (arcs of 20 m radius:
beyond the 10 m full-rudder turn), the depth of each waypoint 5-20 m with at most a
14 deg glide between them, 1.5 m/s; a 0.2-0.5 m/s current from any direction; the plant's
added mass and quadratic damping each 0.8-1.2 times the controller's; the presets' noisy
navigation (0.1 m) and depth (0.02 m) sensors. The run ends 5 s before the path does (a
torpedo cannot hold its end point). The scenario files are kept in ``DIR/missions`` and the
benchmark (a run folder per mission and controller, ``bench.md``) in ``DIR/bench``.

Prints the benchmark's table, then per controller the mean over the missions of the
cross-track and depth RMS after the 20 s transient and the number of missions on which
it is better than the yardstick.
"""

from __future__ import annotations

import argparse
import math
import statistics
from pathlib import Path

import numpy as np
import yaml
from rich.console import Console

from auvmpc.experiments.bench import CROSS_TRACK, DEPTH, format_table, machine_info, run_benchmark
from auvmpc.references import Waypoints3DConfig, make_reference

SPEED_M_PER_S = 1.5
LEG_M = (60.0, 110.0)
TURN_DEG = (45.0, 110.0)
CORNER_RADIUS_M = 20.0
DEPTH_M = (5.0, 20.0)
MAX_GLIDE = math.tan(math.radians(14.0))  # depth change per horizontal metre
CURRENT_M_PER_S = (0.2, 0.5)
MODEL_ERROR = (0.8, 1.2)
WAYPOINTS = 5
END_MARGIN_S = 5.0
TRANSIENT_S = 20.0


def mission(index: int, rng: np.random.Generator) -> dict:
    """One random mission as a scenario mapping (module docstring)."""
    heading = rng.uniform(-math.pi, math.pi)
    points = [(0.0, 0.0, 10.0)]
    for leg in range(WAYPOINTS - 1):
        if leg > 0:
            heading += math.radians(rng.uniform(*TURN_DEG)) * rng.choice((-1.0, 1.0))
        length = rng.uniform(*LEG_M)
        x, y, z = points[-1]
        dive = length * MAX_GLIDE
        depth = float(np.clip(rng.uniform(z - dive, z + dive), *DEPTH_M))
        points.append((x + length * math.cos(heading), y + length * math.sin(heading), depth))
    reference = {
        "type": "waypoints-3d",
        "points": [[round(v, 3) for v in p] for p in points],
        "speed": SPEED_M_PER_S,
        "corner_radius": CORNER_RADIUS_M,
    }
    end = make_reference(Waypoints3DConfig(**reference)).end_time
    first = math.atan2(points[1][1] - points[0][1], points[1][0] - points[0][0])
    speed, direction = rng.uniform(*CURRENT_M_PER_S), rng.uniform(-math.pi, math.pi)
    current = (speed * math.cos(direction), speed * math.sin(direction))
    # Moving with the water (no sideslip through it): the current in the body frame added.
    along = current[0] * math.cos(first) + current[1] * math.sin(first)
    across = -current[0] * math.sin(first) + current[1] * math.cos(first)
    start = [0.0, 0.0, first, SPEED_M_PER_S + along, across, 0.0]
    return {
        "kind": "six-dof",
        "name": f"remus100-random-{index}",
        "duration": round(end - END_MARGIN_S, 1),
        "vehicle": "remus100",
        "reference": reference,
        "initial_state": [round(value, 6) for value in start],
        "initial_depth_m": 10.0,
        "initial_thrust": [900.0, 0.0, 0.0],
        "disturbance": {"water_current": {"velocity_m_per_s": [*map(float, current), 0.0]}},
        "plant": {
            "scale": {
                "added_mass": round(float(rng.uniform(*MODEL_ERROR)), 3),
                "quadratic_damping": round(float(rng.uniform(*MODEL_ERROR)), 3),
            }
        },
        "sensing": {
            "std": [0.1, 0.1, 0.005, 0.01, 0.01, 0.005],
            "depth_std_m": 0.02,
            "depth_rate_std_m_per_s": 0.01,
        },
        "transient_s": TRANSIENT_S,
        "seed": index,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--missions", type=int, default=6)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=Path("results/torpedo-random-missions"))
    parser.add_argument("--controllers", nargs="+", default=["default"])
    parser.add_argument("--yardstick", default="los-pid")
    parser.add_argument("--set", nargs="*", default=[], dest="overrides")
    parser.add_argument("--overwrite", action="store_true")
    args = parser.parse_args()

    folder = args.out / "missions"
    folder.mkdir(parents=True, exist_ok=True)
    files = []
    for index, child in enumerate(np.random.SeedSequence(args.seed).spawn(args.missions)):
        path = folder / f"mission-{index}.yaml"
        path.write_text(yaml.safe_dump(mission(index, np.random.default_rng(child))))
        files.append(str(path))
    rows = run_benchmark(
        args.controllers, files, overrides=args.overrides, yardstick=args.yardstick,
        out=args.out / "bench", figures=False, overwrite=args.overwrite,
        on_run=lambda done, total, name: print(f"[{done}/{total}] {name}", flush=True),
    )  # fmt: skip
    Console(width=200).print(format_table(rows, machine_info()))
    for label in dict.fromkeys(row["controller"] for row in rows):
        own = [row for row in rows if row["controller"] == label]
        ratios = [(row["vs_yardstick"] or {}).get(CROSS_TRACK) for row in own]
        better = sum(ratio is not None and ratio < 1.0 for ratio in ratios)
        cross_track = statistics.fmean(row[CROSS_TRACK] for row in own)
        depth = statistics.fmean(row[DEPTH] for row in own)
        print(
            f"{label}: mean cross-track {cross_track:.4f} m, mean depth {depth:.4f} m, "
            f"cross-track below {args.yardstick}'s on {better} of {len(own)}; "
            f"verdicts {[row['verdict'] for row in own]}"
        )


if __name__ == "__main__":
    main()
