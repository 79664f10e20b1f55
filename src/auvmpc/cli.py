"""Command line: parse, call the library, print. Bad input -> one line, exit code 2."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import (
    BarColumn,
    Progress,
    ProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table
from rich.text import Text

from auvmpc import interrupts
from auvmpc.errors import ConfigError, RunFailed

app = typer.Typer(
    add_completion=False,
    pretty_exceptions_enable=False,
    no_args_is_help=True,
    help="Model-predictive trajectory tracking for AUVs: simulate, reproduce, benchmark.",
)
console = Console()
if not console.is_terminal:  # piped or in CI: do not squeeze tables into 80 columns
    console.width = 160
errors = Console(stderr=True)

USER_ERROR_EXIT = 2
RUN_FAILED_EXIT = 1  # not the input's fault as far as auvmpc can tell


def main() -> None:
    """Console-script entry point: user errors become one line on stderr, never a traceback;
    SIGINT / SIGTERM one line on what was kept, exit 130 / 143."""
    interrupts.reset()
    previous = interrupts.install()
    try:
        _main()
    finally:
        interrupts.restore(previous)  # for callers of main() in a longer-lived process


def _main() -> None:
    try:
        app()
    except ConfigError as error:
        errors.print(f"error: {error}", highlight=False, soft_wrap=True, markup=False)
        sys.exit(USER_ERROR_EXIT)
    except RunFailed as error:
        if interrupts.requested() is not None:
            _interrupted()  # the signal, not the run, ended it (interrupts.py)
        if os.environ.get("AUVMPC_TRACEBACK"):
            raise
        errors.print(
            f"error: {error} (nothing was written; AUVMPC_TRACEBACK=1 shows where)",
            highlight=False, soft_wrap=True, markup=False,
        )  # fmt: skip
        sys.exit(RUN_FAILED_EXIT)
    except KeyboardInterrupt:  # raised outside a command (typer turns the rest into exit 130)
        _interrupted()
    except SystemExit:
        if interrupts.requested() is not None:
            _interrupted()
        raise
    except Exception:
        # Whatever a signal's exception became on its way out of native code (SWIG turns
        # it into NotImplementedError or SystemError), a requested stop is a stop.
        if interrupts.requested() is not None:
            _interrupted()
        raise


def _interrupted() -> None:
    signum = interrupts.requested() or 2
    name = "SIGTERM" if signum == 15 else "SIGINT" if signum == 2 else f"signal {signum}"
    errors.print(
        f"interrupted ({name}): {interrupts.kept()}", highlight=False, soft_wrap=True, markup=False
    )
    sys.exit(128 + signum)


YesLong = Annotated[
    bool,
    typer.Option(
        "--yes-long",
        help="run even beyond the cost limits (1e7 plant steps, 4 h a run, 48 h a campaign: "
        "estimates); memory beyond what is available is still refused",
    ),
]

Overwrite = Annotated[
    bool,
    typer.Option(
        "--overwrite", help="replace an earlier auvmpc output folder there (never anything else)"
    ),
]


def _warn(warnings: list[str]) -> None:
    for warning in warnings:
        errors.print(f"warning: {warning}", highlight=False, soft_wrap=True, markup=False)


def progress_bar() -> Progress:
    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=errors,
        transient=True,
        disable=not errors.is_terminal,  # a transient bar only leaves blank lines in a log
    )


@app.command()
def run(
    scenario: Annotated[
        str | None, typer.Argument(help="built-in name or path to a scenario YAML")
    ] = None,
    out: Annotated[Path | None, typer.Option("--out", help="run folder to write")] = None,
    controller: Annotated[
        str | None,
        typer.Option(
            "--controller",
            help="a controller.type (other settings from the scenario) or a bench label "
            "such as ltv-mpc-nc30 (its overrides; --set still wins)",
        ),
    ] = None,
    set_: Annotated[
        list[str] | None,
        typer.Option("--set", help="override any field: a.b.c=value (value read as YAML)"),
    ] = None,
    figures: Annotated[bool, typer.Option(help="draw figures")] = True,
    figure_format: Annotated[str, typer.Option("--figure-format", help="png | pdf | svg")] = "png",
    dpi: Annotated[int, typer.Option("--dpi", help="figure resolution (dots per inch)")] = 120,
    from_campaign: Annotated[
        Path | None,
        typer.Option("--from-campaign", help="campaign folder: rerun one of its runs (--index)"),
    ] = None,
    index: Annotated[
        int | None, typer.Option("--index", help="run index within --from-campaign")
    ] = None,
    yardstick: Annotated[
        bool, typer.Option("--yardstick", help="with --from-campaign: the run's yardstick twin")
    ] = False,
    overwrite: Overwrite = False,
    yes_long: YesLong = False,
) -> None:
    """Simulate one scenario (or one run of a campaign) and write log.csv, run.json and figures."""
    from auvmpc.api import controller_overrides
    from auvmpc.experiments.outputs import OutputKind, check_output_folder, folder_name
    from auvmpc.experiments.run import simulate, write_run
    from auvmpc.scenario import load_scenario

    check_figure_options(figure_format, dpi, option="--figure-format")
    overrides = [*controller_overrides(controller), *(set_ or [])]
    if from_campaign is not None:
        from auvmpc.experiments.campaign import scenario_for_run

        if scenario is not None:
            raise ConfigError("SCENARIO", scenario, "give a scenario or --from-campaign, not both")
        if index is None:
            raise ConfigError("--index", None, "--from-campaign needs the run index")
        resolved = scenario_for_run(from_campaign, index, overrides, yardstick=yardstick)
    else:
        if scenario is None:
            raise ConfigError("SCENARIO", None, "name one (or --from-campaign DIR --index K)")
        if index is not None:
            raise ConfigError("--index", index, "only with --from-campaign")
        if yardstick:
            raise ConfigError("--yardstick", True, "only with --from-campaign")
        resolved = load_scenario(scenario, overrides)
    name = folder_name(resolved.scenario.name, "name")  # a label and a folder, never a path
    if from_campaign is not None:
        name = f"{name}-run{index}{'-yardstick' if yardstick else ''}"
    label = f"{name}-{controller or resolved.scenario.controller.type}"
    out_dir = out if out is not None else Path("runs") / label
    check_output_folder(out_dir, OutputKind.RUN, overwrite=overwrite)  # before, not after
    with progress_bar() as progress:
        task = progress.add_task(f"{name}", total=None)
        result = simulate(
            resolved,
            on_step=lambda k, n: progress.update(task, completed=k, total=n),
            long_ok=yes_long,
        )
    _warn(result.warnings)
    write_run(
        result,
        out_dir,
        figures=figures,
        figure_format=figure_format,
        dpi=dpi,
        overwrite=overwrite,
    )
    print_metrics(result.metrics, title=label)
    console.print(f"wrote {out_dir}")
    warn_if_not_ok(result.metrics)


@app.command()
def explain(
    scenario: Annotated[str, typer.Argument(help="built-in name or path to a scenario YAML")],
    controller: Annotated[
        str | None, typer.Option("--controller", help="as for run: a type or a bench label")
    ] = None,
    set_: Annotated[
        list[str] | None,
        typer.Option("--set", help="override any field: a.b.c=value (value read as YAML)"),
    ] = None,
) -> None:
    """Say what a run of this scenario would use that it does not state, and why, and what the
    checks before a run find; run nothing."""
    from rich.table import Table

    from auvmpc.api import controller_overrides
    from auvmpc.scenario import load_scenario
    from auvmpc.scenario.sanity import preflight

    resolved = load_scenario(scenario, [*controller_overrides(controller), *(set_ or [])])
    choices = getattr(resolved, "choices", {})
    table = Table(title=f"{resolved.scenario.name}: chosen for {resolved.model.name}")
    for column in ("setting", "value", "why"):
        table.add_column(column, overflow="fold")
    for name, choice in choices.items():
        table.add_row(f"controller.{name}", str(choice["value"]), choice["why"])
    if choices:
        console.print(table)
    else:
        console.print("the scenario states every setting the vehicle would decide")
    warnings = preflight(resolved)
    _warn(warnings)
    if not warnings:
        console.print("checks before a run: nothing to report")


@app.command()
def reproduce(
    out: Annotated[Path, typer.Option("--out", help="folder for runs, tables, figures")] = Path(
        "results/paper"
    ),
    sweep: Annotated[bool, typer.Option(help="include the inertia-uncertainty sweep")] = True,
    figures: Annotated[bool, typer.Option(help="draw PNG figures")] = True,
    overwrite: Overwrite = False,
) -> None:
    """Reproduce the paper's simulations (section 4.1) into one folder."""
    from auvmpc.experiments.outputs import OutputKind, check_output_folder
    from auvmpc.experiments.reproduce import reproduce as run_all

    check_output_folder(out, OutputKind.REPRODUCE, overwrite=overwrite)

    with progress_bar() as progress:
        task = progress.add_task("reproduce", total=None)

        def advance(done: int, total: int, name: str) -> None:
            progress.update(task, completed=done, total=total, description=name)

        run_all(out, include_sweep=sweep, figures=figures, on_run=advance, overwrite=overwrite)
    console.print((out / "summary.md").read_text(), highlight=False)
    console.print((out / "depth.md").read_text(), highlight=False)
    console.print(f"wrote {out}")


