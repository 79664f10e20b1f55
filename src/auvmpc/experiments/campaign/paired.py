"""The yardstick: every run of a campaign simulated a second time with ``spec.yardstick``
applied last (e.g. the converged OCP), its metrics stored beside the run's.

Part of :mod:`auvmpc.experiments.campaign` (docs/campaigns.md).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from auvmpc.experiments.campaign.sampling import plan_run
from auvmpc.experiments.campaign.spec import Campaign, _resolve

if TYPE_CHECKING:
    from auvmpc.experiments.run import RunResult

__all__ = [
    "RMS_BAR_FACTOR",
    "RMS_BAR_FLOOR_M",
    "YARDSTICK_PREFIX",
    "paired_columns",
    "rms_over_bar",
]

YARDSTICK_PREFIX = "yardstick_"
RMS_METRIC = "rms_position_error_after_transient_m"
# rms_over_bar = rms / max(RMS_BAR_FLOOR_M, RMS_BAR_FACTOR * the yardstick's rms) (issue 24):
# within 20 % of the converged OCP's error, and never asked for better than 0.1 m.
RMS_BAR_FACTOR = 1.2
RMS_BAR_FLOOR_M = 0.1


def rms_over_bar(rms: float | None, yardstick_rms: float | None) -> float | None:
    """The run's RMS error after the transient over the bar the yardstick sets (<= 1 meets it);
    None when either run has no such error."""
    if rms is None or yardstick_rms is None:
        return None
    return rms / max(RMS_BAR_FLOOR_M, RMS_BAR_FACTOR * yardstick_rms)


def _lost(metrics: Mapping[str, Any]) -> int | None:
    """``verdict == "lost"`` as 0 / 1, for criteria (whose grammar compares numbers)."""
    verdict = metrics.get("verdict")
    return None if verdict is None else int(verdict == "lost")


def paired_columns(campaign: Campaign, index: int, result: RunResult) -> dict[str, Any]:
    """The columns a campaign with a yardstick adds to run ``index``'s metrics, given the
    finished tested run ``result``: ``lost``, ``warnings`` (count) and ``warnings_text``
    (JSON list) of the tested run; then the yardstick twin simulated here, its metrics
    prefixed ``yardstick_`` (with its ``lost`` and ``warnings`` count), or, if it failed,
    only ``yardstick_error`` (one line); and ``rms_over_bar``."""
    from auvmpc.experiments.run import simulate

    columns: dict[str, Any] = {
        "lost": _lost(result.metrics),
        "warnings": len(result.warnings),
        "warnings_text": json.dumps(list(result.warnings)),
    }
    twin: dict[str, Any] = {}
    try:
        _, _, data = plan_run(campaign, index, yardstick=True)
        finished = simulate(_resolve(campaign, data))
        twin = {**finished.metrics, "lost": _lost(finished.metrics)}
        twin["warnings"] = len(finished.warnings)
    except Exception as exc:  # the yardstick's failure is data; the tested run still counts
        from auvmpc.experiments.campaign.execute import _one_line

        twin = {"error": _one_line(exc)}
    columns.update({f"{YARDSTICK_PREFIX}{name}": value for name, value in twin.items()})
    columns["rms_over_bar"] = rms_over_bar(result.metrics.get(RMS_METRIC), twin.get(RMS_METRIC))
    return columns
