"""Parallel speed-up of a campaign on local processes: 1 worker against N workers.

    python benchmarks/campaign_speedup.py [--campaign paper-robustness] [--runs 200]
                                          [--workers 2] [--repeats 1] [--serial]

Each timing is one whole ``run_campaign`` call into a fresh folder (validation, pool
start-up, every run, one SQLite transaction per run), i.e. what a user waits for.
Speed-up = T(1 worker) / T(N workers); efficiency = speed-up / N (1.0 = ideal linear).
With ``--repeats`` the 1-worker and N-worker campaigns alternate and the fastest of each
is kept, which filters out other load on the machine. ``--serial`` also times a plain
loop of ``simulate`` in this process (no pool, no database) as a floor for one core.
The N-worker rows are checked against the 1-worker rows (everything but wall-clock
columns must be identical).

Speed-up needs idle cores: other processes on the machine take CPU from the N-worker
campaign first. The script prints the load average before and after, and ``--wait-idle S``
waits up to S seconds for the 1-minute load average to fall below 0.5 before starting.
"Utilization" is the time the workers spent inside runs (sum of ``wall_s``) over
workers x wall time: what the campaign machinery (start-up, dispatch, one SQLite commit per
run) leaves idle, whatever else the machine is doing.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from auvmpc.experiments.bench import machine_info
from auvmpc.experiments.campaign import (
    NONDETERMINISTIC_COLUMNS,
    load_campaign,
    load_results,
    run_campaign,
    scenario_for_run,
)
from auvmpc.experiments.run import simulate


def timed_campaign(campaign, runs: int, workers: int, folder: Path):
    """Wall time, worker utilization and the deterministic columns of one fresh campaign."""
    out = Path(tempfile.mkdtemp(prefix=f"w{workers}-", dir=folder))
    started = time.perf_counter()
    summary = run_campaign(campaign, out, workers=workers, runs=runs)
    wall = time.perf_counter() - started
    if summary.ok + summary.failed != runs:
        raise RuntimeError(f"{runs} runs expected, got {summary}")
    frame = load_results(out)
    utilization = frame["wall_s"].sum() / (workers * wall)
    return (
        wall,
        utilization,
        frame.drop(columns=[c for c in NONDETERMINISTIC_COLUMNS if c in frame]),
    )


def wait_idle(limit_s: float) -> None:
    deadline = time.monotonic() + limit_s
    while os.getloadavg()[0] >= 0.5 and time.monotonic() < deadline:
        time.sleep(10)


def serial_loop(campaign, runs: int) -> float:
    scenarios = [scenario_for_run(campaign, k) for k in range(runs)]
    started = time.perf_counter()
    for resolved in scenarios:
        simulate(resolved)
    return time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--campaign", default="paper-robustness", help="built-in name or file")
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--serial", action="store_true", help="also time a plain in-process loop")
    parser.add_argument("--wait-idle", type=float, default=0.0, help="wait up to S s for idle")
    args = parser.parse_args()
    wait_idle(args.wait_idle)

    campaign = load_campaign(args.campaign)
    machine = machine_info()
    print(
        f"machine: {machine['cpu_model']}, {machine['cpu_count']} CPUs "
        f"({machine['cpus_allowed']} allowed), {machine['platform']}, Python {machine['python']}"
    )
    print(f"campaign: {campaign.spec.name} ({campaign.spec.description}), first {args.runs} runs")
    print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    one, many = [], []
    with tempfile.TemporaryDirectory(prefix="campaign-speedup-") as folder:
        for repeat in range(args.repeats):
            wall_1, use_1, rows_1 = timed_campaign(campaign, args.runs, 1, Path(folder))
            wall_n, use_n, rows_n = timed_campaign(campaign, args.runs, args.workers, Path(folder))
            if not rows_1.equals(rows_n):
                raise RuntimeError("1-worker and N-worker campaigns stored different rows")
            one.append((wall_1, use_1))
            many.append((wall_n, use_n))
            print(
                f"repeat {repeat + 1}: 1 worker {wall_1:.2f} s ({100 * use_1:.1f} % used), ", end=""
            )
            print(f"{args.workers} workers {wall_n:.2f} s ({100 * use_n:.1f} % used)")
        serial = serial_loop(campaign, args.runs) if args.serial else None
    (best_1, use_1), (best_n, use_n) = min(one), min(many)
    speedup = best_1 / best_n
    print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    print()
    print("| setting | wall s | s per run | worker utilization |")
    print("|---|---:|---:|---:|")
    if serial is not None:
        print(f"| in-process loop, no pool | {serial:.2f} | {serial / args.runs:.3f} | - |")
    print(f"| campaign, 1 worker | {best_1:.2f} | {best_1 / args.runs:.3f} | {100 * use_1:.1f} % |")
    print(
        f"| campaign, {args.workers} workers | {best_n:.2f} | {best_n / args.runs:.3f} "
        f"| {100 * use_n:.1f} % |"
    )
    print()
    print(
        f"speed-up {speedup:.2f}x on {args.workers} workers, "
        f"efficiency {100 * speedup / args.workers:.1f} % of ideal linear"
        + (
            f" ({100 * serial / best_n / args.workers:.1f} % against the in-process loop)"
            if serial
            else ""
        )
    )
    print("rows identical between 1 and N workers (wall-clock columns excluded): yes")


if __name__ == "__main__":
    main()
