"""Every model from one 6-DOF log: how close, and how often the 95 % intervals cover the
truth (issue 27, docs/identification.md).

For each vehicle and noise seed: the 6-DOF excite manoeuvre (``design_excitation(...,
dof=Dof.SIX_DOF)``, 0.1 s rows, box 5 m, phase seed 0) flown on the vehicle's 6-DOF model
(RK4 at the plant's step) from rest 5 m down, noise on what an AHRS, gyro and DVL measure
(attitude 0.002 rad, rates and velocities 0.005), identified by ``identify_six_dof`` from a
start with every one of the 20 parameters 30 % off (alternately up and down, in the 3-DOF
fields, the heave section and the six_dof section alike). Prints per parameter: truth,
identified, interval, excited, the model-error warning, within 10 %, covered; then the
coverage per model.

    PYTHONPATH=src python benchmarks/identification_six_dof.py [--duration 40]
        [--vehicles bluerov2-heavy jmse2210] [--seeds 0 1 2]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from auvmpc.identification.excitation import Dof, design_excitation
from auvmpc.identification.six_dof_log import (
    identify_six_dof,
    offset_vehicle,
    parameter_values,
)
from auvmpc.models.six_dof import SIX_DOF, integrate, plant_step_length, six_dof_model
from auvmpc.models.vehicle import load_vehicle
from auvmpc.sim.plant import substeps_for

SAMPLE_TIME_S = 0.1
ATTITUDE_NOISE_RAD = 0.002
RATE_NOISE = 0.005  # rad/s and m/s
ERROR = 0.3
WITHIN = 0.1


def flown(truth, duration: float) -> tuple[np.ndarray, np.ndarray]:
    """The true 6-DOF states (N+1, 12) and the thrust table (N, n) of the manoeuvre."""
    excitation = design_excitation(truth, duration, SAMPLE_TIME_S, seed=0, box_m=5.0,
                                   dof=Dof.SIX_DOF)  # fmt: skip
    model = six_dof_model(truth)
    substeps = substeps_for(SAMPLE_TIME_S, plant_step_length(truth, SAMPLE_TIME_S))
    states = np.zeros((len(excitation.thrust) + 1, SIX_DOF.size))
    states[0, SIX_DOF.index("z")] = 5.0
    for k, row in enumerate(excitation.thrust):
        states[k + 1] = integrate(model, states[k], row, SAMPLE_TIME_S, substeps)
    return states, excitation.thrust


def noisy(states: np.ndarray, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    measured = states.copy()
    angles = [SIX_DOF.index(name) for name in ("phi", "theta", "psi")]
    rates = [SIX_DOF.index(name) for name in ("u", "v", "w", "p", "q", "r")]
    measured[:, angles] += rng.normal(0, ATTITUDE_NOISE_RAD, (len(states), 3))
    measured[:, rates] += rng.normal(0, RATE_NOISE, (len(states), 6))
    return measured


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=40.0)
    parser.add_argument("--vehicles", nargs="+", default=["bluerov2-heavy"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0])
    args = parser.parse_args()
    print("| vehicle | seed | parameter | truth | identified | 95 % interval | excited | "
          "model error | within 10 % | covered |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    counts: dict[str, list[int]] = {}
    for name in args.vehicles:
        truth = load_vehicle(name)
        states, thrust = flown(truth, args.duration)
        true_values, start = parameter_values(truth), offset_vehicle(truth, ERROR)
        for seed in args.seeds:
            started = time.perf_counter()
            found = identify_six_dof([(name, SAMPLE_TIME_S, noisy(states, seed), thrust)], start)
            seconds = time.perf_counter() - started
            for p in found.parameters:
                value, (low, high) = true_values[p.name], p.ci95
                covered = low <= value <= high
                within = abs(p.value - value) <= WITHIN * abs(value)
                model = "roll-pitch" if p.name.startswith("six_dof.") else (
                    "heave" if p.name.startswith("heave.") else "horizontal")  # fmt: skip
                tally = counts.setdefault(model, [0, 0, 0])
                tally[0] += covered
                tally[1] += within or covered
                tally[2] += 1
                print(f"| {name} | {seed} | {p.name} | {value:.4g} | {p.value:.4g} | "
                      f"[{low:.4g}, {high:.4g}] | {'yes' if p.excited else 'no'} | "
                      f"{'yes' if p.model_error else 'no'} | "
                      f"{'yes' if within else 'no'} | {'yes' if covered else 'no'} |")  # fmt: skip
            rms = dict(zip(found.outputs, np.round(found.validation_rms, 4), strict=True))
            print(f"<!-- {name} seed {seed}: identify {seconds:.1f} s; held-out RMS {rms} -->")
    for model, (covered, ok, total) in counts.items():
        print(f"{model}: covered {covered} of {total}, within 10 % or covered {ok} of {total}")


if __name__ == "__main__":
    main()
