"""Results as a DataFrame, and the campaign report.

Part of :mod:`auvmpc.experiments.campaign` (docs/campaigns.md).
"""

from __future__ import annotations

import ast
import hashlib
import json
import math
import re
import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from auvmpc.errors import ConfigError

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

from auvmpc.experiments.campaign.criterion import (
    Criterion,
    _is_number,
    parse_criterion,
    wilson_interval,
)
from auvmpc.experiments.campaign.paired import (
    PAIRED_FIGURES,
    YARDSTICK_PREFIX,
    paired_summary,
    worst_case_figures,
    worst_cases,
)
from auvmpc.experiments.campaign.sampling import (
    reproduce_command,
)
from auvmpc.experiments.campaign.spec import (
    FIGURES_DIR,
    NONDETERMINISTIC_COLUMNS,
    OVERRIDE_NOTES,
    PERCENTILES,
    REPORT_FILE,
    REPORT_JSON,
    Campaign,
)
from auvmpc.experiments.campaign.store import (
    _campaign_row,
    _reading,
    stored_campaign,
    stored_sessions,
)


def load_results(out_dir: str | Path) -> pd.DataFrame:
    """The rows of a campaign folder as a DataFrame, one row per finished run.

    Columns: ``index``, ``seed``, ``status`` (``ok`` | ``failed``), ``error`` (one line,
    None when ok), one per sampled parameter (file order; a polar as ``<path>.magnitude``
    and ``<path>.direction_deg``; non-numeric values as JSON text), one per metric, then
    ``wall_s`` and ``worker_deaths``. Sorted by index. Safe to call while the campaign runs.
    Floats are exactly those the run produced (the JSON is parsed by Python).
    """
    import pandas as pd

    with _reading(Path(out_dir)) as db:
        parameter_columns, metric_columns = (
            json.loads(text)
            for text in _campaign_row(db, out_dir, "parameter_columns, metric_columns")
        )
        rows = db.execute(
            'SELECT "index", seed, status, error, parameters, metrics, wall_s, worker_deaths '
            'FROM runs ORDER BY "index"'
        ).fetchall()
        stored = [(row, json.loads(row[4]), json.loads(row[5])) for row in rows]
    records = []
    for (index, seed, status, error, _, _, wall_s, deaths), values, measured in stored:
        record = {"index": index, "seed": seed, "status": status, "error": error}
        for name in parameter_columns:
            value = values.get(name)
            record[name] = json.dumps(value) if isinstance(value, list | dict) else value
        for name in metric_columns:
            record[name] = measured.get(name)
        record["wall_s"] = wall_s
        record["worker_deaths"] = deaths
        records.append(record)
    columns = [
        "index",
        "seed",
        "status",
        "error",
        *parameter_columns,
        *metric_columns,
        "wall_s",
        "worker_deaths",
    ]
    frame = pd.DataFrame.from_records(records, columns=columns)
    for name in (*parameter_columns, *metric_columns):
        frame[name] = _typed_column([record[name] for record in records], frame.index)
    frame["wall_s"] = frame["wall_s"].astype(float)
    # object dtype, None when ok: the same with and without errors in the table
    frame["error"] = pd.Series([r["error"] for r in records], index=frame.index, dtype=object)
    frame.attrs["parameter_columns"] = list(parameter_columns)
    frame.attrs["metric_columns"] = list(metric_columns)
    return frame


def paired_difference(
    out_dir: str | Path, baseline_dir: str | Path, metric: str
) -> dict[str, float | int]:
    """``metric`` of each run of ``out_dir`` minus that of the same run index in
    ``baseline_dir``, summarised (runs both folders finished).

    Two campaigns with one seed draw the same parameters for run k (docs/campaigns.md), so
    the difference is what the configuration change alone costs on each draw; e.g. the
    robust tightening's tracking cost, ``rms_position_error_m`` of ``encounter-robust`` minus
    that of ``encounter`` (docs/tightening.md).
    """
    runs, baseline = (load_results(folder).set_index("index") for folder in (out_dir, baseline_dir))
    for frame, folder in ((runs, out_dir), (baseline, baseline_dir)):
        if metric not in frame.columns:
            raise ConfigError("metric", metric, f"not a metric of the campaign in {folder}")
    both = runs.index.intersection(baseline.index)
    ok = both[(runs.loc[both, "status"] == "ok") & (baseline.loc[both, "status"] == "ok")]
    difference = (runs.loc[ok, metric] - baseline.loc[ok, metric]).astype(float).to_numpy()
    if not len(difference):
        raise ConfigError("out_dir", str(out_dir), f"no run finished in both and {baseline_dir}")
    return {
        "runs": int(len(difference)),
        "mean": float(difference.mean()),
        "median": float(np.median(difference)),
        "p95": float(np.percentile(difference, 95)),
        "max": float(difference.max()),
        "min": float(difference.min()),
    }


