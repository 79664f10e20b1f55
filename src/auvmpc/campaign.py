"""Robustness campaigns: one scenario run many times with sampled parameters.

A campaign file names a base scenario, distributions over any scenario field, a number
of runs and one master seed (``docs/campaigns.md`` has the full format). Run ``k``'s
parameters and scenario seed are a pure function of ``(master seed, k)``, so any run can
be reproduced alone (:func:`run_overrides`, :func:`scenario_for_run`).

Runs execute on local processes (``concurrent.futures``, spawn start method) or on a Dask
distributed cluster. Only the coordinating process writes results: one SQLite
transaction per finished run in ``DIR/results.sqlite``, so a campaign killed at any moment
resumes with the same command, redoing nothing that finished and losing nothing.

Data flow::

    load_campaign(FILE) -> validate_campaign -> run_campaign(... DIR)
        -> execute_run(k) on a worker: plan_run -> load scenario -> runner.simulate
        -> one row per run in DIR/results.sqlite -> load_results(DIR) -> campaign_report
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import copy
import functools
import hashlib
import itertools
import json
import math
import multiprocessing
import os
import shlex
import socket
import sqlite3
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from datetime import UTC, datetime
from enum import StrEnum
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
from pydantic import Field, ValidationError, field_validator, model_validator

from auvmpc import __version__
from auvmpc.config import StrictModel, builtin_descriptions, read_yaml_mapping
from auvmpc.errors import ConfigError, FieldError
from auvmpc.scenario import (
    ResolvedScenario,
    apply_override,
    builtin_scenarios,
    scenario_to_dict,
    validate_scenario,
)

if TYPE_CHECKING:
    import pandas as pd
    from matplotlib.figure import Figure

__all__ = [
    "ApplyMode",
    "Campaign",
    "CampaignReport",
    "CampaignSpec",
    "CampaignSummary",
    "Criterion",
    "MAX_WORKER_DEATHS",
    "NONDETERMINISTIC_COLUMNS",
    "RunSample",
    "TIMING_METRICS",
    "builtin_campaigns",
    "campaign_report",
    "execute_run",
    "load_campaign",
    "load_results",
    "parse_criterion",
    "reproduce_command",
    "run_campaign",
    "run_overrides",
    "sample_run",
    "scenario_for_run",
    "stored_campaign",
    "validate_campaign",
    "wilson_interval",
]

RESULTS_FILE = "results.sqlite"
LOCK_FILE = ".campaign.lock"
REPORT_FILE = "report.md"
REPORT_JSON = "report.json"
FIGURES_DIR = "figures"
# Changes whenever the rules that turn (seed, index) into parameters change: part of the
# campaign hash, so a folder written under other rules is never resumed.
SAMPLING_RULES = "auvmpc-campaign/1"
# A run whose worker process died this many times is recorded as failed, not retried.
MAX_WORKER_DEATHS = 2
# Wall-clock measurements: stored, but they differ between two runs of the same campaign.
TIMING_METRICS = ("solve_ms_median", "solve_ms_p99", "solve_ms_max")
NONDETERMINISTIC_COLUMNS = (*TIMING_METRICS, "wall_s", "worker_deaths")
WILSON_Z_95 = 1.959963984540054  # two-sided 95 % normal quantile
PERCENTILES = (5, 50, 95)
# A "normal" without bounds is checked at mean +- this many standard deviations.
NORMAL_CHECK_STDS = 3.0


# --------------------------------------------------------------------------------------
# Campaign file schema
# --------------------------------------------------------------------------------------


class ApplyMode(StrEnum):
    """How a sampled value meets the scenario's value at the same path."""

    SET = "set"  # replace it
    ADD = "add"  # base value + sample (an offset)
    MULTIPLY = "multiply"  # base value * sample (a scale factor)


class _Distribution(StrictModel):
    apply: ApplyMode = Field(
        default=ApplyMode.SET, description="set the field, or add to / multiply its base value"
    )

    def random(self) -> bool:
        return True


class Uniform(_Distribution):
    """Uniform on [low, high)."""

    type: Literal["uniform"]
    low: float
    high: float

    @model_validator(mode="after")
    def _ordered(self) -> Uniform:
        if not self.high >= self.low:
            raise FieldError("high", self.high, f"must be >= low {self.low}")
        return self

    def draw(self, u: float) -> float:
        return self.low + (self.high - self.low) * u

    def extremes(self) -> list[tuple[str, Any]]:
        return [("low", self.low), ("high", self.high)]


class LogUniform(_Distribution):
    """Log-uniform on [low, high): uniform in log(value); low > 0."""

    type: Literal["log-uniform"]
    low: Annotated[float, Field(gt=0)]
    high: float

    @model_validator(mode="after")
    def _ordered(self) -> LogUniform:
        if not self.high >= self.low:
            raise FieldError("high", self.high, f"must be >= low {self.low}")
        return self

    def draw(self, u: float) -> float:
        value = math.exp(math.log(self.low) + (math.log(self.high) - math.log(self.low)) * u)
        return min(max(value, self.low), self.high)  # exp(log(x)) may miss x by an ulp

    def extremes(self) -> list[tuple[str, Any]]:
        return [("low", self.low), ("high", self.high)]


class Normal(_Distribution):
    """Gaussian, optionally truncated to [low, high] (inverse-CDF sampling, one draw)."""

    type: Literal["normal"]
    mean: float
    std: Annotated[float, Field(ge=0)]
    low: float | None = None
    high: float | None = None

    @model_validator(mode="after")
    def _bounds(self) -> Normal:
        if self.low is not None and self.high is not None and not self.high > self.low:
            raise FieldError("high", self.high, f"must be > low {self.low}")
        if self.std == 0:
            if (self.low is not None and self.mean < self.low) or (
                self.high is not None and self.mean > self.high
            ):
                raise FieldError("mean", self.mean, "outside [low, high] with std 0")
        elif self._mass() < 1e-9:
            raise FieldError("low", self.low, "the bounds hold almost none of the distribution")
        return self

    def _cdf_bounds(self) -> tuple[float, float]:
        from scipy.special import ndtr

        a = 0.0 if self.low is None else float(ndtr((self.low - self.mean) / self.std))
        b = 1.0 if self.high is None else float(ndtr((self.high - self.mean) / self.std))
        return a, b

    def _mass(self) -> float:
        a, b = self._cdf_bounds()
        return b - a

    def draw(self, u: float) -> float:
        from scipy.special import ndtri

        if self.std == 0:
            return self.mean
        a, b = self._cdf_bounds()
        p = min(max(a + (b - a) * u, 1e-300), 1.0 - 2.0**-53)
        value = self.mean + self.std * float(ndtri(p))
        if self.low is not None:
            value = max(value, self.low)
        if self.high is not None:
            value = min(value, self.high)
        return value

    def extremes(self) -> list[tuple[str, Any]]:
        spread = NORMAL_CHECK_STDS * self.std
        low = ("low", self.low) if self.low is not None else ("mean - 3 std", self.mean - spread)
        high = (
            ("high", self.high) if self.high is not None else ("mean + 3 std", self.mean + spread)
        )
        return [low, ("mean", min(max(self.mean, low[1]), high[1])), high]


class Integers(_Distribution):
    """Whole numbers, uniform on low..high (both included)."""

    type: Literal["integers"]
    low: int
    high: int

    @model_validator(mode="after")
    def _ordered(self) -> Integers:
        if not self.high >= self.low:
            raise FieldError("high", self.high, f"must be >= low {self.low}")
        return self

    def draw(self, u: float) -> int:
        count = self.high - self.low + 1
        return self.low + min(int(u * count), count - 1)

    def extremes(self) -> list[tuple[str, Any]]:
        return [("low", self.low), ("high", self.high)]


