"""The fault detector (estimation/fault_detection.py) measured: false detections with no fault,
and what a dead horizontal thruster costs with and without it.

* ``--presets``: every horizontal and 6-DOF preset scenario without a fault, with
  ``fault_detection: true``, under nmpc, ltv-mpc and mpc: the thrusters it wrongly finds
  failed.
* ``--survey FIRST LAST``: random hard surveys (experiments/survey_cases.py: random vehicle,
  90-degree corners, current, +-30 % model error, noise, discs on the path), seeds FIRST..
  LAST-1: the healthy run's false detections; then one random horizontal thruster dead from
  a random time after the transient, flown with the detector and without it (the controller
  not told): detection delay, false detections, RMS after over RMS before the fault, verdict.

    PYTHONPATH=src python benchmarks/fault_detection.py --presets --survey 0 20

``--sigmas S`` runs with the detector's score threshold at S instead of its LOSS_SIGMAS.
Found faults are printed with their score (lambda over its standard error).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import auvmpc
from auvmpc.estimation import fault_detection
from auvmpc.experiments.run import RunSession, run_plant
from auvmpc.experiments.survey_cases import hard_survey_case
from auvmpc.scenario.loader import resolve_document
from auvmpc.sim.loop import PlantDiverged, run_session

CONTROLLERS = ("nmpc", "ltv-mpc", "mpc")


def flown(resolved) -> tuple[RunSession, dict | None]:
    """The session after its run against the scenario's plant, and the metrics (None: the
    plant diverged)."""
    session = RunSession(resolved)
    plant, sensor = run_plant(resolved)
    try:
        run_session(session, plant, sensor, None, resolved.faults)
    except PlantDiverged:
        return session, None
    return session, session.result().metrics


def found_text(session: RunSession) -> str:
    names = session.input_names
    return (
        ", ".join(
            f"{names[f.index]} at {t:g} s ({f.lost:.2f} lost, score {f.sigmas:.1f})"
            for _, t, f in session.faults_found
        )
        or "none"
    )


def presets() -> int:
    print("| preset | controller | healthy thrusters found failed |")
    print("|---|---|---|")
    folder = Path(auvmpc.__file__).parent / "presets" / "scenarios"
    false = 0
    for name in sorted(path.stem for path in folder.glob("*.yaml")):
        scenario = auvmpc.load_scenario(name).scenario
        if not hasattr(scenario, "fault_detection") or scenario.faults:
            continue  # a depth scenario (no horizontal thrusters to watch), or not healthy
        for controller in CONTROLLERS:
            resolved = auvmpc.load_scenario(name, ["fault_detection=true"], controller=controller)
            session, _ = flown(resolved)
            false += len(session.faults_found)
            print(f"| {name} | {controller} | {found_text(session)} |", flush=True)
    print(f"\nfalse detections over the presets: {false}")
    return false


def survey(first: int, last: int) -> None:
    print("| seed | healthy: found | dead | delay s | false | RMS after/before | verdict | "
          "not told: RMS after/before, verdict |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    delays, false, lost = [], 0, {"detected": 0, "not told": 0}
    for seed in range(first, last):
        rng = np.random.default_rng(seed)
        case = hard_survey_case(rng, seed) | {"fault_detection": True}
        healthy, _ = flown(resolve_document(case, Path.cwd()))
        false += len(healthy.faults_found)
        names = healthy.input_names
        actuator = names[int(rng.integers(len(names)))]
        transient, duration = case.get("transient_s", 20.0), case["duration"]
        at = round(float(rng.uniform(transient, 0.8 * duration)), 1)
        fault = [{"actuator": actuator, "at": at, "effectiveness": 0.0}]
        cells = []
        for detect in (True, False):
            faulty = case | {"faults": fault, "fault_detection": detect}
            session, metrics = flown(resolve_document(faulty, Path.cwd()))
            label = "detected" if detect else "not told"
            if metrics is None:
                lost[label] += 1
                cells.append(("-", "-", "-", "diverged"))
                continue
            lost[label] += metrics["verdict"] == "lost"
            before, after = metrics["rms_before_fault_m"], metrics["rms_after_fault_m"]
            ratio = "-" if not before or after is None else f"{after / before:.2f}"
            delay = metrics["fault_detection_delay_s"]
            if detect:
                false += metrics["false_fault_detections"]
                if delay is not None:
                    delays.append(delay)
                    scores = [f.sigmas for _, _, f in session.faults_found
                              if names[f.index] == actuator]  # fmt: skip
                    delay = f"{delay:.2f} (score {scores[0]:.0f})" if scores else f"{delay:.2f}"
            cells.append((delay, metrics["false_fault_detections"], ratio, metrics["verdict"]))
        (delay, wrong, ratio, verdict), (_, _, ratio_untold, verdict_untold) = cells
        delay_text = "not found" if delay is None else delay
        print(f"| {seed} | {found_text(healthy)} | {actuator} at {at:g} s | {delay_text} | "
              f"{wrong} | {ratio} | {verdict} | {ratio_untold}, {verdict_untold} |",
              flush=True)  # fmt: skip
    count = last - first
    print(
        f"\n{count} cases: found {len(delays)} of {count} dead thrusters, delay median "
        f"{np.median(delays) if delays else float('nan'):.2f} s, max "
        f"{max(delays) if delays else float('nan'):.2f} s; false detections {false}; lost "
        f"(or diverged) with the detector {lost['detected']}, not told {lost['not told']}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", action="store_true")
    parser.add_argument("--survey", nargs=2, type=int, metavar=("FIRST", "LAST"))
    parser.add_argument("--sigmas", type=float, help="the detector's score threshold")
    args = parser.parse_args()
    if args.sigmas is not None:
        fault_detection.LOSS_SIGMAS = args.sigmas
    print(f"score threshold {fault_detection.LOSS_SIGMAS:g}")
    began = time.perf_counter()
    if args.presets:
        presets()
    if args.survey:
        survey(*args.survey)
    print(f"\n{time.perf_counter() - began:.0f} s")


if __name__ == "__main__":
    main()
