"""The exported controller on a random vehicle, replayed on every target: how far each
target's commands are from the Python run's (issue 29's 1e-6 N bar, docs/onboard.md).

    python benchmarks/random_vehicle_export.py --aarch64 .venv/hpipm-aarch64 \\
        --blasfeo .venv/blasfeo-x64-haswell --blasfeo-aarch64 .venv/blasfeo-armv8a-a57 \\
        [--vehicle 2] [--set controller.thrust_penalty=absolute] [--fast-tolerance 1e-8]

The scenario is the vehicle sweep's (benchmarks/vehicle_sweep.py, ``sweep_scenario``): random
vehicle ``--vehicle`` on a circle at 0.3 m/s for 60 s, with a 0.5 m disc on the circle a
quarter turn ahead, run with the exported controller (nmpc, every move free, the default
offset-free estimator) and exported with the aarch64 HPIPM and both tuned BLASFEOs. Each
target replays the run once (``auvmpc verify-c``; aarch64 under qemu); the table gives the
largest |F_C - F_Python|, at which step, and the steps whose status differs.
``--fast-tolerance``: the real-time QP's fast-pass tolerance for the run and the export alike
(solvers/hpipm.py, 1e-4), to see how the differences move with it.
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

from vehicle_sweep import sweep_scenario

from auvmpc.experiments.run import simulate, write_run
from auvmpc.export.c_library import export_c, verify_c
from auvmpc.scenario import ResolvedScenario, apply_override, validate_scenario
from auvmpc.solvers import hpipm

_FREE = ["controller.type=nmpc", "controller.control_horizon=null"]
_TARGETS = ("x86-64-generic", "x86-64-tuned", "aarch64", "aarch64-tuned")


def scenario(vehicle: int, overrides: list[str]) -> dict:
    """The sweep's circle for random vehicle ``vehicle`` with a 0.5 m disc on it, a quarter
    turn after the start."""
    data = sweep_scenario(vehicle)
    radius = data["reference"]["radius"]
    data["obstacles"] = [{"center": [0.0, radius], "radius": 0.5}]
    for override in [*_FREE, *overrides]:
        apply_override(data, override)
    return data


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--aarch64", type=Path, required=True, help="make hpipm-aarch64's folder")
    parser.add_argument("--blasfeo", type=Path, required=True, help="a tuned x86-64 BLASFEO")
    parser.add_argument("--blasfeo-aarch64", type=Path, required=True, help="a tuned aarch64 one")
    parser.add_argument("--vehicle", type=int, default=2, help="random vehicle's seed")
    parser.add_argument("--set", action="append", default=[], help="an override, as for run")
    parser.add_argument("--fast-tolerance", type=float, help="the fast pass's (default 1e-4)")
    arguments = parser.parse_args()
    if arguments.fast_tolerance is not None:  # before anything reads the settings
        mode, mu0, _, warm = hpipm._FAST_PASS
        hpipm._FAST_PASS = (mode, mu0, arguments.fast_tolerance, warm)
    data = scenario(arguments.vehicle, arguments.set)
    resolved = ResolvedScenario(validate_scenario(data), Path.cwd())
    with tempfile.TemporaryDirectory(prefix="auvmpc-random-export-") as scratch:
        run_dir, export = Path(scratch) / "run", Path(scratch) / "export"
        result = simulate(resolved)
        write_run(result, run_dir, figures=False)
        export_c(resolved, export, aarch64=arguments.aarch64,
                 blasfeo=[arguments.blasfeo, arguments.blasfeo_aarch64])  # fmt: skip
        tolerance = hpipm._FAST_PASS[2]
        print(f"{data['name']}: {data['vehicle']['description']}, {result.metrics['verdict']}, "
              f"fast-pass tolerance {tolerance:g}, {' '.join(arguments.set)}")  # fmt: skip
        print("target | max |F_C - F_Python| N | at step | status differences")
        for target in _TARGETS:
            verified = verify_c(export, run_dir, target=target)
            print(f"{target} | {verified.max_difference_n:.2g} | {verified.worst_step} | "
                  f"{verified.status_differences}")  # fmt: skip


if __name__ == "__main__":
    main()
