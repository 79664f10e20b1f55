"""Random-vehicle sweep: does each controller solve every step on vehicles from 10 kg to 2 t?

    python benchmarks/vehicle_sweep.py --vehicles 100 --workers 2 \
        [--controllers nmpc ltv-mpc-nc30 nmpc-full default] [--disturbed]

Each vehicle comes from :func:`auvmpc.models.random_vehicles.random_vehicle` (seeded by its index);
it follows a circle at 0.3 m/s (radius 4 m, or 4 s m for a vehicle of length scale s > 1)
starting on the circle, with the scenario defaults and every controller's defaults. The table
gives per controller the vehicles with at least one fallback step, the worst ones, and the
RMS error; a last line counts the vehicles where a fast controller fell back although
``nmpc-full`` (IPOPT) solved every step: that number is the control-core issue's criterion.
The label ``default`` runs the default controller with no settings (docs/tuning.md);
``--disturbed`` adds generality.py's disturbed condition (current, model error, noise).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
from generality import TRANSIENT_S, disturb

from auvmpc.controllers.config import CONTROLLER_PRESETS
from auvmpc.errors import RunFailed
from auvmpc.experiments.run import simulate
from auvmpc.models.random_vehicles import random_vehicle
from auvmpc.scenario import ResolvedScenario, validate_scenario

SPEED_M_PER_S = 0.3
DURATION_S = 60.0


def sweep_scenario(index: int) -> dict:
    vehicle = random_vehicle(np.random.default_rng(index), name=f"random-{index}")
    scale = max(1.0, (vehicle.mass / 13.5) ** (1.0 / 3.0))
    radius = 4.0 * scale
    return {
        "name": f"sweep-{index}",
        "duration": DURATION_S,
        "vehicle": vehicle.model_dump(mode="json"),
        "reference": {"type": "circle", "center": [0, 0], "radius": radius, "speed": SPEED_M_PER_S},
        "initial_state": [radius, 0.0, math.pi / 2, 0.0, 0.0, 0.0],
        "seed": index,
        "transient_s": TRANSIENT_S,
    }


# The default controller with no settings.
LABELS = {**CONTROLLER_PRESETS, "default": ()}


def run_one(job: tuple[int, str, bool]) -> dict:
    from pathlib import Path

    from auvmpc.scenario import apply_override

    index, label, disturbed = job
    data = sweep_scenario(index)
    if disturbed:
        disturb(data, random_vehicle(np.random.default_rng(index)))
    for override in LABELS[label]:
        apply_override(data, override)
    started = time.perf_counter()
    try:
        result = simulate(ResolvedScenario(validate_scenario(data), Path.cwd()))
    except RunFailed as error:  # the plant diverged: a result of the sweep, not its end
        return {"index": index, "controller": label, "mass": data["vehicle"]["mass"],
                "fallbacks": -1, "rms": math.inf, "rms_after": math.inf,
                "wall_s": time.perf_counter() - started, "failure": str(error)}  # fmt: skip
    metrics = result.metrics
    return {
        "index": index,
        "controller": label,
        "mass": data["vehicle"]["mass"],
        "fallbacks": int(metrics["solver_failures"]),
        "rms": float(metrics["rms_position_error_m"]),
        "rms_after": float(metrics["rms_position_error_after_transient_m"]),
        "wall_s": time.perf_counter() - started,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--vehicles", type=int, default=100)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--controllers", nargs="+", default=["nmpc", "ltv-mpc-nc30", "nmpc-full"],
        choices=sorted(LABELS),
    )  # fmt: skip
    parser.add_argument("--disturbed", action="store_true")
    args = parser.parse_args(argv)
    jobs = [(i, c, args.disturbed) for i in range(args.vehicles) for c in args.controllers]
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(run_one, jobs, chunksize=1))
    by = {(r["index"], r["controller"]): r for r in rows}
    condition = "disturbed" if args.disturbed else "ideal"
    print(
        f"{args.vehicles} random vehicles, circle at {SPEED_M_PER_S} m/s, {DURATION_S:.0f} s, "
        f"{condition}; RMS>tr: after the first {TRANSIENT_S:.0f} s"
    )
    print(
        f"{'controller':16s} {'vehicles w/ fallback':>21s} {'max fallbacks':>14s} "
        f"{'median RMS m':>13s} {'max RMS m':>10s} {'max RMS>tr m':>13s}"
    )
    for c in args.controllers:
        mine = [r for r in rows if r["controller"] == c]
        failing = [r for r in mine if r["fallbacks"]]
        rms = np.array([r["rms"] for r in mine])
        after = np.array([r["rms_after"] for r in mine])
        diverged = sum(r["fallbacks"] < 0 for r in mine)
        most = max(r["fallbacks"] for r in mine)
        most_text = f"{most:d}" + (f" +{diverged} diverged" if diverged else "")
        print(
            f"{c:16s} {len(failing):21d} {most_text:>14s} "
            f"{np.median(rms):13.4f} {rms.max():10.4f} {after.max():13.4f}"
        )
        # A diverged run (fallbacks -1) first, then the most fallbacks.
        for r in sorted(failing, key=lambda r: (r["fallbacks"] >= 0, -r["fallbacks"]))[:5]:
            what = f"{r['fallbacks']} fallbacks" if r["fallbacks"] >= 0 else r["failure"]
            print(f"    vehicle {r['index']:3d} ({r['mass']:7.1f} kg): {what}")
    if "nmpc-full" in args.controllers:
        solved = [i for i in range(args.vehicles) if by[(i, "nmpc-full")]["fallbacks"] == 0]
        for c in args.controllers:
            if c == "nmpc-full":
                continue
            bad = [i for i in solved if by[(i, c)]["fallbacks"]]
            print(
                f"{c}: {len(bad)} of {len(solved)} vehicles that nmpc-full solves fall back"
                + (f" ({bad[:10]})" if bad else "")
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
