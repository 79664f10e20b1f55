"""Where the exported C controller's step spends its work: instructions, interior-point
iterations, parts and floating-point operations, counted by valgrind's callgrind.

    python benchmarks/c_step_profile.py EXPORT_DIR RUN_DIR [--step K]

EXPORT_DIR is an ``auvmpc export-c`` folder, RUN_DIR the ``auvmpc run`` folder it replays
(as for ``auvmpc verify-c``). The export is built in place (``make``) and its replay harness
run under callgrind, collecting only inside ``auvmpc_step`` and dumping after every call, so
each sample's count is its own. Instruction counts do not depend on the machine's load, which
is why this, and not a timer, compares variants on a shared machine; ``taskset -c 1 auvmpc
verify-c EXPORT_DIR RUN_DIR`` gives the times.

Printed: the instructions per step (median, mean after the cold first step, the first), the
iterations per step, the per-part split of one step (the first after the cold start with the
median's iteration count, or ``--step K``), and that step's double-precision flops: every
executed instruction's mnemonic is read back from ``objdump`` of the object it is in; scalar
add/sub/mul/div/sqrt/min/max count 1, two-lane SSE2 ``*pd`` 2, fused multiply-adds 2 per lane.
Needs valgrind, callgrind_annotate, objdump and nm (Debian: valgrind, binutils).
"""

from __future__ import annotations

import argparse
import collections
import csv
import json
import re
import statistics
import subprocess
import tempfile
from pathlib import Path

from auvmpc.export.c_targets import host_machine

# The parts of a step, as the functions callgrind attributes them to (inclusive counts).
_HPIPM_SOLVE = "d_ocp_qp_ipm_solve"
_FACTORISE_AND_SOLVE = "d_ocp_qp_fact_solve_kkt_step"
_CORRECTOR = "d_ocp_qp_solve_kkt_step"
_RESIDUALS = ("d_ocp_qp_res_compute", "d_ocp_qp_res_compute_inf_norm")
_STAGE_FUNCTIONS = ("rti_stage", "rti_terminal")
_ESTIMATOR = ("observer_predict", "observer_correct")
_SCALAR = {"addsd", "subsd", "mulsd", "divsd", "sqrtsd", "minsd", "maxsd"}
_PACKED = {"addpd", "subpd", "mulpd", "divpd", "sqrtpd", "minpd", "maxpd"}


def _callgrind(export: Path, run: Path, folder: Path, steps: int | None, instructions: bool):
    """Run the replay under callgrind; returns its stdout rows (k, F..., status, iterations)."""
    command = [
        "valgrind",
        "--tool=callgrind",
        f"--callgrind-out-file={folder}/cg",
        "--dump-after=auvmpc_step",
        "--toggle-collect=auvmpc_step",
    ]
    if instructions:
        command += ["--dump-instr=yes", "--compress-pos=no", "--compress-strings=no"]
    command += [str(_replay(export)), str(run / "log.csv"), str(export / "replay_data.txt")]
    if steps is not None:
        command.append(str(steps))
    result = subprocess.run(command, capture_output=True, text=True, check=True)
    return list(csv.reader(result.stdout.splitlines()))[1:]


def _replay(export: Path) -> Path:
    """The replay ``make`` builds for this computer (export.json's default target)."""
    defaults = json.loads((export / "export.json").read_text())["default_targets"]
    return export / "build" / defaults[host_machine()] / "replay"


def _total(dump: Path) -> int:
    return int(re.search(r"^totals: (\d+)", dump.read_text(), re.M).group(1))


