"""An identification manoeuvre: multisine forces in surge, sway and yaw, as thrusts.

Each axis gets its own harmonics of one base frequency (surge every third from the first,
sway from the second, yaw from the third), so the three forces are orthogonal over a
period and every axis is excited over the whole band at once (orthogonal multisines,
Morelli 2003; Pintelon and Schoukens 2012, ch. 3). Phases are random from the seed; the
band's top is where the thrust rate limit still lets a full-amplitude sine through, at most
a quarter of the sampling frequency. The forces are mapped to thrusts by the minimum-norm
allocation ``F = T_pinv tau``, scaled into the thrust limits, faded in and out, then each
sample is clipped into the thrust and rate limits (so a table is always feasible).

The vehicle stays in a box of water by the amplitude alone: the forces are zero-mean and
the amplitude is reduced until the nominal model, simulated open loop, stays within
``box_m`` of its start (no feedback: it would correlate the input with the noise).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from auvmpc.errors import ConfigError
from auvmpc.models.integrators import rk4
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.vehicle import (
    VehicleParams,
    dynamics,
    load_vehicle,
    preset_names,
    stable_plant_step,
)
from auvmpc.scenario.model import DEFAULT_PLANT_STEP_S
from auvmpc.sim.plant import substeps_for

__all__ = [
    "Excitation",
    "design_excitation",
    "excitation_scenario",
    "simulate_open_loop",
    "write_excitation",
]

# Share of the thrust limits the multisine's peak may take before the fade and the clip.
PEAK_SHARE = 0.9
# Fade-in and fade-out (s): a raised cosine, so the table starts and ends at zero thrust.
FADE_S = 5.0
# Each try that leaves the box shrinks the amplitude by this factor.
SHRINK = 0.8
MAX_TRIES = 12
RATE_REACH = 2.0
MIN_HARMONICS = 3
# A manoeuvre lasts at least this many fade times (fade in, excite, fade out).
MIN_DURATION_FACTOR = 4


@dataclass(frozen=True)
class Excitation:
    """A thrust table and what it does to the nominal vehicle."""

    sample_time: float  # s
    thrust: np.ndarray  # (N, n) N, row k applied over [k Te, (k+1) Te)
    frequencies_hz: tuple[np.ndarray, np.ndarray, np.ndarray]  # per axis (surge, sway, yaw)
    amplitude_share: float  # of the thrust limits the peak takes (before the clip)
    excursion_m: float  # the nominal model's largest distance from its start
    peak_speeds: np.ndarray  # (3,) largest |u|, |v| (m/s), |r| (rad/s) of the nominal model


def _multisine(t: np.ndarray, frequencies: np.ndarray, phases: np.ndarray) -> np.ndarray:
    signal = np.sin(2.0 * math.pi * frequencies[None, :] * t[:, None] + phases[None, :]).sum(1)
    peak = np.max(np.abs(signal))
    return signal / peak if peak > 0 else signal


def _fade(t: np.ndarray, duration: float) -> np.ndarray:
    fade = min(FADE_S, duration / 4.0)
    window = np.ones_like(t)
    rising, falling = t < fade, t > duration - fade
    window[rising] = 0.5 - 0.5 * np.cos(math.pi * t[rising] / fade)
    window[falling] = 0.5 - 0.5 * np.cos(math.pi * (duration - t[falling]) / fade)
    return window


def _clip_to_limits(thrust: np.ndarray, vehicle: VehicleParams, sample_time: float):
    limits = vehicle.actuators.limits
    clipped = np.empty_like(thrust)
    previous = np.zeros(thrust.shape[1])
    for k, wanted in enumerate(thrust):
        previous, _ = limits.project(wanted, previous, sample_time)
        clipped[k] = previous
    return clipped


def simulate_open_loop(
    vehicle: VehicleParams, thrust: np.ndarray, sample_time: float, current_world=None
) -> np.ndarray:
    """The 3-DOF model's states (N+1, 6) from rest at the origin under ``thrust`` (N, n),
    each row held over its sample (RK4 at the plant's stable step), in a constant
    ``current_world`` (2,: m/s) if given."""
    substeps = substeps_for(sample_time, stable_plant_step(vehicle, DEFAULT_PLANT_STEP_S))
    states = np.zeros((len(thrust) + 1, HORIZONTAL.size))
    for k, row in enumerate(thrust):
        states[k + 1] = rk4(
            lambda x, u: dynamics(x, u, vehicle, current_world=current_world),
            states[k], row, sample_time, substeps,
        )  # fmt: skip
    return states


def design_excitation(
    vehicle: VehicleParams,
    duration: float,
    sample_time: float = 0.1,
    seed: int = 0,
    box_m: float = 15.0,
    period_s: float = 60.0,
) -> Excitation:
    """The thrust table of an identification manoeuvre (module docstring).

    Parameters
    ----------
    vehicle : the nominal vehicle (allocation, thrust and rate limits, model for the box)
    duration : s; the table has round(duration / sample_time) rows
    sample_time : s, how long each row is held
    seed : the phases' random generator seed
    box_m : the nominal model must stay within this distance of its start (m)
    period_s : the multisine's shortest base period (s); longer where the rate limit leaves
        too few harmonics below the top of the band
    """
    if not (duration > 0 and sample_time > 0 and box_m > 0 and period_s > 0):
        raise ValueError("duration, sample_time, box_m and period_s must be > 0")
    steps = round(duration / sample_time)
    t = sample_time * np.arange(steps)
    rng = np.random.default_rng(seed)
    low, high = vehicle.thrust_limits
    reach = PEAK_SHARE * min(-low, high) if low < 0 < high else PEAK_SHARE * (high - low) / 2
    # The highest frequency a sine of amplitude ``reach`` can follow under the rate limit.
    # A multisine's components share the peak, so the band may reach RATE_REACH times
    # further; the base period grows until each axis has MIN_HARMONICS of its own.
    top = min(RATE_REACH * vehicle.thrust_rate_limit / (2.0 * math.pi * reach), 0.25 / sample_time)
    period = max(period_s, 3 * MIN_HARMONICS / top)
    harmonics = np.arange(1, math.floor(top * period + 1e-9) + 1)
    base = 1.0 / period
    frequencies = tuple(base * harmonics[axis::3] for axis in range(3))
    forces = np.column_stack(
        [_multisine(t, f, rng.uniform(0.0, 2.0 * math.pi, f.size)) for f in frequencies]
    )
    # Each axis to unit authority, then all thrusts scaled so that the peak fits the limits.
    thrust_shape = forces * vehicle.thrust_authority[None, :] @ vehicle.T_pinv.T
    peak = np.max(np.abs(thrust_shape))
    # The fade ends on the last row, so the table ends at zero thrust.
    thrust_shape = thrust_shape / peak * _fade(t, t[-1])[:, None] if peak > 0 else thrust_shape
    share = 1.0
    for _ in range(MAX_TRIES):
        thrust = _clip_to_limits(share * reach * thrust_shape, vehicle, sample_time)
        states = simulate_open_loop(vehicle, thrust, sample_time)
        excursion = float(np.max(np.hypot(states[:, 0], states[:, 1])))
        if excursion <= box_m:
            break
        share *= SHRINK
    return Excitation(
        sample_time=sample_time,
        thrust=thrust,
        frequencies_hz=frequencies,
        amplitude_share=share * PEAK_SHARE,
        excursion_m=excursion,
        peak_speeds=np.max(np.abs(states[:, 3:]), axis=0),
    )


def excitation_scenario(
    vehicle: str, excitation: Excitation, table: str, name: str, box_m: float
) -> dict:
    """The scenario (a mapping to write as YAML) that plays ``excitation`` from the thrust
    table file ``table`` (relative to the scenario's folder) on ``vehicle`` (a preset name
    or a vehicle file path as the scenario should name it). The reference only marks the
    start, where the position error metrics measure the excursion from."""
    steps = len(excitation.thrust)
    te = excitation.sample_time
    return {
        "name": name,
        "description": (
            f"identification manoeuvre (auvmpc excite): orthogonal multisine forces, "
            f"{excitation.amplitude_share:.0%} of the thrust limits at peak, open loop; the "
            f"nominal model stays within {excitation.excursion_m:.1f} m of the start "
            f"(box {box_m:g} m)"
        ),
        "duration": round(steps * te, 9),
        "vehicle": vehicle,
        "reference": {"type": "waypoints", "points": [[0.0, 0.0], [0.1, 0.0]], "speed": 0.1},
        "initial_state": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        "controller": {
            "type": "thrust-playback",
            "sample_time": te,
            "playback": {"path": table},
        },
        "seed": 0,
    }


def write_excitation(
    vehicle: str,
    out: Path,
    duration: float,
    seed: int = 0,
    sample_time: float = 0.1,
    box_m: float = 15.0,
    overwrite: bool = False,
) -> Excitation:
    """``auvmpc excite``: the scenario ``out`` (YAML) and its thrust table beside it (same
    stem, ``.csv``) for ``vehicle`` (a preset name or a vehicle file)."""
    from auvmpc.controllers.playback import write_thrust_table

    out = Path(out)
    if out.suffix not in (".yaml", ".yml"):
        raise ConfigError("--out", str(out), "the scenario file must end in .yaml or .yml")
    table = out.with_suffix(".csv")
    for path in (out, table):
        if path.exists() and not overwrite:
            raise ConfigError("--out", str(path), "exists; pass --overwrite to replace it")
    for name, value in (("--duration", duration), ("--sample-time", sample_time),
                        ("--box", box_m)):  # fmt: skip
        if not (math.isfinite(value) and value > 0):
            raise ConfigError(name, value, "must be a finite number > 0")
    if duration < MIN_DURATION_FACTOR * FADE_S:
        raise ConfigError(
            "--duration", duration, f"too short: at least {MIN_DURATION_FACTOR * FADE_S:g} s"
        )
    params = load_vehicle(vehicle, "VEHICLE")
    excitation = design_excitation(params, duration, sample_time, seed, box_m)
    named = vehicle
    if vehicle not in preset_names():  # a file: named from the scenario's folder
        named = os.path.relpath(Path(vehicle).resolve(), out.resolve().parent)
    scenario = excitation_scenario(named, excitation, table.name, out.stem, box_m)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_thrust_table(table, sample_time, excitation.thrust, params.actuators.layout.names)
    out.write_text(
        f"# auvmpc excite {vehicle} --duration {duration:g} --seed {seed}: thrusts in "
        f"{table.name}\n" + yaml.safe_dump(scenario, sort_keys=False, default_flow_style=None)
    )
    return excitation
