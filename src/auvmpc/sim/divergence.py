"""Why a simulated plant blew up: the likely scenario field, checked in a fixed order.

A run whose plant state stops being finite ends ``lost`` (experiments/run.py); its reason
names the first of these that holds, each checked once:

1. ``initial_state``: a start speed over ``FAST_FACTOR`` times the plant's steady top speed
   in that axis (the damping at that speed is too stiff for the plant's RK4 step);
2. ``disturbance.water_current``: a current faster than the plant's steady top speed (the
   thrusters cannot hold the vehicle against it, and the relative speed it drags through
   the damping is one the step was not chosen for);
3. ``disturbance.current_force_world``: a force larger than the thrusters' authority in
   the horizontal plane;
4. ``plant.max_step``: a step the scenario gives that is longer than the one RK4 is stable
   at for this plant (:func:`auvmpc.models.vehicle.stable_plant_step`);
5. otherwise the plant vehicle itself (damping, inertia, thrust limits).
"""

from __future__ import annotations

import math

import numpy as np

from auvmpc.models.layout import (
    HORIZONTAL,
    HORIZONTAL_COMPONENTS,
    HORIZONTAL_VELOCITY,
    PLANAR_FORCE_XY,
)

__all__ = ["FAST_FACTOR", "likely_cause"]

# A start speed this many times the steady top speed is beyond anything the vehicle reaches.
FAST_FACTOR = 3.0


def likely_cause(resolved) -> str:
    """The likely cause of a blown-up plant in ``resolved`` (module docstring), one phrase
    naming the field."""
    scenario = resolved.scenario
    plant = getattr(resolved, "plant", None)
    if (
        plant is None
        or not hasattr(plant, "thrust_authority")
        or not hasattr(scenario, "initial_state")
    ):
        return "the plant vehicle or plant.max_step (check its damping, inertia and limits)"
    from auvmpc.models.vehicle import stable_plant_step, steady_speed

    tops = [
        steady_speed(linear, quadratic, float(force))
        for linear, quadratic, force in zip(
            (plant.Xu, plant.Yv, plant.Nr),
            (plant.Xuu, plant.Yvv, plant.Nrr),
            plant.thrust_authority,
            strict=True,
        )
    ]
    state = np.asarray(scenario.initial_state, dtype=float)
    start = [state[HORIZONTAL.index(name)] for name in HORIZONTAL_VELOCITY.names]
    for name, value, top in zip(HORIZONTAL_VELOCITY.names, start, tops, strict=True):
        if abs(value) > FAST_FACTOR * top:
            return (
                f"initial_state: a start {name} of {value:g}, over {FAST_FACTOR:g} x the "
                f"{plant.name}'s steady top {name} {top:.3g} (its damping there is too stiff "
                "for the plant step)"
            )
    disturbance = getattr(scenario, "disturbance", None)
    current = getattr(disturbance, "water_current", None)
    if current is not None:
        speed = math.hypot(*current.velocity_m_per_s[HORIZONTAL_COMPONENTS])
        surge, sway = (tops[HORIZONTAL_VELOCITY.index(name)] for name in ("u", "v"))
        if speed > min(surge, sway):
            return (
                f"disturbance.water_current: {speed:.3g} m/s, faster than the {plant.name}'s "
                f"steady top speed ({surge:.3g} m/s surge, {sway:.3g} m/s sway): the "
                "thrusters cannot hold it"
            )
    force = getattr(disturbance, "current_force_world", None)
    if force is not None:
        magnitude = math.hypot(*force)
        authority = float(min(plant.thrust_authority[PLANAR_FORCE_XY]))
        if magnitude > authority:
            return (
                f"disturbance.current_force_world: {magnitude:.3g} N, more than the "
                f"{plant.name}'s thrust authority ({authority:.3g} N)"
            )
    given = getattr(getattr(resolved, "given", None), "plant", None)
    step = scenario.plant.max_step
    if given is not None and given.max_step is not None:
        stable = stable_plant_step(plant, step)
        if step > stable * (1.0 + 1e-9):
            return (
                f"plant.max_step: {step:g} s, longer than the {stable:.3g} s RK4 is stable at "
                f"for the {plant.name} at the speeds its thrust reaches"
            )
    return (
        f"the plant vehicle {plant.name} (damping, inertia, thrust limits) at the plant step "
        f"{step:g} s: none of initial_state, the disturbance or plant.max_step is out of range"
    )
