"""An identification manoeuvre: multisine forces on the excited axes, as thrusts.

The axes are those of one model (:class:`Dof`): surge, sway and yaw on the horizontal
thrusters (the 3-DOF model), or heave on the vertical ones (the heave model). Each axis gets
its own harmonics of one base frequency (with three axes: surge every third from the
first, sway from the second, yaw from the third), so the forces are orthogonal over a
period and every axis is excited over the whole band at once (orthogonal multisines,
Morelli 2003; Pintelon and Schoukens 2012, ch. 3). Phases are random from the seed; the
band's top is where the thrust rate limit still lets a full-amplitude sine through, at most
a quarter of the sampling frequency. The forces are mapped to thrusts by the minimum-norm
allocation (``F = T_pinv tau``; heave: an equal share per vertical thruster), scaled into
the thrust limits around the trim (the thrust that holds the nominal vehicle still: zero,
or in heave the nominal net buoyancy's opposite), faded in and out, then each sample is
clipped into the thrust and rate limits (so a table is always feasible).

The vehicle stays in a box of water by the amplitude alone: the forces are zero-mean about
the trim and the amplitude is reduced until the nominal model, simulated open loop, stays
within ``box_m`` of its start (horizontal distance, or depth change; no feedback: it would
correlate the input with the noise).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np
import yaml

from auvmpc.errors import ConfigError
from auvmpc.models.actuators import ActuatorSet
from auvmpc.models.heave import heave_plant_step
from auvmpc.models.integrators import rk4
from auvmpc.models.layout import DEPTH, HORIZONTAL
from auvmpc.models.vehicle import (
    VehicleParams,
    dynamics,
    load_vehicle,
    preset_names,
    stable_plant_step,
)
from auvmpc.scenario.depth import DepthPlantConfig
from auvmpc.scenario.model import DEFAULT_PLANT_STEP_S
from auvmpc.sim.plant import substeps_for

__all__ = [
    "Dof",
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
# A heave manoeuvre's scenario starts this far below the surface beyond its box (m).
DEPTH_MARGIN_M = 1.0
# A 6-DOF manoeuvre keeps the nominal vehicle's roll and pitch within this (rad).
MAX_TILT_RAD = math.radians(20.0)


class Dof(StrEnum):
    """The degrees of freedom a manoeuvre excites (``auvmpc excite --dof``)."""

    HORIZONTAL = "horizontal"  # surge, sway, yaw on the horizontal thrusters: the 3-DOF model
    HEAVE = "heave"  # heave on the heave section's vertical thrusters: the depth model
    # all six on every six_dof thruster: the 6-DOF model (roll and pitch beside the above)
    SIX_DOF = "six-dof"


@dataclass(frozen=True)
class Excitation:
    """A thrust table and what it does to the nominal vehicle."""

    sample_time: float  # s
    thrust: np.ndarray  # (N, n) N, row k applied over [k Te, (k+1) Te)
    frequencies_hz: tuple[np.ndarray, ...]  # per axis (surge, sway, yaw; or heave)
    amplitude_share: float  # of the thrust limits the peak takes (before the clip)
    excursion_m: float  # the nominal model's largest distance (or depth change) from its start
    peak_speeds: np.ndarray  # largest |u|, |v| (m/s), |r| (rad/s); or |w| (m/s): nominal model
    dof: Dof = Dof.HORIZONTAL


@dataclass(frozen=True)
class _Axes:
    """What the design needs of the degrees of freedom it excites (:func:`_axes`)."""

    actuators: ActuatorSet  # the thrusters the table drives
    authority: np.ndarray  # (a,) each axis's force scale (N, N m)
    to_thrust: np.ndarray  # (n, a) the minimum-norm allocation of the axes' forces
    trim: np.ndarray  # (n,) the thrust that holds the nominal vehicle still
    # thrust table (N, n), sample time -> the nominal model's largest excursion from its
    # start (m) and its largest speeds
    motion: Callable[[np.ndarray, float], tuple[float, np.ndarray]]


def _axes(vehicle: VehicleParams, dof: Dof) -> _Axes:
    if dof is Dof.HORIZONTAL:

        def planar(thrust: np.ndarray, sample_time: float) -> tuple[float, np.ndarray]:
            states = simulate_open_loop(vehicle, thrust, sample_time)
            peak = np.max(np.abs(states[:, HORIZONTAL.nu]), axis=0)
            x, y = states[:, HORIZONTAL.index("x")], states[:, HORIZONTAL.index("y")]
            return float(np.max(np.hypot(x, y))), peak

        n = vehicle.n_thrusters
        return _Axes(vehicle.actuators, vehicle.thrust_authority, vehicle.T_pinv, np.zeros(n),
                     planar)  # fmt: skip
    if dof is Dof.SIX_DOF:
        return _six_dof_axes(vehicle)
    heave = vehicle.heave
    if heave is None:
        raise ConfigError("VEHICLE", vehicle.name, "has no heave section: nothing to excite")
    n = heave.thruster_count

    def vertical(thrust: np.ndarray, sample_time: float) -> tuple[float, np.ndarray]:
        states = simulate_heave_open_loop(vehicle, thrust, sample_time)
        depth, rate = states[:, DEPTH.index("z")], states[:, DEPTH.span("w", "w")]
        return float(np.max(np.abs(depth))), np.max(np.abs(rate), axis=0)

    return _Axes(
        heave.actuators,
        np.array([n * heave.thrust_limits[1]]),
        np.full((n, 1), 1.0 / n),  # the pseudo-inverse of the heave row [1 ... 1]
        np.full(n, -heave.net_buoyancy_N / n),
        vertical,
    )


def _six_dof_axes(vehicle: VehicleParams) -> _Axes:
    """Surge, sway, heave, roll, pitch and yaw on every ``six_dof`` thruster (the minimum-norm
    allocation ``pinv(T)``; an axis the thrusters cannot push, e.g. jmse2210's pitch, gets no
    force), about the trim that holds the nominal vehicle's net buoyancy and moments at rest
    level. The box is the 6-DOF model's distance from its start."""
    from auvmpc.models.actuators import WRENCH
    from auvmpc.models.six_dof import (
        BODY_VELOCITY,
        SIX_DOF,
        PitchSingularity,
        integrate,
        plant_step_length,
        restoring_forces,
        six_dof_model,
    )

    six = vehicle.six_dof
    if six is None or vehicle.heave is None:
        raise ConfigError(
            "VEHICLE", vehicle.name, "needs six_dof and heave sections for a 6-DOF manoeuvre"
        )
    T = np.asarray(six.T)
    limits = vehicle.six_dof_actuators.limits
    authority = np.maximum(T * limits.upper, T * limits.lower).sum(axis=1)
    # Roll and pitch get at most the moment that holds a static tilt of MAX_TILT_RAD against
    # the righting moment (the thrusters could capsize a vehicle a few centimetres stable).
    righting = (
        six.center_of_gravity[2] * six.weight(vehicle.mass)
        - six.center_of_buoyancy[2] * six.buoyancy
    )
    tilting = WRENCH.span("K", "M")
    authority[tilting] = np.minimum(authority[tilting], righting * math.sin(MAX_TILT_RAD))
    to_thrust = np.linalg.pinv(T)
    # Zero for an axis no thruster pushes: the pseudo-inverse maps nothing to it.
    to_thrust[:, authority <= 1e-9 * np.max(authority)] = 0.0
    g0 = np.asarray(
        restoring_forces(six.weight(vehicle.mass), six.buoyancy, six.center_of_gravity,
                         six.center_of_buoyancy, 0.0, 0.0),
    ).ravel()  # fmt: skip
    model = six_dof_model(vehicle)
    step = plant_step_length(vehicle, DEFAULT_PLANT_STEP_S)

    def motion(thrust: np.ndarray, sample_time: float) -> tuple[float, np.ndarray]:
        substeps = substeps_for(sample_time, step)
        states = np.zeros((len(thrust) + 1, SIX_DOF.size))
        velocities = SIX_DOF.nu
        try:
            for k, row in enumerate(thrust):
                states[k + 1] = integrate(model, states[k], row, sample_time, substeps)
        except PitchSingularity:
            return math.inf, np.full(BODY_VELOCITY.size, math.inf)
        tilt = float(np.max(np.abs(states[:, SIX_DOF.span("phi", "theta")])))
        distance = float(np.max(np.linalg.norm(states[:, SIX_DOF.span("x", "z")], axis=1)))
        # a tilt beyond MAX_TILT_RAD counts as leaving the box: the amplitude shrinks
        peak = np.max(np.abs(states[:, velocities]), 0)
        return (distance if tilt <= MAX_TILT_RAD else math.inf), peak

    return _Axes(vehicle.six_dof_actuators, authority, to_thrust, to_thrust @ g0, motion)


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