@app.command()
def bench(
    controllers: Annotated[
        list[str] | None,
        typer.Option(
            "--controllers",
            help="controller labels, repeated or comma-separated; LABEL@field=value adds an "
            "override to that row only",
        ),
    ] = None,
    scenarios: Annotated[
        list[str] | None,
        typer.Option("--scenarios", help="scenario names or files, repeated or comma-separated"),
    ] = None,
    json_file: Annotated[Path | None, typer.Option("--json", help="write the rows as JSON")] = None,
    repeats: Annotated[int, typer.Option(help="runs per pair; wall time is their median")] = 1,
    set_: Annotated[
        list[str] | None, typer.Option("--set", help="override a field in every run")
    ] = None,
    yardstick: Annotated[
        str | None,
        typer.Option(
            "--yardstick",
            help="controller label every row is measured against on each scenario (same seed), "
            "e.g. los-pid; run too; without --controllers the other is the scenario's own",
        ),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option("--out", help="folder for a run folder per row and the table (bench.md)"),
    ] = None,
    figures: Annotated[bool, typer.Option(help="with --out: draw each run's figures")] = True,
    overwrite: Annotated[
        bool,
        typer.Option("--overwrite", help="replace an existing --json file or --out benchmark"),
    ] = False,
) -> None:
    """Time controllers x scenarios on one core: per-step median/p99/max, wall time, metrics."""
    from auvmpc.experiments.bench import (
        DEFAULT_CONTROLLERS,
        DEFAULT_SCENARIOS,
        SCENARIO_CONTROLLER_LABEL,
        format_table,
        machine_info,
        rows_to_json,
        run_benchmark,
    )
    from auvmpc.experiments.outputs import (
        OutputKind,
        check_output_file,
        check_output_folder,
        write_named_file,
    )

    if json_file is not None:
        check_output_file(json_file, overwrite=overwrite, option="--json")
    if out is not None:
        check_output_folder(out, OutputKind.BENCH, overwrite=overwrite)  # before, not after
    # Measured against a yardstick, the controller to measure is the scenario's own.
    default = (SCENARIO_CONTROLLER_LABEL,) if yardstick is not None else DEFAULT_CONTROLLERS
    with progress_bar() as progress:
        task = progress.add_task("bench", total=None)
        rows = run_benchmark(
            _split(controllers) or default,
            _split(scenarios) or DEFAULT_SCENARIOS,
            repeats,
            on_run=lambda done, total, name: progress.update(
                task, completed=done, total=total, description=name
            ),
            overrides=tuple(set_ or ()),
            yardstick=yardstick,
            out=out,
            figures=figures,
            overwrite=overwrite,
        )
    console.print(format_table(rows, machine_info()))
    if json_file is not None:
        write_named_file(json_file, rows_to_json(rows), option="--json")
        console.print(f"wrote {json_file}")
    if out is not None:
        console.print(f"wrote {out}")


