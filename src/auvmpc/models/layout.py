"""Named layouts: which entry of a model's state (or of a force) vector is which quantity.

Code outside a model's own equations reads vectors through a layout (``HORIZONTAL.position``,
``HORIZONTAL.index("psi")``, ``PLANAR_FORCE.index("N")``) rather than by number, so that a model
with another order is one new layout, not edits wherever a number was written.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "DEPTH",
    "DEPTH_PROFILE",
    "HORIZONTAL",
    "HORIZONTAL_COMPONENTS",
    "HORIZONTAL_VELOCITY",
    "OBSTACLE_TRACK",
    "PLANAR_FORCE",
    "PLANAR_FORCE_XY",
    "PLANAR_MOMENT",
    "WORLD_VECTOR",
    "Layout",
]


@dataclass(frozen=True)
class Layout:
    """Names of a vector's entries, in order (units and frames: the model's module)."""

    names: tuple[str, ...]

    @property
    def size(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Where ``name`` sits; a ValueError naming the known names if it does not."""
        if name not in self.names:
            raise ValueError(f"no state {name!r} in {self.names}")
        return self.names.index(name)

    def span(self, first: str, last: str) -> slice:
        """The entries ``first`` .. ``last`` (inclusive) as a slice (a view, not a copy)."""
        return slice(self.index(first), self.index(last) + 1)

    @property
    def position(self) -> slice:
        """World x, y (m)."""
        return self.span("x", "y")

    @property
    def heading(self) -> int:
        """psi (rad), continuous."""
        return self.index("psi")

    @property
    def body_velocity(self) -> slice:
        """Surge and sway u, v (m/s)."""
        return self.span("u", "v")

    @property
    def nu(self) -> slice:
        """Fossen's nu, the body velocities u .. r (m/s, rad/s): u, v, r in the horizontal
        model, u, v, w, p, q, r in the 6-DOF one."""
        return self.span("u", "r")

    def vector(self, values: Any) -> np.ndarray:
        """A per-state vector from a sequence in state order or a mapping by state name
        (names left out are 0)."""
        if isinstance(values, dict):
            unknown = set(values) - set(self.names)
            if unknown:
                raise ValueError(f"unknown state names {sorted(unknown)}; known: {self.names}")
            return np.array([float(values.get(name, 0.0)) for name in self.names])
        vector = np.asarray(values, dtype=float)
        if vector.shape != (self.size,):
            raise ValueError(f"need {self.size} values ({self.names}), got shape {vector.shape}")
        return vector


# The 3-DOF horizontal model (models/vehicle.py): world x, y (m), heading psi (rad), body surge
# u, sway v (m/s), yaw rate r (rad/s).
HORIZONTAL = Layout(names=("x", "y", "psi", "u", "v", "r"))
# Its velocity part [u, v, r]: the state of identification's 3-DOF velocity model.
HORIZONTAL_VELOCITY = Layout(names=HORIZONTAL.names[HORIZONTAL.nu])
# The 1-DOF heave model (models/heave.py): depth z (m, up, negative below the surface), heave
# rate w (m/s, up).
DEPTH = Layout(names=("z", "w"))
# A 3-D reference's depth profile (references.py, DepthProfile): depth below the surface (NED
# z, down, m), its rate (m/s) and acceleration (m/s2).
DEPTH_PROFILE = Layout(names=("z", "z_rate", "z_acceleration"))
# A force and yaw moment in the horizontal plane [X, Y, N] (N, N, N m): a world-frame
# disturbance, a body-frame generalised force, a vehicle's thrust authority.
PLANAR_FORCE = Layout(names=("X", "Y", "N"))
# Its force [X, Y] and its moment N.
PLANAR_FORCE_XY, PLANAR_MOMENT = PLANAR_FORCE.span("X", "Y"), PLANAR_FORCE.index("N")
# A vector in the world frame, NED (x north, y east, z down): a water velocity (m/s).
WORLD_VECTOR = Layout(names=("x", "y", "z"))
# Its horizontal components x, y: what the horizontal plane sees of it.
HORIZONTAL_COMPONENTS = WORLD_VECTOR.span("x", "y")
# A tracked obstacle's constant-velocity state (estimation/ekf.py, ConstantVelocityKalman):
# world position x, y (m) and velocity vx, vy (m/s).
OBSTACLE_TRACK = Layout(names=("x", "y", "vx", "vy"))