def _typed_column(raw: list[Any], index: pd.Index) -> pd.Series:
    """Whole numbers as nullable Int64, other numbers as float64 (NaN if missing), the
    rest (JSON text, strings) as objects: the same dtype whatever rows failed."""
    import pandas as pd

    values = [v for v in raw if v is not None]
    if values and all(isinstance(v, int) and not isinstance(v, bool) for v in values):
        return pd.Series(raw, index=index, dtype="Int64")
    if all(_is_number(v) for v in values):
        return pd.Series([np.nan if v is None else v for v in raw], index=index, dtype=float)
    return pd.Series(raw, index=index, dtype=object)


@dataclass
class CampaignReport:
    """Summary of a campaign folder.

    Attributes
    ----------
    summary : dict
        JSON-ready numbers (also written as ``report.json``).
    markdown : str
        ``report.md``.
    figures : dict of str to Figure
        Histograms and metric-vs-parameter scatter plots (``figures/<name>.png``).
    files : list of Path
        Files written (empty with ``write=False``).
    """

    summary: dict[str, Any]
    markdown: str
    figures: dict[str, Figure]
    files: list[Path]


def campaign_report(
    out_dir: str | Path,
    criterion: str | None = None,
    *,
    worst: int = 5,
    worst_by: str | None = None,
    worst_order: Literal["desc", "asc"] | None = None,
    figures: bool = True,
    write: bool = True,
    paired_figures: int = PAIRED_FIGURES,
    workers: int = 1,
) -> CampaignReport:
    """Success rate, metric percentiles, worst runs and plots of a campaign folder.

    Parameters
    ----------
    criterion : str, optional
        Success criterion (:class:`Criterion`); default: the campaign file's
        ``criterion``, else "the run finished" (status ok).
    worst : int
        Number of worst runs listed, each with the command that reproduces it.
    worst_by : str, optional
        Column ranking them; default: the first name in the criterion, else
        ``rms_position_error_m``.
    worst_order : {"desc", "asc"}, optional
        ``desc``: largest is worst. Default: from the criterion (``x < c`` -> desc,
        ``x > c`` -> asc), else asc for names starting ``min_`` and desc otherwise.
    figures : bool
        Draw figures.
    write : bool
        Write ``report.md``, ``report.json`` and ``figures/*.png`` into ``out_dir``; for a
        criterion other than the campaign file's, ``report-<criterion>.md``, ``.json`` and
        ``figures-<criterion>/`` next to them (:func:`report_names`), never over them.
    paired_figures : int
        With a yardstick: the worst runs simulated again, controller and yardstick, and
        drawn (with ``figures``); 0 for none.
    workers : int
        Processes simulating those runs again.
    """
    from auvmpc.experiments.outputs import adding, atomic_write_text

    out = Path(out_dir)
    campaign = stored_campaign(out)
    frame = load_results(out)
    if frame.empty:
        raise ConfigError("DIR", str(out), "no finished runs yet")
    text = criterion if criterion is not None else campaign.spec.criterion
    report_file, report_json, figures_dir = report_names(criterion, campaign.spec.criterion)
    parsed = parse_criterion(text) if text else None
    ok = frame[frame["status"] == "ok"]
    if parsed is not None and len(ok):
        passed = parsed.evaluate(frame)
    else:  # no criterion, or every run failed (no metric to evaluate it on)
        passed = (frame["status"] == "ok").to_numpy() & (parsed is None)
    n, successes = len(frame), int(passed.sum())
    low, high = wilson_interval(successes, n)
    # Text metrics (verdict, verdict_reason) have no percentiles: verdicts are counted.
    metric_columns = [c for c in frame.attrs["metric_columns"] if _numeric(frame[c])]
    verdicts = (
        {str(k): int(v) for k, v in ok["verdict"].value_counts().sort_index().items()}
        if "verdict" in ok.columns
        else {}
    )
    numeric_parameters = [c for c in frame.attrs["parameter_columns"] if _numeric(frame[c])]
    rank_by = worst_by or (parsed.names[0] if parsed else "rms_position_error_m")
    if len(ok) and rank_by not in frame.columns:
        raise ConfigError("--worst-by", rank_by, f"unknown column; metrics: {metric_columns}")
    order = worst_order or _worst_order(parsed, rank_by)
    if order not in ("asc", "desc"):
        raise ConfigError("--worst-order", order, "choose asc or desc")
    if isinstance(worst, bool) or not isinstance(worst, int) or worst < 0:
        raise ConfigError("--worst", worst, "need a whole number >= 0")
    ranked = ok.assign(_passed=passed[frame["status"].to_numpy() == "ok"])
    if len(ranked):
        ranked = ranked.sort_values(
            rank_by, ascending=order == "asc", na_position="last", kind="stable"
        )
    worst_rows = [
        {
            "index": int(row["index"]),
            "seed": int(row["seed"]),
            rank_by: _plain(row[rank_by]),
            "passed": bool(row["_passed"]),
            "parameters": {c: _plain(row[c]) for c in campaign.parameter_columns},
            "command": reproduce_command(campaign, int(row["index"]), out),
            "from_campaign": shlex.join(
                ["auvmpc", "run", "--from-campaign", str(out), "--index", str(row["index"])]
            ),
        }
        for _, row in ranked.head(worst).iterrows()
    ]
    failed_rows = [
        {
            "index": int(row["index"]),
            "error": row["error"],
            "command": reproduce_command(campaign, int(row["index"]), out),
        }
        for _, row in frame[frame["status"] != "ok"].iterrows()
    ]
    summary = {
        "campaign": campaign.spec.name,
        "description": campaign.spec.description,
        "hash": campaign.hash,
        "base": campaign.base_label,
        "seed": campaign.spec.seed,
        "runs_in_file": campaign.spec.runs,
        "rows": n,
        "ok": int(len(ok)),
        "failed": int(n - len(ok)),
        "criterion": text or "status == ok",
        "successes": successes,
        "success_rate": successes / n if n else None,
        "success_ci95": [low, high],
        "verdicts": verdicts,
        "metrics": {c: _stats(ok[c]) for c in metric_columns},
        "parameters": {c: _stats(frame[c]) for c in numeric_parameters},
        "worst_by": rank_by,
        "worst_order": order,
        "worst": worst_rows,
        "failed_runs": failed_rows,
        "override_notes": _override_notes(frame),
    }
    drawn = (
        _report_figures(
            frame, passed, metric_columns, numeric_parameters, parsed, rank_by, campaign
        )
        if figures and len(ok)
        else {}
    )
    summary["figures"] = [f"{figures_dir}/{name}.png" for name in drawn]
    if campaign.spec.yardstick is not None:
        summary["paired"] = paired_summary(frame, campaign, out)
        if figures and paired_figures > 0:
            indices = worst_cases(frame, paired_figures)
            cases, worst_drawn = worst_case_figures(
                frame, campaign, out, indices, figures_dir, workers
            )
            summary["paired"]["worst"] = cases
            drawn.update(worst_drawn)
    summary["sessions"] = stored_sessions(out)
    markdown = _markdown(summary)
    files: list[Path] = []
    if write:
        from auvmpc.plots import save_figures

        names = [report_json, report_file, *([figures_dir] if drawn else [])]
        with adding(out, names, "DIR"):
            if drawn:
                files += save_figures(drawn, out / figures_dir)
            text = json.dumps(summary, indent=2, allow_nan=False) + "\n"
            atomic_write_text(out / report_json, text)
            atomic_write_text(out / report_file, markdown)
        files += [out / report_json, out / report_file]
    return CampaignReport(summary, markdown, drawn, files)