def _split(values: list[str] | None) -> list[str]:
    return [part for value in values or () for part in value.split(",") if part]


class _RunRateColumn(ProgressColumn):
    """Finished runs per second (the speed over rich's recent updates)."""

    def render(self, task) -> Text:
        speed = task.finished_speed or task.speed
        return Text("-- runs/s" if speed is None else f"{speed:.2f} runs/s")


def campaign_progress_bar() -> Progress:
    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        _RunRateColumn(),
        TimeElapsedColumn(),
        TextColumn("ETA"),
        TimeRemainingColumn(),
        console=errors,
        transient=True,
        disable=not errors.is_terminal,  # a transient bar only leaves blank lines in a log
    )


@app.command()
def campaign(
    file: Annotated[str, typer.Argument(help="built-in campaign name or path to a campaign YAML")],
    out: Annotated[
        Path, typer.Option("--out", help="campaign folder; run the same command again to resume")
    ],
    workers: Annotated[
        int | None, typer.Option("--workers", help="local worker processes (default: all CPUs)")
    ] = None,
    runs: Annotated[int | None, typer.Option("--runs", help="run only the first N runs")] = None,
    scheduler: Annotated[
        str | None,
        typer.Option("--scheduler", help="Dask scheduler address, e.g. tcp://host:8786"),
    ] = None,
    report: Annotated[bool, typer.Option(help="write report.md and figures when done")] = True,
    criterion: Annotated[
        str | None,
        typer.Option("--criterion", help="success criterion, e.g. 'max_position_error_m < 1'"),
    ] = None,
    overwrite: Annotated[
        bool,
        typer.Option("--overwrite", help="discard an earlier auvmpc campaign there, start over"),
    ] = False,
    controller: Annotated[
        str | None,
        typer.Option(
            "--controller",
            help="controller label as for 'run --controller' (e.g. ltv-mpc, nmpc), applied to "
            "the tested runs, not the yardstick: another campaign, so another --out",
        ),
    ] = None,
    yardstick_from: Annotated[
        Path | None,
        typer.Option(
            "--yardstick-from",
            help="folder of this campaign with another --controller (finished or partial): "
            "copy its yardstick twins instead of simulating them again",
        ),
    ] = None,
    yes_long: YesLong = False,
) -> None:
    """Run (or resume) a robustness campaign: many runs with sampled parameters, in parallel."""
    from auvmpc.experiments.campaign import campaign_report as make_report
    from auvmpc.experiments.campaign import count_finished, load_campaign, run_campaign
    from auvmpc.experiments.outputs import OutputKind, check_output_folder

    check_output_folder(out, OutputKind.CAMPAIGN, overwrite=overwrite, resume=True)
    loaded = load_campaign(file, controller=controller)

    def kept() -> str:
        rows = count_finished(out)
        return f"{rows} finished runs kept in {out}; the same command resumes from there"

    with interrupts.describe_kept(kept), campaign_progress_bar() as progress:
        task = None

        def advance(done: int, total: int) -> None:
            nonlocal task
            if task is None:  # start at the runs already stored, so the rate counts new ones
                task = progress.add_task(loaded.spec.name, total=total, completed=done)
            else:
                progress.update(task, completed=done, total=total)

        summary = run_campaign(
            loaded,
            out,
            workers=workers,
            runs=runs,
            scheduler=scheduler,
            on_progress=advance,
            overwrite=overwrite,
            yardstick_from=yardstick_from,
            long_ok=yes_long,
        )
    console.print(
        f"{summary.total} runs: {summary.ok} ok, {summary.failed} failed "
        f"({summary.new} run now in {summary.wall_s:.1f} s)",
        highlight=False,
    )
    if summary.ok == 0:
        # Nothing to report on: every run failed or was refused (the store says why).
        raise RunFailed(
            f"campaign {loaded.spec.name}: none of its {summary.total} runs finished; "
            f"first error: {summary.first_error}"
        )
    if report:
        result = make_report(out, criterion, workers=workers or 1)
        console.print(result.markdown, highlight=False, markup=False)
    console.print(f"wrote {out}")


