"""A saved run folder, read once and checked: ``run.json``, ``log.csv`` and what they hold.

The one reader of a run folder for every command that reads one (``plot``, ``animate``,
``compare``, ``export``, ``verify-c``; ``identify`` reads log.csv with the same table checks,
:class:`~auvmpc.sim.log.LogTable`) and for the Python API. What auvmpc cannot have written
is one :class:`~auvmpc.errors.ConfigError` line naming the file and the damage (exit 2
from the CLI): run.json that is not UTF-8 JSON, not an object or without a key the command
needs, or whose scenario or vehicle does not validate; log.csv as
:meth:`SimLog.read_csv <auvmpc.sim.log.SimLog.read_csv>` checks it, and longer than
run.json's scenario can have run. :func:`read_run_tables` gives the log by column name, as
a DataFrame (the bag export and ``auvmpc.load_run`` read every kind of log and columns added
later that way).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd
from pydantic import ValidationError

from auvmpc.controllers.config import SAVED_RUN
from auvmpc.errors import ConfigError, format_validation_error
from auvmpc.experiments.kinds import RunKind, kind_of
from auvmpc.models.vehicle import VehicleParams
from auvmpc.safe_yaml import read_text_file
from auvmpc.sim.log import MAX_LOG_BYTES, LogTable, SimLog, read_log_table

__all__ = ["RunFolder", "RunTables", "read_run_folder", "read_run_tables"]

# What run.json holds (docs/run-folder.md): the keys whose values are objects.
_OBJECT_KEYS = ("scenario", "plant", "model", "metrics")


@dataclass
class RunFolder:
    """A run folder's run.json (``info``, an object holding the keys asked for) and, read
    when first asked for, its log.csv (``table``) and what they hold, each checked."""

    path: Path
    info: dict[str, Any]
    field: str = "RUN_DIR"  # what the errors name: the command's argument
    _table: LogTable | None = None  # log.csv, read once

    @property
    def run_json(self) -> Path:
        return self.path / "run.json"

    @property
    def kind(self) -> RunKind:
        try:
            return kind_of(self.info["scenario"])
        except ConfigError as error:
            reason = f"{error.reason} ({self.run_json})"
            raise ConfigError(error.field, error.value, reason) from None

    def scenario(self):
        """run.json's scenario, validated (as it was resolved: every default filled in)."""
        kind = self.kind
        try:
            return kind.scenario_type.model_validate(
                self.info["scenario"], context={SAVED_RUN: True}
            )
        except ValidationError as error:
            raise format_validation_error(error, "scenario", str(self.run_json)) from None

    def vehicle(self, key: str) -> VehicleParams:
        """run.json's ``model`` (the controller's vehicle) or ``plant`` (the simulated one)."""
        if key not in self.info:
            raise ConfigError(self.field, str(self.run_json), f"run.json has no {key!r}")
        try:
            return VehicleParams.model_validate(self.info[key])
        except ValidationError as error:
            raise format_validation_error(error, key, str(self.run_json)) from None

    def table(self) -> LogTable:
        if self._table is None:
            self._table = read_log_table(self.path / "log.csv", self.field)
        return self._table

    def log(self, kind: RunKind | None = None) -> SimLog:
        """log.csv as a log of ``kind`` (default: the run's own), checked as
        :meth:`SimLog.read_csv` checks it and against the length of run.json's scenario."""
        own = self.kind
        if own.reads_model or (kind or own).reads_model:
            self.vehicle("model")  # checked: one line if it is damaged
        log = (kind or own).read_log(self.table(), self.info)
        self._check_length(log)
        return log

    def _check_length(self, log: SimLog) -> None:
        """A log longer than its run's scenario allows (duration / sample time commands) was
        not written by that run. A shorter one may be whole (a session closed early): what
        shows a cut there is a final row with a command (:meth:`LogTable.final_row_empty`)."""
        scenario = self.info["scenario"]
        controller = scenario.get("controller")
        duration = scenario.get("duration")
        sample_time = controller.get("sample_time") if isinstance(controller, dict) else None
        numbers = (int, float)
        if not (isinstance(duration, numbers) and isinstance(sample_time, numbers)):
            return
        if not (duration > 0 and sample_time > 0):
            return
        steps = int(round(duration / sample_time))
        if log.steps > steps:
            raise self.table().damaged(
                f"has {log.steps} commands, more than {steps}, all that run.json's scenario "
                f"runs ({duration:g} s at {sample_time:g} s): not this run's log"
            )


def read_run_folder(
    run_dir: str | Path, keys: tuple[str, ...] = ("scenario",), field: str = "RUN_DIR"
) -> RunFolder:
    """A run folder's run.json, checked: UTF-8 JSON, an object, holding ``scenario`` and
    ``keys`` (its ``scenario``, ``plant``, ``model`` and ``metrics`` objects); log.csv must
    be there. Anything else is one line naming ``field`` and the file."""
    path = Path(run_dir)
    if not (path / "run.json").is_file() or not (path / "log.csv").is_file():
        raise ConfigError(field, str(run_dir), "not a run folder (needs run.json and log.csv)")
    file = path / "run.json"
    text = read_text_file(file, field, "run.json", MAX_LOG_BYTES)
    try:
        info = json.loads(text)
    except json.JSONDecodeError as error:
        raise ConfigError(
            field, str(file), f"run.json is not valid JSON (line {error.lineno}: {error.msg})"
        ) from None
    except RecursionError:
        raise ConfigError(field, str(file), "run.json nests too deep to be a run's") from None
    if not isinstance(info, dict):
        raise ConfigError(
            field, str(file), f"run.json holds a {type(info).__name__}, not a run's record"
        )
    for key in ("scenario", *keys):
        if key not in info:
            raise ConfigError(field, str(file), f"run.json has no {key!r}")
    for key in _OBJECT_KEYS:
        if key in info and not isinstance(info[key], dict):
            raise ConfigError(
                field, str(file), f"run.json's {key!r} is a {type(info[key]).__name__}, "
                "not an object",
            )  # fmt: skip
    return RunFolder(path, info, field)


@dataclass(frozen=True)
class RunTables:
    """What a run folder holds, as read for export and plotting: run.json and log.csv."""

    info: dict[str, Any]
    log: pd.DataFrame
    input_names: tuple[str, ...]  # the run's inputs (SimLog.input_names), in order

    @property
    def thrust_columns(self) -> list[str]:
        """The thrust columns: the run's inputs, in order."""
        return list(self.input_names)


def read_run_tables(run_dir: Path) -> RunTables:
    """run.json and log.csv of a run folder, both checked (:class:`RunFolder`), log.csv as
    a DataFrame of every column it has."""
    folder = read_run_folder(run_dir)
    folder.scenario()  # checked: what the bag reads of it (obstacles, horizon) is valid
    names = folder.log().input_names
    table = folder.table()
    return RunTables(folder.info, table.frame(), names)
