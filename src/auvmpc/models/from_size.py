"""First estimates of a vehicle's model from its size, mass and thrusters (``auvmpc vehicle new``).

Body axes x forward, y starboard, z down; the hull's envelope is ``length`` x ``width`` x
``height`` (m) along them. Fossen's names and signs: added-mass derivatives and damping
coefficients are negative. Every estimate assumes a neutrally buoyant vehicle, so that the
water it displaces weighs its mass, rho V = m.

* **Added mass** of the *equivalent ellipsoid*: the ellipsoid with the envelope's proportions
  and the displaced volume V = m / rho, semi-axes a, b, c (x, y, z). With Lamb's integrals
  (Lamb, "The inertia-coefficients of an ellipsoid moving in fluid", ARC R&M 623, 1918;
  Lamb, *Hydrodynamics*, 1932, sec. 114-115; Imlay, DTMB report 1528, 1961)

      alpha0 = a b c int_0^inf dl / ((a2 + l) D(l)),  D = sqrt((a2 + l)(b2 + l)(c2 + l))

  (beta0, gamma0 likewise with b2, c2; alpha0 + beta0 + gamma0 = 2), in closed form
  alpha0 = 2/3 a b c R_D(b2, c2, a2) with Carlson's symmetric integral R_D, the
  translational k-factors are k = alpha0 / (2 - alpha0) (X_udot = -k_x m, ...) and the
  added moment of inertia about z is

      -N_rdot = m / 5 (a2 - b2)^2 (beta0 - alpha0) / (2 (a2 - b2) + (a2 + b2)(alpha0 - beta0))

  (K_pdot, M_qdot by cyclic permutation). For a prolate spheroid a > b = c these are
  Fossen's k1, k2 and k' times the displaced mass and its I_y (Fossen 2021, sec. 8.4.2,
  MSS ``imlay61.m``); a sphere has k = 1/2 and no added inertia.
* **Rigid-body inertia** of a uniform solid filling the envelope: a box,
  m (L2 + W2) / 12 about z, or an ellipsoid, m (L2 + W2) / 20.
* **Quadratic damping** from form drag, -1/2 rho Cd A on the projected area A across each
  axis. Cd: a box 1.05 on every face (a cube face-on); an ellipsoid by its slenderness
  along the flow, s = extent along / sqrt(product of the two across): 1.17 flat (s -> 0, a
  disk), 0.47 at s = 1 (a sphere), 0.27 at s >= 2 (a 2:1 ellipsoid), linear in between
  (Hoerner, *Fluid-Dynamic Drag*, 1965, at Re ~ 1e5; the NASA Glenn drag-coefficient
  tables). Turning: strips of each face moving sideways at r times their distance from the
  axis, e.g. N_rr = -rho H (Cd_y L^4 + Cd_x W^4) / 64.
* **Linear damping** from skin friction at the top speed U: -1/2 rho C_f S U per axis, with
  the ITTC 1957 line C_f = 0.075 / (log10 Re - 2)^2 at Re = U x (extent along the flow) /
  nu and S the envelope's wetted surface; turning: the same strips, N_r = (Y_v L2 + X_u W2) /
  12. Without a stated top speed U is where the full surge thrust meets this drag.

These are first estimates to start from (factor-of-two values; the BlueROV2's published
sway drag is 3.5 times this box's), meant to be replaced by identified ones.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from pydantic import ValidationError
from scipy.special import elliprd

from auvmpc.errors import ConfigError, format_validation_error
from auvmpc.models.actuators.thruster import planar_direction
from auvmpc.models.vehicle import (
    Thruster,
    VehicleParams,
    VehicleSize,
    allocation_matrix,
    steady_speed,
)

__all__ = [
    "HullShape",
    "SizeEstimate",
    "ellipsoid_added_mass",
    "estimate_vehicle",
    "lamb_integrals",
    "vehicle_file_text",
]

FRESH_WATER_DENSITY = 1000.0  # kg/m3
KINEMATIC_VISCOSITY = 1.0e-6  # m2/s, water at 20 C
GRAVITY = 9.81  # m/s2
# Hoerner 1965 (at Re ~ 1e5), as tabled by NASA Glenn "Shape effects on drag": a cube face-on.
BOX_DRAG_COEFFICIENT = 1.05
# An ellipsoid's Cd by slenderness along the flow: a disk broadside (1.17), a sphere (0.47),
# a 2:1 ellipsoid nose-on (0.27); held beyond 2 (the friction line adds the rest).
ELLIPSOID_DRAG = ((0.0, 1.17), (1.0, 0.47), (2.0, 0.27))
# A net buoyancy of this share of the weight: vehicles are trimmed slightly positive, to
# float up when the power fails.
BUOYANCY_SHARE = 0.005
# The metacentric height BG as a share of the height: the BlueROV2's 4.9 cm of 25 cm.
METACENTRIC_SHARE = 0.2
FALLBACK_TOP_SPEED = 1.0  # m/s, for a layout without surge thrust
# Without a stated thrust rate: the full range in this time, an assumption (electric
# thrusters respond in tens of milliseconds; a slower ramp keeps the command gentle).
RAMP_TIME_S = 1.0


class HullShape(StrEnum):
    """What the envelope looks like: an open-frame ROV or a streamlined hull."""

    BOX = "box"
    ELLIPSOID = "ellipsoid"


def lamb_integrals(a: float, b: float, c: float) -> tuple[float, float, float]:
    """Lamb's alpha0, beta0, gamma0 of an ellipsoid with semi-axes a, b, c (module docstring):
    2/3 a b c R_D with the semi-axis along the motion last. They sum to 2."""
    abc = a * b * c
    a2, b2, c2 = a * a, b * b, c * c
    return (
        2.0 / 3.0 * abc * float(elliprd(b2, c2, a2)),
        2.0 / 3.0 * abc * float(elliprd(c2, a2, b2)),
        2.0 / 3.0 * abc * float(elliprd(a2, b2, c2)),
    )


def _rotational(p: float, q: float, integral_p: float, integral_q: float) -> float:
    """Added inertia per displaced mass (m2) for turning in the plane of semi-axes p, q."""
    difference = p * p - q * q
    if abs(difference) <= 1e-12 * (p * p + q * q):
        return 0.0  # round in that plane: turning moves no water
    denominator = 2.0 * difference + (p * p + q * q) * (integral_p - integral_q)
    return difference**2 * (integral_q - integral_p) / (5.0 * denominator)


def ellipsoid_added_mass(a: float, b: float, c: float, displaced_mass: float) -> np.ndarray:
    """M_A's diagonal [m_x, m_y, m_z, I_x, I_y, I_z] (kg, kg m2, positive) of an ellipsoid
    with semi-axes a, b, c (m) along x, y, z displacing ``displaced_mass`` (kg)."""
    alpha, beta, gamma = lamb_integrals(a, b, c)
    k = [value / (2.0 - value) for value in (alpha, beta, gamma)]
    rotational = [
        _rotational(b, c, beta, gamma),  # about x: the y-z plane
        _rotational(c, a, gamma, alpha),  # about y
        _rotational(a, b, alpha, beta),  # about z
    ]
    return displaced_mass * np.array([*k, *rotational])


def _friction_coefficient(reynolds: float) -> float:
    """ITTC 1957 model-ship correlation line."""
    return 0.075 / (math.log10(max(reynolds, 1.0e3)) - 2.0) ** 2


def _wetted_surface(extent: np.ndarray, shape: HullShape) -> float:
    if shape is HullShape.BOX:
        length, width, height = extent
        return 2.0 * (length * width + length * height + width * height)
    a, b, c = extent / 2.0
    p = 1.6075  # Knud Thomsen's approximation of an ellipsoid's surface, within 1.1 %
    return 4.0 * math.pi * (((a * b) ** p + (a * c) ** p + (b * c) ** p) / 3.0) ** (1.0 / p)


def _drag_coefficients(extent: np.ndarray, shape: HullShape) -> np.ndarray:
    if shape is HullShape.BOX:
        return np.full(3, BOX_DRAG_COEFFICIENT)
    slender = [extent[i] / math.sqrt(np.prod(np.delete(extent, i))) for i in range(3)]
    points, values = zip(*ELLIPSOID_DRAG, strict=True)
    return np.interp(slender, points, values)


def _turning(per_axis: np.ndarray, extent: np.ndarray, quadratic: bool) -> np.ndarray:
    """Roll, pitch and yaw terms from the translational ones by strips (module docstring):
    turning about axis i, the faces normal to j move at r times the distance along k.
    Quadratic: ``per_axis[j]`` is -1/2 rho Cd_j per unit area, and the faces (extent e_i
    along the axis) give per_axis[j] e_i int |x|^3 dx = per_axis[j] e_i e_k^4 / 32.
    Linear: ``per_axis[j]`` is the whole axis's coefficient spread evenly along k, giving
    per_axis[j] e_k^2 / 12."""
    turning = np.zeros(3)
    for i in range(3):
        for j in range(3):
            if j == i:
                continue
            k = 3 - i - j
            if quadratic:
                turning[i] += per_axis[j] * extent[i] * extent[k] ** 4 / 32.0
            else:
                turning[i] += per_axis[j] * extent[k] ** 2 / 12.0
    return turning


@dataclass(frozen=True)
class SizeEstimate:
    """A vehicle estimated from its size: the validated parameters, how each was estimated
    (the top speed used among them), the shape and the water density."""

    params: VehicleParams
    notes: dict[str, str]
    shape: HullShape
    water_density: float


def estimate_vehicle(
    name: str,
    mass: float,
    size: VehicleSize,
    thrusters: Sequence[tuple[float, float, float]],
    thrust_limits: tuple[float, float],
    thrust_rate_limit: float | None,
    *,
    shape: HullShape = HullShape.BOX,
    top_speed: float | None = None,
    vertical_thrusters: Sequence[tuple[float, float]] = (),
    six_dof: bool = False,
    water_density: float = FRESH_WATER_DENSITY,
) -> SizeEstimate:
    """Estimate a vehicle's model from its envelope, mass and thruster layout (module
    docstring for the formulas). ``thrusters``: (x, y, angle_deg) each; ``vertical_thrusters``:
    (x, y) each, pushing up, for a heave section (and with ``six_dof`` a six_dof section);
    ``thrust_rate_limit`` None: the full range in one second, marked estimated.
    Raises ConfigError naming the option at fault."""
    if six_dof and not vertical_thrusters:
        raise ConfigError("--six-dof", True, "needs the vertical thrusters (--vertical-thruster)")
    rho = water_density
    extent = np.array([size.length, size.width, size.height], dtype=float)
    planar = tuple(Thruster(position=(x, y), angle_deg=angle) for x, y, angle in thrusters)
    # The equivalent ellipsoid: the envelope's proportions, the displaced volume m / rho.
    volume = mass / rho
    stretch = (6.0 * volume / (math.pi * float(np.prod(extent)))) ** (1.0 / 3.0)
    semi = stretch * extent / 2.0
    added = ellipsoid_added_mass(*semi, mass)
    # Rigid body: a uniform solid filling the envelope.
    divisor = 12.0 if shape is HullShape.BOX else 20.0
    squares = extent**2
    inertia = (
        mass
        * np.array([squares[1] + squares[2], squares[0] + squares[2], squares[0] + squares[1]])
        / divisor
    )
    # Form drag across each axis.
    cd = _drag_coefficients(extent, shape)
    across = np.array([extent[1] * extent[2], extent[0] * extent[2], extent[0] * extent[1]]) * (
        1.0 if shape is HullShape.BOX else math.pi / 4.0
    )
    quadratic = -0.5 * rho * cd * across
    quadratic_turning = _turning(-0.5 * rho * cd, extent, quadratic=True)
    surface = _wetted_surface(extent, shape)

    def linear_at(speed: float) -> np.ndarray:
        reynolds = speed * extent / KINEMATIC_VISCOSITY
        return np.array(
            [-0.5 * rho * _friction_coefficient(re) * surface * speed for re in reynolds]
        )

    lower, upper = thrust_limits
    rate_given = thrust_rate_limit is not None
    if thrust_rate_limit is None:
        thrust_rate_limit = (upper - lower) / RAMP_TIME_S
    columns = allocation_matrix(planar)
    surge_force = float(np.maximum(columns[0] * upper, columns[0] * lower).sum())
    given = top_speed is not None
    if top_speed is None:
        top_speed = FALLBACK_TOP_SPEED
        if surge_force > 0.0:
            for _ in range(30):  # C_f changes slowly with the speed: a fixed point
                top_speed = steady_speed(
                    float(linear_at(top_speed)[0]), float(quadratic[0]), surge_force
                )
    linear = linear_at(top_speed)
    linear_turning = _turning(linear, extent, quadratic=False)
    data = {
        "name": name,
        "description": f"{mass:g} kg, {size.length:g} x {size.width:g} x {size.height:g} m "
        f"{shape.value}: first estimates from size and mass (auvmpc vehicle new)",
        "source": "auvmpc vehicle new: mass, size and thrusters as given; the rest estimated "
        "(added mass: Lamb 1918 / Imlay 1961 k-factors of the equivalent ellipsoid, Fossen "
        "2021 sec. 8.4.2; drag: Hoerner 1965; skin friction: ITTC 1957)",
        "mass": mass,
        "size": size.model_dump(),
        "m11": mass + added[0],
        "m22": mass + added[1],
        "Iz_rb": inertia[2],
        "Iz_added": added[5],
        "Xu": linear[0], "Xuu": quadratic[0],
        "Yv": linear[1], "Yvv": quadratic[1],
        "Nr": linear_turning[2], "Nrr": quadratic_turning[2],
        "thrusters": [t.model_dump() for t in planar],
        "thrust_limits": thrust_limits,
        "thrust_rate_limit": thrust_rate_limit,
    }  # fmt: skip
    estimated = ["m11", "m22", "Iz_rb", "Iz_added", "Xu", "Xuu", "Yv", "Yvv", "Nr", "Nrr"]
    if not rate_given:
        estimated.append("thrust_rate_limit")
    net_buoyancy = BUOYANCY_SHARE * mass * GRAVITY
    if vertical_thrusters:
        data["heave"] = {
            "m_heave": mass + added[2],
            "Zw": linear[2],
            "Zww": quadratic[2],
            "net_buoyancy_N": net_buoyancy,
            "thruster_count": len(vertical_thrusters),
            "thrust_limits": thrust_limits,
            "thrust_rate_limit": thrust_rate_limit,
        }
        estimated.append("heave")
    if six_dof:
        thrusters_3d = [
            {"position": (x, y, 0.0),
             "direction": planar_direction(a)}
            for x, y, a in thrusters
        ] + [{"position": (x, y, 0.0), "direction": (0.0, 0.0, -1.0)}
             for x, y in vertical_thrusters]  # fmt: skip
        data["six_dof"] = {
            "inertia": tuple(inertia),
            "center_of_gravity": (0.0, 0.0, 0.0),
            "center_of_buoyancy": (0.0, 0.0, -METACENTRIC_SHARE * size.height),
            "displaced_volume": (mass + net_buoyancy / GRAVITY) / rho,
            "water_density": rho,
            "gravity": GRAVITY,
            "added_mass": tuple(-added),
            "linear_damping": (*linear, *linear_turning),
            "quadratic_damping": (*quadratic, *quadratic_turning),
            "thrusters": thrusters_3d,
        }
        estimated.append("six_dof")
    data["estimated"] = estimated
    try:
        params = VehicleParams.model_validate(data)
    except ValidationError as error:
        raise format_validation_error(error, "vehicle") from None
    notes = _notes(shape, cd, top_speed, given, stretch)
    return SizeEstimate(params, notes, shape, rho)


def _notes(
    shape: HullShape, cd: np.ndarray, top_speed: float, given: bool, stretch: float
) -> dict[str, str]:
    ellipsoid = (
        f"equivalent ellipsoid (the envelope's proportions scaled by {stretch:.3f} to the "
        "displaced volume m / rho), Lamb's k-factors"
    )
    solid = f"uniform solid {shape.value} filling the envelope"
    speed = (
        f"the stated top speed {top_speed:.3g} m/s"
        if given
        else f"the top speed {top_speed:.3g} m/s where the full surge thrust meets this drag"
    )
    return {
        "m11": f"m - X_udot; X_udot = -k_x m of the {ellipsoid}",
        "m22": "m - Y_vdot; Y_vdot = -k_y m, the same ellipsoid",
        "Iz_rb": f"{solid}: m (L2 + W2) / {12 if shape is HullShape.BOX else 20}",
        "Iz_added": "-N_rdot of the same ellipsoid (Lamb's rotational coefficient)",
        "Xu": f"skin friction, ITTC 1957 line, wetted surface of the envelope, at {speed}",
        "Xuu": f"form drag -1/2 rho Cd W H, Cd {cd[0]:.3g} ({shape.value}; Hoerner 1965)",
        "Yv": "skin friction as Xu",
        "Yvv": f"form drag -1/2 rho Cd L H, Cd {cd[1]:.3g}",
        "Nr": "(Yv L2 + Xu W2) / 12: the friction spread along the hull",
        "Nrr": "-rho H (Cd_y L^4 + Cd_x W^4) / 64: strips of the sides turning",
        "thrust_rate_limit": f"ASSUMPTION: the full thrust range in {RAMP_TIME_S:g} s",
        "heave": f"m_heave = m - Z_wdot (ellipsoid), Zww form drag on L W (Cd {cd[2]:.3g}), Zw "
        f"skin friction; net buoyancy +{BUOYANCY_SHARE:.1%} of the weight (trimmed to float "
        "up); vertical thrusters as the horizontal ones",
        "six_dof": f"inertia of the {solid}; added mass of the ellipsoid (all six); damping "
        f"as above, roll and pitch by the same strips; centre of buoyancy "
        f"{METACENTRIC_SHARE:g} x height above the centre of gravity",
    }


def _number(value: float) -> str:
    return f"{value:.6g}"


def _flow(value) -> str:
    """A value as flow-style YAML: numbers to 6 significant digits, sequences and mappings
    nested."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{key}: {_flow(item)}" for key, item in value.items()) + "}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_flow(item) for item in value) + "]"
    return _number(float(value))