@app.command("campaign-report")
def campaign_report(
    out: Annotated[Path, typer.Argument(help="a campaign folder")],
    criterion: Annotated[
        str | None,
        typer.Option("--criterion", help="success criterion (default: the campaign file's)"),
    ] = None,
    worst: Annotated[int, typer.Option("--worst", help="worst runs to list")] = 5,
    worst_by: Annotated[
        str | None, typer.Option("--worst-by", help="column ranking the worst runs")
    ] = None,
    worst_order: Annotated[
        str | None, typer.Option("--worst-order", help="desc: largest is worst; asc: smallest")
    ] = None,
    figures: Annotated[bool, typer.Option(help="draw PNG figures")] = True,
    workers: Annotated[
        int, typer.Option("--workers", help="processes re-simulating the worst yardstick pairs")
    ] = 1,
) -> None:
    """Success rate with a 95 % interval, metric percentiles, worst runs, plots."""
    from auvmpc.experiments.campaign import campaign_report as make_report

    result = make_report(
        out,
        criterion,
        worst=worst,
        worst_by=worst_by,
        worst_order=worst_order,
        figures=figures,
        workers=workers,
    )
    console.print(result.markdown, highlight=False, markup=False)
    console.print(f"wrote {', '.join(str(path) for path in result.files[-2:])}")


@app.command()
def scenarios() -> None:
    """List the built-in scenarios."""
    from auvmpc.scenario import builtin_scenarios

    for name, description in builtin_scenarios().items():
        console.print(f"{name:<22} {description}", highlight=False)


@app.command()
def vehicles() -> None:
    """List the built-in vehicle presets: mass, size, thrusters, the models each has."""
    from auvmpc.models.vehicle import load_vehicle, preset_names

    table = Table(title="vehicle presets (a scenario names one with vehicle: NAME)")
    for column in ("name", "mass kg", "size m (L x W x H)", "thrusters", "DOF", "description"):
        table.add_column(column, overflow="fold")
    for name in preset_names():
        vehicle = load_vehicle(name)
        size = vehicle.size
        vertical = vehicle.heave.thruster_count if vehicle.heave is not None else 0
        if vehicle.has_thrusters:
            thrusters = f"{vehicle.n_thrusters}" + (f" + {vertical} vertical" if vertical else "")
        else:  # a propeller and fins: its inputs by name
            thrusters = "none: " + ", ".join(vehicle.six_dof_actuators.layout.names)
        models = (
            (["3-DOF"] if vehicle.has_thrusters else [])
            + (["depth"] if vehicle.heave else [])
            + (["6-DOF"] if vehicle.six_dof else [])
        )
        table.add_row(
            name,
            f"{vehicle.mass:g}",
            "-" if size is None else f"{size.length:g} x {size.width:g} x {size.height:g}",
            thrusters,
            ", ".join(models),
            vehicle.description,
        )
    console.print(table)


vehicle_app = typer.Typer(no_args_is_help=True, help="Write vehicle files.")
app.add_typer(vehicle_app, name="vehicle")


def _numbers(text: str, count: int, option: str, form: str) -> tuple[float, ...]:
    """``count`` finite numbers separated by commas, or a one-line ConfigError naming
    ``option``."""
    import math

    parts = text.split(",")
    try:
        values = tuple(float(part) for part in parts)
    except ValueError:
        values = ()
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise ConfigError(option, text, f"need {form}")
    return values


def _positive(value: float | None, option: str) -> None:
    import math

    if value is not None and not (math.isfinite(value) and value > 0):
        raise ConfigError(option, value, "must be a finite number > 0")


@vehicle_app.command("new")
def vehicle_new(
    name: Annotated[str, typer.Argument(help="the vehicle's short identifier")],
    mass: Annotated[float, typer.Option("--mass", help="rigid-body mass (kg)")],
    length: Annotated[float, typer.Option("--length", help="envelope along x, forward (m)")],
    width: Annotated[float, typer.Option("--width", help="envelope along y, starboard (m)")],
    height: Annotated[float, typer.Option("--height", help="envelope along z, down (m)")],
    thruster: Annotated[
        list[str],
        typer.Option(
            "--thruster",
            help="X,Y,ANGLE_DEG of a horizontal thruster (m, m, deg from +x towards +y), "
            "repeated; e.g. --thruster=0.156,0.111,-45",
        ),
    ],
    thrust_limits: Annotated[
        str, typer.Option("--thrust-limits", help="LOW,HIGH per thruster (N), e.g. -40,51")
    ],
    out: Annotated[Path, typer.Option("--out", help="vehicle file to write (.yaml)")],
    thrust_rate_limit: Annotated[
        float | None,
        typer.Option(
            "--thrust-rate-limit",
            help="per thruster |dF/dt| (N/s); default: the full range in one second (marked "
            "estimated)",
        ),
    ] = None,
    top_speed: Annotated[
        float | None,
        typer.Option(
            "--top-speed",
            help="top speed (m/s) for the skin friction; default: where the full surge "
            "thrust meets the estimated drag",
        ),
    ] = None,
    shape: Annotated[
        str, typer.Option("--shape", help="box (open-frame ROV) | ellipsoid (streamlined hull)")
    ] = "box",
    six_dof: Annotated[
        bool, typer.Option("--six-dof", help="add a six_dof section (needs vertical thrusters)")
    ] = False,
    vertical_thruster: Annotated[
        list[str] | None,
        typer.Option(
            "--vertical-thruster",
            help="X,Y of a thruster pushing up (m), repeated: adds a heave section",
        ),
    ] = None,
    water_density: Annotated[
        float, typer.Option("--water-density", help="kg/m3: 1000 fresh, 1025 sea water")
    ] = 1000.0,
    overwrite: Annotated[
        bool, typer.Option("--overwrite", help="replace an existing --out file")
    ] = False,
) -> None:
    """Write a vehicle file with first estimates of its model from the mass and size
    (added mass, inertia, damping: docs/vehicles.md); it loads as-is."""
    from auvmpc.experiments.outputs import atomic_write_text, check_output_file
    from auvmpc.models.from_size import HullShape, estimate_vehicle, vehicle_file_text
    from auvmpc.models.vehicle import VehicleSize, load_vehicle

    if not name.strip() or not name.isprintable():
        raise ConfigError("NAME", name, "must be one printable line")
    for value, option in ((mass, "--mass"), (length, "--length"), (width, "--width"),
                          (height, "--height"), (top_speed, "--top-speed"),
                          (water_density, "--water-density")):  # fmt: skip
        _positive(value, option)
    _positive(thrust_rate_limit, "--thrust-rate-limit")
    shapes = [member.value for member in HullShape]
    if shape not in shapes:
        raise ConfigError("--shape", shape, f"one of {shapes}")
    form = "X,Y,ANGLE_DEG (m, m, deg), e.g. 0.156,0.111,-45"
    planar = [_numbers(text, 3, "--thruster", form) for text in thruster]
    if len(planar) < 2:
        raise ConfigError("--thruster", thruster, "need at least two horizontal thrusters")
    low, high = _numbers(thrust_limits, 2, "--thrust-limits", "LOW,HIGH (N), e.g. -40.2,51.5")
    if not low < high:
        raise ConfigError("--thrust-limits", thrust_limits, "need LOW < HIGH")
    vertical = [_numbers(text, 2, "--vertical-thruster", "X,Y (m), e.g. 0.12,-0.218")
                for text in vertical_thruster or ()]  # fmt: skip
    if out.suffix not in (".yaml", ".yml"):
        raise ConfigError("--out", str(out), "a vehicle file ends in .yaml or .yml")
    target = check_output_file(out, overwrite=overwrite, option="--out")
    estimate = estimate_vehicle(
        name, mass, VehicleSize(length=length, width=width, height=height), planar,
        (low, high), thrust_rate_limit, shape=HullShape(shape), top_speed=top_speed,
        vertical_thrusters=vertical, six_dof=six_dof, water_density=water_density,
    )  # fmt: skip
    text = vehicle_file_text(estimate)
    atomic_write_text(target, text)
    load_vehicle(target)  # what was written loads as-is
    console.print(
        f"wrote {out}: {len(estimate.params.estimated)} estimated fields "
        f"({', '.join(estimate.params.estimated)}); next: check them against a run of the "
        "real vehicle, later `auvmpc identify`",
        highlight=False,
    )


