"""``auvmpc identify --then-run SCENARIO``: the identified vehicle flown straight away.

The scenario runs twice with its own vehicle as the plant (or its ``plant.vehicle``, where
it names one): once with the identified file as the controller's model, once with the start
vehicle. Both run folders and their comparison (``auvmpc compare``) are written beside the
identified file, in ``<stem>-flown/``: what the identification bought, on the mission.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from auvmpc.models.vehicle import preset_names

__all__ = ["Flight", "fly_identified"]

MODELS = ("identified", "start")


@dataclass(frozen=True)
class Flight:
    """The two runs' folders and metrics, and the comparison's folder."""

    folders: dict[str, Path]
    metrics: dict[str, dict]
    comparison: Path


def fly_identified(scenario: str, identified: Path, start: str, overwrite: bool = False) -> Flight:
    """Fly ``scenario`` with ``identified`` and then ``start`` (a preset or a vehicle file)
    as the controller's model, the scenario's vehicle as the plant (module docstring)."""
    from auvmpc.experiments.compare import compare_runs, load_compared_runs
    from auvmpc.experiments.run import simulate, write_run
    from auvmpc.scenario import load_scenario

    written = load_scenario(scenario).scenario
    plant = written.plant.vehicle if written.plant.vehicle is not None else written.vehicle
    # Overrides are YAML: a mapping as JSON (a subset), a file by its absolute path (a
    # relative one would be read from the scenario's folder).
    plant_override = [] if written.plant.vehicle is not None else [f"plant.vehicle={_yaml(plant)}"]
    models = {"identified": str(Path(identified).resolve()), "start": _absolute(start)}
    folder = Path(identified).parent / f"{Path(identified).stem}-flown"
    folders, metrics = {}, {}
    for label in MODELS:
        resolved = load_scenario(scenario, [f"vehicle={_yaml(models[label])}", *plant_override])
        result = simulate(resolved)
        folders[label] = write_run(result, folder / label, overwrite=overwrite)
        metrics[label] = result.metrics
    runs = load_compared_runs([folders[label] for label in MODELS], list(MODELS))
    compare_runs(runs, folder / "compare")
    return Flight(folders, metrics, folder / "compare")


def _absolute(spec: str) -> str:
    """A preset's name as it is, a file's path made absolute."""
    return spec if spec in preset_names() else str(Path(spec).resolve())


def _yaml(value) -> str:
    """``value`` as an override's YAML text: a name or path as a quoted string, a mapping as
    JSON."""
    return json.dumps(value)