def _inclusive(dump: Path) -> dict[str, int]:
    text = subprocess.run(
        ["callgrind_annotate", "--inclusive=yes", "--threshold=100", str(dump)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    costs = {}
    for line in text.splitlines():
        match = re.match(r"\s*([\d,]+) \(.*?\)\s+\S*?:(\S+?) \[", line)
        if match:
            costs[match.group(2)] = int(match.group(1).replace(",", ""))
    return costs


def _flops(dump: Path) -> tuple[dict[str, list[int]], int]:
    """Per object: [instructions, flops] of one --dump-instr dump; and all instructions."""
    cost: dict[tuple[str, int], int] = collections.defaultdict(int)
    entry: dict[tuple[str, str], int] = {}
    obj = function = None
    call_line = False
    for line in dump.read_text().splitlines():
        if line.startswith("ob="):
            obj = line[3:]
        elif line.startswith("fn="):
            function = line[3:]
        elif line.startswith("calls="):
            call_line = True  # the next cost line is the call's inclusive cost
        else:
            match = re.match(r"^(0x[0-9a-f]+) \d+ (\d+)", line)  # positions: instr line
            if match:
                if call_line:
                    call_line = False
                    continue
                address = int(match.group(1), 16)
                cost[(obj, address)] += int(match.group(2))
                key = (obj, function)
                entry[key] = min(entry.get(key, address), address)
    totals: dict[str, list[int]] = collections.defaultdict(lambda: [0, 0])
    for name in {o for o, _ in cost}:
        path = Path(name)
        if not path.exists():
            continue
        dynamic = ".so" in path.name
        symbols = {}
        listing = subprocess.run(
            ["nm", "-D", name] if dynamic else ["nm", name], capture_output=True, text=True
        ).stdout
        for symbol in listing.splitlines():
            parts = symbol.split()
            if len(parts) == 3 and parts[1] in "tTwW":
                symbols[parts[2]] = int(parts[0], 16)
        # Where the object was loaded: a function's first executed address minus its symbol.
        bases = [a - symbols[f] for (o, f), a in entry.items() if o == name and f in symbols]
        if not bases:
            continue
        base = collections.Counter(bases).most_common(1)[0][0]
        mnemonics = {}
        disassembly = subprocess.run(
            ["objdump", "-d", "--no-show-raw-insn", name], capture_output=True, text=True
        ).stdout
        for instruction in disassembly.splitlines():
            match = re.match(r"^\s*([0-9a-f]+):\s+(\S+)", instruction)
            if match:
                mnemonics[int(match.group(1), 16)] = match.group(2)
        for (o, address), count in cost.items():
            if o == name:
                totals[path.name][0] += count
                totals[path.name][1] += count * _flop_weight(mnemonics.get(address - base, ""))
    return totals, sum(cost.values())


def _flop_weight(mnemonic: str) -> int:
    if re.match(r"v?f(n)?m(add|sub)", mnemonic):
        return 2 if mnemonic.endswith("sd") else 4
    base = mnemonic[1:] if mnemonic.startswith("v") else mnemonic
    return 1 if base in _SCALAR else 2 if base in _PACKED else 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("export", type=Path)
    parser.add_argument("run", type=Path)
    parser.add_argument("--step", type=int, default=None, help="the sample to split (0-based)")
    arguments = parser.parse_args()
    export, run = arguments.export, arguments.run
    subprocess.run(["make", "-s", "-C", str(export)], check=True, stdout=subprocess.DEVNULL)
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        rows = _callgrind(export, run, folder, None, instructions=False)
        counts = [_total(folder / f"cg.{k + 1}") for k in range(len(rows))]
        iterations = [int(row[-1]) for row in rows]
        typical = statistics.median_low(iterations[1:])
        step = arguments.step
        if step is None:
            step = next(k for k in range(1, len(rows)) if iterations[k] == typical)
        costs = _inclusive(folder / f"cg.{step + 1}")
    print(f"{export}: {len(rows)} steps")
    print(
        f"  instructions per step: median {statistics.median(counts):,.0f}, "
        f"mean after the first {statistics.mean(counts[1:]):,.0f}, first {counts[0]:,}"
    )
    print(
        f"  interior-point iterations per step: median {statistics.median(iterations):g}, "
        f"mean after the first {statistics.mean(iterations[1:]):.2f}, "
        f"max after the first {max(iterations[1:])}, first {iterations[0]}"
    )
    total = costs.get("auvmpc_step", 0)
    solve = costs.get(_HPIPM_SOLVE, 0)
    factorise, corrector = costs.get(_FACTORISE_AND_SOLVE, 0), costs.get(_CORRECTOR, 0)
    residuals = sum(costs.get(name, 0) for name in _RESIDUALS)
    stage = sum(costs.get(name, 0) for name in _STAGE_FUNCTIONS)
    data = sum(
        v for name, v in costs.items() if name.startswith(("d_ocp_qp_set_", "d_ocp_qp_sol_get_"))
    )
    estimator = sum(costs.get(name, 0) for name in _ESTIMATOR)
    rest = total - solve - stage - data - estimator
    print(f"  step {step} ({iterations[step]} iterations): {total:,} instructions")
    print(
        f"    HPIPM solve {solve:,} (factorisation and solve {factorise:,}, corrector "
        f"{corrector:,}, residuals {residuals:,}, "
        f"other {solve - factorise - corrector - residuals:,})"
    )
    print(
        f"    stage functions (CasADi) {stage:,}; HPIPM data set and read {data:,}; "
        f"estimator {estimator:,}; the rest (shift, shell, checks) {rest:,}"
    )
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch)
        _callgrind(export, run, folder, step + 1, instructions=True)
        per_object, instructions = _flops(folder / f"cg.{step + 1}")
    flops = sum(f for _, f in per_object.values())
    read_back = sum(i for i, _ in per_object.values())
    print(
        f"    flops {flops:,} ("
        + ", ".join(
            f"{name} {f:,}" for name, (_, f) in sorted(per_object.items(), key=lambda kv: -kv[1][1])
        )
        + f"); instructions read back {read_back:,} of {instructions:,}"
    )


if __name__ == "__main__":
    main()