@app.command()
def excite(
    vehicle: Annotated[str, typer.Argument(help="preset name or vehicle file")],
    out: Annotated[Path, typer.Option("--out", help="scenario file to write (.yaml)")],
    duration: Annotated[float, typer.Option("--duration", help="manoeuvre length (s)")] = 300.0,
    seed: Annotated[int, typer.Option("--seed", help="seed of the multisine phases")] = 0,
    sample_time: Annotated[
        float, typer.Option("--sample-time", help="how long each thrust row is held (s)")
    ] = 0.1,
    box: Annotated[
        float,
        typer.Option(
            "--box", help="the nominal model stays this close to its start (m; heave: depth)"
        ),
    ] = 15.0,
    dof: Annotated[
        str,
        typer.Option(
            "--dof",
            help="horizontal (surge, sway, yaw: the 3-DOF model), heave (the vertical "
            "thrusters: the depth model, a depth scenario) or six-dof (all six axes on every "
            "thruster: a 6-DOF scenario, for every model)",
        ),
    ] = "horizontal",
    overwrite: Overwrite = False,
) -> None:
    """Write an identification manoeuvre: a scenario that plays a thrust table open loop,
    and the table (CSV, beside it) to play on the real vehicle."""
    from auvmpc.identification import write_excitation
    from auvmpc.identification.excitation import Dof

    if dof not in set(Dof):
        raise ConfigError("--dof", dof, f"one of {', '.join(Dof)}")
    excitation = write_excitation(
        vehicle, out, duration, seed, sample_time, box, overwrite, Dof(dof)
    )
    console.print(
        f"wrote {out} and {out.with_suffix('.csv').name}: {len(excitation.thrust)} rows of "
        f"{excitation.sample_time:g} s, peak {excitation.amplitude_share:.0%} of the thrust "
        f"limits, nominal excursion {excitation.excursion_m:.1f} m",
        highlight=False,
    )


def _channel_list(text: str | None, flag: str) -> tuple[int, ...]:
    """``1,2,3,4`` -> (1, 2, 3, 4); one line naming the flag for anything else."""
    if not text:
        return ()
    try:
        return tuple(int(item) for item in text.split(","))
    except ValueError:
        raise ConfigError(flag, text, "a comma-separated list of channel numbers") from None


