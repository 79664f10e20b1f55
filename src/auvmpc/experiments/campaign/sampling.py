"""Sampling: each run's parameters as a pure function of (master seed, run index),
and the validation of a whole campaign before any run.

Part of :mod:`auvmpc.experiments.campaign` (docs/campaigns.md).
"""

from __future__ import annotations

import copy
import hashlib
import math
import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from auvmpc.errors import ConfigError
from auvmpc.experiments.campaign.criterion import (
    _is_number,
)
from auvmpc.experiments.campaign.spec import (
    ApplyMode,
    Campaign,
    CampaignSpec,
    Grid,
    Polar,
    _check_fixed,
    _fixed_data,
    _fixed_plan,
    _lookup,
    _related,
    _resolve,
    _resolved_dict,
    _split_length,
    _yaml_text,
)
from auvmpc.scenario import (
    ResolvedScenario,
    apply_override,
    validate_document,
)


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


@dataclass(frozen=True)
class RunPlan:
    """How run ``index`` is made (:func:`plan_run`).

    Attributes
    ----------
    sample : RunSample
        What it draws.
    overrides : list of str
        The ``field=value`` strings that ``auvmpc run BASE --set ...`` is given for it.
    data : dict
        Its scenario mapping.
    notes : list of str
        What its overrides decided that the user should hear of (a knob dropped where
        an override changed the controller's type), as ``auvmpc run`` warns of them.
    """

    sample: RunSample
    overrides: list[str]
    data: dict[str, Any]
    notes: list[str]


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
    campaign: Campaign,
    index: int,
    replace: Mapping[str, Any] | None = None,
    *,
    yardstick: bool = False,
) -> RunPlan:
    """Run ``index``: its sample, its ``field=value`` overrides, its scenario mapping and
    the notes the overrides made.

    The overrides, applied with :func:`auvmpc.scenario.apply_override` to the base
    scenario in order, give exactly the mapping returned: the campaign builds each run
    from the same strings that ``auvmpc run BASE --set ...`` is given.

    Parameters
    ----------
    replace : mapping, optional
        Parameter path -> value used instead of the draw (validation of the extremes).
    yardstick : bool
        The run's yardstick twin: without the controller label's overrides, with
        ``spec.yardstick`` applied last (``campaign.spec.yardstick`` must be set).
    """
    if yardstick and campaign.spec.yardstick is None:
        raise ConfigError("yardstick", campaign.spec.name, "the campaign has no yardstick")
    sample = sample_run(campaign, index)
    draws = {**sample.draws, **(replace or {})}
    data, notes = _fixed_plan(campaign, implicit=True, index=index, yardstick=yardstick)
    overrides = [*campaign.fixed_overrides(yardstick), f"seed={sample.seed}"]
    notes += apply_override(data, overrides[-1])
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
                    _fixed_data(campaign, implicit=True, index=index, yardstick=yardstick),
                    campaign,
                )
                current = _lookup(defaults, target.split("."))
            value = _combine(current, value, distribution.apply, path)
        text = f"{target}={_yaml_text(value)}"
        notes += _apply_parameter(data, text, path, value)
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
        notes += _apply_parameter(data, text, path, count)
        overrides.append(text)
    for i, text in enumerate(campaign.spec.yardstick if yardstick else ()):
        try:
            notes += apply_override(data, text)
        except ConfigError as error:
            raise ConfigError(f"yardstick.{i}", text, str(error)) from None
        overrides.append(text)
    return RunPlan(sample, overrides, data, notes)


def _apply_parameter(data: dict[str, Any], text: str, path: str, value: Any) -> list[str]:
    try:
        return apply_override(data, text)
    except ConfigError as error:
        raise ConfigError(f"parameters.{path}", value, error.reason) from None


def run_overrides(campaign: Campaign, index: int, *, yardstick: bool = False) -> list[str]:
    """``field=value`` strings such that ``auvmpc run BASE --set ...`` reproduces run ``index``
    (or its yardstick twin)."""
    return plan_run(campaign, index, yardstick=yardstick).overrides


