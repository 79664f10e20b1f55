"""The sampled horizontal model and its compiled functions, built once per vehicle.

Every controller and estimator that predicts with the 3-DOF model needs the same few CasADi
functions of the RK4 map over one sample, under a world-frame force and moment ``d`` and the
thrusters' runtime effectiveness ``e`` (n,; 1 healthy, 0 dead: each thruster's share of its
command that acts, ``ActuatorSet.force``), the last input of every function here:
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
        self.n_inputs = n = model.n_thrusters
        # The map is written in the thrust that acts, a = e * F (ActuatorSet.force's A (e * u)
        # for the linear thrusters every prediction model has), and each function below is
        # that map evaluated at a = e * F, its thrust Jacobian's columns times e (the chain
        # rule). Differentiated in a, not through e * F, the healthy vehicle's functions do
        # the operations they did before effectiveness was an input, so e = 1 gives the same
        # numbers to the bit (a derivative taken through e * F is rounded differently).
        state, acting, force = ca.SX.sym("x", nx), ca.SX.sym("a", n), ca.SX.sym("d", nd)
        thrust, effectiveness = ca.SX.sym("F", n), ca.SX.sym("e", n)
        f = world_disturbance_dynamics(model)
        following = rk4(lambda x, u: f(x, u, force), state, acting, sample_time, substeps)
        self._acting = (state, acting, force, following)
        self._commanded = (state, thrust, force, effectiveness)
        # (x, a, d) -> x_next: the map in the thrust that acts, for what differentiates it
        # itself (the stage QP) and composes it with a = e * F.
        self.acting_step = ca.Function("rk4_step_acting", [state, acting, force], [following])
        self.step = self._in_commands("rk4_step", [following])
        self._jit = jit
        # The estimator's map of [x; d] (d a random walk) and its Jacobian.
        augmented = ca.vertcat(state, force)
        next_augmented = ca.vertcat(following, force)
        healthy = ca.Function(
            "observer_step_acting",
            [augmented, acting],
            [next_augmented, ca.jacobian(next_augmented, augmented)],
        )
        estimate = ca.SX.sym("z", nx + nd)
        self.augmented_step = ca.Function(
            "observer_step",
            [estimate, thrust, effectiveness],
            healthy.call([estimate, thrust * effectiveness]),
        )

    def _in_commands(self, name: str, outputs: list, thrust_jacobian: int | None = None):
        """``outputs`` (expressions in the acting thrust) as a function of (x, F, d, e): at
        a = e * F, output ``thrust_jacobian`` (a Jacobian in a) times e column by column."""
        state, acting, force, _ = self._acting
        healthy = ca.Function(name + "_acting", [state, acting, force], outputs)
        x, thrust, d, effectiveness = self._commanded
        values = healthy.call([x, thrust * effectiveness, d])
        if thrust_jacobian is not None:
            columns = values[thrust_jacobian]
            values[thrust_jacobian] = columns * ca.repmat(effectiveness.T, columns.size1(), 1)
        return ca.Function(name, [x, thrust, d, effectiveness], values)

    # Compiled on first use (each is a run of the C compiler): a controller that evaluates
    # none of them (the C controller, which has its own) compiles nothing here.
    @functools.cached_property
    def numeric_step(self) -> Callable[..., np.ndarray]:
        """The step on NumPy values, for evaluations outside a solver (the shift of a warm
        start, once per sample): compiled and called through ctypes where jit allows, since
        a CasADi call from Python costs ~35 us (auvmpc.native)."""
        native = native_function(self.step) if self._jit else None
        return native if native is not None else _flat(self.step)

    @functools.cached_property
    def linearised_step(self) -> ca.Function:
        """(x, F, d, e) -> (x_next, A, B): the step with its Jacobians in x and F."""
        state, acting, _, following = self._acting
        jacobians = [ca.jacobian(following, state), ca.jacobian(following, acting)]
        linearised = self._in_commands("rk4_step_linearised", [following, *jacobians], 2)
        return compiled(linearised) if self._jit else linearised

    @functools.cached_property
    def disturbed_linearised_step(self) -> ca.Function:
        """The linearised step plus the Jacobian in d, for the robust back-offs
        (ocp/tightening.py); built on first use, so nominal controllers compile nothing more."""
        state, acting, force, following = self._acting
        jacobians = [ca.jacobian(following, x) for x in (state, acting, force)]
        disturbed = self._in_commands("rk4_step_linearised_disturbed", [following, *jacobians], 2)
        return compiled(disturbed) if self._jit else disturbed

    @functools.cache  # noqa: B019 -- one per horizon; the model itself lives for the process
    def rollout(self, horizon: int) -> ca.Function:
        """(x0, F (n, N), d (3, N), e (n,)) -> states 1..N (6, N)."""
        return self.step.mapaccum("rk4_rollout", horizon)

    @functools.cache  # noqa: B019
    def linearised_rollout(self, horizon: int) -> ca.Function:
        """(x0, F (n, N), d (3, N), e (n,)) -> (X (6, N), A (6, 6N), B (6, nN)) along a
        rollout."""
        return self.linearised_step.mapaccum("rollout", horizon)

    @functools.cache  # noqa: B019
    def linearised_nodes(self, horizon: int) -> ca.Function:
        """(X (6, N), F (n, N), d (3, N), e (n,)) -> successors and Jacobians at N given
        nodes."""
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
