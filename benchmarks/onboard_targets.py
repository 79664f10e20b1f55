"""The exported controller on each target, in one run: the generic x86-64 build against the
tuned one (median step time), and the instructions per step on x86-64 and aarch64 (docs/onboard.md).

    python benchmarks/onboard_targets.py --aarch64 .venv/hpipm-aarch64 \\
        --blasfeo .venv/blasfeo-x64-haswell [--scenario paper-obstacles] [--repeats 5]

Runs the scenario with the exported controller (nmpc, every move free), exports it with the
aarch64 and the tuned BLASFEO, and verifies every target (auvmpc verify-c): the generic and
the tuned x86-64 build ``--repeats`` times each, alternately, for their median step (the
median of the replays' medians: the machine is shared); then each target once with the
instructions counted (callgrind natively, a QEMU plugin for aarch64). Prints the machine
(lscpu's model name, load average) and one table row per target.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import tempfile
from pathlib import Path

from auvmpc.experiments.run import simulate, write_run
from auvmpc.export.c_library import export_c, verify_c
from auvmpc.scenario import load_scenario

_FREE = ["controller.type=nmpc", "controller.control_horizon=null"]


def _machine() -> str:
    model = platform.processor() or "unknown CPU"
    try:
        for line in subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines():
            if line.startswith("Model name:"):
                model = line.split(":", 1)[1].strip()
    except OSError:
        pass
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    return f"{model}, {os.cpu_count()} CPUs, load average {load}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--aarch64", type=Path, required=True, help="make hpipm-aarch64's folder")
    parser.add_argument("--blasfeo", type=Path, required=True, help="a tuned x86-64 BLASFEO")
    parser.add_argument("--scenario", default="paper-obstacles")
    parser.add_argument("--repeats", type=int, default=5)
    arguments = parser.parse_args()
    print(f"machine: {_machine()}")
    with tempfile.TemporaryDirectory(prefix="auvmpc-onboard-") as scratch:
        run_dir, export = Path(scratch) / "run", Path(scratch) / "export"
        write_run(simulate(load_scenario(arguments.scenario, _FREE)), run_dir, figures=False)
        export_c(
            load_scenario(arguments.scenario, []), export,
            blasfeo=arguments.blasfeo, aarch64=arguments.aarch64,
        )  # fmt: skip
        timed = {"x86-64-generic": [], "x86-64-tuned": []}
        for _ in range(arguments.repeats):
            for target, medians in timed.items():
                medians.append(verify_c(export, run_dir, target=target).step_us_median)
        counted = {
            target: verify_c(export, run_dir, target=target, instructions=True)
            for target in ("x86-64-generic", "x86-64-tuned", "aarch64")
        }
    print(f"{arguments.scenario}: {counted['aarch64'].steps} steps, {arguments.repeats} "
          "timed replays per x86-64 build")  # fmt: skip
    header = ("target", "max |dF| N", "status diffs", "heap calls", "max iterations (bound)",
              "median step us", "instructions median", "instructions max")  # fmt: skip
    print(" | ".join(header))
    for target, result in counted.items():
        medians = timed.get(target)
        step = f"{statistics.median(medians):.0f}" if medians else "(emulated)"
        print(" | ".join([
            target, f"{result.max_difference_n:.2g}", str(result.status_differences),
            str(result.heap_calls), f"{result.max_iterations} ({result.iteration_bound})", step,
            f"{statistics.median(result.instructions):,.0f}", f"{max(result.instructions):,}",
        ]))  # fmt: skip
    generic, tuned = (statistics.median(timed[t]) for t in ("x86-64-generic", "x86-64-tuned"))
    print(f"generic / tuned median step: {generic / tuned:.2f}")


if __name__ == "__main__":
    main()