def reproduce_command(
    campaign: Campaign,
    index: int,
    out_dir: str | Path | None = None,
    *,
    yardstick: bool = False,
) -> str:
    """The shell command that reruns run ``index`` (or its yardstick twin) alone with
    ``auvmpc run``: ``auvmpc run BASE --set ...``, or for generated cases, which have no
    scenario file, ``auvmpc run --from-campaign OUT_DIR --index K`` (``out_dir`` needed)."""
    if campaign.base_source is None:
        if out_dir is None:
            raise ConfigError("out_dir", None, "generated cases are rerun from the campaign folder")
        words = ["auvmpc", "run", "--from-campaign", str(out_dir), "--index", str(index)]
        return shlex.join([*words, "--yardstick"] if yardstick else words)
    words = ["auvmpc", "run", campaign.base_source]
    for text in run_overrides(campaign, index, yardstick=yardstick):
        words += ["--set", text]
    return shlex.join(words)


def scenario_for_run(
    campaign_or_dir: Campaign | str | Path,
    index: int,
    overrides: Sequence[str] = (),
    *,
    yardstick: bool = False,
) -> ResolvedScenario:
    """Run ``index`` of a campaign (or of the campaign stored in a results folder),
    resolved and ready for :func:`auvmpc.experiments.run.simulate`; ``overrides`` apply last.
    With ``yardstick``, the run's yardstick twin (:func:`plan_run`)."""
    from auvmpc.experiments.campaign.store import stored_campaign  # store imports this module

    campaign = (
        campaign_or_dir
        if isinstance(campaign_or_dir, Campaign)
        else stored_campaign(Path(campaign_or_dir))
    )
    runs = campaign.spec.runs
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < runs:
        raise ConfigError("--index", index, f"need a run index in 0..{runs - 1} ({runs} runs)")
    plan = plan_run(campaign, index, yardstick=yardstick)
    notes = [note for text in overrides for note in apply_override(plan.data, text)]
    return _resolve(campaign, plan.data, [*plan.notes, *notes])


def validate_campaign(
    campaign: Campaign, runs: int | None = None, workers: int = 1, long_ok: bool = False
) -> None:
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
    twins = (False, True) if campaign.spec.yardstick is not None else (False,)
    from auvmpc.scenario.cost import check_campaign_cost

    _check_fixed(campaign)
    seconds = {False: 0.0, True: 0.0}
    for yardstick in twins:
        seconds[yardstick] = _check_plan(campaign, 0, None, "run 0", yardstick, long_ok)
    for path, distribution in campaign.spec.parameters.items():
        for label, value in distribution.extremes():
            cost = _check_plan(campaign, 0, (path, value), f"at {label}", long_ok=long_ok)
            seconds[False] = max(seconds[False], cost)
    check_campaign_cost(seconds[False] + seconds[True], count, workers, long_ok)
    for index in range(1, count):
        for yardstick in twins:
            where = f"run {index}{' yardstick' if yardstick else ''}"
            try:
                validate_document(
                    plan_run(campaign, index, yardstick=yardstick).data, Path(campaign.base_dir)
                )
            except ConfigError as error:
                raise _blame(campaign, error, None, where, yardstick) from None


def _check_plan(
    campaign: Campaign,
    index: int,
    replaced: tuple[str, Any] | None,
    where: str,
    yardstick: bool = False,
    long_ok: bool = False,
) -> float:
    """Resolve one planned run and check its memory and cost; its estimated seconds."""
    from auvmpc.scenario.cost import check_cost
    from auvmpc.scenario.sanity import check_memory

    try:
        plan = plan_run(
            campaign, index, dict([replaced]) if replaced else None, yardstick=yardstick
        )
        resolved = _resolve(campaign, plan.data)
        check_memory(resolved)
        return check_cost(resolved, confirmed=long_ok).seconds
    except ConfigError as error:
        if yardstick:
            where += " yardstick"
        raise _blame(campaign, error, replaced, where, yardstick) from None


def _blame(
    campaign: Campaign,
    error: ConfigError,
    replaced: tuple[str, Any] | None,
    where: str,
    yardstick: bool = False,
) -> ConfigError:
    """Name the parameter an invalid scenario comes from: the one set to an extreme (the
    others are at their valid run-0 values), else a yardstick override or a parameter whose
    path the error is about."""
    if error.field.startswith(("parameters.", "yardstick.")):
        return ConfigError(error.field, error.value, f"{error.reason} ({where})")
    for i, text in enumerate(campaign.spec.yardstick if yardstick else ()):
        if _related(text.partition("=")[0], error.field):
            return ConfigError(f"yardstick.{i}", text, f"{error} ({where})")
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
