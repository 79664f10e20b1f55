"""A jammed fin on the REMUS 100 (issue 26's bar: "a stuck fin on the torpedo is detected
and the run ends degraded, not lost, where the remaining actuators can still hold depth").

Each fault is flown four ways: declared (the mission tells six-dof-nmpc the fin's value,
``Observation.stuck_at``, and it flies with the fin fixed there), declared as not acting
only (effectiveness 0, the fin's lift left to the controller's estimates: what a
controller that does not read ``stuck_at`` gets), found by the 6-DOF fault detector
(``fault_detection: true``, nobody told), and not told at all. Printed: the detection delay
and the value found, the depth error's and the cross-track error's RMS before the fault
(from the transient) and after it, and the verdict.

    PYTHONPATH=src python benchmarks/stuck_fin.py --scenario remus100-survey --at 150 \\
        --faults stern_planes_deg:2 stern_planes_deg:5 stern_planes_deg:10 rudder_deg:5

``--healthy`` first flies the scenario with the detector and no fault (its false
detections).
"""

from __future__ import annotations

import argparse
import time
from unittest import mock

import auvmpc
from auvmpc.experiments.run import RunSession, run_plant
from auvmpc.sim.faults import FaultSchedule
from auvmpc.sim.loop import PlantDiverged, run_session

MODES = ("declared", "declared, effectiveness 0 only", "detector", "not told")


def flown(name: str, overrides: list[str]) -> tuple[RunSession, dict | None, float]:
    """The session after its run, the metrics (None: the plant diverged) and the wall time."""
    resolved = auvmpc.load_scenario(name, overrides)
    session = RunSession(resolved)
    plant, sensor = run_plant(resolved)
    started = time.perf_counter()
    try:
        run_session(session, plant, sensor, None, resolved.faults)
    except PlantDiverged:
        return session, None, time.perf_counter() - started
    return session, session.result().metrics, time.perf_counter() - started


def _number(value, digits: str = ".3f") -> str:
    return "-" if value is None else format(value, digits)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="remus100-survey")
    parser.add_argument("--at", type=float, default=150.0, help="when the fin jams (s)")
    parser.add_argument("--faults", nargs="+", default=["stern_planes_deg:5"],
                        help="ACTUATOR:VALUE each")  # fmt: skip
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES)
    parser.add_argument("--healthy", action="store_true")
    parser.add_argument("--set", nargs="*", default=[], help="further scenario overrides")
    args = parser.parse_args()
    if args.healthy:
        session, metrics, wall = flown(args.scenario, [*args.set, "faults=[]",
                                                       "fault_detection=true"])  # fmt: skip
        found = [(session.input_names[f.index], t) for _, t, f in session.faults_found]
        print(f"healthy, detector on: found {found or 'nothing'}, verdict "
              f"{metrics and metrics['verdict']} ({wall:.0f} s wall)\n")  # fmt: skip
    print("| fault | told | delay s | found | depth RMS before, after m | cross-track RMS "
          "before, after m | verdict | wall s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for item in args.faults:
        actuator, value = item.split(":")
        for mode in args.modes:
            declared = "true" if mode.startswith("declared") else "false"
            overrides = [
                *args.set,
                f"faults=[{{actuator: {actuator}, at: {args.at}, stuck_at: {value}, "
                f"declared: {declared}}}]",
                f"fault_detection={'true' if mode == 'detector' else 'false'}",
            ]
            if mode == "declared, effectiveness 0 only":
                with mock.patch.object(FaultSchedule, "stuck", lambda self, t: None):
                    session, metrics, wall = flown(args.scenario, overrides)
            else:
                session, metrics, wall = flown(args.scenario, overrides)
            if metrics is None:
                print(f"| {actuator} at {value} | {mode} | | | | | diverged | {wall:.0f} |")
                continue
            found = ", ".join(
                f"{session.input_names[f.index]} "
                + (f"stuck at {f.stuck_at:.2f}" if f.stuck_at is not None else f"{f.lost:.2f} lost")
                for _, _, f in session.faults_found
            )
            print(
                f"| {actuator} at {value} | {mode} | "
                f"{_number(metrics['fault_detection_delay_s'], '.2f')} | {found or '-'} | "
                f"{_number(metrics['depth_rms_before_fault_m'])}, "
                f"{_number(metrics['depth_rms_after_fault_m'])} | "
                f"{_number(metrics['cross_track_rms_before_fault_m'])}, "
                f"{_number(metrics['cross_track_rms_after_fault_m'])} | "
                f"{metrics['verdict']} | {wall:.0f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