class Choice(_Distribution):
    """One of ``values`` (any YAML values), equally likely or with ``weights``."""

    type: Literal["choice"]
    values: list[Any] = Field(min_length=1)
    weights: list[Annotated[float, Field(ge=0)]] | None = None

    @model_validator(mode="after")
    def _weights(self) -> Choice:
        _check_finite(self.values, "values")
        if self.weights is not None:
            if len(self.weights) != len(self.values):
                raise FieldError("weights", self.weights, f"need {len(self.values)}, one per value")
            if not sum(self.weights) > 0:
                raise FieldError("weights", self.weights, "need a positive sum")
        return self

    def draw(self, u: float) -> Any:
        weights = self.weights or [1.0] * len(self.values)
        target = u * sum(weights)
        for value, cumulative in zip(self.values, itertools.accumulate(weights), strict=True):
            if target < cumulative:
                return copy.deepcopy(value)
        return copy.deepcopy(self.values[-1])

    def extremes(self) -> list[tuple[str, Any]]:
        return [(f"values[{i}]", value) for i, value in enumerate(self.values)]


class Grid(_Distribution):
    """Not random: every grid parameter together spans a Cartesian product (see
    :func:`sample_run`); run k takes combination ``k mod (product size)``."""

    type: Literal["grid"]
    values: list[Any] = Field(min_length=1)

    @model_validator(mode="after")
    def _finite(self) -> Grid:
        _check_finite(self.values, "values")
        return self

    def random(self) -> bool:
        return False

    def extremes(self) -> list[tuple[str, Any]]:
        return [(f"values[{i}]", value) for i, value in enumerate(self.values)]


ScalarDistribution = Annotated[
    Uniform | LogUniform | Normal | Integers | Choice, Field(discriminator="type")
]


class Polar(_Distribution):
    """A 2-vector ``[m cos d, m sin d]`` from a magnitude and a direction in degrees
    (e.g. a current force: ``disturbance.current_force_world``)."""

    type: Literal["polar"]
    magnitude: ScalarDistribution
    direction_deg: ScalarDistribution

    @model_validator(mode="after")
    def _numbers(self) -> Polar:
        for name in ("magnitude", "direction_deg"):
            part = getattr(self, name)
            if part.apply is not ApplyMode.SET:
                raise FieldError(
                    f"{name}.apply", part.apply.value, "only the polar itself may apply"
                )
            if isinstance(part, Choice) and not all(_is_number(v) for v in part.values):
                raise FieldError(f"{name}.values", part.values, "need numbers")
        return self

    @staticmethod
    def vector(magnitude: float, direction_deg: float) -> list[float]:
        angle = math.radians(direction_deg)
        return [magnitude * math.cos(angle), magnitude * math.sin(angle)]

    def extremes(self) -> list[tuple[str, Any]]:
        return [
            (f"magnitude {m_label}, direction_deg {d_label}", self.vector(m, d))
            for (m_label, m), (d_label, d) in itertools.product(
                self.magnitude.extremes(), self.direction_deg.extremes()
            )
        ]


Distribution = Annotated[
    Uniform | LogUniform | Normal | Integers | Choice | Grid | Polar, Field(discriminator="type")
]
DISTRIBUTION_TYPES = ("uniform", "log-uniform", "normal", "integers", "choice", "grid", "polar")


class CampaignSpec(StrictModel):
    """A campaign file as written (``docs/campaigns.md``)."""

    name: str = Field(description="identifier")
    description: str = Field(default="", description="one line for humans")
    base: str = Field(description="built-in scenario name, or scenario file relative to this file")
    overrides: tuple[str, ...] = Field(
        default=(), description="field=value applied to every run, as `auvmpc run --set`"
    )
    runs: Annotated[int, Field(ge=1)] = Field(description="number of runs")
    seed: Annotated[int, Field(ge=0)] = Field(description="master seed of every run's draws")
    parameters: dict[str, Distribution] = Field(
        default_factory=dict, description="scenario field path -> distribution"
    )
    criterion: str | None = Field(
        default=None, description="default success criterion of the report, e.g. 'x_m < 1'"
    )

    @field_validator("overrides")
    @classmethod
    def _overrides(cls, overrides: tuple[str, ...]) -> tuple[str, ...]:
        for i, text in enumerate(overrides):
            path, separator, _ = text.partition("=")
            if not separator or not path:
                raise FieldError(str(i), text, "expected field=value")
        return overrides

    @field_validator("parameters")
    @classmethod
    def _paths(cls, parameters: dict[str, Any]) -> dict[str, Any]:
        for path, distribution in parameters.items():
            target, is_length = _split_length(path)
            if not _valid_path(target):
                raise FieldError(path, path, "not a field path like a.b.0.c or len(a.b)")
            if target.split(".")[0] == "seed":
                raise FieldError(path, path, "the run seed derives from the master seed and index")
            if is_length:
                if isinstance(distribution, Polar) or distribution.apply is not ApplyMode.SET:
                    raise FieldError(path, distribution.type, "a list length takes whole numbers")
                if isinstance(distribution, Uniform | LogUniform | Normal):
                    raise FieldError(
                        path, distribution.type, "a list length needs integers, choice or grid"
                    )
        lengths = [_split_length(p)[0] for p in parameters if _split_length(p)[1]]
        if len(set(lengths)) != len(lengths):
            raise FieldError("len", lengths, "one length parameter per list")
        return parameters

    @field_validator("criterion")
    @classmethod
    def _criterion(cls, criterion: str | None) -> str | None:
        if criterion is not None:
            try:
                parse_criterion(criterion)  # syntax only; names are checked against the results
            except ConfigError as error:
                raise FieldError("criterion", error.value, error.reason) from None
        return criterion


def _check_finite(value: Any, where: str) -> None:
    if isinstance(value, float) and not math.isfinite(value):
        raise FieldError(where, value, "must be finite")
    if isinstance(value, list):
        for item in value:
            _check_finite(item, where)
    elif isinstance(value, dict):
        for item in value.values():
            _check_finite(item, where)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _split_length(path: str) -> tuple[str, bool]:
    if path.startswith("len(") and path.endswith(")"):
        return path[4:-1], True
    return path, False


def _valid_path(path: str) -> bool:
    parts = path.split(".")
    return (
        bool(path)
        and all(part.isdigit() or (part.isidentifier() and part.isascii()) for part in parts)
        and not parts[0].isdigit()
    )


# --------------------------------------------------------------------------------------
# Loading
# --------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Campaign:
    """A campaign file plus what it points at.

    Attributes
    ----------
    spec : CampaignSpec
        The file's contents, validated.
    source : str
        Built-in name or path as given.
    base_source : str
        The base scenario: built-in name or absolute path (what ``auvmpc run`` is given).
    base_data : dict
        The base scenario file's mapping, as read (before any override).
    base_dir : str
        Folder that relative paths inside the scenario resolve against.
    implicit_overrides : tuple of str
        ``field=value`` overrides added after ``spec.overrides`` so that every parameter
        path exists (e.g. ``controller.Q=[5, 5, 5, 1, 1, 1]`` when the base scenario leaves
        ``controller.Q`` at its default and a parameter samples ``controller.Q.0``).
    """

    spec: CampaignSpec
    source: str
    base_source: str
    base_data: dict[str, Any]
    base_dir: str
    implicit_overrides: tuple[str, ...] = ()

    @property
    def fixed_overrides(self) -> tuple[str, ...]:
        return (*self.spec.overrides, *self.implicit_overrides)

    @functools.cached_property
    def hash(self) -> str:
        """SHA-256 of everything that decides the runs (not name, description, runs, criterion)."""
        identity = {
            "rules": SAMPLING_RULES,
            "base": self.base_data,
            "overrides": list(self.spec.overrides),
            "seed": self.spec.seed,
            "parameters": {
                path: distribution.model_dump(mode="json")
                for path, distribution in self.spec.parameters.items()
            },
        }
        return hashlib.sha256(_canonical_json(identity).encode()).hexdigest()

    @functools.cached_property
    def parameter_columns(self) -> tuple[str, ...]:
        """Result columns of the sampled parameters, in file order."""
        columns: list[str] = []
        for path, distribution in self.spec.parameters.items():
            if isinstance(distribution, Polar):
                columns += [f"{path}.magnitude", f"{path}.direction_deg"]
            else:
                columns.append(path)
        return tuple(columns)

    def payload(self) -> str:
        """Everything a worker needs, as one JSON string."""
        return _canonical_json(
            {
                "spec": self.spec.model_dump(mode="json"),
                "source": self.source,
                "base_source": self.base_source,
                "base_data": self.base_data,
                "base_dir": self.base_dir,
            }
        )


