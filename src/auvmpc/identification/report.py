"""What ``auvmpc identify`` writes: the vehicle file, identification.json, a Markdown
report and a fit figure (docs/identification.md)."""

from __future__ import annotations

import datetime as _dt
import json
from pathlib import Path
from typing import Any

import yaml
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from auvmpc.atomic_write import atomic_write_text
from auvmpc.errors import ConfigError
from auvmpc.identification.estimation import CURRENT, GAIN, Identification, ParameterEstimate
from auvmpc.identification.excitation import Dof
from auvmpc.identification.logs import LogOptions
from auvmpc.identification.roll_pitch import PARAMETERS as SIX_DOF_PARAMETERS
from auvmpc.identification.roll_pitch import SIX_DOF_FIELDS, put_identified
from auvmpc.models.vehicle import load_vehicle, validated_vehicle, vehicle_data
from auvmpc.plots import save_figures

__all__ = [
    "fit_figure",
    "identification_json",
    "markdown_report",
    "vehicle_file_text",
    "write_identification",
]


def _number(value: float) -> float:
    return float(f"{value:.6g}")


def _labels(found: Identification) -> list[str]:
    """Each output with its unit: ``u (m/s)``."""
    return [f"{name} ({unit})" for name, unit in zip(found.outputs, found.units, strict=True)]


# The thrust gain goes into the vehicle file as these fields times the gain.
GAIN_SCALED = ("thrust_limits", "thrust_rate_limit")


def vehicle_file_text(start: dict[str, Any], found: Identification, start_name: str) -> str:
    """The start file's fields with the identified values, ``estimated`` listing them and
    a header saying where they came from (the logs, the intervals).

    An identified thrust gain g scales the horizontal thrusters' limits (``thrust_limits``,
    ``thrust_rate_limit``): the file then says what the thrusters deliver in the water, in
    the scale of the masses and dampings (docs/identification.md). A current is not a
    vehicle's: it is only in the header."""
    identified = [p for p in found.parameters if p.excited]
    data = put_identified(start, {p.name: _number(p.value) for p in identified})
    if any(p.name in SIX_DOF_PARAMETERS for p in identified):  # the six_dof lists, rounded
        data["six_dof"] = {
            name: [_number(v) for v in value] if name in SIX_DOF_FIELDS[:4] else value
            for name, value in data["six_dof"].items()
        }
    gain = found.extra(GAIN)
    scaled = gain is not None and gain.excited
    if scaled:
        data["thrust_limits"] = [_number(gain.value * limit) for limit in start["thrust_limits"]]
        data["thrust_rate_limit"] = _number(gain.value * start["thrust_rate_limit"])
    listed = list(data.get("estimated", ()))
    names = [p.name for p in identified] + list(GAIN_SCALED if scaled else ())
    data["estimated"] = listed + [name for name in names if name not in listed]
    logs = ", ".join(found.logs)
    note = f"identified from {len(found.logs)} log(s) by auvmpc identify (start: {start_name})"
    description = str(data.get("description", "")).strip()
    data["description"] = f"{description}; {note}" if description else note
    if "source" in data:
        data["source"] = f"{data['source']}; {note}"
    today = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d")
    header = [
        f"# Identified by auvmpc identify on {today} from: {logs}",
        f"# start file: {start_name}; {found.model}, output error (IPOPT);",
        "# 95 % intervals from the Fisher information (identification.json beside this file):",
    ]
    for estimate in found.parameters:
        header.append(f"#   {_estimate_line(estimate)}")
    if gain is not None:
        header.append(f"#   {_estimate_line(gain)}")
        if scaled:
            header.append(
                f"#     thrust_limits, thrust_rate_limit: the start file's x {gain.value:.6g}, "
                "the force the logged commands gave; command F / gain through the thrust map "
                "the log was made with"
            )
    current = [found.extra(name) for name in CURRENT]
    if current[0] is not None:
        header.append("#   not a vehicle parameter, in the log's heading frame (m/s):")
        header += [f"#   {_estimate_line(estimate)}" for estimate in current]
    rms = ", ".join(f"{value:.3g}" for value in found.validation_rms)
    header.append(
        f"# held-out validation RMS {', '.join(found.outputs)}: {rms} ({', '.join(found.units)})"
    )
    body = yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100)
    return "\n".join(header) + "\n" + body


def _estimate_line(estimate: ParameterEstimate) -> str:
    low, high = estimate.ci95
    kept = ""
    if estimate.fixed:
        kept = "  held at the start value (--fix)"
    elif not estimate.excited:
        kept = "  NOT EXCITED: start value kept"
    elif estimate.model_error:
        kept = "  MODEL ERROR: the log's halves disagree beyond the interval"
    return f"{estimate.name}: {estimate.value:.6g} [{low:.6g}, {high:.6g}]{kept}"


