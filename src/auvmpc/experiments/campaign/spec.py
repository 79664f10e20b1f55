"""Campaign files: constants, the schema, loading, and the exact YAML text of a value.

Part of :mod:`auvmpc.experiments.campaign` (docs/campaigns.md).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import hashlib
import itertools
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, ValidationError, field_validator, model_validator

from auvmpc.config import StrictModel, builtin_descriptions
from auvmpc.errors import ConfigError, FieldError
from auvmpc.experiments.campaign.criterion import (
    _is_number,
    parse_criterion,
)
from auvmpc.safe_yaml import read_text_file, read_yaml_mapping
from auvmpc.scenario import (
    ResolvedScenario,
    apply_override,
    builtin_scenarios,
    scenario_to_dict,
)
from auvmpc.scenario.loader import resolve_document

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

# Every run is checked before the first starts, about 1 ms each: 10^6 runs take minutes to
# check (and days to run); `runs: 1e8` was an hours-long silent check before (issue 28).
MAX_RUNS = 1_000_000


# Wall-clock measurements: stored, but they differ between two runs of the same campaign.
TIMING_METRICS = ("solve_ms_median", "solve_ms_p99", "solve_ms_max")


NONDETERMINISTIC_COLUMNS = (
    *TIMING_METRICS,
    *(f"yardstick_{name}" for name in TIMING_METRICS),  # campaigns with a yardstick
    "wall_s",
    "worker_deaths",
)


PERCENTILES = (5, 50, 95)


# The column of a run's notes from its overrides (a JSON list; only where there are some):
# what an override decided that the user should hear of, e.g. the knobs of the old type
# dropped where it changed the controller's type. ``auvmpc run`` prints them and run.json
# keeps them among its ``warnings``; the report lists each once.
OVERRIDE_NOTES = "override_notes"


# A "normal" without bounds is checked at mean +- this many standard deviations.
NORMAL_CHECK_STDS = 3.0


class CaseKind(StrEnum):
    """Kinds of generated cases (:data:`auvmpc.experiments.survey_cases.CASE_KINDS`)."""

    HARD_SURVEY = "hard-survey"
    LOOPS = "loops"


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


class Cases(StrictModel):
    """Generated base scenarios: run k's is ``survey_cases.make_case(kind, seed, k)``."""

    kind: CaseKind = Field(
        description="hard-survey (lawnmowers with 90-degree corners and discs) or loops "
        "(circles and figure-eights), random vehicles in a current, with model error and noise"
    )


class CampaignSpec(StrictModel):
    """A campaign file as written (``docs/campaigns.md``)."""

    name: str = Field(description="identifier")
    description: str = Field(default="", description="one line for humans")
    base: str | None = Field(
        default=None,
        description="built-in scenario name, or scenario file relative to this file "
        "(or give `cases`)",
    )
    cases: Cases | None = Field(
        default=None, description="generated base scenarios, one per run, instead of `base`"
    )
    overrides: tuple[str, ...] = Field(
        default=(), description="field=value applied to every run, as `auvmpc run --set`"
    )
    controller: str | None = Field(
        default=None,
        description="controller label of `auvmpc run --controller` (e.g. ltv-mpc, nmpc): its "
        "overrides apply to the tested runs after `overrides`, never to the yardstick",
    )
    yardstick: tuple[str, ...] | None = Field(
        default=None,
        description="field=value overrides applied last to a second simulation of every run "
        "(e.g. the converged OCP); its metrics are stored with a yardstick_ prefix",
    )
    runs: Annotated[int, Field(ge=1, le=MAX_RUNS)] = Field(description="number of runs")
    seed: Annotated[int, Field(ge=0)] = Field(description="master seed of every run's draws")
    parameters: dict[str, Distribution] = Field(
        default_factory=dict, description="scenario field path -> distribution"
    )
    criterion: str | None = Field(
        default=None, description="default success criterion of the report, e.g. 'x_m < 1'"
    )

    @field_validator("overrides", "yardstick")
    @classmethod
    def _overrides(cls, overrides: tuple[str, ...] | None) -> tuple[str, ...] | None:
        for i, text in enumerate(overrides or ()):
            path, separator, _ = text.partition("=")
            if not separator or not path:
                raise FieldError(str(i), text, "expected field=value")
        return overrides

    @field_validator("yardstick")
    @classmethod
    def _yardstick(cls, yardstick: tuple[str, ...] | None) -> tuple[str, ...] | None:
        if yardstick is not None and not yardstick:
            raise FieldError("yardstick", [], "give at least one field=value, or leave it out")
        return yardstick

    @model_validator(mode="after")
    def _one_base(self) -> CampaignSpec:
        if self.base is not None and self.cases is not None:
            raise FieldError("cases", self.cases.kind, "give base or cases, not both")
        if self.base is None and self.cases is None:
            raise FieldError("base", None, "give base (a scenario) or cases (generated ones)")
        return self

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