def builtin_campaigns() -> dict[str, str]:
    """Built-in campaign names and their one-line descriptions."""
    return builtin_descriptions("campaigns")


def load_campaign(source: str | Path) -> Campaign:
    """Read and validate a campaign: built-in name or YAML file path.

    Only the file's own schema and the base scenario are checked here;
    :func:`validate_campaign` checks the sampled scenarios.

    Raises
    ------
    ConfigError
        Missing file, bad YAML, unknown key, impossible distribution (``low > high``,
        ``std < 0``, empty ``values``, log-uniform ``low <= 0``, ...), bad field path, or
        an invalid base scenario or fixed override; the message names the field.
    """
    text_source = str(source)
    builtins = builtin_campaigns()
    if text_source in builtins:
        text = (resources.files("auvmpc.presets") / "campaigns" / f"{text_source}.yaml").read_text()
        folder = None
    else:
        path = Path(text_source)
        if not path.is_file():
            raise ConfigError(
                "campaign", text_source, f"no such file or built-in; built-ins: {list(builtins)}"
            )
        text, folder = path.read_text(), path.resolve().parent
    data = _read_yaml(text, "campaign", text_source)
    spec = _validate_spec(data)
    base_source, base_data, base_dir = _read_base(spec.base, folder)
    campaign = Campaign(spec, text_source, base_source, base_data, base_dir)
    _check_fixed(campaign)
    return _with_implicit_overrides(campaign)


def _read_yaml(text: str, field: str, origin: str) -> dict[str, Any]:
    return read_yaml_mapping(text, field, origin, "campaign fields")


def _validate_spec(data: dict[str, Any]) -> CampaignSpec:
    try:
        return CampaignSpec.model_validate(data)
    except ValidationError as error:
        raise _spec_error(error) from None


def _spec_error(error: ValidationError) -> ConfigError:
    """The first error, named by its path in the file (distribution type tags left out)."""
    first = error.errors()[0]
    location = [str(part) for part in first["loc"]]
    location = location[:2] + [part for part in location[2:] if part not in DISTRIBUTION_TYPES]
    reason, value = first["msg"], first.get("input")
    cause = first.get("ctx", {}).get("error")
    if isinstance(cause, FieldError):
        if not (location and location[-1] == cause.field):
            location.append(cause.field)
        reason, value = cause.reason, cause.value
    kind = first["type"]
    if kind == "extra_forbidden":
        reason = "unknown key"
    elif kind == "union_tag_not_found":
        reason = f"needs a 'type': one of {list(DISTRIBUTION_TYPES)}"
    elif kind == "union_tag_invalid":
        reason = f"unknown distribution type; one of {list(DISTRIBUTION_TYPES)}"
    elif kind == "model_attributes_type" and location[:1] == ["parameters"]:
        reason = "expected a distribution mapping like {type: uniform, low: 0, high: 1}"
    field_name = ".".join(location) or "<campaign>"
    return ConfigError(field_name, value, reason[0].lower() + reason[1:] if reason else "invalid")


def _read_base(base: str, folder: Path | None) -> tuple[str, dict[str, Any], str]:
    if base in builtin_scenarios():
        text = (resources.files("auvmpc.presets") / "scenarios" / f"{base}.yaml").read_text()
        return base, _read_yaml(text, "base", base), str(folder or Path.cwd())
    path = Path(base)
    if not path.is_absolute():
        path = (folder or Path.cwd()) / path
    if not path.is_file():
        raise ConfigError(
            "base",
            base,
            f"no such scenario file or built-in; built-ins: {list(builtin_scenarios())}",
        )
    path = path.resolve()
    return str(path), _read_yaml(path.read_text(), "base", base), str(path.parent)


def _with_implicit_overrides(campaign: Campaign) -> Campaign:
    """Add overrides that make each sampled list element's container exist in the data.

    ``apply_override`` creates missing mapping keys but cannot index a list the base
    scenario leaves at its default; writing the default list out first keeps every run
    expressible as ``auvmpc run BASE --set ...``.
    """
    data = _fixed_data(campaign)
    defaults = _resolved_dict(data, campaign)
    implicit: list[str] = []
    for path in campaign.spec.parameters:
        keys = _split_length(path)[0].split(".")
        node: Any = data
        for depth, key in enumerate(keys):
            if isinstance(node, dict) and (key not in node or node[key] is None):
                default = _lookup(defaults, keys[: depth + 1])
                needs_list = any(k.isdigit() for k in keys[depth + 1 :])
                if needs_list and isinstance(default, list | dict):
                    text = f"{'.'.join(keys[: depth + 1])}={_yaml_text(default)}"
                    apply_override(data, text)
                    implicit.append(text)
                else:
                    break
            if isinstance(node, dict):
                node = node.get(key)
            elif isinstance(node, list) and key.isdigit() and int(key) < len(node):
                node = node[int(key)]
            else:
                break
    return Campaign(
        campaign.spec,
        campaign.source,
        campaign.base_source,
        campaign.base_data,
        campaign.base_dir,
        tuple(implicit),
    )


def _fixed_data(campaign: Campaign, implicit: bool = False) -> dict[str, Any]:
    """The base scenario with the file's overrides (and, if asked, the implicit ones)."""
    data = copy.deepcopy(campaign.base_data)
    for i, text in enumerate(campaign.spec.overrides):
        try:
            apply_override(data, text)
        except ConfigError as error:
            raise ConfigError(f"overrides.{i}", text, str(error)) from None
    if implicit:
        for text in campaign.implicit_overrides:
            apply_override(data, text)
    return data


def _check_fixed(campaign: Campaign) -> None:
    """The base scenario with the fixed overrides must be valid on its own."""
    data = _fixed_data(campaign)
    try:
        _resolve(campaign, data)
    except ConfigError as error:
        for i, text in enumerate(campaign.spec.overrides):
            if _related(text.partition("=")[0], error.field):
                raise ConfigError(f"overrides.{i}", text, str(error)) from None
        raise ConfigError("base", campaign.spec.base, f"invalid scenario: {error}") from None


def _related(path: str, field_name: str) -> bool:
    """Whether an error about ``field_name`` can come from setting ``path``."""
    return (
        field_name == path or field_name.startswith(f"{path}.") or path.startswith(f"{field_name}.")
    )


def _resolved_dict(data: dict[str, Any], campaign: Campaign) -> dict[str, Any]:
    """Scenario ``data`` (known valid) dumped with every default filled in."""
    return scenario_to_dict(validate_scenario(copy.deepcopy(data)))


def _lookup(data: Any, keys: Sequence[str]) -> Any:
    node = data
    for key in keys:
        if isinstance(node, dict) and key in node:
            node = node[key]
        elif isinstance(node, list) and key.isdigit() and int(key) < len(node):
            node = node[int(key)]
        else:
            return None
    return node


# --------------------------------------------------------------------------------------
# Sampling: a pure function of (master seed, run index)
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RunSample:
    """What run ``index`` draws.

    Attributes
    ----------
    index : int
    seed : int
        The run's scenario ``seed`` (noise, varying currents), from the master seed.
    draws : dict
        Parameter path -> drawn value (before ``apply``; a polar gives its vector).
    columns : dict
        Result column -> value: the draws, a polar as ``<path>.magnitude`` and
        ``<path>.direction_deg``.
    """

    index: int
    seed: int
    draws: dict[str, Any]
    columns: dict[str, Any]


def _stream(master_seed: int, index: int, label: str) -> np.random.Generator:
    """The generator of one parameter of one run: depends on the seed, index and path only,
    so adding or removing a parameter leaves the others' draws unchanged."""
    digest = hashlib.sha256(label.encode()).digest()
    words = (int.from_bytes(digest[:4], "little"), int.from_bytes(digest[4:8], "little"))
    return np.random.default_rng(np.random.SeedSequence(master_seed, spawn_key=(index, *words)))


def run_seed(master_seed: int, index: int) -> int:
    """Scenario seed of run ``index``: 32 bits from ``SeedSequence(master_seed, (index,))``."""
    sequence = np.random.SeedSequence(master_seed, spawn_key=(index,))
    return int(sequence.generate_state(1, np.uint32)[0])