def _override_notes(frame: pd.DataFrame) -> list[dict[str, Any]]:
    """Each note the runs' overrides made (:data:`OVERRIDE_NOTES`), once: its text, whose
    it is (``run``, or ``yardstick`` for the twins) and how many runs it was made for."""
    counts: dict[tuple[str, str], int] = {}
    for whose, column in (
        ("run", OVERRIDE_NOTES),
        ("yardstick", YARDSTICK_PREFIX + OVERRIDE_NOTES),
    ):
        if column in frame.columns:
            for text in frame[column].dropna():
                for note in json.loads(text):
                    counts[whose, note] = counts.get((whose, note), 0) + 1
    return [{"note": note, "of": whose, "runs": runs} for (whose, note), runs in counts.items()]


def report_names(criterion: str | None, own: str | None) -> tuple[str, str, str]:
    """(report .md, report .json, figures folder) for a report by ``criterion``.

    The campaign's own report (no criterion given, or the file's own) is ``report.md``,
    ``report.json`` and ``figures/``; another criterion gets names of its own, made from
    its text and a hash of it, so that it never replaces the campaign's report.
    """
    if criterion is None or criterion.strip() == (own or "").strip():
        return REPORT_FILE, REPORT_JSON, FIGURES_DIR
    slug = re.sub(r"[^A-Za-z0-9]+", "_", criterion).strip("_")[:40] or "criterion"
    tag = f"{slug}-{hashlib.sha256(criterion.strip().encode()).hexdigest()[:8]}"
    return f"report-{tag}.md", f"report-{tag}.json", f"{FIGURES_DIR}-{tag}"


