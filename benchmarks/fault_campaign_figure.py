"""The thruster-loss campaign's figure and numbers (docs/faults.md): per run, the tracking
after the fault over before it against the share of the thruster's force left, watched
(horizontal) and unwatched (vertical) thrusters apart, and the detection delays.

    auvmpc campaign thruster-loss --out results/thruster-loss
    PYTHONPATH=src python benchmarks/fault_campaign_figure.py results/thruster-loss \
        --figure docs/figures/thruster-loss-campaign.png
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from auvmpc.experiments.campaign import load_results  # noqa: E402
from auvmpc.sim.verdict import Verdict  # noqa: E402

WATCHED = ("F1", "F2", "F3", "F4")  # the BlueROV2 Heavy's horizontal thrusters
MARKERS = {Verdict.OK: "o", Verdict.DEGRADED: "s", Verdict.LOST: "x"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("campaign", help="the campaign's results folder")
    parser.add_argument("--figure", help="where to draw the figure (png)")
    args = parser.parse_args()
    frame = load_results(args.campaign)
    frame["ratio"] = frame["rms_after_fault_m"] / frame["rms_before_fault_m"]
    frame["watched"] = frame["faults.0.actuator"].isin(WATCHED)
    frame["severe"] = frame["faults.0.effectiveness"] <= 0.5
    for (watched, severe), group in frame.groupby(["watched", "severe"]):
        delays = group["fault_detection_delay_s"].dropna()
        which = "horizontal" if watched else "vertical"
        share = "half or more" if severe else "under half"
        print(
            f"{which}, {share} lost: {len(group)} runs, found {len(delays)}, delay median "
            f"{delays.median() if len(delays) else float('nan'):.2f} s, p95 "
            f"{delays.quantile(0.95) if len(delays) else float('nan'):.2f} s, max "
            f"{delays.max() if len(delays) else float('nan'):.2f} s; RMS after/before median "
            f"{group['ratio'].median():.2f}, p95 {group['ratio'].quantile(0.95):.2f}, max "
            f"{group['ratio'].max():.2f}; false detections "
            f"{int(group['false_fault_detections'].sum())}; verdicts "
            f"{dict(group['verdict'].value_counts())}"
        )
    if not args.figure:
        return
    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 4), layout="constrained")
    for watched, colour, label in ((True, "tab:blue", "horizontal (watched)"),
                                   (False, "tab:orange", "vertical (not watched)")):  # fmt: skip
        group = frame[frame["watched"] == watched]
        for verdict, marker in MARKERS.items():
            rows = group[group["verdict"] == verdict]
            if len(rows):
                left.scatter(rows["faults.0.effectiveness"], rows["ratio"], s=14, c=colour,
                             marker=marker, label=f"{label}, {verdict}")  # fmt: skip
    left.set_yscale("log")
    left.axhline(2.0, color="grey", linestyle="--", linewidth=0.8)
    left.set_xlabel("share of the thruster's force left")
    left.set_ylabel("RMS after the fault / RMS before")
    left.legend(fontsize=7)
    delays = frame.loc[frame["watched"], "fault_detection_delay_s"].dropna()
    right.hist(delays.clip(upper=5.0), bins=25, color="tab:blue")
    right.set_xlabel("detection delay (s; longer ones at 5)")
    right.set_ylabel("runs")
    right.set_title(f"horizontal thrusters: {len(delays)} of {int(frame['watched'].sum())} found")
    figure.suptitle(f"thruster-loss campaign: {len(frame)} runs, BlueROV2 Heavy lawnmower")
    figure.savefig(args.figure, dpi=100)
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