def _grid_combination(spec: CampaignSpec, index: int) -> dict[str, Any]:
    grids = [(path, d) for path, d in spec.parameters.items() if isinstance(d, Grid)]
    size = math.prod(len(d.values) for _, d in grids)
    combination = index % size if grids else 0
    chosen = {}
    for path, distribution in reversed(grids):  # the last grid parameter varies fastest
        combination, digit = divmod(combination, len(distribution.values))
        chosen[path] = copy.deepcopy(distribution.values[digit])
    return chosen


def sample_run(campaign: Campaign, index: int) -> RunSample:
    """Draw run ``index``'s parameters; a pure function of (master seed, index).

    Each random parameter has its own stream (seeded by the master seed, the index and
    the parameter's path) and takes one uniform double ``u`` from it; the value is a
    documented function of ``u`` (``docs/campaigns.md``). Grid parameters are not random.
    """
    if index < 0:
        raise ValueError(f"run index must be >= 0, got {index}")
    spec = campaign.spec
    grid = _grid_combination(spec, index)
    draws: dict[str, Any] = {}
    columns: dict[str, Any] = {}
    for path, distribution in spec.parameters.items():
        if isinstance(distribution, Grid):
            value = grid[path]
            columns[path] = value
        elif isinstance(distribution, Polar):
            magnitude = distribution.magnitude.draw(
                float(_stream(spec.seed, index, f"{path}.magnitude").random())
            )
            direction = distribution.direction_deg.draw(
                float(_stream(spec.seed, index, f"{path}.direction_deg").random())
            )
            value = Polar.vector(magnitude, direction)
            columns[f"{path}.magnitude"] = magnitude
            columns[f"{path}.direction_deg"] = direction
        else:
            value = distribution.draw(float(_stream(spec.seed, index, path).random()))
            columns[path] = value
        draws[path] = value
    return RunSample(index, run_seed(spec.seed, index), draws, columns)


def _combine(current: Any, value: Any, mode: ApplyMode, path: str) -> Any:
    if mode is ApplyMode.SET:
        return value
    operation = (lambda a, b: a + b) if mode is ApplyMode.ADD else (lambda a, b: a * b)
    if _is_number(current) and _is_number(value):
        return operation(current, value)
    if (
        isinstance(current, list)
        and isinstance(value, list)
        and len(current) == len(value)
        and all(_is_number(x) for x in (*current, *value))
    ):
        return [operation(a, b) for a, b in zip(current, value, strict=True)]
    raise ConfigError(
        f"parameters.{path}",
        current,
        f"apply {mode.value} needs a number at {path} in the base scenario",
    )


def plan_run(
    campaign: Campaign, index: int, replace: Mapping[str, Any] | None = None
) -> tuple[RunSample, list[str], dict[str, Any]]:
    """Run ``index``: its sample, its ``field=value`` overrides and its scenario mapping.

    The overrides, applied with :func:`auvmpc.scenario.apply_override` to the base
    scenario in order, give exactly the mapping returned: the campaign builds each run
    from the same strings that ``auvmpc run BASE --set ...`` is given.

    Parameters
    ----------
    replace : mapping, optional
        Parameter path -> value used instead of the draw (validation of the extremes).
    """
    sample = sample_run(campaign, index)
    draws = {**sample.draws, **(replace or {})}
    data = _fixed_data(campaign, implicit=True)
    overrides = [*campaign.fixed_overrides, f"seed={sample.seed}"]
    apply_override(data, overrides[-1])
    defaults: dict[str, Any] | None = None
    for path, distribution in campaign.spec.parameters.items():
        target, is_length = _split_length(path)
        if is_length:
            continue
        value = draws[path]
        if distribution.apply is not ApplyMode.SET:
            current = _lookup(data, target.split("."))
            if current is None:
                defaults = defaults or _resolved_dict(
                    _fixed_data(campaign, implicit=True), campaign
                )
                current = _lookup(defaults, target.split("."))
            value = _combine(current, value, distribution.apply, path)
        text = f"{target}={_yaml_text(value)}"
        _apply_parameter(data, text, path, value)
        overrides.append(text)
    for path in campaign.spec.parameters:
        target, is_length = _split_length(path)
        if not is_length:
            continue
        items = _lookup(data, target.split("."))
        count = draws[path]
        if not isinstance(items, list):
            raise ConfigError(
                f"parameters.{path}", items, f"{target} is not a list in the base scenario"
            )
        if not (
            isinstance(count, int) and not isinstance(count, bool) and 0 <= count <= len(items)
        ):
            raise ConfigError(
                f"parameters.{path}", count, f"need a whole number in 0..{len(items)}"
            )
        text = f"{target}={_yaml_text(items[:count])}"
        _apply_parameter(data, text, path, count)
        overrides.append(text)
    return sample, overrides, data


def _apply_parameter(data: dict[str, Any], text: str, path: str, value: Any) -> None:
    try:
        apply_override(data, text)
    except ConfigError as error:
        raise ConfigError(f"parameters.{path}", value, error.reason) from None


def run_overrides(campaign: Campaign, index: int) -> list[str]:
    """``field=value`` strings such that ``auvmpc run BASE --set ...`` reproduces run ``index``."""
    return plan_run(campaign, index)[1]


def reproduce_command(campaign: Campaign, index: int) -> str:
    """The shell command that reruns run ``index`` alone with ``auvmpc run``."""
    words = ["auvmpc", "run", campaign.base_source]
    for text in run_overrides(campaign, index):
        words += ["--set", text]
    return shlex.join(words)


def _resolve(campaign: Campaign, data: dict[str, Any]) -> ResolvedScenario:
    return ResolvedScenario(validate_scenario(data), Path(campaign.base_dir))


def scenario_for_run(
    campaign_or_dir: Campaign | str | Path, index: int, overrides: Sequence[str] = ()
) -> ResolvedScenario:
    """Run ``index`` of a campaign (or of the campaign stored in a results folder),
    resolved and ready for :func:`auvmpc.runner.simulate`; ``overrides`` apply last."""
    campaign = (
        campaign_or_dir
        if isinstance(campaign_or_dir, Campaign)
        else stored_campaign(Path(campaign_or_dir))
    )
    if isinstance(index, bool) or not isinstance(index, int) or index < 0:
        raise ConfigError("--index", index, "need a whole number >= 0")
    _, _, data = plan_run(campaign, index)
    for text in overrides:
        apply_override(data, text)
    return _resolve(campaign, data)


# --------------------------------------------------------------------------------------
# Validation before any run
# --------------------------------------------------------------------------------------


def validate_campaign(campaign: Campaign, runs: int | None = None) -> None:
    """Reject a campaign that would produce an invalid scenario, before any run starts.

    Checked, in order: the base scenario with the fixed overrides (fully resolved); run 0
    (fully resolved); every parameter at each of its extremes (uniform/log-uniform/integers
    ``low`` and ``high``, normal bounds or mean +- 3 std, every choice and grid value,
    polar corners), the others at their run-0 values (fully resolved); then every run
    ``0..runs-1`` through the scenario schema.

    Raises
    ------
    ConfigError
        Naming ``parameters.<path>`` for a parameter at fault (unknown field, index out
        of range, value the field does not accept), ``base`` / ``overrides.<i>`` for the
        fixed part.
    """
    count = campaign.spec.runs if runs is None else runs
    _check_fixed(campaign)
    _check_plan(campaign, 0, None, "run 0")
    for path, distribution in campaign.spec.parameters.items():
        for label, value in distribution.extremes():
            _check_plan(campaign, 0, (path, value), f"at {label}")
    for index in range(1, count):
        try:
            _, _, data = plan_run(campaign, index)
            validate_scenario(data)
        except ConfigError as error:
            raise _blame(campaign, error, None, f"run {index}") from None


def _check_plan(
    campaign: Campaign, index: int, replaced: tuple[str, Any] | None, where: str
) -> None:
    try:
        _, _, data = plan_run(campaign, index, dict([replaced]) if replaced else None)
        _resolve(campaign, data)
    except ConfigError as error:
        raise _blame(campaign, error, replaced, where) from None


