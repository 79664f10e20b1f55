"""A saved run folder read by column name: ``run.json`` as a dict, ``log.csv`` as a DataFrame.

For tools that must work on every kind of log (horizontal, depth, later 6-DOF) and on
columns added later: the bag export, the Python API. ``runner.read_run`` gives the
horizontal log as a :class:`~auvmpc.sim.log.SimLog` instead.
"""

from __future__ import annotations

import csv
import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import numpy as np
import pandas as pd

from auvmpc.errors import ConfigError

__all__ = ["RunTables", "read_log_frame", "read_run_tables"]

_HORIZONTAL_THRUST = re.compile(r"^F\d+$")
_VERTICAL_THRUST = re.compile(r"^Fz\d+$")


@dataclass(frozen=True)
class RunTables:
    """What a run folder holds, as read for export and plotting: run.json and log.csv."""

    info: dict[str, Any]
    log: pd.DataFrame

    @property
    def thrust_columns(self) -> list[str]:
        """Thrust columns by name: horizontal F1..Fn, then vertical Fz1..Fzm."""
        names = [c for c in self.log.columns if _HORIZONTAL_THRUST.match(c)]
        names += [c for c in self.log.columns if _VERTICAL_THRUST.match(c)]
        return names


def read_run_tables(run_dir: Path) -> RunTables:
    """run.json and log.csv of a run folder; a folder that is not one is a ConfigError."""
    run_dir = Path(run_dir)
    if not (run_dir / "run.json").is_file() or not (run_dir / "log.csv").is_file():
        raise ConfigError("RUN_DIR", str(run_dir), "not a run folder (needs run.json and log.csv)")
    info = json.loads((run_dir / "run.json").read_text())
    log = read_log_frame(run_dir / "log.csv")
    if "t" not in log.columns or log.empty:
        raise ConfigError("RUN_DIR", str(run_dir), "log.csv has no rows or no t column")
    return RunTables(info, log)


def read_log_frame(source: Path | TextIO) -> pd.DataFrame:
    """log.csv (a path or an open text stream) as a DataFrame, every number exactly as
    written (Python's float parser).

    Columns are kept by name; text columns (``status``) stay text, empty cells are NaN.
    """
    if isinstance(source, str | Path):
        with open(source, newline="") as handle:
            rows = list(csv.reader(handle))
    else:
        rows = list(csv.reader(source))
    header, body = rows[0], rows[1:]
    columns = {}
    for i, name in enumerate(header):
        cells = [row[i] if i < len(row) else "" for row in body]
        try:
            columns[name] = np.array([float(c) if c else np.nan for c in cells], dtype=float)
        except ValueError:
            columns[name] = cells
    return pd.DataFrame(columns)