@dataclass(frozen=True, eq=False)
class Campaign:
    """A campaign file plus what it points at.

    Attributes
    ----------
    spec : CampaignSpec
        The file's contents, validated.
    source : str
        Built-in name or path as given.
    base_source : str or None
        The base scenario: built-in name or absolute path (what ``auvmpc run`` is given);
        None for generated cases (``spec.cases``), which have no file.
    base_data : dict
        The base scenario file's mapping, as read (before any override); empty for
        generated cases (:meth:`base_for` makes each run's).
    base_dir : str
        Folder that relative paths inside the scenario resolve against.
    implicit_overrides : tuple of str
        ``field=value`` overrides added after ``spec.overrides`` so that every parameter
        path exists (e.g. ``controller.Q=[5, 5, 5, 1, 1, 1]`` when the base scenario leaves
        ``controller.Q`` at its default and a parameter samples ``controller.Q.0``).
    controller_overrides : tuple of str
        The overrides ``spec.controller`` stands for (``auvmpc run --controller``), applied
        to the tested runs after ``spec.overrides``, never to the yardstick.
    """

    spec: CampaignSpec
    source: str
    base_source: str | None
    base_data: dict[str, Any]
    base_dir: str
    implicit_overrides: tuple[str, ...] = ()
    controller_overrides: tuple[str, ...] = ()

    def fixed_overrides(self, yardstick: bool = False) -> tuple[str, ...]:
        """Overrides of every run before its seed and parameters (the yardstick's leave out
        the controller label's)."""
        controller = () if yardstick else self.controller_overrides
        return (*self.spec.overrides, *controller, *self.implicit_overrides)

    def base_for(self, index: int) -> dict[str, Any]:
        """Run ``index``'s base scenario mapping, a fresh copy: the base file's, or case
        ``index`` of ``spec.cases`` (:func:`auvmpc.experiments.survey_cases.make_case`)."""
        if self.spec.cases is None:
            return copy.deepcopy(self.base_data)
        from auvmpc.experiments.survey_cases import make_case

        return make_case(self.spec.cases.kind.value, self.spec.seed, index)

    @property
    def base_label(self) -> str:
        """The base for humans: the scenario, or ``cases: <kind>``."""
        if self.spec.cases is None:
            return str(self.base_source)
        return f"cases: {self.spec.cases.kind.value}"

    @functools.cached_property
    def hash(self) -> str:
        """SHA-256 of :meth:`identity`."""
        return hashlib.sha256(_canonical_json(self.identity()).encode()).hexdigest()

    def identity(self) -> dict[str, Any]:
        """Everything that decides the runs (not name, description, runs, criterion).

        The keys of the newer options (cases, controller, yardstick) enter only when set, so
        a campaign without them keeps the hash it always had."""
        identity: dict[str, Any] = {
            "rules": SAMPLING_RULES,
            "overrides": list(self.spec.overrides),
            "seed": self.spec.seed,
            "parameters": {
                path: distribution.model_dump(mode="json")
                for path, distribution in self.spec.parameters.items()
            },
        }
        if self.spec.cases is None:
            identity["base"] = self.base_data
        else:
            identity["cases"] = self.spec.cases.model_dump(mode="json")
        if self.controller_overrides:
            identity["controller"] = list(self.controller_overrides)
        if self.spec.yardstick is not None:
            identity["yardstick"] = list(self.spec.yardstick)
        return identity

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
        """Everything a worker needs, as one JSON string (the controller label's overrides
        expanded here, so that a worker need not import the API to expand them)."""
        return _canonical_json(
            {
                "spec": self.spec.model_dump(mode="json"),
                "source": self.source,
                "base_source": self.base_source,
                "base_data": self.base_data,
                "base_dir": self.base_dir,
                "controller_overrides": list(self.controller_overrides),
            }
        )


def builtin_campaigns() -> dict[str, str]:
    """Built-in campaign names and their one-line descriptions."""
    return builtin_descriptions("campaigns")


def load_campaign(source: str | Path, controller: str | None = None) -> Campaign:
    """Read and validate a campaign: built-in name or YAML file path.

    Only the file's own schema and the base scenario are checked here;
    :func:`validate_campaign` checks the sampled scenarios.

    Parameters
    ----------
    controller : str, optional
        A controller label (``auvmpc campaign --controller``) replacing the file's
        ``controller``: a campaign of its own (another hash).

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
        if not path.exists():
            raise ConfigError(
                "campaign", text_source, f"no such file or built-in; built-ins: {list(builtins)}"
            )
        text, folder = read_text_file(path, "campaign", "campaign file"), path.resolve().parent
    data = _read_yaml(text, "campaign", text_source)
    spec = _validate_spec(data)
    if controller is not None:
        spec = spec.model_copy(update={"controller": controller})
    if spec.base is not None:
        base_source, base_data, base_dir = _read_base(spec.base, folder)
    else:  # generated cases: no file; nothing relative inside them
        base_source, base_data, base_dir = None, {}, str(folder or Path.cwd())
    campaign = Campaign(
        spec, text_source, base_source, base_data, base_dir,
        controller_overrides=expand_controller(spec.controller),
    )  # fmt: skip
    _check_fixed(campaign)
    return _with_implicit_overrides(campaign)


def expand_controller(label: str | None) -> tuple[str, ...]:
    """The overrides of a campaign's ``controller`` label (those of ``auvmpc run --controller``)."""
    if label is None:
        return ()
    from auvmpc.api import controller_overrides

    try:
        return tuple(controller_overrides(label))
    except ConfigError as error:
        raise ConfigError("controller", error.value, error.reason) from None


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
    if not path.exists():
        raise ConfigError(
            "base",
            base,
            f"no such scenario file or built-in; built-ins: {list(builtin_scenarios())}",
        )
    path = path.resolve()
    text = read_text_file(path, "base", "scenario file")
    return str(path), _read_yaml(text, "base", base), str(path.parent)


