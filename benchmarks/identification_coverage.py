"""Issue 27's coverage statistic: do ``auvmpc identify``'s 95 % intervals cover the truth?

    PYTHONPATH=src python benchmarks/identification_coverage.py [--random 20] [--seed 100]
        [--duration 300] [--workers 2] [--no-eight] [--eight-random N] [--default-plant-step]

For every preset vehicle and ``--random`` random plausible vehicles
(:func:`auvmpc.models.random_vehicles.random_vehicle`, seeds ``--seed`` + i), as
benchmarks/identification.py does for one: design the ``auvmpc excite`` manoeuvre, fly it
as its scenario with sensor noise (identification.py's SENSING_STD) in a constant water
current of 0.2 to 0.3 m/s from a random direction, identify from the noisy velocities and
heading with the current as an unknown (``identify --current``), starting from a file with
every parameter 30 % off (signs from the seed). Per vehicle: the parameters the report calls
excited, how many of them are within 10 % of the truth or covered by their interval, how
many intervals cover the truth, whether the current's do, the wall time of the
identification; then the coverage of the 95 % intervals over all excited parameters.

The excite run's plant is integrated **accurately**: RK4 at a tenth of its stability limit
for the vehicle (:func:`accurate_plant_step`), not at the simulator's default, which is
chosen for stability (up to 2.5 / the fastest damping rate, at most 0.05 s): on a light
random vehicle whose yaw damping acts at 24 1/s, one default step leaves 6 % more of a
decaying yaw rate than the equations do, and a fit to such a log finds that integrator, not
the vehicle file (z-scores of 3 to 7.5 in yaw). A real vehicle is the continuous equations.
``--default-plant-step`` runs the simulator's default instead.

Then the default controller flies generality.py's figure-eight (half-width 6 s m at
0.3 m/s, 150 s, after 30 s) in the same current with generality's sensor noise, the truth
as the plant and as the model, then the identified file (what identify writes, from the
start file) as the model: the RMS ratio identified / true (issue 27: <= 1.1).
``--eight-random N`` flies it for the presets and the first N random vehicles only,
``--no-eight`` for none.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import yaml
from generality import SENSOR_STD, scenario
from identification import WITHIN, measured_excite_log, perturbed

from auvmpc.experiments.bench import machine_info
from auvmpc.experiments.run import simulate
from auvmpc.identification.estimation import HorizontalGreyBox, identify
from auvmpc.identification.report import vehicle_file_text
from auvmpc.models.random_vehicles import random_vehicle
from auvmpc.models.vehicle import load_vehicle, stable_plant_step, thruster_preset_names
from auvmpc.scenario import ResolvedScenario, validate_scenario
from auvmpc.scenario.model import DEFAULT_PLANT_STEP_S

CURRENT_SPEED_M_PER_S = (0.2, 0.3)
RATIO_TARGET = 1.1
COVERAGE_TARGET = 0.9
# The plant's RK4 step as a share of its stability limit: at lambda h = 0.25 one step's decay
# is within 1e-5 of exp(-lambda h) (the stability limit is lambda h = 2.785).
ACCURATE_SHARE = 0.1


def accurate_plant_step(truth) -> float:
    """An RK4 step (s) at which the plant is the vehicle's equations to about 1e-5 per step,
    at the speeds its thrusters reach (module docstring)."""
    share = ACCURATE_SHARE * stable_plant_step(truth, math.inf)
    return min(DEFAULT_PLANT_STEP_S, share)


def vehicle(job: tuple[str, int]):
    """(name, truth) of a preset or of random vehicle ``index``."""
    kind, index = job
    if kind == "preset":
        return thruster_preset_names()[index], load_vehicle(thruster_preset_names()[index])
    name = f"random-{index}"
    return name, random_vehicle(np.random.default_rng(index), name=name)


def eight_rms(truth, model: dict, current: np.ndarray, name: str) -> float:
    """The default controller's RMS (m, after the transient) on generality.py's figure-eight,
    ``truth`` the plant and ``model`` (a vehicle's fields) the controller's model."""
    data = scenario(model, "eight", "identified", [], name=name)
    data["plant"] = {"vehicle": truth.model_dump(mode="json")}
    data["sensing"] = {"std": SENSOR_STD}
    data["disturbance"] = {"water_current": {"velocity_m_per_s": [*map(float, current), 0.0]}}
    result = simulate(ResolvedScenario(validate_scenario(data), Path.cwd()))
    return float(result.metrics["rms_position_error_after_transient_m"])


def run_one(job: tuple[str, int, int, float, bool, bool]) -> dict:
    kind, index, seed, duration, eight, accurate = job
    name, truth = vehicle((kind, index))
    rng = np.random.default_rng(seed)
    speed = rng.uniform(*CURRENT_SPEED_M_PER_S)
    direction = rng.uniform(0.0, 2.0 * math.pi)
    current = speed * np.array([math.cos(direction), math.sin(direction)])
    plant_step = accurate_plant_step(truth) if accurate else None
    log = measured_excite_log(truth, name, duration, seed, current, plant_step)
    start = perturbed(truth, rng)
    began = time.perf_counter()
    found = identify([log], start, greybox=HorizontalGreyBox(start, current=True))
    wall = time.perf_counter() - began
    excited = [p for p in found.parameters if p.excited]
    covered = [p.ci95[0] <= getattr(truth, p.name) <= p.ci95[1] for p in excited]
    close = [abs(p.value - getattr(truth, p.name)) <= WITHIN * abs(getattr(truth, p.name))
             for p in excited]  # fmt: skip
    missed = [f"{p.name} {(p.value / getattr(truth, p.name) - 1):+.1%}" if getattr(truth, p.name)
              else f"{p.name} {p.value:+.2g}" for p, ok in zip(excited, covered, strict=True)
              if not ok]  # fmt: skip
    current_covered = [
        p.ci95[0] <= value <= p.ci95[1] for p, value in zip(found.extras, current, strict=True)
    ]
    row = {
        "vehicle": name,
        "mass": truth.mass,
        "plant_step": plant_step or stable_plant_step(truth, DEFAULT_PLANT_STEP_S),
        "excited": len(excited),
        "unexcited": found.unexcited,
        "ok": sum(a or b for a, b in zip(close, covered, strict=True)),
        "close": sum(close),
        "covered": sum(covered),
        "missed": missed,
        "current": float(speed),
        "current_error": float(np.hypot(*[p.value for p in found.extras] - current)),
        "current_covered": sum(current_covered),
        "wall_s": wall,
        "iterations": found.iterations,
        "status": found.solver_status,
    }
    if eight:
        start_data = start.model_dump(mode="json")
        identified = yaml.safe_load(vehicle_file_text(start_data, found, f"{name}-start"))
        row["rms_true"] = eight_rms(truth, truth.model_dump(mode="json"), current, name)
        row["rms_identified"] = eight_rms(truth, identified, current, name)
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--random", type=int, default=20)
    parser.add_argument("--seed", type=int, default=100, help="first random vehicle's seed")
    parser.add_argument("--duration", type=float, default=300.0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--no-eight", action="store_true")
    parser.add_argument("--eight-random", type=int, default=None)
    parser.add_argument("--default-plant-step", action="store_true")
    args = parser.parse_args(argv)
    eight_random = args.random if args.eight_random is None else args.eight_random
    accurate = not args.default_plant_step
    jobs = [("preset", i, i, args.duration, not args.no_eight, accurate)
            for i in range(len(thruster_preset_names()))]  # fmt: skip
    jobs += [
        ("random", args.seed + i, args.seed + i, args.duration,
         not args.no_eight and i < eight_random, accurate)
        for i in range(args.random)
    ]  # fmt: skip
    began = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        rows = list(pool.map(run_one, jobs, chunksize=1))
    total = time.perf_counter() - began
    machine = machine_info()
    print(
        f"{len(rows)} vehicles, {args.duration:g} s excite logs, sensor noise, a 0.2-0.3 m/s "
        f"current (identify --current), start files 30 % off, the excite run's plant "
        f"step {'accurate' if accurate else 'the default'}; {args.workers} workers, "
        f"{machine['cpu_model']} ({machine['cpu_count']} CPUs), Python {machine['python']}, "
        f"{total / 60:.1f} min in all"
    )
    print()
    print(
        "| vehicle | mass kg | plant step s | excited | within 10 % or covered | covered "
        "| current m/s "
        "| current error m/s | current covered | identify s | eight RMS true m "
        "| eight RMS identified m | ratio | intervals missing the truth |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        eight = ["-", "-", "-"]
        if "rms_true" in r:
            ratio = r["rms_identified"] / r["rms_true"]
            eight = [f"{r['rms_true']:.4f}", f"{r['rms_identified']:.4f}", f"{ratio:.3f}"]
        unexcited = f" (not excited: {', '.join(r['unexcited'])})" if r["unexcited"] else ""
        print(
            f"| {r['vehicle']} | {r['mass']:.1f} | {r['plant_step']:.3g} "
            f"| {r['excited']}{unexcited} | {r['ok']} "
            f"| {r['covered']} | {r['current']:.3f} | {r['current_error']:.4f} "
            f"| {r['current_covered']} of 2 | {r['wall_s']:.1f} | {' | '.join(eight)} "
            f"| {', '.join(r['missed']) or '-'} |"
        )
    excited = sum(r["excited"] for r in rows)
    ok = sum(r["ok"] for r in rows)
    covered = sum(r["covered"] for r in rows)
    current = sum(r["current_covered"] for r in rows)
    walls = np.array([r["wall_s"] for r in rows])
    print()
    print(f"excited parameters within 10 % or covered: {ok} of {excited}")
    print(
        f"coverage of the 95 % intervals: {covered} of {excited} = {covered / excited:.1%} "
        f"(target >= {COVERAGE_TARGET:.0%}); the current's: {current} of {2 * len(rows)}"
    )
    print(f"identification wall time: median {np.median(walls):.1f} s, max {walls.max():.1f} s")
    ratios = [r["rms_identified"] / r["rms_true"] for r in rows if "rms_true" in r]
    if ratios:
        worst = max(ratios)
        print(
            f"figure-eight RMS identified / true: {len(ratios)} vehicles, median "
            f"{np.median(ratios):.3f}, max {worst:.3f} (target <= {RATIO_TARGET}), "
            f"{sum(x <= RATIO_TARGET for x in ratios)} within"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
