"""The fin-jam campaign's figure and numbers (docs/faults.md): per run, the jammed angle
against the depth (stern planes) or the cross-track (rudder) RMS after the fault, by
verdict, and how long the detector took.

    auvmpc campaign fin-jam --out results/fin-jam
    PYTHONPATH=src python benchmarks/fin_jam_figure.py results/fin-jam \
        --figure docs/figures/fin-jam-campaign.png
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from auvmpc.experiments.campaign import load_results  # noqa: E402
from auvmpc.sim.verdict import Verdict  # noqa: E402

MARKERS = {Verdict.OK: "o", Verdict.DEGRADED: "s", Verdict.LOST: "x"}
# What a jam of each fin costs: the stern planes pitch the vehicle (its depth), the rudder
# turns it (its path).
COST = {
    "stern_planes_deg": "depth_rms_after_fault_m",
    "rudder_deg": "cross_track_rms_after_fault_m",
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("campaign", help="the campaign's results folder")
    parser.add_argument("--figure", help="where to draw the figure (png)")
    args = parser.parse_args()
    frame = load_results(args.campaign)
    figure, axes = plt.subplots(1, 3, figsize=(13.5, 4.0))
    for fin, cost in COST.items():
        group = frame[frame["faults.0.actuator"] == fin]
        delays = group["fault_detection_delay_s"].dropna()
        verdicts = group["verdict"].value_counts().to_dict()
        print(
            f"{fin}: {len(group)} runs, found {len(delays)}, delay median "
            f"{delays.median():.2f} s, max {delays.max():.2f} s; {cost} median "
            f"{group[cost].median():.3f} m, max {group[cost].max():.3f} m; verdicts {verdicts}"
        )
        axis = axes[0] if fin == "stern_planes_deg" else axes[1]
        for verdict, marker in MARKERS.items():
            runs = group[group["verdict"] == verdict]
            axis.scatter(runs["faults.0.stuck_at"], runs[cost], marker=marker, label=verdict)
        axis.set(xlabel=f"{fin} jammed at (deg)", ylabel=f"{cost} (m)", yscale="log")
        axis.legend()
        found = group.dropna(subset=["fault_detection_delay_s"])
        axes[2].scatter(found["faults.0.stuck_at"], found["fault_detection_delay_s"], label=fin)
    axes[2].set(xlabel="jammed at (deg)", ylabel="found after (s)", yscale="log")
    axes[2].legend()
    figure.suptitle(f"fin-jam: {len(frame)} runs, remus100-stuck-fin, the detector on")
    figure.tight_layout()
    if args.figure:
        figure.savefig(args.figure, dpi=110)


if __name__ == "__main__":
    main()
