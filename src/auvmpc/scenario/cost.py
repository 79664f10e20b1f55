"""What a run will cost before it starts: samples, plant steps, memory and wall time.

An estimate, stated as one, so that a scenario that could only hang (``plant.max_step:
1e-7``, ``controller.sample_time: 1e-6``, a vehicle whose stable plant step is
microseconds) or run for days (``prediction_horizon: 3000``) is refused in one line naming
the field, before anything is built. Beyond the limits below a run is refused unless the
caller confirms it (``auvmpc run --yes-long``, ``auvmpc campaign --yes-long``); memory is
checked by :func:`auvmpc.scenario.sanity.check_memory`, never waived (the run could only
crash).

Wall time per sample: the controller's step, ``STEP_MS`` at a 30-step horizon (the p99 of
`auvmpc bench` on paper-obstacles, docs/performance.md, 2026-11-23, rounded up) grown as
``(ny / 30)^2`` (measured on paper-obstacles, duration 5 s, on the 2-core test machine,
median ms per step at ny = 30 / 300 / 600: real-time nmpc 3.8 / 364 / 1224, nmpc full 48 /
309 / 537, ltv-mpc 12 / 803 / 3773, mpc without blocking 8.4 / 7085 at 300: between ny^1
and ny^3), plus the loop, ``LOOP_MS`` a sample, and the plant, ``PLANT_STEP_MS`` per RK4
sub-step, ``MANY_PLANT_STEP_MS`` when a sample has more than ``_FEW_SUBSTEPS`` (measured with
the baseline on paper-ideal, 400 samples: 0.58 ms a sample in all at 10 sub-steps, 0.16 ms
of it the controller; 0.32 ms a sub-step at 100 sub-steps, 0.60 ms at 1000, building the
plant's compiled step included). A rough figure, good to a factor of a few: it tells a
minute from a day, not 10 s from 20 s; the build of a large nonlinear program (minutes at
ny = 3000) is not in it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from auvmpc.errors import ConfigError

__all__ = [
    "CostEstimate",
    "MAX_CAMPAIGN_HOURS",
    "MAX_PLANT_STEPS",
    "MAX_RUN_HOURS",
    "check_cost",
    "check_campaign_cost",
    "estimate_cost",
    "readable_bytes",
]

# Beyond these an estimate is refused unless confirmed. 1e7 RK4 sub-steps is 139 h of
# simulated time at the default 0.05 s step, about 8 min of plant alone; 4 h is longer than
# any run of the paper, survey or benchmark presets by far (the longest take seconds).
MAX_PLANT_STEPS = 10_000_000
MAX_RUN_HOURS = 4.0
MAX_CAMPAIGN_HOURS = 48.0  # on the campaign's workers, all runs (and yardstick twins)

# Controller step at a 30-step horizon (ms; module docstring).
STEP_MS = {
    "baseline": 0.3,
    "mpc": 1.0,
    "ltv-mpc": 4.0,
    "nmpc": 2.0,  # real-time
    "nmpc-full": 25.0,
    "do-mpc": 55.0,
    "depth-mpc": 1.0,
    "thrust-playback": 0.05,
}
_UNKNOWN_STEP_MS = 25.0  # a registered controller the table does not know: as a full NLP
_REFERENCE_HORIZON = 30
LOOP_MS = 0.3
PLANT_STEP_MS = 0.05
MANY_PLANT_STEP_MS = 0.5
_FEW_SUBSTEPS = 10
# Past this many sub-steps per sample the plant step, not the duration, is what is unusual.
_MANY_SUBSTEPS = 100
# A sample time below this (every preset's is 0.05-0.5 s) is what makes samples many.
_SHORT_SAMPLE_S = 0.01


@dataclass(frozen=True)
class CostEstimate:
    """A run's size and rough cost (module docstring)."""

    samples: int
    substeps: int  # plant RK4 sub-steps per sample
    memory_bytes: float  # log plus the controller's build, as check_memory counts them
    seconds: float
    controller_seconds: float  # the controller's share of ``seconds``

    @property
    def plant_steps(self) -> int:
        return self.samples * self.substeps

    def summary(self) -> str:
        return (
            f"{self.samples} samples, {self.plant_steps} plant steps, about "
            f"{readable_bytes(self.memory_bytes)} and {_duration(self.seconds)} (an estimate)"
        )


