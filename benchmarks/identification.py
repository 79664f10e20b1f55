"""Does ``auvmpc identify`` recover a vehicle from its excitation manoeuvre? (issue 27)

For each vehicle: design the ``auvmpc excite`` manoeuvre, simulate its scenario with sensor
noise (``sensing.std``, below), identify from the NOISY velocities the controller was given
(the run's in-memory log; log.csv keeps the truth) starting from a file with every
hydrodynamic parameter off by +-30 % (alternating signs, seeded), and print per parameter:
truth, start, identified, 95 % interval, whether the report calls it excited, and whether
it is within 10 % of the truth or its interval covers it.

    PYTHONPATH=src python benchmarks/identification.py [--duration 300] [--vehicles ...]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from auvmpc.controllers.playback import write_thrust_table
from auvmpc.experiments.run import simulate
from auvmpc.identification.estimation import PARAMETERS, identify
from auvmpc.identification.excitation import design_excitation, excitation_scenario
from auvmpc.identification.logs import VelocityLog
from auvmpc.models.vehicle import VehicleParams, load_vehicle
from auvmpc.scenario import load_scenario

# Sensor noise of [x, y, psi, u, v, r] (m, m, rad, m/s, m/s, rad/s): a DVL-grade velocity
# (5 mm/s) and a gyro-grade yaw rate (0.005 rad/s).
SENSING_STD = [0.05, 0.05, 0.01, 0.005, 0.005, 0.005]
ERROR = 0.3  # start file: every parameter off by this share
WITHIN = 0.1  # pass: within this share of the truth, or the interval covers the truth


def perturbed(truth, rng):
    signs = rng.choice([-1.0, 1.0], size=len(PARAMETERS))
    data = truth.model_dump()
    for sign, name in zip(signs, PARAMETERS, strict=True):
        data[name] = float(getattr(truth, name)) * (1.0 + sign * ERROR)
    return load_vehicle(data)


def measured_excite_log(
    truth: VehicleParams,
    name: str,
    duration: float,
    seed: int,
    current=None,
    plant_step: float | None = None,
) -> VelocityLog:
    """The ``auvmpc excite`` manoeuvre of ``truth`` simulated as its scenario with sensor
    noise (SENSING_STD), in a constant water ``current`` (north, east: m/s) if given, the
    plant's RK4 step ``plant_step`` (s) if given: the noisy velocities and heading the
    controller was given, and the thrusts."""
    excitation = design_excitation(truth, duration, seed=seed)
    with tempfile.TemporaryDirectory() as folder:
        table = Path(folder) / "excite.csv"
        write_thrust_table(
            table, excitation.sample_time, excitation.thrust, truth.actuators.layout.names
        )
        scenario = excitation_scenario(name, excitation, "excite.csv", "bench", 15.0)
        scenario["vehicle"] = truth.model_dump(mode="json")
        if current is not None:
            velocity = [float(current[0]), float(current[1]), 0.0]
            scenario["disturbance"] = {"water_current": {"velocity_m_per_s": velocity}}
        if plant_step is not None:
            scenario["plant"] = {"max_step": plant_step}
        path = Path(folder) / "excite.yaml"
        path.write_text(yaml.safe_dump(scenario, sort_keys=False))
        resolved = load_scenario(path, [f"sensing.std={SENSING_STD}", f"seed={seed}"])
        log = simulate(resolved).log
    return VelocityLog(name, log.sample_time, log.measured[:, 3:6], log.thrust,
                       heading=log.measured[:, 2])  # fmt: skip


def run(vehicle_name: str, duration: float, seed: int) -> list[dict]:
    truth = load_vehicle(vehicle_name)
    measured = measured_excite_log(truth, vehicle_name, duration, seed)
    start = perturbed(truth, np.random.default_rng(seed))
    began = time.perf_counter()
    found = identify([measured], start)
    wall = time.perf_counter() - began
    rows = []
    for estimate in found.parameters:
        true_value = float(getattr(truth, estimate.name))
        low, high = estimate.ci95
        close = abs(estimate.value - true_value) <= WITHIN * abs(true_value)
        covered = low <= true_value <= high
        rows.append(
            {
                "vehicle": vehicle_name,
                "name": estimate.name,
                "truth": true_value,
                "start": estimate.start,
                "value": estimate.value,
                "ci95": (low, high),
                "excited": estimate.excited,
                "ok": close or covered or not estimate.excited,
                "covered": covered,
            }
        )
    print(
        f"{vehicle_name}: {found.fit_samples} fit + {found.validation_samples} held-out samples,"
        f" identify {wall:.1f} s, IPOPT {found.solver_status} ({found.iterations} it), "
        f"validation RMS u,v,r {np.round(found.validation_rms, 4).tolist()} "
        f"(start {np.round(found.validation_rms_start, 4).tolist()})"
    )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=300.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument(
        "--vehicles", nargs="+", default=["jmse2210", "bluerov2-heavy", "videoray-pro3"]
    )
    args = parser.parse_args()
    rows = [row for name in args.vehicles for row in run(name, args.duration, args.seed)]
    print()
    print(
        "| vehicle | parameter | truth | start | identified | 95 % interval | excited | within? |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for row in rows:
        low, high = row["ci95"]
        verdict = "yes" if row["ok"] else "NO"
        if not row["excited"]:
            verdict = "n/a (start kept)"
        print(
            f"| {row['vehicle']} | {row['name']} | {row['truth']:.4g} | {row['start']:.4g} | "
            f"{row['value']:.4g} | [{low:.4g}, {high:.4g}] | "
            f"{'yes' if row['excited'] else 'no'} | {verdict} |"
        )
    failed = [f"{r['vehicle']}.{r['name']}" for r in rows if not r["ok"]]
    covered = sum(row["covered"] for row in rows)
    print(f"\nintervals covering the truth: {covered} of {len(rows)}")
    print(f"excited and neither within {WITHIN:.0%} nor covered: {failed or 'none'}")


if __name__ == "__main__":
    main()