def _entry(p: ParameterEstimate) -> dict[str, Any]:
    return {
        "value": p.value,
        "ci95": list(p.ci95),
        "excited": p.excited,
        "start": p.start,
        "equation_error": p.equation_error,
        "fixed": p.fixed,
        "model_error": p.model_error,
    }


# identification.json's keys of the current's components.
CURRENT_KEYS = dict(zip(CURRENT, ("x", "y"), strict=True))
CURRENT_FRAME = (
    "world, as the log's heading: x where psi = 0, y where psi = 90 deg (NED logs: north, "
    "east); m/s"
)


def identification_json(found: Identification) -> dict[str, Any]:
    """identification.json: per parameter ``value``, ``ci95`` and ``excited`` (the
    contract), plus the start value and how the fit went; the thrust gain and the current,
    where asked for, in the same form beside them."""
    extras: dict[str, Any] = {}
    gain = found.extra(GAIN)
    if gain is not None:
        extras[GAIN] = _entry(gain)
    current = {key: found.extra(name) for name, key in CURRENT_KEYS.items()}
    if current["x"] is not None:
        extras["current"] = {key: _entry(p) for key, p in current.items()}
        extras["current"]["frame"] = CURRENT_FRAME
    return {
        "parameters": {p.name: _entry(p) for p in found.parameters},
        **extras,
        "logs": found.logs,
        "sample_time_s": found.sample_time,
        "fit_samples": found.fit_samples,
        "validation_samples": found.validation_samples,
        "validation_rms": dict(zip(found.outputs, found.validation_rms.tolist(), strict=True)),
        "validation_rms_start": dict(
            zip(found.outputs, found.validation_rms_start.tolist(), strict=True)
        ),
        "residual_rms": dict(zip(found.outputs, found.noise_std.tolist(), strict=True)),
        "solver_status": found.solver_status,
        "iterations": found.iterations,
        "started_from_equation_error": found.equation_error_used,
        "not_excited": found.unexcited,
        "model_error": found.model_error,
        "fixed": found.fixed,
    }


def markdown_report(found: Identification, start_name: str, figure: str | None) -> str:
    lines = [
        "# Identification report",
        "",
        f"Logs: {', '.join(found.logs)} (sample time {found.sample_time:g} s; "
        f"{found.fit_samples} samples fitted, the last {found.validation_samples} held out).",
        f"Start file: {start_name}. Output error solved by IPOPT: {found.solver_status}, "
        f"{found.iterations} iterations, {found.substeps} RK4 steps per sample; started from "
        f"{'the equation-error estimate' if found.equation_error_used else 'the start file'}.",
        "",
        "| parameter | start | equation error | identified | 95 % interval | excited |",
        "|---|---|---|---|---|---|",
    ]
    for p in found.parameters + found.extras:
        excited = "fixed" if p.fixed else ("yes" if p.excited else "**no**")
        excited += ", **model error**" if p.model_error else ""
        lines.append(
            f"| {p.name} | {p.start:.4g} | {p.equation_error:.4g} | {p.value:.4g} | "
            f"[{p.ci95[0]:.4g}, {p.ci95[1]:.4g}] | {excited} |"
        )
    if found.extra(CURRENT[0]) is not None:
        lines += ["", f"The current (current_x, current_y) is not the vehicle's: {CURRENT_FRAME}."]
    gain = found.extra(GAIN)
    if gain is not None and gain.excited:
        lines += [
            "",
            f"The vehicle file's thrust_limits and thrust_rate_limit are the start file's x "
            f"{gain.value:.4g} (thrust_gain): the force the logged commands gave.",
        ]
    lines += [
        "",
        f"Held-out validation (simulated {', '.join(found.outputs)} vs the log, RMS):",
        "",
        "| model | " + " | ".join(_labels(found)) + " |",
        "|---|" + "---|" * len(found.outputs),
        "| identified | " + " | ".join(f"{x:.4g}" for x in found.validation_rms) + " |",
        "| start | " + " | ".join(f"{x:.4g}" for x in found.validation_rms_start) + " |",
        "",
        "Fit residual RMS (about the measurement noise when the model fits): "
        + ", ".join(f"{x:.3g}" for x in found.noise_std)
        + f" ({', '.join(found.outputs)}).",
    ]
    if found.unexcited:
        lines += [
            "",
            f"**Not excited** by these logs (start value kept): {', '.join(found.unexcited)}.",
        ]
    if found.model_error:
        lines += [
            "",
            f"**Model error** dominates (excited, but the two halves of the logs give values "
            f"further apart than their intervals allow; value and interval not to be trusted "
            f"as they stand): {', '.join(found.model_error)}.",
        ]
    if figure:
        lines += ["", f"![held-out fit]({figure})"]
    return "\n".join(lines) + "\n"


