"""Appearing and moving discs on a straight line: how close each controller comes.

    python benchmarks/disc_encounters.py [--controllers mpc mpc-nc30] [--set FIELD=VALUE ...]

The 19 cases behind docs/paper-reproduction.md item 4: a line at 0.5 m/s from the origin,
the vehicle starting on it at speed, 40 s, and one disc of radius 0.5 m

* ``appear<t>``: at (10, 0), on the line, appearing at t = 0, 1, ..., 10 s;
* ``appear5-y<y>``: at (10, y), y = -0.3, -0.15, 0.15, 0.3 m, appearing at 5 s;
* ``moving<vy>``: crossing x = 10 m at vy = 0.2 and -0.2 m/s (from 4 m either side), 0.1
  and 0.3 m/s (from -2 and -6 m), there from 5 s to 30 s.

One line per case and controller (min clearance, final and max position error), then a
summary per controller: discs touched (clearance < 0) and the smallest clearance.
"""

from __future__ import annotations

import argparse

from auvmpc.controllers.config import CONTROLLER_PRESETS
from auvmpc.experiments.run import simulate
from auvmpc.scenario import load_scenario

LINE = "reference={type: line, start: [0, 0], heading_deg: 0, speed: 0.5}"


def cases() -> list[tuple[str, str]]:
    """(name, obstacle in scenario syntax) of every case."""
    found = []
    for t in range(11):
        found.append((f"appear{t}", f"{{center: [10.0, 0.0], radius: 0.5, appear_time: {t}}}"))
    for y in (-0.3, -0.15, 0.15, 0.3):
        disc = f"{{center: [10.0, {y}], radius: 0.5, appear_time: 5.0}}"
        found.append((f"appear5-y{y:g}", disc))
    for vy, y0 in ((0.2, -4.0), (-0.2, 4.0), (0.1, -2.0), (0.3, -6.0)):
        disc = (
            f"{{center: [10.0, {y0}], radius: 0.5, velocity: [0.0, {vy}], "
            "appear_time: 5.0, vanish_time: 30.0}"
        )
        found.append((f"moving{vy:g}", disc))
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--controllers", nargs="+", default=["mpc", "mpc-nc30"])
    parser.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE")
    args = parser.parse_args()
    for label in args.controllers:
        clearances = []
        for name, disc in cases():
            scenario = load_scenario(
                "paper-ideal",
                [
                    *CONTROLLER_PRESETS[label],
                    LINE,
                    "initial_state=[0, 0, 0, 0.5, 0, 0]",
                    "duration=40",
                    f"obstacles=[{disc}]",
                    *args.set,
                ],
            )
            metrics = simulate(scenario).metrics
            clearance = metrics["min_obstacle_clearance_m"]
            clearances.append(clearance)
            print(
                f"{label:10s} {name:15s} clearance {clearance:+.3f} m  "
                f"final error {metrics['final_position_error_m']:.4f} m  "
                f"max error {metrics['max_position_error_m']:.3f} m",
                flush=True,
            )
        touched = sum(c < 0 for c in clearances)
        print(f"{label}: {touched} of {len(clearances)} touched, min {min(clearances):+.3f} m")


if __name__ == "__main__":
    main()