def readable_bytes(n_bytes: float) -> str:
    """A size in bytes as people read it (``1.5 GiB``)."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n_bytes < 1024 or unit == "PiB":
            return f"{n_bytes:.3g} {unit}"
        n_bytes /= 1024
    return f"{n_bytes:.3g} PiB"  # pragma: no cover


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.2g} s"
    if seconds < 7200:
        return f"{seconds / 60:.3g} min"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.3g} h"
    return f"{seconds / 86400:.3g} days"


def _step_ms(config) -> float:
    kind = str(config.type)
    if kind == "nmpc" and str(getattr(config, "nmpc_mode", "real-time")) == "full":
        kind = "nmpc-full"
    base = STEP_MS.get(kind, _UNKNOWN_STEP_MS)
    horizon = getattr(config, "prediction_horizon", None) or _REFERENCE_HORIZON
    return base * max(1.0, horizon / _REFERENCE_HORIZON) ** 2


def estimate_cost(resolved) -> CostEstimate:
    """The cost of simulating ``resolved`` (any kind) once."""
    from auvmpc.scenario.sanity import memory_needs
    from auvmpc.sim.plant import substeps_for

    scenario = resolved.scenario
    config = scenario.controller
    samples = math.ceil(scenario.duration / config.sample_time - 1e-9)
    substeps = substeps_for(config.sample_time, scenario.plant.max_step)
    controller_s = samples * _step_ms(config) / 1e3
    per_substep = PLANT_STEP_MS if substeps <= _FEW_SUBSTEPS else MANY_PLANT_STEP_MS
    plant_s = samples * (LOOP_MS + substeps * per_substep) / 1e3
    memory = max(need for _, _, need, _ in memory_needs(resolved))
    return CostEstimate(samples, substeps, memory, controller_s + plant_s, controller_s)


def _steps_field(resolved, estimate: CostEstimate) -> tuple[str, object, str]:
    """The field that makes the plant steps many, and why."""
    scenario = resolved.scenario
    if estimate.substeps > _MANY_SUBSTEPS:
        given = getattr(getattr(resolved, "given", None), "plant", None)
        why = (
            ""
            if given is None or given.max_step is not None
            else " (chosen for RK4 stability of the plant vehicle at the speeds its thrust "
            "reaches: check its damping, inertia and thrust limits)"
        )
        return "plant.max_step", scenario.plant.max_step, why
    if scenario.controller.sample_time < _SHORT_SAMPLE_S:
        return "controller.sample_time", scenario.controller.sample_time, ""
    return "duration", scenario.duration, ""


def check_cost(resolved, confirmed: bool = False) -> CostEstimate:
    """The estimate of ``resolved``; beyond MAX_PLANT_STEPS or MAX_RUN_HOURS, a ConfigError
    naming the field responsible, unless ``confirmed``."""
    estimate = estimate_cost(resolved)
    if confirmed:
        return estimate
    if estimate.plant_steps > MAX_PLANT_STEPS:
        field, value, why = _steps_field(resolved, estimate)
        raise ConfigError(
            field,
            value,
            f"{estimate.samples:.3g} samples x {estimate.substeps} plant steps = "
            f"{estimate.plant_steps:.3g} plant steps, over the {MAX_PLANT_STEPS:.0e} limit"
            f"{why}; --yes-long runs it anyway",
        )
    if estimate.seconds > 3600 * MAX_RUN_HOURS:
        config = resolved.scenario.controller
        horizon = getattr(config, "prediction_horizon", None) or 0
        if estimate.controller_seconds > estimate.seconds / 2 and horizon > _REFERENCE_HORIZON:
            field, value = "controller.prediction_horizon", horizon
        else:
            field, value, _ = _steps_field(resolved, estimate)
        raise ConfigError(
            field,
            value,
            f"the run would take about {_duration(estimate.seconds)} (an estimate, for "
            f"{estimate.samples} samples of {_step_ms(config):.3g} ms and "
            f"{estimate.plant_steps} plant steps), over the {MAX_RUN_HOURS:g} h limit; "
            "--yes-long runs it anyway",
        )
    return estimate


def check_campaign_cost(
    seconds_per_run: float, runs: int, workers: int, confirmed: bool = False
) -> None:
    """A campaign of ``runs`` simulations of at most ``seconds_per_run`` each on
    ``workers`` processes: refused beyond MAX_CAMPAIGN_HOURS unless ``confirmed``."""
    total = seconds_per_run * runs / max(workers, 1)
    if confirmed or total <= 3600 * MAX_CAMPAIGN_HOURS:
        return
    raise ConfigError(
        "runs",
        runs,
        f"{runs} simulations of up to {_duration(seconds_per_run)} each on {workers} "
        f"workers would take about {_duration(total)} (an estimate), over the "
        f"{MAX_CAMPAIGN_HOURS:g} h limit; fewer --runs, more --workers, or --yes-long",
    )