def _section(name: str, section, note: str, list_note: str = "") -> list[str]:
    """A vehicle file section, its fields in the model's order; a list of mappings (the
    thrusters) one entry per line, after ``list_note``."""
    lines = [f"{name + ':':<20}# ESTIMATES: {note}"]
    for field, value in section.model_dump(exclude_none=True).items():
        if isinstance(value, list | tuple) and value and isinstance(value[0], dict):
            lines.append(f"  {field}:         # {list_note}" if list_note else f"  {field}:")
            lines += [f"    - {_flow(item)}" for item in value]
        else:
            lines.append(f"  {field}: {_flow(value)}")
    return lines


def vehicle_file_text(estimate: SizeEstimate) -> str:
    """The vehicle file (YAML) of an estimate: the presets' keys, each estimated field with a
    comment on how, and the next step named. Loads as-is with ``load_vehicle``."""
    p = estimate.params
    notes = estimate.notes
    size = p.size
    lines = [
        f"# {p.name}: a vehicle file written by `auvmpc vehicle new` from the mass, the size and",
        "# the thruster layout. Every field in `estimated` is a FIRST ESTIMATE from the size",
        "# (formulas and sources: docs/vehicles.md, auvmpc.models.from_size), good to a factor",
        "# of about two. Next step: fit them to logs of the real vehicle with `auvmpc identify`",
        "# (a later feature); until then compare a run with the vehicle and adjust.",
        f"# Water density {estimate.water_density:g} kg/m3; shape {estimate.shape.value}.",
        f"name: {json.dumps(p.name)}",  # a JSON string is a YAML string, quotes escaped
        f"description: {json.dumps(p.description)}",
        f"source: {json.dumps(p.source)}",
        f"estimated: [{', '.join(p.estimated)}]",
        f"mass: {_number(p.mass)}            # kg, given",
        f"size: {{length: {_number(size.length)}, width: {_number(size.width)}, "
        f"height: {_number(size.height)}}}   # m, given",
    ]
    for key in ("m11", "m22", "Iz_rb", "Iz_added", "Xu", "Xuu", "Yv", "Yvv", "Nr", "Nrr"):
        lines.append(f"{key}: {_number(getattr(p, key))}   # {notes[key]}")
    lines.append("thrusters:          # given: position (m), angle (deg from +x towards +y)")
    for thruster in p.thrusters:
        angle = _number(thruster.angle_deg)
        lines.append(f"  - {{position: {_flow(thruster.position)}, angle_deg: {angle}}}")
    lines.append(f"thrust_limits: {_flow(p.thrust_limits)}   # N per thruster, given")
    rate_note = notes["thrust_rate_limit"] if "thrust_rate_limit" in p.estimated else "given"
    lines.append(
        f"thrust_rate_limit: {_number(p.thrust_rate_limit)}   # N/s per thruster, {rate_note}"
    )
    if p.heave is not None:
        lines += _section("heave", p.heave, notes["heave"])
    if p.six_dof is not None:
        in_order = "the horizontal ones first, in order, then the vertical ones"
        lines += _section("six_dof", p.six_dof, notes["six_dof"], in_order)
    return "\n".join(lines) + "\n"