def _clip_to_limits(thrust: np.ndarray, actuators: ActuatorSet, sample_time: float):
    limits = actuators.limits
    clipped = np.empty_like(thrust)
    previous = np.zeros(thrust.shape[1])
    for k, wanted in enumerate(thrust):
        previous, _ = limits.project(wanted, previous, sample_time)
        clipped[k] = previous
    return clipped


def simulate_open_loop(
    vehicle: VehicleParams, thrust: np.ndarray, sample_time: float, current_world=None
) -> np.ndarray:
    """The 3-DOF model's states [x, y, psi, u, v, r] (N+1, HORIZONTAL.size) from rest at the
    origin under ``thrust`` (N, n), each row held over its sample (RK4 at the plant's stable
    step), in a constant horizontal ``current_world`` [x, y] (m/s) if given."""
    substeps = substeps_for(sample_time, stable_plant_step(vehicle, DEFAULT_PLANT_STEP_S))
    states = np.zeros((len(thrust) + 1, HORIZONTAL.size))
    for k, row in enumerate(thrust):
        states[k + 1] = rk4(
            lambda x, u: dynamics(x, u, vehicle, current_world=current_world),
            states[k], row, sample_time, substeps,
        )  # fmt: skip
    return states


def simulate_heave_open_loop(
    vehicle: VehicleParams, thrust: np.ndarray, sample_time: float
) -> np.ndarray:
    """The heave model's states ``[z, w]`` (N+1, DEPTH.size) from rest at z = 0 (its start) under
    the vertical ``thrust`` (N, n), as the depth plant steps them in calm water."""
    substeps = substeps_for(sample_time, DepthPlantConfig().max_step)
    states = np.zeros((len(thrust) + 1, DEPTH.size))
    for k, row in enumerate(thrust):
        states[k + 1] = heave_plant_step(
            vehicle.heave, states[k], row, k * sample_time, sample_time, substeps, _calm
        )
    return states