@app.command()
def identify(
    logs: Annotated[
        list[str],
        typer.Argument(
            help="auvmpc run folders, ROS 2 bags (folder, .mcap, .db3), ArduSub DataFlash "
            "logs (.bin, .log)",
            metavar="LOG",
        ),
    ],
    vehicle: Annotated[str, typer.Option("--vehicle", help="start vehicle: preset or file")],
    out: Annotated[Path, typer.Option("--out", help="identified vehicle file to write (.yaml)")],
    holdout: Annotated[
        float, typer.Option("--holdout", help="share at the end of each log kept to validate")
    ] = 0.2,
    sample_time: Annotated[
        float | None,
        typer.Option(
            "--sample-time",
            help="bags, DataFlash: resampling step (s); default the commands' median interval",
        ),
    ] = None,  # fmt: skip
    odometry_topic: Annotated[
        str, typer.Option("--odometry-topic", help="bags: nav_msgs/msg/Odometry topic")
    ] = "/odom",
    thrust_topic: Annotated[
        str,
        typer.Option(
            "--thrust-topic",
            help="bags: std_msgs/msg/Float64MultiArray topic of "
            "the thrusters' forces (N), in the vehicle's order",
        ),
    ] = "/thrust",  # fmt: skip
    wrench_topic: Annotated[
        str | None,
        typer.Option(
            "--wrench-topic",
            help="bags: geometry_msgs/msg/WrenchStamped topic of "
            "the body wrench, used instead of the thrust topic",
        ),
    ] = None,  # fmt: skip
    body_frame: Annotated[
        str,
        typer.Option(
            "--body-frame",
            help="bags: frd (x fwd, y starboard: auvmpc export) or flu (REP 103 base_link)",
        ),
    ] = "frd",  # fmt: skip
    thruster_curve: Annotated[
        str,
        typer.Option(
            "--thruster-curve",
            help="DataFlash: PWM to force, t200-16v, t200-12v or a CSV file (pwm_us, force_n)",
        ),
    ] = "t200-16v",  # fmt: skip
    channels: Annotated[
        str | None,
        typer.Option(
            "--channels",
            help="DataFlash: RCOU channels of the vehicle's thrusters "
            "in its order, e.g. 1,2,3,4 (default 1..n)",
        ),
    ] = None,  # fmt: skip
    reversed_channels: Annotated[
        str | None,
        typer.Option("--reversed", help="DataFlash: channels whose thrust is reversed, e.g. 2,3"),
    ] = None,
    dof: Annotated[
        str,
        typer.Option(
            "--dof",
            help="the model: horizontal (3-DOF), heave (the depth model, from run folders "
            "with Fz1..), six-dof (the 3-DOF, heave and roll and pitch models, from 6-DOF "
            "run folders, ROS 2 bags or DataFlash logs), or auto: heave "
            "if the first log is a depth run's, six-dof if a 6-DOF run's",
        ),
    ] = "auto",
    current: Annotated[
        bool,
        typer.Option(
            "--current",
            help="also estimate a constant current (world frame, from the logged heading); "
            "reported, not written into the vehicle (horizontal only)",
        ),
    ] = False,
    thrust_gain: Annotated[
        bool,
        typer.Option(
            "--thrust-gain",
            help="also estimate one gain on every thrust (needs --fix: the gain is measured "
            "in a held parameter's scale); the vehicle file's thrust limits are scaled by it "
            "(horizontal only)",
        ),
    ] = False,
    fix: Annotated[
        str | None,
        typer.Option(
            "--fix",
            help="parameters held at the start file's values, e.g. m11 or m11,Iz_added "
            "(heave: heave.m_heave)",
        ),
    ] = None,
    then_run: Annotated[
        str | None,
        typer.Option(
            "--then-run",
            help="then fly this scenario (its vehicle the plant) with the identified and the "
            "start vehicle as the model; both runs and their comparison in OUT-STEM-flown/",
            metavar="SCENARIO",
        ),
    ] = None,
    overwrite: Overwrite = False,
) -> None:
    """Identify the 3-DOF model (masses, added inertia, damping; optionally a current and a
    thrust gain), the heave model (heave mass, damping, net buoyancy) or, from 6-DOF logs,
    both and roll and pitch from logs; write the vehicle file, identification.json,
    identification.md and a fit figure beside it."""
    from auvmpc.identification import LogOptions, write_identification
    from auvmpc.identification.excitation import Dof
    from auvmpc.identification.heave import is_heave_log

    if dof != "auto" and dof not in set(Dof):
        raise ConfigError("--dof", dof, f"one of auto, {', '.join(Dof)}")
    chosen = None if dof == "auto" else Dof(dof)
    from auvmpc.identification.roll_pitch import is_six_dof_log

    heave = chosen is Dof.HEAVE or (chosen is None and is_heave_log(logs[0]))
    six_dof = chosen is Dof.SIX_DOF or (chosen is None and is_six_dof_log(logs[0]))
    if then_run is not None and (heave or six_dof):
        raise ConfigError(
            "--then-run", then_run, "flies horizontal scenarios: not after heave or six-dof"
        )

    options = LogOptions(
        sample_time=sample_time,
        odometry_topic=odometry_topic,
        thrust_topic=thrust_topic,
        wrench_topic=wrench_topic,
        body_frame=body_frame,
        thruster_curve=thruster_curve,
        channels=_channel_list(channels, "--channels"),
        reversed_channels=_channel_list(reversed_channels, "--reversed"),
    )
    fixed = tuple(name.strip() for name in fix.split(",") if name.strip()) if fix else ()
    found = write_identification(
        logs, vehicle, out, holdout, overwrite, options, chosen,
        current=current, thrust_gain=thrust_gain, fixed=fixed,
    )  # fmt: skip
    table = Table(title=f"identified from {len(found.logs)} log(s)")
    for column in ("parameter", "start", "identified", "95 % interval", "excited"):
        table.add_column(column)
    for p in found.parameters + found.extras:
        table.add_row(
            p.name, f"{p.start:.4g}", f"{p.value:.4g}", f"[{p.ci95[0]:.4g}, {p.ci95[1]:.4g}]",
            "fixed" if p.fixed else ("NO" if not p.excited else
                                     "model error" if p.model_error else "yes"),
        )  # fmt: skip
    console.print(table)
    rms = ", ".join(f"{x:.3g}" for x in found.validation_rms)
    rms_start = ", ".join(f"{x:.3g}" for x in found.validation_rms_start)
    console.print(
        f"held-out RMS {', '.join(found.outputs)}: {rms} (start file: {rms_start})",
        highlight=False,
    )
    if found.unexcited:
        _warn([f"not excited by the logs, start value kept: {', '.join(found.unexcited)}"])
    if found.model_error:
        _warn([f"excited, but model error dominates the fit (the log's halves disagree beyond "
               f"the interval): {', '.join(found.model_error)}"])  # fmt: skip
    console.print(f"wrote {out} and identification.json, .md, -fit.png beside it")
    if then_run is not None:
        from auvmpc.identification.flight import fly_identified

        flight = fly_identified(then_run, out, vehicle, overwrite)
        for label, metrics in flight.metrics.items():
            rms = metrics["rms_position_error_after_transient_m"]
            after = "n/a" if rms is None else f"{rms:.3g} m"
            console.print(
                f"{then_run} with the {label} model: RMS after the transient {after}, "
                f"verdict {metrics['verdict']} ({flight.folders[label]})",
                highlight=False,
            )
        console.print(f"compared in {flight.comparison}", highlight=False)


