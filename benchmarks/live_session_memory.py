"""Peak Python memory (tracemalloc) of a long live session: a scenario stepped by hand through
``auvmpc.session(..., live_log=...)`` against the project's own plant, as a script driving a
vehicle would; what the session holds as it goes (its log grows by a row a sample), and the
peak of its ``close()`` (metrics, no figures).

    python benchmarks/live_session_memory.py --duration 3600 --scenario bluerov2-figure-eight
"""

from __future__ import annotations

import argparse
import tempfile
import time
import tracemalloc
from pathlib import Path

import auvmpc
from auvmpc.experiments.run import run_plant
from auvmpc.sim.loop import run_session


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=3600.0, help="s")
    parser.add_argument("--scenario", default="bluerov2-figure-eight")
    args = parser.parse_args()
    resolved = auvmpc.load_scenario(args.scenario, {"duration": args.duration})
    folder = Path(tempfile.mkdtemp())
    tracemalloc.start()
    start_bytes = tracemalloc.get_traced_memory()[0]
    session = auvmpc.session(resolved, live_log=folder / "live.csv")
    plant, sensor = run_plant(resolved)
    tracemalloc.reset_peak()
    opened = tracemalloc.get_traced_memory()[0]
    steps = round(session.duration / session.sample_time)
    held = {}

    def sampled(k: int, _: int) -> None:
        if k in (steps // 4, steps // 2, steps):
            held[k] = tracemalloc.get_traced_memory()[0] - opened

    began = time.perf_counter()
    run_session(session, plant, sensor, sampled)  # the batch run's loop, on the live session
    current, peak = tracemalloc.get_traced_memory()
    mb, wall = 1e6, time.perf_counter() - began
    print(f"{args.scenario}, {args.duration:g} s: {steps} samples in {wall:.0f} s")
    growth = ", ".join(f"{k}: {size / mb:.2f} MB" for k, size in held.items())
    print(f"held above the opened session after k samples: {growth}")
    after = (current - start_bytes) / mb
    print(f"peak while stepping {(peak - opened) / mb:.2f} MB above the opened session; held")
    print(f"after the run {after:.2f} MB above the start (session, controller, log)")
    tracemalloc.reset_peak()
    session.close()
    print(f"close(): peak {(tracemalloc.get_traced_memory()[1] - start_bytes) / mb:.2f} MB; "
          f"live.csv {(folder / 'live.csv').stat().st_size / mb:.1f} MB")  # fmt: skip


if __name__ == "__main__":
    main()