def _calm(z: float, t: float) -> float:
    return 0.0


def design_excitation(
    vehicle: VehicleParams,
    duration: float,
    sample_time: float = 0.1,
    seed: int = 0,
    box_m: float = 15.0,
    period_s: float = 60.0,
    dof: Dof = Dof.HORIZONTAL,
) -> Excitation:
    """The thrust table of an identification manoeuvre (module docstring).

    Parameters
    ----------
    vehicle : the nominal vehicle (allocation, thrust and rate limits, model for the box)
    duration : s; the table has round(duration / sample_time) rows
    sample_time : s, how long each row is held
    seed : the phases' random generator seed
    box_m : the nominal model must stay within this distance of its start (m; in heave, this
        change of depth)
    period_s : the multisine's shortest base period (s); longer where the rate limit leaves
        too few harmonics below the top of the band
    dof : the axes to excite: the horizontal thrusters' (table columns F1..Fn) or the
        vertical ones' (Fz1..Fzn)
    """
    if not (duration > 0 and sample_time > 0 and box_m > 0 and period_s > 0):
        raise ValueError("duration, sample_time, box_m and period_s must be > 0")
    axes = _axes(vehicle, Dof(dof))
    count = len(axes.authority)
    steps = round(duration / sample_time)
    t = sample_time * np.arange(steps)
    rng = np.random.default_rng(seed)
    limits = axes.actuators.limits
    low, high = float(np.max(limits.lower)), float(np.min(limits.upper))
    span = min(-low, high) if low < 0 < high else (high - low) / 2
    # The multisine swings about the trim (zero, or what holds the net buoyancy).
    reach = PEAK_SHARE * span - float(np.max(np.abs(axes.trim)))
    if reach <= 0:
        raise ConfigError(
            "VEHICLE", vehicle.name, "its trim takes the thrust limits: no thrust left to excite"
        )
    # The highest frequency a sine of amplitude ``reach`` can follow under the rate limit.
    # A multisine's components share the peak, so the band may reach RATE_REACH times
    # further; the base period grows until each axis has MIN_HARMONICS of its own.
    rate = float(np.min(limits.rate))
    top = min(RATE_REACH * rate / (2.0 * math.pi * reach), 0.25 / sample_time)
    period = max(period_s, count * MIN_HARMONICS / top)
    harmonics = np.arange(1, math.floor(top * period + 1e-9) + 1)
    base = 1.0 / period
    frequencies = tuple(base * harmonics[axis::count] for axis in range(count))
    forces = np.column_stack(
        [_multisine(t, f, rng.uniform(0.0, 2.0 * math.pi, f.size)) for f in frequencies]
    )
    # Each axis to unit authority, then all thrusts scaled so that the peak fits the limits.
    thrust_shape = forces * axes.authority[None, :] @ axes.to_thrust.T
    peak = np.max(np.abs(thrust_shape))
    # The fade ends on the last row, so the table ends at zero thrust.
    fade = _fade(t, t[-1])[:, None]
    thrust_shape = thrust_shape / peak * fade if peak > 0 else thrust_shape
    share = 1.0
    for _ in range(MAX_TRIES):
        wanted = fade * axes.trim[None, :] + share * reach * thrust_shape
        thrust = _clip_to_limits(wanted, axes.actuators, sample_time)
        excursion, peak_speeds = axes.motion(thrust, sample_time)
        if excursion <= box_m:
            break
        share *= SHRINK
    return Excitation(
        sample_time=sample_time,
        thrust=thrust,
        frequencies_hz=frequencies,
        amplitude_share=share * reach / span,
        excursion_m=excursion,
        peak_speeds=peak_speeds,
        dof=Dof(dof),
    )


