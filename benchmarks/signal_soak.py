"""Signals at random moments, many times (issue 28's done-when): SIGINT and SIGTERM sent to
``auvmpc run`` and ``auvmpc campaign`` at a random time during the command, TRIES times each.

Every try must end with exit 130 (SIGINT) or 143 (SIGTERM), never 1, or with 0 where the
command finished before the signal (a process the signal itself ended, outside auvmpc's
handler, while Python imports before it is installed or exits after it is put back, counts
as 130 / 143: the exit status a shell shows for it); leave the user's file beside the
output untouched; leave no complete-looking result (a run: no folder at all; a campaign:
its store holds only finished rows); and an interrupted campaign, resumed, must end with
every run exactly once. Prints one row per (command, signal) and exits 1 if any try broke a
rule.

    python benchmarks/signal_soak.py [--tries 20] [--seed 28] [--command run] [--signal SIGINT]
"""

from __future__ import annotations

import argparse
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from auvmpc.experiments.campaign import load_results

CODES = {signal.SIGINT: 130, signal.SIGTERM: 143}
USER_FILE, USER_TEXT = "notes.txt", "the user's own notes"
CAMPAIGN_RUNS = 6
# Signals land anywhere from the imports (about 1.5 s on 2 cores) to deep in the work.
WINDOW_S = {"run": (0.2, 6.0), "campaign": (0.2, 7.0)}
COMMANDS = {
    "run": ["run", "paper-obstacles", "--set", "duration=300", "--no-figures", "--out"],
    "campaign": [
        "campaign", "paper-robustness", "--runs", str(CAMPAIGN_RUNS), "--workers", "2",
        "--no-report", "--out",
    ],
}  # fmt: skip


def _auvmpc(args: list[str], cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "auvmpc", *args],
        cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


def one_try(
    command: str, signum: signal.Signals, delay: float, work: Path
) -> tuple[bool, list[str]]:
    """One signal after ``delay`` s: whether the command had finished before it, and the
    rules the try broke (none: [])."""
    work.mkdir()
    (work / USER_FILE).write_text(USER_TEXT)
    process = _auvmpc([*COMMANDS[command], "out"], work)
    time.sleep(delay)
    finished_first = process.poll() is not None
    if not finished_first:
        process.send_signal(signum)
    _, stderr = process.communicate(timeout=120)
    broken = []
    expected = 0 if finished_first else CODES[signum]
    code = 128 - process.returncode if process.returncode < 0 else process.returncode
    if code != expected:
        broken.append(f"exit {process.returncode} (wanted {expected}): {stderr.strip()[-200:]}")
    if "Traceback" in stderr:
        broken.append("a traceback")
    if (work / USER_FILE).read_text() != USER_TEXT:
        broken.append("the user's file changed")
    leftovers = [p.name for p in work.iterdir() if p.name not in (USER_FILE, "out")]
    if leftovers:
        broken.append(f"left {leftovers}")
    out = work / "out"
    if command == "run" and code != 0 and out.exists():
        broken.append("a run folder after an interrupted run")
    if command == "campaign" and code in CODES.values():
        resumed = subprocess.run(
            [sys.executable, "-m", "auvmpc", *COMMANDS[command], "out"],
            cwd=work, capture_output=True, text=True, timeout=600,
        )  # fmt: skip
        if resumed.returncode != 0:
            broken.append(f"resume exit {resumed.returncode}: {resumed.stderr.strip()[-200:]}")
        else:
            rows = load_results(out)
            if rows["index"].tolist() != list(range(CAMPAIGN_RUNS)):
                broken.append(f"resumed to the runs {rows['index'].tolist()}")
            if (rows["status"] != "ok").any():
                broken.append("a resumed run failed")
    return finished_first, broken


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tries", type=int, default=20)
    parser.add_argument("--seed", type=int, default=28)
    parser.add_argument("--command", choices=list(COMMANDS), action="append")
    parser.add_argument("--signal", choices=[s.name for s in CODES], action="append")
    options = parser.parse_args()
    rng = np.random.default_rng(options.seed)
    failures = 0
    print(f"{'command':9} {'signal':8} {'tries':>5} {'stopped':>7} {'finished':>8} {'broken':>6}")
    with tempfile.TemporaryDirectory(prefix="auvmpc-soak-") as scratch:
        for command in options.command or COMMANDS:
            for signum in [signal.Signals[name] for name in options.signal or []] or CODES:
                stopped = finished = broken = 0
                for i in range(options.tries):
                    delay = float(rng.uniform(*WINDOW_S[command]))
                    work = Path(scratch) / f"{command}-{signum.name}-{i}"
                    finished_first, rules = one_try(command, signum, delay, work)
                    finished += finished_first
                    stopped += not finished_first
                    if rules:
                        broken += 1
                        print(f"  try {i} at {delay:.2f} s: {'; '.join(rules)}", flush=True)
                failures += broken
                print(
                    f"{command:9} {signum.name:8} {options.tries:5d} {stopped:7d} "
                    f"{finished:8d} {broken:6d}",
                    flush=True,
                )
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