def _numeric(column: pd.Series) -> bool:
    import pandas as pd

    return pd.api.types.is_numeric_dtype(column) and not pd.api.types.is_bool_dtype(column)


def _worst_order(parsed: Criterion | None, name: str) -> Literal["desc", "asc"]:
    if parsed is not None:
        for node in ast.walk(parsed.tree):
            if isinstance(node, ast.Compare) and len(node.ops) == 1:
                left, right = node.left, node.comparators[0]
                op = node.ops[0]
                if isinstance(right, ast.Name) and not isinstance(left, ast.Name):
                    left, right = right, left
                    op = {
                        ast.Lt: ast.Gt(),
                        ast.LtE: ast.GtE(),
                        ast.Gt: ast.Lt(),
                        ast.GtE: ast.LtE(),
                    }.get(type(op), op)
                if isinstance(left, ast.Name) and parsed.aliases.get(left.id, left.id) == name:
                    if isinstance(op, ast.Lt | ast.LtE):
                        return "desc"
                    if isinstance(op, ast.Gt | ast.GtE):
                        return "asc"
    return "asc" if name.startswith("min_") else "desc"


def _plain(value: Any) -> Any:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating):
        return None if math.isnan(value) else float(value)
    try:
        import pandas as pd

        if value is pd.NA:
            return None
    except ImportError:  # pragma: no cover
        pass
    return value


def _stats(column: pd.Series) -> dict[str, Any]:
    values = column.dropna().astype(float).to_numpy() if len(column) else np.array([])
    stats: dict[str, Any] = {"n": int(len(values))}
    if len(values):
        stats["min"] = float(values.min())
        for q in PERCENTILES:
            stats[f"p{q}"] = float(np.percentile(values, q))
        stats["max"] = float(values.max())
    else:
        stats.update({"min": None, **{f"p{q}": None for q in PERCENTILES}, "max": None})
    return stats