FigureFormat = Annotated[str, typer.Option("--format", help="png | pdf | svg")]
Dpi = Annotated[int, typer.Option("--dpi", help="resolution (dots per inch) of raster output")]


def check_figure_options(fmt: str, dpi: int, option: str = "--format") -> None:
    from auvmpc.plots import FIGURE_FORMATS

    if fmt not in FIGURE_FORMATS:
        raise ConfigError(option, fmt, f"one of {list(FIGURE_FORMATS)}")
    if not 10 <= dpi <= 2400:
        raise ConfigError("--dpi", dpi, "must be between 10 and 2400")


@app.command()
def plot(
    run_dir: Annotated[Path, typer.Argument(help="a folder written by 'auvmpc run'")],
    fmt: FigureFormat = "png",
    dpi: Dpi = 120,
) -> None:
    """Re-draw the figures of a saved run from its log.csv and run.json."""
    from auvmpc.experiments.outputs import OutputKind, require_own_folder
    from auvmpc.experiments.run import redraw

    require_own_folder(run_dir, OutputKind.RUN, "RUN_DIR")
    if not (run_dir / "run.json").is_file() or not (run_dir / "log.csv").is_file():
        raise ConfigError("RUN_DIR", str(run_dir), "not a run folder (needs run.json and log.csv)")
    check_figure_options(fmt, dpi)
    redraw(run_dir, fmt, dpi)
    console.print(f"redrew figures in {run_dir} ({fmt})")


@app.command()
def compare(
    run_dirs: Annotated[list[Path], typer.Argument(help="two or more folders of 'auvmpc run'")],
    out: Annotated[Path, typer.Option("--out", help="folder for the overlays and the table")],
    label: Annotated[
        list[str] | None, typer.Option("--label", help="legend name per run, in order")
    ] = None,
    fmt: FigureFormat = "png",
    dpi: Dpi = 120,
) -> None:
    """Overlay runs (trajectories, errors, thrusts) and tabulate their metrics."""
    from auvmpc.experiments.compare import compare_runs, load_compared_runs, metrics_markdown

    check_figure_options(fmt, dpi)
    runs = load_compared_runs(run_dirs, label)
    compare_runs(runs, out, fmt, dpi)
    console.print(metrics_markdown(runs), highlight=False, markup=False)
    console.print(f"wrote {out}")


@app.command()
def animate(
    run_dir: Annotated[Path, typer.Argument(help="a folder written by 'auvmpc run'")],
    out: Annotated[
        Path | None,
        typer.Option("--out", help="file .gif or .mp4 (default RUN_DIR/animation.gif)"),
    ] = None,
    fps: Annotated[float, typer.Option("--fps", help="playback frames per second")] = 20.0,
    speed: Annotated[
        float, typer.Option("--speed", help="simulated seconds per second of playback")
    ] = 10.0,
    dpi: Annotated[int, typer.Option("--dpi", help="resolution (6 in square frame)")] = 80,
) -> None:
    """Animate a run: vehicle, thrust arrows, reference and horizon, obstacles, clock."""

    from auvmpc.animation import AnimationSettings, animate_run
    from auvmpc.experiments.outputs import new_entry
    from auvmpc.experiments.run import read_planar_run

    _, scenario, model, log = read_planar_run(run_dir, "animate")
    settings = AnimationSettings(fps=fps, speed=speed, dpi=dpi)
    if out is None:
        out = run_dir / "animation.gif"
    with new_entry(out, "--out") as target, progress_bar() as progress:
        task = progress.add_task("frames", total=None)
        animate_run(
            log, scenario, model, target, settings,
            on_frame=lambda done, total: progress.update(task, completed=done, total=total),
        )  # fmt: skip
    console.print(f"wrote {out}")


@app.command()
def export(
    run_dir: Annotated[Path, typer.Argument(help="a folder written by 'auvmpc run'")],
    format_: Annotated[
        str, typer.Option("--format", help="rosbag2 (MCAP storage; needs auvmpc[ros])")
    ] = "rosbag2",
    out: Annotated[
        Path | None, typer.Option("--out", help="folder to create (default RUN_DIR/rosbag2)")
    ] = None,
) -> None:
    """Write a run in another tool's format: a ROS 2 bag for Foxglove, PlotJuggler, rviz."""
    from auvmpc.export import export_rosbag2

    if format_ != "rosbag2":
        raise ConfigError("--format", format_, "one of ['rosbag2']")
    console.print(f"wrote {export_rosbag2(run_dir, out)}")