def excitation_scenario(
    vehicle: str, excitation: Excitation, table: str, name: str, box_m: float
) -> dict:
    """The scenario (a mapping to write as YAML) that plays ``excitation`` from the thrust
    table file ``table`` (relative to the scenario's folder) on ``vehicle`` (a preset name
    or a vehicle file path as the scenario should name it). The reference only marks the
    start, where the position error metrics measure the excursion from.

    A heave manoeuvre is a depth scenario (``kind: depth``): the vehicle starts at rest
    :data:`DEPTH_MARGIN_M` below the box of depth, in water as deep again below it, the
    pressure sensor sampling every row; the reference holds the start depth. A 6-DOF one is
    a 6-DOF scenario (``kind: six-dof``) whose thrust-playback drives every ``six_dof``
    thruster (no depth channel: controllers/channels.py's ``EveryThruster``), from rest as
    deep below the surface; its reference marks the start and holds the start depth."""
    steps = len(excitation.thrust)
    te = excitation.sample_time
    heave = excitation.dof is Dof.HEAVE
    kind = {Dof.HEAVE: {"kind": "depth"}, Dof.SIX_DOF: {"kind": "six-dof"}}
    scenario = {
        **kind.get(excitation.dof, {}),
        "name": name,
        "description": (
            f"identification manoeuvre (auvmpc excite): orthogonal multisine forces, "
            f"{excitation.amplitude_share:.0%} of the thrust limits at peak, open loop; the "
            f"nominal model stays within {excitation.excursion_m:.1f} m "
            f"{'of depth' if heave else 'of the start'} (box {box_m:g} m)"
        ),
        "duration": round(steps * te, 9),
        "vehicle": vehicle,
    }
    if heave:
        start = -(box_m + DEPTH_MARGIN_M)
        scenario |= {
            "tank": {"depth_m": round(2.0 * (box_m + DEPTH_MARGIN_M), 9)},
            "sensor": {"rate_hz": round(1.0 / te, 9)},
            "reference": {"initial_depth_m": start, "final_depth_m": start, "step_time_s": 0.0},
        }
    else:
        scenario |= {
            "reference": {"type": "waypoints", "points": [[0.0, 0.0], [0.1, 0.0]], "speed": 0.1},
            "initial_state": [0.0] * HORIZONTAL.size,  # at rest at the origin
        }
    if excitation.dof is Dof.SIX_DOF:
        start_depth = box_m + DEPTH_MARGIN_M
        scenario["reference"] = scenario["reference"] | {"depth": {"start_m": start_depth}}
        scenario |= {
            "initial_depth_m": start_depth,
            "water_depth_m": round(2.0 * start_depth, 9),
        }
    controller = {"type": "thrust-playback", "sample_time": te, "playback": {"path": table}}
    return scenario | {"controller": controller, "seed": 0}


def write_excitation(
    vehicle: str,
    out: Path,
    duration: float,
    seed: int = 0,
    sample_time: float = 0.1,
    box_m: float = 15.0,
    overwrite: bool = False,
    dof: Dof = Dof.HORIZONTAL,
) -> Excitation:
    """``auvmpc excite``: the scenario ``out`` (YAML) and its thrust table beside it (same
    stem, ``.csv``) for ``vehicle`` (a preset name or a vehicle file), exciting ``dof``."""
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
    excitation = design_excitation(params, duration, sample_time, seed, box_m, dof=dof)
    named = vehicle
    if vehicle not in preset_names():  # a file: named from the scenario's folder
        named = os.path.relpath(Path(vehicle).resolve(), out.resolve().parent)
    scenario = excitation_scenario(named, excitation, table.name, out.stem, box_m)
    out.parent.mkdir(parents=True, exist_ok=True)
    inputs = _axes(params, excitation.dof).actuators.layout.names
    write_thrust_table(table, sample_time, excitation.thrust, inputs)
    out.write_text(
        f"# auvmpc excite {vehicle} --dof {excitation.dof} --duration {duration:g} --seed "
        f"{seed}: thrusts in {table.name}\n"
        + yaml.safe_dump(scenario, sort_keys=False, default_flow_style=None)
    )
    return excitation