def _report_figures(
    frame: pd.DataFrame,
    passed: np.ndarray,
    metric_columns: Sequence[str],
    parameters: Sequence[str],
    parsed: Criterion | None,
    rank_by: str,
    campaign: Campaign,
) -> dict[str, Figure]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ok = (frame["status"] == "ok").to_numpy()
    shown = [c for c in metric_columns if _varies(frame.loc[ok, c])]
    figures: dict[str, Figure] = {}
    if shown:
        columns = 3
        rows = math.ceil(len(shown) / columns)
        figure = Figure(figsize=(10.0, 2.4 * rows), layout="constrained")
        FigureCanvasAgg(figure)
        figure.suptitle(f"{campaign.spec.name}: metrics over {int(ok.sum())} finished runs")
        for i, name in enumerate(shown):
            ax = figure.add_subplot(rows, columns, i + 1)
            ax.hist(
                frame.loc[ok, name].dropna().astype(float), bins=30, color="tab:blue", alpha=0.8
            )
            ax.set_xlabel(name, fontsize=8)
            ax.set_ylabel("runs", fontsize=8)
            ax.tick_params(labelsize=7)
        figures["histograms"] = figure
    key_metrics = list(
        dict.fromkeys([*(parsed.names if parsed else ()), rank_by, "rms_position_error_m"])
    )
    key_metrics = [m for m in key_metrics if m in shown]
    for metric in key_metrics:
        if not parameters:
            break
        columns = min(3, len(parameters))
        rows = math.ceil(len(parameters) / columns)
        figure = Figure(figsize=(3.6 * columns, 2.9 * rows), layout="constrained")
        FigureCanvasAgg(figure)
        figure.suptitle(f"{metric} against each sampled parameter")
        y = frame[metric].astype(float).to_numpy()
        for i, parameter in enumerate(parameters):
            ax = figure.add_subplot(rows, columns, i + 1)
            x = frame[parameter].astype(float).to_numpy()
            if parsed is not None:
                good, bad = ok & passed, ok & ~passed
                ax.scatter(x[good], y[good], s=9, color="tab:blue", label="pass")
                ax.scatter(x[bad], y[bad], s=12, color="tab:red", marker="x", label="fail")
                if i == 0:
                    ax.legend(fontsize=7)
            else:
                ax.scatter(x[ok], y[ok], s=9, color="tab:blue")
            ax.set_xlabel(parameter, fontsize=8)
            ax.set_ylabel(metric, fontsize=8)
            ax.tick_params(labelsize=7)
        figures[f"{metric}-vs-parameters"] = figure
    return figures


def _varies(column: pd.Series) -> bool:
    """Whether a histogram of the column shows anything (not constant up to round-off)."""
    values = column.dropna().astype(float).to_numpy()
    if len(values) < 2:
        return False
    low, high = float(values.min()), float(values.max())
    return high - low > 1e-9 * max(1.0, abs(low), abs(high))