@app.command("export-c")
def export_c(
    scenario: Annotated[str, typer.Argument(help="built-in name or path to a scenario YAML")],
    out: Annotated[Path, typer.Option("--out", help="folder to write the C library into")],
    set_: Annotated[
        list[str] | None,
        typer.Option("--set", help="override any field: a.b.c=value (value read as YAML)"),
    ] = None,
    overwrite: Overwrite = False,
    blasfeo: Annotated[
        list[Path] | None,
        typer.Option(
            "--blasfeo",
            help="folder with a libblasfeo.so built for one CPU: also the target x86-64-tuned "
            "(or aarch64-tuned) under the wheel's HPIPM; once per instruction set "
            "(docs/onboard.md)",
        ),
    ] = None,
    aarch64: Annotated[
        Path | None,
        typer.Option(
            "--aarch64",
            help="folder with the aarch64 HPIPM and BLASFEO (make hpipm-aarch64): also the "
            "target aarch64",
        ),
    ] = None,
    generic_blasfeo: Annotated[
        Path | None,
        typer.Option(
            "--generic-blasfeo",
            help="folder with a libblasfeo.so built for AVX (make blasfeo-avx): the target "
            "x86-64-generic's BLASFEO instead of the wheel's GENERIC one, on the same CPUs "
            "(docs/onboard.md)",
        ),
    ] = None,
) -> None:
    """Write the scenario's real-time controller (nmpc, every move free) as a self-contained
    C99 library that builds with `make` (`make TARGET=aarch64`) anywhere."""
    from auvmpc.export.c_library import export_c as write_export
    from auvmpc.scenario import load_scenario

    resolved = load_scenario(scenario, set_ or [])
    written = write_export(
        resolved, out, overwrite=overwrite, blasfeo=blasfeo or (), aarch64=aarch64,
        generic_blasfeo=generic_blasfeo,
    )  # fmt: skip
    console.print(f"wrote {written}")


@app.command("verify-c")
def verify_c(
    folder: Annotated[Path, typer.Argument(metavar="DIR", help="a folder written by export-c")],
    run_dir: Annotated[
        Path,
        typer.Argument(
            help="a run of the same scenario with controller.type=nmpc, "
            "controller.control_horizon=null (and, for a six-dof one, no sensor noise)"
        ),
    ],
    target: Annotated[
        str | None,
        typer.Option(
            "--target",
            help="the export's make TARGET to build and replay (aarch64: cross-built, run "
            "under qemu-aarch64); default: this computer's",
        ),
    ] = None,
    instructions: Annotated[
        bool,
        typer.Option(
            "--instructions",
            help="also count each step's instructions (valgrind; a QEMU plugin emulated)",
        ),
    ] = False,
) -> None:
    """Build an export, replay a run through it, compare with the run's Python commands."""
    from auvmpc.export.c_library import median_instructions
    from auvmpc.export.c_library import verify_c as replay_and_compare

    result = replay_and_compare(folder, run_dir, target=target, instructions=instructions)
    counted = median_instructions(result)
    console.print(
        f"target {result.target}  "
        f"steps {result.steps}  max |F_C - F_Python| {result.max_difference_n:.3g} N "
        f"(step {result.worst_step})  fallbacks {result.fallbacks}  "
        f"recoveries {result.recoveries}  status differences {result.status_differences}  "
        f"step median {result.step_us_median:.0f} us  max {result.step_us_max:.0f} us "
        f"({result.step_us_max_after_first:.0f} us after the cold first step)  "
        f"static memory {result.static_bytes} B controller + {result.workspace_bytes} B HPIPM  "
        f"heap calls in steps {result.heap_calls}  iterations max {result.max_iterations} "
        f"(bound {result.iteration_bound})"
        + (
            ""
            if result.depth_max_iterations is None
            else f"  depth: fallbacks {result.depth_fallbacks}  recoveries "
            f"{result.depth_recoveries}  status differences {result.depth_status_differences}  "
            f"DAQP iterations max {result.depth_max_iterations}"
        )
        + (
            ""
            if counted is None
            else f"  instructions per step: median {counted:.0f}, max {max(result.instructions)}"
        )  # fmt: skip
    )
    if result.failures:
        errors.print(
            f"not reproduced: {'; '.join(result.failures)}",
            highlight=False, soft_wrap=True, markup=False,
        )  # fmt: skip
        raise typer.Exit(RUN_FAILED_EXIT)


@app.command()
def schema(
    kind: Annotated[str, typer.Argument(help="scenario | vehicle | campaign")] = "scenario",
    markdown: Annotated[
        bool,
        typer.Option("--markdown", help="print docs/scenario-reference.md (all files) instead"),
    ] = False,
) -> None:
    """Print the JSON Schema of a scenario, vehicle or campaign file (from the pydantic models)."""
    import json

    from auvmpc.experiments.json_schema import SchemaKind, json_schema, reference_markdown

    if markdown:
        sys.stdout.write(reference_markdown())
        return
    kinds = [member.value for member in SchemaKind]
    if kind not in kinds:
        raise ConfigError("KIND", kind, f"one of {kinds}")
    sys.stdout.write(json.dumps(json_schema(kind), indent=2) + "\n")


def warn_if_not_ok(metrics: dict) -> None:
    """One line on stderr when the run's verdict is not ok (auvmpc.sim.verdict)."""
    verdict = metrics.get("verdict")
    if verdict is not None and verdict != "ok":
        _warn([f"run {verdict}: {metrics['verdict_reason']}"])


def print_metrics(metrics: dict, title: str) -> None:
    table = Table(title=title, show_header=True)
    table.add_column("metric")
    table.add_column("value", justify="right")
    for key, value in metrics.items():
        text = (
            "-" if value is None else (f"{value:.4g}" if isinstance(value, float) else str(value))
        )
        table.add_row(key, text)
    console.print(table)


if __name__ == "__main__":
    main()