def _blame(
    campaign: Campaign, error: ConfigError, replaced: tuple[str, Any] | None, where: str
) -> ConfigError:
    """Name the parameter an invalid scenario comes from: the one set to an extreme (the
    others are at their valid run-0 values), else one whose path the error is about."""
    if error.field.startswith("parameters."):
        return ConfigError(error.field, error.value, f"{error.reason} ({where})")
    suspects = [replaced[0]] if replaced else list(campaign.spec.parameters)
    for path in suspects:
        target = _split_length(path)[0]
        if _related(target, error.field):
            return ConfigError(f"parameters.{path}", error.value, f"{error.reason} ({where})")
        if replaced:
            return ConfigError(
                f"parameters.{path}", replaced[1], f"{error.field}: {error.reason} ({where})"
            )
    return ConfigError("parameters", where, f"give an invalid scenario: {error}")


# --------------------------------------------------------------------------------------
# One run, on a worker
# --------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=4)
def _campaign_from_payload(payload: str) -> Campaign:
    data = json.loads(payload)
    campaign = Campaign(
        CampaignSpec.model_validate(data["spec"]),
        data["source"],
        data["base_source"],
        data["base_data"],
        data["base_dir"],
    )
    return _with_implicit_overrides(campaign)


def execute_run(payload: str, index: int) -> dict[str, Any]:
    """Simulate run ``index`` of the campaign in ``payload`` (:meth:`Campaign.payload`).

    An exception inside the run is the run's result (status ``failed``, one-line
    ``error``, full ``traceback``), never raised: only a broken worker or environment
    makes this function raise.

    Returns
    -------
    dict
        ``index``, ``seed``, ``status`` (``ok`` | ``failed``), ``parameters`` (result
        columns), ``metrics`` (empty when failed), ``error``, ``traceback``, ``wall_s``,
        ``worker`` (host:pid).
    """
    from auvmpc.runner import simulate

    campaign = _campaign_from_payload(payload)
    sample = sample_run(campaign, index)
    started = time.perf_counter()
    metrics: dict[str, Any] = {}
    error = trace = None
    try:
        _, _, data = plan_run(campaign, index)
        metrics = simulate(_resolve(campaign, data)).metrics
        status = "ok"
    except Exception as exc:  # the run's own failure is a result, recorded once
        status, error, trace = "failed", _one_line(exc), traceback.format_exc()
    return {
        "index": index,
        "seed": sample.seed,
        "status": status,
        "parameters": sample.columns,
        "metrics": metrics,
        "error": error,
        "traceback": trace,
        "wall_s": time.perf_counter() - started,
        "worker": f"{socket.gethostname()}:{os.getpid()}",
    }


def _one_line(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[0]}" if text else type(error).__name__


