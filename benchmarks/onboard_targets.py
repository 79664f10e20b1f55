"""The exported controller on each target, in one run: the generic x86-64 build against the
tuned one (median step time), and the instructions per step on x86-64 and aarch64
(docs/onboard.md).

    python benchmarks/onboard_targets.py --aarch64 .venv/hpipm-aarch64 \\
        --blasfeo .venv/blasfeo-x64-haswell --blasfeo-aarch64 .venv/blasfeo-armv8a-a57 \\
        [--generic-blasfeo .venv/blasfeo-x64-sandy-bridge] [--scenario paper-obstacles] \\
        [--repeats 5]

Runs the scenario with the exported controller (nmpc, every move free) and exports it twice:
with the aarch64 HPIPM and both tuned BLASFEOs, and with none of them (the generic x86-64
build alone, whose BLASFEO is then the wheel's GENERIC one everywhere; with the tuned x86-64
BLASFEO exported, the generic build carries it for glibc's loader to take on a CPU with AVX2
and FMA); with ``--generic-blasfeo``, a third time with that BLASFEO (built for AVX) as the
generic build's own and nothing else. Each x86-64 build is replayed ``--repeats`` times, the
builds in turn, for its median step (the median of the replays' medians: the machine is
shared); then every build once with its instructions counted (callgrind natively, a QEMU
plugin for aarch64). Prints the machine (lscpu's model name, load average) and one table row
per build.
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
from auvmpc.solvers.blasfeo_target import blasfeo_target

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
    parser.add_argument("--blasfeo-aarch64", type=Path, required=True, help="a tuned aarch64 one")
    parser.add_argument("--generic-blasfeo", type=Path, help="an AVX x86-64 BLASFEO")
    parser.add_argument("--scenario", default="paper-obstacles")
    parser.add_argument("--repeats", type=int, default=5)
    arguments = parser.parse_args()
    print(f"machine: {_machine()}")
    with tempfile.TemporaryDirectory(prefix="auvmpc-onboard-") as scratch:
        run_dir = Path(scratch) / "run"
        full, plain = Path(scratch) / "export", Path(scratch) / "generic-only"
        write_run(simulate(load_scenario(arguments.scenario, _FREE)), run_dir, figures=False)
        scenario = load_scenario(arguments.scenario, [])
        export_c(scenario, full, aarch64=arguments.aarch64,
                 blasfeo=[arguments.blasfeo, arguments.blasfeo_aarch64])  # fmt: skip
        export_c(scenario, plain)
        builds = {  # label -> (export, target, timed)
            "x86-64-generic, GENERIC BLASFEO": (plain, "x86-64-generic", True),
        }
        if arguments.generic_blasfeo is not None:
            avx = Path(scratch) / "generic-avx"
            export_c(scenario, avx, generic_blasfeo=arguments.generic_blasfeo)
            label = f"x86-64-generic, {blasfeo_target(arguments.generic_blasfeo)} BLASFEO"
            builds[label] = (avx, "x86-64-generic", True)
        builds |= {
            "x86-64-generic, tuned BLASFEO by glibc-hwcaps": (full, "x86-64-generic", True),
            "x86-64-tuned": (full, "x86-64-tuned", True),
            "aarch64 (qemu)": (full, "aarch64", False),
            "aarch64-tuned (qemu)": (full, "aarch64-tuned", False),
        }
        timed = {label: [] for label, (_, _, on) in builds.items() if on}
        for _ in range(arguments.repeats):
            for label, medians in timed.items():
                export, target, _ = builds[label]
                medians.append(verify_c(export, run_dir, target=target).step_us_median)
        counted = {
            label: verify_c(export, run_dir, target=target, instructions=True)
            for label, (export, target, _) in builds.items()
        }
    steps = next(iter(counted.values())).steps
    repeats = arguments.repeats
    print(f"{arguments.scenario}: {steps} steps, {repeats} timed replays per x86-64 build")
    header = ("build", "max |dF| N", "status diffs", "heap calls", "max iterations (bound)",
              "median step us", "instructions median", "instructions max")  # fmt: skip
    print(" | ".join(header))
    for label, result in counted.items():
        medians = timed.get(label)
        step = f"{statistics.median(medians):.0f}" if medians else "(emulated)"
        print(" | ".join([
            label, f"{result.max_difference_n:.2g}", str(result.status_differences),
            str(result.heap_calls), f"{result.max_iterations} ({result.iteration_bound})", step,
            f"{statistics.median(result.instructions):,.0f}", f"{max(result.instructions):,}",
        ]))  # fmt: skip
    tuned = statistics.median(timed["x86-64-tuned"])
    for label in (label for label in timed if label != "x86-64-tuned"):
        print(f"{label} / x86-64-tuned median step: {statistics.median(timed[label]) / tuned:.2f}")


if __name__ == "__main__":
    main()