def _fmt(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


def _markdown(summary: Mapping[str, Any]) -> str:
    low, high = summary["success_ci95"]
    rate = summary["success_rate"]
    lines = [
        f"# Campaign `{summary['campaign']}`",
        "",
        summary["description"] or "",
        "",
        f"- base scenario: `{summary['base']}`; master seed {summary['seed']}; "
        f"campaign hash `{summary['hash'][:12]}`",
        f"- rows: {summary['rows']} of {summary['runs_in_file']} runs "
        f"({summary['ok']} ok, {summary['failed']} failed)",
        "",
        "## Success",
        "",
        f"Criterion: `{summary['criterion']}` (a run that failed never passes).",
        "",
        f"**{summary['successes']} / {summary['rows']} passed"
        + (f" = {100 * rate:.1f} %" if rate is not None else "")
        + f", 95 % Wilson interval [{100 * low:.1f} %, {100 * high:.1f} %]**",
        "",
        "Verdicts of the finished runs: "
        + (", ".join(f"{k} {v}" for k, v in summary["verdicts"].items()) or "none recorded"),
        "",
        *(_paired_markdown(summary["paired"]) + [""] if "paired" in summary else []),
        "## Metrics over the finished runs",
        "",
        "| metric | n | min | p5 | p50 | p95 | max |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, stats in summary["metrics"].items():
        note = " (wall clock)" if name in NONDETERMINISTIC_COLUMNS else ""
        lines.append(
            f"| `{name}`{note} | {stats['n']} | "
            + " | ".join(_fmt(stats[k]) for k in ("min", "p5", "p50", "p95", "max"))
            + " |"
        )
    if summary["parameters"]:
        lines += [
            "",
            "## Sampled parameters",
            "",
            "| parameter | n | min | p5 | p50 | p95 | max |",
            "|---|---:|---:|---:|---:|---:|---:|",
        ]
        for name, stats in summary["parameters"].items():
            lines.append(
                f"| `{name}` | {stats['n']} | "
                + " | ".join(_fmt(stats[k]) for k in ("min", "p5", "p50", "p95", "max"))
                + " |"
            )
    rank_by = summary["worst_by"]
    direction = "largest" if summary["worst_order"] == "desc" else "smallest"
    lines += ["", f"## Worst runs by `{rank_by}` ({direction} first)", ""]
    for row in summary["worst"]:
        lines += [
            f"- run {row['index']}: `{rank_by}` = {_fmt(row[rank_by])}, "
            f"{'passes' if row['passed'] else 'fails'}; "
            + ", ".join(f"`{k}` = {_fmt(v)}" for k, v in row["parameters"].items()),
            "",
            "  ```sh",
            *dict.fromkeys([f"  {row['from_campaign']}", f"  {row['command']}"]),
            "  ```",
        ]
    if summary["override_notes"]:
        lines += ["", "## Notes from the overrides", ""]
        for row in summary["override_notes"]:
            whose = "yardstick twins of " if row["of"] == "yardstick" else ""
            lines.append(f"- {row['note']} ({whose}{row['runs']} runs)")
    if summary["failed_runs"]:
        lines += ["", "## Failed runs", ""]
        for row in summary["failed_runs"]:
            lines += [
                f"- run {row['index']}: {row['error']}",
                "",
                "  ```sh",
                f"  {row['command']}",
                "  ```",
            ]
    if summary.get("figures"):
        lines += ["", "## Figures", ""]
        lines += [f"![{Path(path).stem}]({path})" for path in summary["figures"]]
    return "\n".join(lines).rstrip() + "\n"


def _paired_markdown(paired: Mapping[str, Any]) -> list[str]:
    """The report's section "Controller against the yardstick"."""
    lines = [
        "## Controller against the yardstick",
        "",
        f"Controller: {paired['controller']}; yardstick: the same run with "
        + ", ".join(f"`{text}`" for text in paired["yardstick"])
        + f" applied last. {paired['paired_runs']} runs where both finished"
        + f"; {paired['warned_runs']} runs warned before they started (`warnings`).",
        "",
        "| | controller | yardstick |",
        "|---|---:|---:|",
    ]
    for row in paired["table"]:
        lines.append(f"| {row['row']} | {_fmt(row['controller'])} | {_fmt(row['yardstick'])} |")
    for folder, runs in paired["copied_from"].items():
        lines += [
            "",
            f"Yardstick twins of {runs} runs copied from `{folder}` (`--yardstick-from`).",
        ]
    lines += [
        "",
        f"Where the yardstick is not lost ({paired['judged_runs']} runs): controller lost in "
        f"{_fmt(paired['judged_lost'])}, `rms_over_bar` > 1 in {_fmt(paired['judged_over_bar'])}.",
        "",
        f"### Runs where the yardstick itself is lost ({len(paired['yardstick_lost'])})",
        "",
        "The bar does not apply to them; a contact counts everywhere.",
        "",
    ]
    if not paired["yardstick_lost"]:
        lines.append("None.")
    for row in paired["yardstick_lost"]:
        lines.append(
            f"- run {row['index']}: controller lost {_fmt(row['lost'])}, min clearance "
            f"{_fmt(row['min_obstacle_clearance_m'])} m, `rms_over_bar` "
            f"{_fmt(row['rms_over_bar'])}: `{row['command']}`"
        )
    if paired["yardstick_failed"]:
        lines += ["", "### Runs whose yardstick failed", ""]
        lines += [f"- run {row['index']}: {row['error']}" for row in paired["yardstick_failed"]]
    if paired.get("worst"):
        lines += [
            "",
            "### Worst cases, simulated again",
            "",
            "Every lost run and contact first, then the largest `rms_over_bar`; each run "
            "simulated again (same scenario, same seed) with the controller and with the "
            "yardstick.",
        ]
        for case in paired["worst"]:
            note = "" if case["reproduced"] else " (the rerun's RMS error differs from the stored)"
            lines += [
                "",
                f"**Run {case['index']}**: `rms_over_bar` {_fmt(case['rms_over_bar'])}, lost "
                f"{_fmt(case['lost'])} (yardstick {_fmt(case['yardstick_lost'])}), min "
                f"clearance {_fmt(case['min_obstacle_clearance_m'])} m{note}",
                "",
            ]
            for who in ("controller", "yardstick"):
                lines.append(f"![run {case['index']} {who}]({case['figures'][who]})")
            lines += ["", "```sh", *case["commands"].values(), "```"]
    return lines
