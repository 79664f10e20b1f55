"""``python -m auvmpc.experiments.campaign FILE --out DIR [--workers N] [--runs N]
[--scheduler ADDR] [--controller LABEL] [--yardstick-from DIR]``:
a minimal entry point without the CLI's dependencies (the kill-and-resume tests use it)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from auvmpc import interrupts
from auvmpc.errors import ConfigError
from auvmpc.experiments.campaign.execute import run_campaign
from auvmpc.experiments.campaign.spec import RESULTS_FILE, load_campaign
from auvmpc.experiments.campaign.store import count_finished


def main(argv: Sequence[str] | None = None) -> int:
    """Minimal entry point without the CLI's dependencies; returns the exit code."""
    parser = argparse.ArgumentParser(
        prog="python -m auvmpc.experiments.campaign",
        description="Run or resume a robustness campaign.",
    )
    parser.add_argument("campaign", help="built-in campaign name or campaign YAML")
    parser.add_argument("--out", required=True, type=Path, help="campaign folder")
    parser.add_argument(
        "--workers", type=int, default=None, help="local processes (default: all CPUs)"
    )
    parser.add_argument("--runs", type=int, default=None, help="run only the first N runs")
    parser.add_argument("--scheduler", default=None, help="Dask scheduler address")
    parser.add_argument(
        "--controller", default=None, help="controller label of the tested runs (not the yardstick)"
    )
    parser.add_argument(
        "--yardstick-from",
        type=Path,
        default=None,
        help="folder of this campaign with another controller: copy its yardstick twins",
    )
    args = parser.parse_args(argv)
    previous = interrupts.install()
    try:
        summary = run_campaign(
            load_campaign(args.campaign, controller=args.controller),
            args.out,
            workers=args.workers,
            runs=args.runs,
            scheduler=args.scheduler,
            yardstick_from=args.yardstick_from,
        )
    except ConfigError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as stop:
        kept = count_finished(args.out)
        print(f"interrupted: {kept} finished runs kept in {args.out}", file=sys.stderr)
        return stop.exit_code if isinstance(stop, interrupts.Interrupted) else 130
    finally:
        interrupts.restore(previous)
    print(
        f"{summary.total} runs: {summary.ok} ok, {summary.failed} failed "
        f"({summary.new} run now, {summary.wall_s:.1f} s) -> {summary.out_dir / RESULTS_FILE}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