def _worker_init(parent_pid: int) -> None:
    """Local pool worker: leave Ctrl-C to the coordinator, exit when the coordinator is gone
    (a coordinator killed with SIGKILL cannot stop its workers itself)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def watch() -> None:
        while True:
            time.sleep(0.5)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="auvmpc-parent-watch", daemon=True).start()


# --------------------------------------------------------------------------------------
# Storage: SQLite, written only by the coordinating process
# --------------------------------------------------------------------------------------

_SCHEMA = """
CREATE TABLE IF NOT EXISTS campaign (
    id INTEGER PRIMARY KEY CHECK (id = 0),
    hash TEXT NOT NULL,
    name TEXT NOT NULL,
    spec TEXT NOT NULL,
    source TEXT NOT NULL,
    base_source TEXT NOT NULL,
    base_data TEXT NOT NULL,
    base_dir TEXT NOT NULL,
    parameter_columns TEXT NOT NULL,
    metric_columns TEXT NOT NULL DEFAULT '[]',
    created_utc TEXT NOT NULL,
    auvmpc_version TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS runs (
    "index" INTEGER PRIMARY KEY,
    seed INTEGER NOT NULL,
    status TEXT NOT NULL CHECK (status IN ('ok', 'failed')),
    error TEXT,
    traceback TEXT,
    parameters TEXT NOT NULL,
    metrics TEXT NOT NULL,
    wall_s REAL,
    worker_deaths INTEGER NOT NULL DEFAULT 0,
    worker TEXT,
    finished_utc TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS worker_deaths (
    "index" INTEGER PRIMARY KEY,
    deaths INTEGER NOT NULL
);
"""


def _connect(path: Path, read_only: bool = False) -> sqlite3.Connection:
    if read_only:
        connection = sqlite3.connect(
            f"{path.resolve().as_uri()}?mode=ro", uri=True, isolation_level=None
        )
    else:
        connection = sqlite3.connect(path, isolation_level=None)
        connection.execute("PRAGMA journal_mode=WAL")
        # FULL: a committed run survives a power cut too, not only a killed process.
        connection.execute("PRAGMA synchronous=FULL")
    connection.execute("PRAGMA busy_timeout=10000")
    return connection


@contextlib.contextmanager
def _transaction(connection: sqlite3.Connection) -> Iterator[sqlite3.Connection]:
    connection.execute("BEGIN IMMEDIATE")
    try:
        yield connection
    except BaseException:
        connection.execute("ROLLBACK")
        raise
    connection.execute("COMMIT")


class _Store:
    """The results file of one campaign folder; only the coordinator holds one."""

    def __init__(self, out_dir: Path, campaign: Campaign) -> None:
        self.path = out_dir / RESULTS_FILE
        self.connection = _connect(self.path)
        self.campaign = campaign
        try:
            self._open(out_dir, campaign)
        except BaseException:
            self.connection.close()
            raise

    def _open(self, out_dir: Path, campaign: Campaign) -> None:
        """Create the tables, or check that they hold this campaign."""
        with _transaction(self.connection) as db:
            for statement in _SCHEMA.split(";"):
                if statement.strip():
                    db.execute(statement)
            row = db.execute("SELECT hash, metric_columns FROM campaign").fetchone()
            if row is not None and row[0] != campaign.hash:
                raise ConfigError(
                    "--out",
                    str(out_dir),
                    f"holds another campaign (hash {row[0][:12]}, this file {campaign.hash[:12]});"
                    " use a new folder",
                )
            self.metric_columns: list[str] = json.loads(row[1]) if row else []
            db.execute(
                "INSERT INTO campaign (id, hash, name, spec, source, base_source, base_data, "
                "base_dir, parameter_columns, created_utc, auvmpc_version) "
                "VALUES (0, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?) ON CONFLICT(id) DO UPDATE SET "
                "name = excluded.name, spec = excluded.spec, source = excluded.source",
                (
                    campaign.hash,
                    campaign.spec.name,
                    json.dumps(campaign.spec.model_dump(mode="json")),
                    campaign.source,
                    campaign.base_source,
                    _canonical_json(campaign.base_data),
                    campaign.base_dir,
                    json.dumps(list(campaign.parameter_columns)),
                    _now(),
                    __version__,
                ),
            )
            self._create_view(db)

    def close(self) -> None:
        self.connection.close()

    def finished(self) -> set[int]:
        return {row[0] for row in self.connection.execute('SELECT "index" FROM runs')}

    def deaths(self) -> dict[int, int]:
        return dict(self.connection.execute('SELECT "index", deaths FROM worker_deaths'))

    def add_death(self, index: int) -> int:
        with _transaction(self.connection) as db:
            db.execute(
                'INSERT INTO worker_deaths ("index", deaths) VALUES (?, 1) '
                'ON CONFLICT("index") DO UPDATE SET deaths = deaths + 1',
                (index,),
            )
            return db.execute(
                'SELECT deaths FROM worker_deaths WHERE "index" = ?', (index,)
            ).fetchone()[0]

    def record(self, result: Mapping[str, Any]) -> None:
        """One finished run, in one transaction."""
        metrics = _finite_or_none(result["metrics"])
        index = result["index"]
        with _transaction(self.connection) as db:
            deaths = db.execute(
                'SELECT deaths FROM worker_deaths WHERE "index" = ?', (index,)
            ).fetchone()
            db.execute(
                'INSERT INTO runs ("index", seed, status, error, traceback, parameters, '
                "metrics, wall_s, worker_deaths, worker, finished_utc) "
                "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                (
                    index,
                    result["seed"],
                    result["status"],
                    result["error"],
                    result["traceback"],
                    json.dumps(_finite_or_none(result["parameters"]), allow_nan=False),
                    json.dumps(metrics, allow_nan=False),
                    result["wall_s"],
                    deaths[0] if deaths else 0,
                    result["worker"],
                    _now(),
                ),
            )
            new = [key for key in metrics if key not in self.metric_columns]
            if new:
                self.metric_columns += new
                db.execute(
                    "UPDATE campaign SET metric_columns = ?", (json.dumps(self.metric_columns),)
                )
                self._create_view(db)

    def _create_view(self, db: sqlite3.Connection) -> None:
        """``results``: one column per parameter and metric, for SQL queries (the exact
        floats come from :func:`load_results`, which parses the JSON in Python)."""
        columns = ['"index"', "seed", "status", "error"]
        for name in self.campaign.parameter_columns:
            columns.append(
                f"json_extract(parameters, {_sql_text(_json_path(name))}) AS {_sql_name(name)}"
            )
        for name in self.metric_columns:
            columns.append(
                f"json_extract(metrics, {_sql_text(_json_path(name))}) AS {_sql_name(name)}"
            )
        columns += ["wall_s", "worker_deaths"]
        db.execute("DROP VIEW IF EXISTS results")
        db.execute(f"CREATE VIEW results AS SELECT {', '.join(columns)} FROM runs")


def _sql_name(name: str) -> str:
    return '"' + name.replace('"', '""') + '"'


def _sql_text(text: str) -> str:
    return "'" + text.replace("'", "''") + "'"


def _json_path(key: str) -> str:
    return '$."' + key.replace('"', '\\"') + '"'


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _finite_or_none(values: Mapping[str, Any]) -> dict[str, Any]:
    """JSON-ready: NaN and infinities become null (SQLite's JSON rejects them)."""
    return {
        key: None if isinstance(value, float) and not math.isfinite(value) else value
        for key, value in values.items()
    }


def _canonical_json(value: Any) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)


@contextlib.contextmanager
def _exclusive(out_dir: Path) -> Iterator[None]:
    """One coordinator per folder (released by the OS even on SIGKILL)."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        yield
        return
    with open(out_dir / LOCK_FILE, "a") as handle:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ConfigError(
                "--out", str(out_dir), "another campaign process is writing here"
            ) from None
        try:
            yield
        finally:
            fcntl.flock(handle.fileno(), fcntl.LOCK_UN)


def stored_campaign(out_dir: Path) -> Campaign:
    """The campaign a results folder was written by (as stored, not as the file is now)."""
    with contextlib.closing(_connect(_results_path(out_dir), read_only=True)) as db:
        row = db.execute(
            "SELECT spec, source, base_source, base_data, base_dir FROM campaign"
        ).fetchone()
    if row is None:
        raise ConfigError("DIR", str(out_dir), "no campaign stored in results.sqlite")
    spec, source, base_source, base_data, base_dir = row
    return _with_implicit_overrides(
        Campaign(
            CampaignSpec.model_validate(json.loads(spec)),
            source,
            base_source,
            json.loads(base_data),
            base_dir,
        )
    )


def _results_path(out_dir: Path) -> Path:
    path = Path(out_dir) / RESULTS_FILE
    if not path.is_file():
        raise ConfigError("DIR", str(out_dir), f"no campaign results here ({RESULTS_FILE} missing)")
    return path


# --------------------------------------------------------------------------------------
# Running a campaign
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CampaignSummary:
    """What :func:`run_campaign` leaves behind.

    Attributes
    ----------
    out_dir : Path
    total : int
        Runs asked for (``--runs`` or the file's ``runs``).
    ok, failed : int
        Rows among runs ``0..total-1``.
    new : int
        Runs executed by this call (the rest were already stored).
    wall_s : float
        Wall time of this call.
    """

    out_dir: Path
    total: int
    ok: int
    failed: int
    new: int
    wall_s: float


def run_campaign(
    source: str | Path | Campaign,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    runs: int | None = None,
    scheduler: str | None = None,
    on_progress: Callable[[int, int], None] | None = None,
) -> CampaignSummary:
    """Run (or resume) a campaign into ``out_dir``.

    Parameters
    ----------
    source : str, Path or Campaign
        Built-in campaign name or campaign file.
    out_dir : path
        Campaign folder; ``results.sqlite`` inside holds one row per finished run. Calling
        again with the same campaign resumes: stored runs are not redone.
    workers : int, optional
        Local worker processes; default: every CPU this process may use. Ignored with
        ``scheduler``.
    runs : int, optional
        Run only runs ``0..runs-1`` (at most the file's ``runs``).
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:8786``); its workers must be
        able to import this version of auvmpc and read the scenario's files.
    on_progress : callable, optional
        ``on_progress(done, total)`` once before the first run and after each stored run.

    Raises
    ------
    ConfigError
        Bad campaign (before any run starts), ``out_dir`` holding another campaign or in
        use by another process, bad ``workers``/``runs``, unreachable scheduler.
    """
    started = time.perf_counter()
    campaign = source if isinstance(source, Campaign) else load_campaign(source)
    total = campaign.spec.runs if runs is None else runs
    if (
        isinstance(total, bool)
        or not isinstance(total, int)
        or not 1 <= total <= campaign.spec.runs
    ):
        raise ConfigError("--runs", runs, f"need a whole number in 1..{campaign.spec.runs}")
    if workers is None:
        workers = (
            len(os.sched_getaffinity(0))
            if hasattr(os, "sched_getaffinity")
            else os.cpu_count() or 1
        )
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ConfigError("--workers", workers, "need a whole number >= 1")
    validate_campaign(campaign, total)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    new = 0
    with _exclusive(out):
        store = _Store(out, campaign)
        try:
            finished = store.finished()
            todo = [k for k in range(total) if k not in finished]
            done = total - len(todo)
            if on_progress is not None:
                on_progress(done, total)

            def record(result: Mapping[str, Any]) -> None:
                nonlocal done, new
                store.record(result)
                done, new = done + 1, new + 1
                if on_progress is not None:
                    on_progress(done, total)

            if todo and scheduler is not None:
                _execute_dask(campaign, todo, scheduler, record)
            elif todo:
                _execute_local(campaign, todo, workers, store, record)
            counts = dict(
                store.connection.execute(
                    'SELECT status, COUNT(*) FROM runs WHERE "index" < ? GROUP BY status', (total,)
                ).fetchall()
            )
        finally:
            store.close()
    return CampaignSummary(
        out, total, counts.get("ok", 0), counts.get("failed", 0), new, time.perf_counter() - started
    )


def _execute_local(
    campaign: Campaign,
    todo: Sequence[int],
    workers: int,
    store: _Store,
    record: Callable[[Mapping[str, Any]], None],
) -> None:
    """Run ``todo`` on a process pool, at most ``workers`` runs in flight.

    A worker process that dies breaks the pool (``BrokenProcessPool``) and fails every run
    in flight; each of them gets a death counted in the results file, the pool is
    recreated and those runs are rerun one at a time, so the culprit dies alone. A run
    counted ``MAX_WORKER_DEATHS`` deaths is recorded as failed.
    """
    payload = campaign.payload()
    deaths = store.deaths()
    queue = deque(k for k in todo if deaths.get(k, 0) == 0)
    alone = deque(k for k in todo if deaths.get(k, 0) > 0)  # suspects from an earlier break
    context = multiprocessing.get_context("spawn")
    while queue or alone:
        size = min(workers, max(len(queue), 1))
        pool = ProcessPoolExecutor(
            max_workers=size,
            mp_context=context,
            initializer=_worker_init,
            initargs=(os.getpid(),),
        )
        in_flight: dict[Future, int] = {}
        victims: list[int] = []
        clean = False
        try:
            _check_pool(pool, size)
            while True:
                if alone:
                    if not in_flight:
                        index = alone.popleft()
                        in_flight[pool.submit(execute_run, payload, index)] = index
                else:
                    while queue and len(in_flight) < workers:
                        index = queue.popleft()
                        in_flight[pool.submit(execute_run, payload, index)] = index
                if not in_flight:
                    break
                finished, _ = wait(in_flight, return_when=FIRST_COMPLETED)
                results = []
                for future in finished:
                    index = in_flight.pop(future)
                    error = future.exception()
                    if isinstance(error, BrokenProcessPool):
                        victims.append(index)
                    elif error is not None:
                        raise RuntimeError(
                            f"run {index} could not be executed: {_one_line(error)}"
                        ) from error
                    else:
                        results.append(future.result())
                if victims:  # every other run in flight fails the same way
                    wait(in_flight)
                    for future, index in in_flight.items():
                        if future.exception() is None:
                            results.append(future.result())
                        else:
                            victims.append(index)
                    in_flight.clear()
                elif not alone:  # refill before writing, so no worker waits on the disk
                    while queue and len(in_flight) < workers:
                        index = queue.popleft()
                        in_flight[pool.submit(execute_run, payload, index)] = index
                for result in results:
                    record(result)
                if victims:
                    break
            clean = not victims
        finally:
            _shutdown(pool, clean)
        for index in sorted(victims):
            if store.add_death(index) >= MAX_WORKER_DEATHS:
                record(_died(campaign, index))
            else:
                alone.append(index)


def _worker_ready() -> int:
    import auvmpc.runner  # noqa: F401  (the import a first run would otherwise pay)

    return os.getpid()


def _check_pool(pool: ProcessPoolExecutor, workers: int) -> None:
    """Start every worker at once and wait until each can import auvmpc.

    Each submit while no worker is idle starts another process, so the workers import in
    parallel rather than one after the other. A worker that cannot even start is the
    environment's fault, not a run's: stop without recording anything, so that a resume
    after the fix runs everything.
    """
    try:
        for future in [pool.submit(_worker_ready) for _ in range(workers)]:
            future.result()
    except BrokenProcessPool:
        raise RuntimeError(
            "campaign worker processes cannot start (see their error above); "
            "auvmpc must be importable by a fresh Python process"
        ) from None


def _shutdown(pool: ProcessPoolExecutor, clean: bool) -> None:
    """Stop the pool; after an error or interruption, without letting runs finish."""
    if clean:
        pool.shutdown(wait=True)
        return
    # ProcessPoolExecutor has no public way to stop running workers before Python 3.14.
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        with contextlib.suppress(Exception):
            process.terminate()
    for process in processes:
        with contextlib.suppress(Exception):
            process.join(timeout=5)


def _died(campaign: Campaign, index: int) -> dict[str, Any]:
    sample = sample_run(campaign, index)
    return {
        "index": index,
        "seed": sample.seed,
        "status": "failed",
        "parameters": sample.columns,
        "metrics": {},
        "error": f"WorkerDied: the worker process died {MAX_WORKER_DEATHS} times while running it",
        "traceback": None,
        "wall_s": None,
        "worker": None,
    }


def _execute_dask(
    campaign: Campaign,
    todo: Sequence[int],
    scheduler: str,
    record: Callable[[Mapping[str, Any]], None],
) -> None:
    """Run ``todo`` as Dask futures. A worker that dies mid-run is handled by the
    scheduler, which reruns its tasks elsewhere up to ``distributed.scheduler.allowed-failures``
    times and then reports ``KilledWorker``: that run is recorded as failed. ``retries`` is
    left at 0: a run's own exception is returned as its result, so anything a task raises
    is an environment problem that retrying would only repeat."""
    try:
        from distributed import Client, as_completed
        from distributed.scheduler import KilledWorker
    except ImportError:
        raise ConfigError(
            "--scheduler", scheduler, "needs dask[distributed] (pip install auvmpc[dask])"
        ) from None
    try:
        client = Client(scheduler, timeout="20s", set_as_default=False)
    except (OSError, TimeoutError) as error:
        raise ConfigError("--scheduler", scheduler, f"cannot connect: {_one_line(error)}") from None
    payload = campaign.payload()
    prefix = f"auvmpc-campaign-{campaign.hash[:12]}"
    futures: dict[Any, int] = {}
    try:
        for index in todo:
            key = f"{prefix}-{index}"
            futures[client.submit(execute_run, payload, index, key=key, pure=False)] = index
        for future in as_completed(futures, loop=client.loop):  # no default client
            index = futures.pop(future)
            if future.status == "error":
                error = future.exception()
                if isinstance(error, KilledWorker):
                    failed = _died(campaign, index)
                    deaths = error.allowed_failures + 1
                    failed["error"] = f"KilledWorker: {deaths} Dask workers died while running it"
                    record(failed)
                else:
                    raise ConfigError(
                        "--scheduler",
                        scheduler,
                        f"run {index} could not execute on the cluster ({_one_line(error)}); "
                        "auvmpc must be importable on every worker",
                    )
            elif future.status != "finished":
                raise ConfigError(
                    "--scheduler",
                    scheduler,
                    f"run {index} was {future.status} by the cluster; "
                    "run the same command again to resume",
                )
            else:
                record(future.result())
            future.release()
    finally:
        for future in futures:
            future.cancel()
        client.close()


# --------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------


def load_results(out_dir: str | Path) -> pd.DataFrame:
    """The rows of a campaign folder as a DataFrame, one row per finished run.

    Columns: ``index``, ``seed``, ``status`` (``ok`` | ``failed``), ``error`` (one line,
    None when ok), one per sampled parameter (file order; a polar as ``<path>.magnitude``
    and ``<path>.direction_deg``; non-numeric values as JSON text), one per metric, then
    ``wall_s`` and ``worker_deaths``. Sorted by index. Safe to call while the campaign runs.
    Floats are exactly those the run produced (the JSON is parsed by Python).
    """
    import pandas as pd

    path = _results_path(Path(out_dir))
    with contextlib.closing(_connect(path, read_only=True)) as db:
        parameter_columns, metric_columns = (
            json.loads(text)
            for text in db.execute(
                "SELECT parameter_columns, metric_columns FROM campaign"
            ).fetchone()
        )
        rows = db.execute(
            'SELECT "index", seed, status, error, parameters, metrics, wall_s, worker_deaths '
            'FROM runs ORDER BY "index"'
        ).fetchall()
    records = []
    for index, seed, status, error, parameters, metrics, wall_s, deaths in rows:
        values = json.loads(parameters)
        measured = json.loads(metrics)
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


# --------------------------------------------------------------------------------------
# Success criterion: a small, safe expression language over result columns
# --------------------------------------------------------------------------------------

_COMPARISONS: dict[type, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    ast.Lt: np.less,
    ast.LtE: np.less_equal,
    ast.Gt: np.greater,
    ast.GtE: np.greater_equal,
    ast.Eq: np.equal,
    ast.NotEq: np.not_equal,
}


@dataclass(frozen=True)
class Criterion:
    """A parsed success criterion.

    Grammar: comparisons ``name OP number`` (``<  <=  >  >=  ==  !=``, chains like
    ``0 <= x < 1`` allowed) combined with ``and``, ``or``, ``not`` and parentheses. A name is
    a metric or parameter column; one that is not a Python identifier is written in
    backticks (`` `plant.scale.Iz_rb` ``). A comparison involving a missing value (null
    metric) is false. Parsed with :mod:`ast` and evaluated by walking the tree: nothing is
    ever passed to ``eval``.
    """

    text: str
    tree: ast.Expression
    names: tuple[str, ...]
    aliases: dict[str, str] = field(default_factory=dict)

    def evaluate(self, frame: pd.DataFrame) -> np.ndarray:
        """Boolean array, one per row; rows with status other than ``ok`` are False."""
        missing = [name for name in self.names if name not in frame.columns]
        if missing:
            known = [c for c in frame.columns if c not in ("index", "seed", "status", "error")]
            raise ConfigError("criterion", missing[0], f"unknown column; known: {known}")
        values = {}
        for name in self.names:
            try:
                values[name] = frame[name].astype(float).to_numpy()
            except (TypeError, ValueError):
                raise ConfigError("criterion", name, "not a numeric column") from None
        result = self._node(self.tree.body, values, len(frame))
        return np.asarray(result & (frame["status"] == "ok").to_numpy(), dtype=bool)

    def _node(self, node: ast.AST, values: dict[str, np.ndarray], n: int) -> Any:
        if isinstance(node, ast.BoolOp):
            parts = [self._node(v, values, n) for v in node.values]
            combine = np.logical_and if isinstance(node.op, ast.And) else np.logical_or
            return functools.reduce(combine, parts)
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            return np.logical_not(self._node(node.operand, values, n))
        if isinstance(node, ast.Compare):
            left = self._operand(node.left, values, n)
            result = np.ones(n, dtype=bool)
            for op, right_node in zip(node.ops, node.comparators, strict=True):
                right = self._operand(right_node, values, n)
                known = ~np.isnan(left) & ~np.isnan(right)
                with np.errstate(invalid="ignore"):
                    result &= known & _COMPARISONS[type(op)](left, right)
                left = right
            return result
        raise AssertionError(f"unchecked node {ast.dump(node)}")  # parse_criterion rejects it

    def _operand(self, node: ast.AST, values: dict[str, np.ndarray], n: int) -> np.ndarray:
        if isinstance(node, ast.Name):
            return values[self.aliases.get(node.id, node.id)]
        return np.full(n, _number(node))


def _number(node: ast.AST) -> float:
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        value = _number(node.operand)
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.Constant) and _is_number(node.value):
        return float(node.value)
    raise ValueError


def parse_criterion(text: str) -> Criterion:
    """Parse a success criterion (grammar in :class:`Criterion`).

    Raises
    ------
    ConfigError
        Naming ``criterion`` and the offending part.
    """
    aliases: dict[str, str] = {}
    parts = text.split("`")
    if len(parts) % 2 == 0:
        raise ConfigError("criterion", text, "unbalanced backtick")
    for i in range(1, len(parts), 2):
        alias = f"_column_{i // 2}"
        aliases[alias] = parts[i]
        parts[i] = alias
    try:
        tree = ast.parse("".join(parts).strip(), mode="eval")
    except SyntaxError:
        raise ConfigError("criterion", text, "not a valid expression") from None
    names: list[str] = []

    def check(node: ast.AST, boolean: bool) -> None:
        if boolean and isinstance(node, ast.BoolOp):
            for value in node.values:
                check(value, True)
        elif boolean and isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.Not):
            check(node.operand, True)
        elif boolean and isinstance(node, ast.Compare):
            if not all(type(op) in _COMPARISONS for op in node.ops):
                raise ConfigError("criterion", text, "comparisons are < <= > >= == !=")
            for operand in (node.left, *node.comparators):
                check(operand, False)
        elif not boolean and isinstance(node, ast.Name):
            name = aliases.get(node.id, node.id)
            if name not in names:
                names.append(name)
        elif not boolean:
            try:
                _number(node)
            except ValueError:
                raise ConfigError(
                    "criterion", ast.unparse(node), "operands are column names and numbers"
                ) from None
        else:
            raise ConfigError(
                "criterion", ast.unparse(node), "expected comparisons joined by and / or / not"
            )

    check(tree.body, True)
    return Criterion(text, tree, tuple(names), aliases)


def wilson_interval(successes: int, trials: int, z: float = WILSON_Z_95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion (95 % by default); (0, 1) if no trials."""
    if trials == 0:
        return 0.0, 1.0
    p = successes / trials
    denominator = 1 + z * z / trials
    centre = (p + z * z / (2 * trials)) / denominator
    half = z / denominator * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials))
    return max(0.0, centre - half), min(1.0, centre + half)


# --------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------


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
        Write ``report.md``, ``report.json`` and ``figures/*.png`` into ``out_dir``.
    """
    from auvmpc.runner import atomic_write_text

    out = Path(out_dir)
    campaign = stored_campaign(out)
    frame = load_results(out)
    if frame.empty:
        raise ConfigError("DIR", str(out), "no finished runs yet")
    text = criterion if criterion is not None else campaign.spec.criterion
    parsed = parse_criterion(text) if text else None
    ok = frame[frame["status"] == "ok"]
    if parsed is not None and len(ok):
        passed = parsed.evaluate(frame)
    else:  # no criterion, or every run failed (no metric to evaluate it on)
        passed = (frame["status"] == "ok").to_numpy() & (parsed is None)
    n, successes = len(frame), int(passed.sum())
    low, high = wilson_interval(successes, n)
    metric_columns = frame.attrs["metric_columns"]
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
            "command": reproduce_command(campaign, int(row["index"])),
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
            "command": reproduce_command(campaign, int(row["index"])),
        }
        for _, row in frame[frame["status"] != "ok"].iterrows()
    ]
    summary = {
        "campaign": campaign.spec.name,
        "description": campaign.spec.description,
        "hash": campaign.hash,
        "base": campaign.base_source,
        "seed": campaign.spec.seed,
        "runs_in_file": campaign.spec.runs,
        "rows": n,
        "ok": int(len(ok)),
        "failed": int(n - len(ok)),
        "criterion": text or "status == ok",
        "successes": successes,
        "success_rate": successes / n if n else None,
        "success_ci95": [low, high],
        "metrics": {c: _stats(ok[c]) for c in metric_columns},
        "parameters": {c: _stats(frame[c]) for c in numeric_parameters},
        "worst_by": rank_by,
        "worst_order": order,
        "worst": worst_rows,
        "failed_runs": failed_rows,
    }
    drawn = (
        _report_figures(
            frame, passed, metric_columns, numeric_parameters, parsed, rank_by, campaign
        )
        if figures and len(ok)
        else {}
    )
    summary["figures"] = [f"{FIGURES_DIR}/{name}.png" for name in drawn]
    markdown = _markdown(summary)
    files: list[Path] = []
    if write:
        from auvmpc.plots import save_figures

        files += save_figures(drawn, out / FIGURES_DIR)
        atomic_write_text(out / REPORT_JSON, json.dumps(summary, indent=2, allow_nan=False) + "\n")
        atomic_write_text(out / REPORT_FILE, markdown)
        files += [out / REPORT_JSON, out / REPORT_FILE]
    return CampaignReport(summary, markdown, drawn, files)


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
        "## Metrics over the finished runs",
        "",
        "| metric | n | min | p5 | p50 | p95 | max |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, stats in summary["metrics"].items():
        note = " (wall clock)" if name in TIMING_METRICS else ""
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
            f"  {row['from_campaign']}",
            f"  {row['command']}",
            "  ```",
        ]
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


# --------------------------------------------------------------------------------------
# YAML text of a value, read back exactly by apply_override
# --------------------------------------------------------------------------------------


def _yaml_text(value: Any) -> str:
    """Flow-style YAML that ``yaml.safe_load`` reads back as exactly ``value``.

    Floats use ``repr`` (shortest round-trip form) with a ``.0`` added to a bare
    mantissa, because YAML 1.1 reads ``1e-05`` as a string but ``1.0e-05`` as a float.
    """
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"non-finite value {value!r}")
        text = repr(value)
        mantissa, exponent_mark, exponent = text.partition("e")
        if exponent_mark and "." not in mantissa:
            text = f"{mantissa}.0e{exponent}"
        return text
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_yaml_text(item) for item in value) + "]"
    if isinstance(value, dict):
        return (
            "{"
            + ", ".join(f"{json.dumps(str(k))}: {_yaml_text(v)}" for k, v in value.items())
            + "}"
        )
    raise TypeError(f"cannot write {type(value).__name__} as YAML")


# --------------------------------------------------------------------------------------
# python -m auvmpc.campaign FILE --out DIR [--workers N] [--runs N] [--scheduler ADDRESS]
# --------------------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    """Minimal entry point without the CLI's dependencies; returns the exit code."""
    parser = argparse.ArgumentParser(
        prog="python -m auvmpc.campaign", description="Run or resume a robustness campaign."
    )
    parser.add_argument("campaign", help="built-in campaign name or campaign YAML")
    parser.add_argument("--out", required=True, type=Path, help="campaign folder")
    parser.add_argument(
        "--workers", type=int, default=None, help="local processes (default: all CPUs)"
    )
    parser.add_argument("--runs", type=int, default=None, help="run only the first N runs")
    parser.add_argument("--scheduler", default=None, help="Dask scheduler address")
    args = parser.parse_args(argv)
    # Through the imported module, not __main__: workers unpickle auvmpc.campaign.execute_run.
    from auvmpc import campaign as module

    try:
        summary = module.run_campaign(
            args.campaign, args.out, workers=args.workers, runs=args.runs, scheduler=args.scheduler
        )
    except ConfigError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(
        f"{summary.total} runs: {summary.ok} ok, {summary.failed} failed "
        f"({summary.new} run now, {summary.wall_s:.1f} s) -> {summary.out_dir / RESULTS_FILE}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
