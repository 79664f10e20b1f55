"""The sampled horizontal model and its compiled functions, built once per vehicle.

Every controller and estimator that predicts with the 3-DOF model needs the same few CasADi
functions of the RK4 map over one sample, under a world-frame force and moment ``d``:
its value, its Jacobians, the augmented map of the offset-free estimator, and rollouts over a
horizon. :func:`horizontal_model` builds them once per (vehicle, sample time, substeps) in a
process, so a campaign that runs many scenarios of one vehicle compiles them once.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import casadi as ca
import numpy as np

from auvmpc.codegen import compiled
from auvmpc.models.integrators import rk4
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.vehicle import VehicleParams, body_from_world, dynamics
from auvmpc.native import native_function

__all__ = ["DiscreteModel", "horizontal_model"]


# The world-frame force X, Y (N) and moment N (N m) that the offset-free estimator estimates.
DISTURBANCE_NAMES = ("X", "Y", "N")


def world_disturbance_dynamics(model: VehicleParams):
    """x' = f(x, F, d_world): the model with a world-frame force and moment added."""

    def f(state, thrust, disturbance_world):
        d_u, d_v = body_from_world(disturbance_world, state[HORIZONTAL.heading])
        return dynamics(state, thrust, model, (d_u, d_v, disturbance_world[2]))

    return f


class DiscreteModel:
    """The RK4 map over one sample and what is built from it (module docstring)."""

    layout = HORIZONTAL

    def __init__(self, model: VehicleParams, sample_time: float, substeps: int, jit: bool) -> None:
        nx, nd = self.layout.size, len(DISTURBANCE_NAMES)
        self.sample_time, self.substeps = sample_time, substeps
        self.n_inputs = model.n_thrusters
        state, thrust = ca.SX.sym("x", nx), ca.SX.sym("F", self.n_inputs)
        force = ca.SX.sym("d", nd)
        f = world_disturbance_dynamics(model)
        following = rk4(lambda x, u: f(x, u, force), state, thrust, sample_time, substeps)
        self.step = ca.Function("rk4_step", [state, thrust, force], [following])
        # The step on NumPy values, for evaluations outside a solver (the shift of a warm
        # start, once per sample): compiled and called through ctypes where jit allows, since
        # a CasADi call from Python costs ~35 us (auvmpc.native).
        native = native_function(self.step) if jit else None
        self.numeric_step: Callable[..., np.ndarray] = (
            native if native is not None else _flat(self.step)
        )
        linearised = ca.Function(
            "rk4_step_linearised",
            [state, thrust, force],
            [following, ca.jacobian(following, state), ca.jacobian(following, thrust)],
        )
        self.linearised_step = compiled(linearised) if jit else linearised
        self._symbols = (state, thrust, force, following)
        self._jit = jit
        # The estimator's map of [x; d] (d a random walk) and its Jacobian.
        augmented = ca.vertcat(state, force)
        next_augmented = ca.vertcat(following, force)
        self.augmented_step = ca.Function(
            "observer_step",
            [augmented, thrust],
            [next_augmented, ca.jacobian(next_augmented, augmented)],
        )

    @functools.cached_property
    def disturbed_linearised_step(self) -> ca.Function:
        """The linearised step plus the Jacobian in d, for the robust back-offs
        (ocp/tightening.py); built on first use, so nominal controllers compile nothing more."""
        state, thrust, force, following = self._symbols
        disturbed = ca.Function(
            "rk4_step_linearised_disturbed",
            [state, thrust, force],
            [
                following,
                ca.jacobian(following, state),
                ca.jacobian(following, thrust),
                ca.jacobian(following, force),
            ],
        )
        return compiled(disturbed) if self._jit else disturbed

    @functools.cache  # noqa: B019 -- one per horizon; the model itself lives for the process
    def rollout(self, horizon: int) -> ca.Function:
        """(x0, F (n, N), d (3, N)) -> states 1..N (6, N)."""
        return self.step.mapaccum("rk4_rollout", horizon)

    @functools.cache  # noqa: B019
    def linearised_rollout(self, horizon: int) -> ca.Function:
        """(x0, F (n, N), d (3, N)) -> (X (6, N), A (6, 6N), B (6, nN)) along a rollout."""
        return self.linearised_step.mapaccum("rollout", horizon)

    @functools.cache  # noqa: B019
    def linearised_nodes(self, horizon: int) -> ca.Function:
        """(X (6, N), F (n, N), d (3, N)) -> successors and Jacobians at N given nodes."""
        return self.linearised_step.map(horizon)

    @functools.cache  # noqa: B019
    def disturbed_linearised_rollout(self, horizon: int) -> ca.Function:
        """As linearised_rollout, plus G (6, 3N): the Jacobians in d."""
        return self.disturbed_linearised_step.mapaccum("disturbed_rollout", horizon)

    @functools.cache  # noqa: B019
    def disturbed_linearised_nodes(self, horizon: int) -> ca.Function:
        """As linearised_nodes, plus G (6, 3N): the Jacobians in d."""
        return self.disturbed_linearised_step.map(horizon)


def _flat(function: ca.Function) -> Callable[..., np.ndarray]:
    """``function``'s single output as a flat NumPy array."""
    return lambda *inputs: np.asarray(function(*inputs)).ravel()


@functools.lru_cache(maxsize=32)
def _cached(model_json: str, sample_time: float, substeps: int, jit: bool) -> DiscreteModel:
    return DiscreteModel(VehicleParams.model_validate_json(model_json), sample_time, substeps, jit)


def horizontal_model(
    model: VehicleParams, sample_time: float, substeps: int, jit: bool = True
) -> DiscreteModel:
    """The sampled model of ``model``, built once per process for these settings."""
    return _cached(model.model_dump_json(), float(sample_time), int(substeps), bool(jit))