def _with_implicit_overrides(campaign: Campaign) -> Campaign:
    """Add overrides that make each sampled list element's container exist in the data.

    ``apply_override`` creates missing mapping keys but cannot index a list the base
    scenario leaves at its default; writing the default list out first keeps every run
    expressible as ``auvmpc run BASE --set ...``. Generated cases refuse them: a default
    may depend on the case's vehicle, so no one list fits every run.
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
                    prefix = ".".join(keys[: depth + 1])
                    if campaign.spec.cases is not None:
                        raise ConfigError(
                            f"parameters.{path}",
                            path,
                            f"generated cases leave {prefix} at its default, which may differ "
                            "between cases; set the whole list in overrides",
                        )
                    text = f"{prefix}={_yaml_text(default)}"
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
    return dataclasses.replace(campaign, implicit_overrides=tuple(implicit))


def _fixed_data(
    campaign: Campaign, implicit: bool = False, index: int = 0, yardstick: bool = False
) -> dict[str, Any]:
    """Run ``index``'s base scenario with the file's overrides and the controller label's
    (not for the yardstick), and, if asked, the implicit ones."""
    return _fixed_plan(campaign, implicit, index, yardstick)[0]


def _fixed_plan(
    campaign: Campaign, implicit: bool = False, index: int = 0, yardstick: bool = False
) -> tuple[dict[str, Any], list[str]]:
    """:func:`_fixed_data`, and the notes its overrides made (:data:`OVERRIDE_NOTES`)."""
    data = campaign.base_for(index)
    notes: list[str] = []
    for i, text in enumerate(campaign.spec.overrides):
        try:
            notes += apply_override(data, text)
        except ConfigError as error:
            raise ConfigError(f"overrides.{i}", text, str(error)) from None
    for text in () if yardstick else campaign.controller_overrides:
        try:
            notes += apply_override(data, text)
        except ConfigError as error:
            raise ConfigError("controller", campaign.spec.controller, str(error)) from None
    if implicit:
        for text in campaign.implicit_overrides:
            notes += apply_override(data, text)
    return data, notes


def _check_fixed(campaign: Campaign) -> None:
    """The base scenario (case 0 of generated ones) with the fixed overrides must be valid."""
    data = _fixed_data(campaign)
    try:
        _resolve(campaign, data)
    except ConfigError as error:
        for i, text in enumerate(campaign.spec.overrides):
            if _related(text.partition("=")[0], error.field):
                raise ConfigError(f"overrides.{i}", text, str(error)) from None
        for text in campaign.controller_overrides:
            if _related(text.partition("=")[0], error.field):
                raise ConfigError("controller", campaign.spec.controller, str(error)) from None
        if campaign.spec.cases is not None:
            raise ConfigError(
                "cases", campaign.spec.cases.kind.value, f"invalid scenario (case 0): {error}"
            ) from None
        raise ConfigError("base", campaign.spec.base, f"invalid scenario: {error}") from None


def _related(path: str, field_name: str) -> bool:
    """Whether an error about ``field_name`` can come from setting ``path``."""
    return (
        field_name == path or field_name.startswith(f"{path}.") or path.startswith(f"{field_name}.")
    )


def _resolved_dict(data: dict[str, Any], campaign: Campaign) -> dict[str, Any]:
    """Scenario ``data`` (known valid) dumped with every default filled in, those chosen for
    the vehicle included (a parameter may scale the default thrust weights)."""
    return scenario_to_dict(_resolve(campaign, copy.deepcopy(data)).scenario)


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


def _resolve(
    campaign: Campaign, data: dict[str, Any], notes: Sequence[str] = ()
) -> ResolvedScenario:
    """Scenario ``data`` resolved; ``notes``, what its overrides decided, first among its
    own (run.json ``warnings``, as ``auvmpc run BASE --set ...`` keeps them)."""
    return resolve_document(data, Path(campaign.base_dir), notes)


def _canonical_json(value: Any) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False)


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