def fit_figure(found: Identification) -> Figure:
    """The held-out part of the first log: measured, identified and start model outputs."""
    trace = found.traces[0]
    labels = _labels(found)
    figure = Figure(figsize=(8, 1.1 + 1.8 * len(labels)))
    FigureCanvasAgg(figure)
    axes = figure.subplots(len(labels), 1, sharex=True, squeeze=False)[:, 0]
    for i, ax in enumerate(axes):
        ax.plot(trace["t"], trace["measured"][:, i], color="0.6", lw=0.8, label="log")
        ax.plot(trace["t"], trace["start"][:, i], "--", color="tab:red", lw=1.0, label="start")
        ax.plot(trace["t"], trace["identified"][:, i], color="tab:blue", lw=1.2,
                label="identified")  # fmt: skip
        ax.set_ylabel(labels[i])
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", ncols=3, fontsize="small")
    axes[-1].set_xlabel("time into the held-out part (s)")
    figure.suptitle("Held-out validation: simulated from the first measured state")
    return figure


def write_identification(
    log_paths: list[str],
    vehicle: str,
    out: Path,
    holdout: float = 0.2,
    overwrite: bool = False,
    options: LogOptions | None = None,
    dof: Dof | None = None,
    current: bool = False,
    thrust_gain: bool = False,
    fixed: tuple[str, ...] = (),
) -> Identification:
    """``auvmpc identify``: identify from logs (run folders, ROS 2 bags, DataFlash logs:
    :func:`~auvmpc.identification.logs.read_log`, read as ``options`` say) starting from
    ``vehicle`` (preset or file) and write ``out`` with identification.json,
    identification.md and identification-fit.png beside it.

    ``dof``: the model to identify, the 3-DOF one (horizontal) or the heave one; None picks
    heave when the first log is a run folder with vertical thrusts (a depth run's log.csv,
    :func:`~auvmpc.identification.heave.is_heave_log`), else horizontal. The 3-DOF model
    also estimates a constant ``current`` and a ``thrust_gain`` if asked
    (:class:`~auvmpc.identification.estimation.HorizontalGreyBox`); the ``fixed`` parameters
    are held at the start file's values."""
    from auvmpc.identification.estimation import HorizontalGreyBox, identify
    from auvmpc.identification.heave import HeaveGreyBox, is_heave_log, read_heave_log
    from auvmpc.identification.logs import read_log
    from auvmpc.identification.roll_pitch import is_six_dof_log
    from auvmpc.identification.six_dof_log import identify_six_dof, read_six_dof_samples

    out = Path(out)
    if out.suffix not in (".yaml", ".yml"):
        raise ConfigError("--out", str(out), "the vehicle file must end in .yaml or .yml")
    folder = out.parent
    outputs = [out, *(folder / name for name in OUTPUT_NAMES)]
    for path in outputs:
        if path.exists() and not overwrite:
            raise ConfigError("--out", str(path), "exists; pass --overwrite to replace it")
    start_data, source = vehicle_data(vehicle, "--vehicle")
    start = validated_vehicle(start_data, source, "--vehicle")
    if not log_paths:
        raise ConfigError("LOG", None, "give at least one log")
    if dof is None:
        dof = Dof.HEAVE if is_heave_log(log_paths[0]) else Dof.HORIZONTAL
        dof = Dof.SIX_DOF if is_six_dof_log(log_paths[0]) else dof
    if dof is not Dof.HORIZONTAL and (current or thrust_gain):
        raise ConfigError(
            "--current" if current else "--thrust-gain", None,
            f"the {dof} model has no current or thrust gain: only the horizontal (3-DOF) "
            "identification estimates them",
        )  # fmt: skip
    if dof is Dof.SIX_DOF:  # every model in turn (one line if the start has no six_dof)
        samples = [read_six_dof_samples(path, start, options) for path in log_paths]
        found = identify_six_dof(samples, start, holdout, fixed)
    elif dof is Dof.HEAVE:
        heave = HeaveGreyBox(start)  # one line if the start vehicle has no heave section
        logs = [read_heave_log(path, heave.thrusters) for path in log_paths]
        outputs = {log.outputs for log in logs}
        if len(outputs) > 1:
            raise ConfigError(
                "LOG", None, "give logs that all have the heave rate w or all only the depth z"
            )
        greybox = HeaveGreyBox(start, logs[0].outputs)
    else:
        logs = [read_log(path, start.n_thrusters, options) for path in log_paths]
        greybox = HorizontalGreyBox(start, current, thrust_gain)
    if dof is not Dof.SIX_DOF:
        found = identify(logs, start, holdout, greybox, fixed)
    text = vehicle_file_text(start_data, found, vehicle)
    load_vehicle(yaml.safe_load(text), "identified vehicle")  # loads as-is, or a bug here
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out, text)
    atomic_write_text(
        folder / "identification.json", json.dumps(identification_json(found), indent=2) + "\n"
    )
    save_figures({"identification-fit": fit_figure(found)}, folder, dpi=FIT_FIGURE_DPI)
    atomic_write_text(
        folder / "identification.md", markdown_report(found, vehicle, "identification-fit.png")
    )
    return found


OUTPUT_NAMES = ("identification.json", "identification.md", "identification-fit.png")
FIT_FIGURE_DPI = 110
