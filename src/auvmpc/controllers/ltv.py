"""LTV-MPC: the RK4 model linearised along the previous solution shifted one step.

The paper freezes the state-dependent matrices at the current state, so over its
15 s look-ahead the predicted heading never turns. Here the nonlinear RK4 model
is rolled out from the measured state under the previous plan's thrusts
(shifted one sample), and linearised at every point of that rollout with exact
CasADi Jacobians, so the prediction follows the turn.
"""

from __future__ import annotations

from typing import Literal

import casadi as ca
import numpy as np

from auvmpc.controllers.base import FLOAT_BYTES, MemoryNeed
from auvmpc.controllers.config import (
    ControllerType,
    OptimisingControllerConfig,
    PlanLinearisation,
    QpStructure,
    Relinearisation,
    TightenedConstraints,
    type_field,
)
from auvmpc.controllers.mpc import _TRUST_REGION_SCALE, NX, AffinePrediction, LinearMpc
from auvmpc.models.discrete import horizontal_model
from auvmpc.models.layout import PLANAR_FORCE
from auvmpc.models.vehicle import VehicleParams
from auvmpc.solvers.sparse_qp import SparseIncrementalQp

__all__ = ["LtvMpc", "LtvMpcConfig", "linearised_rollout"]


def linearised_rollout(
    model: VehicleParams, sample_time: float, substeps: int, horizon: int, jit: bool = False
) -> ca.Function:
    """CasADi function (x0 (nx), F (n, ny), d (nd, ny)) -> (X (nx, ny), A (nx, nx ny), B (nx,
    n ny)), nx = HORIZONTAL.size, nd = PLANAR_FORCE.size (the world force and moment).

    X[:, i] is the state after step i of the rollout; A_i, B_i are the Jacobians of the
    one-sample RK4 map at (X_{i-1}, F_i) (models/discrete.py builds them once per vehicle).
    """
    return horizontal_model(model, sample_time, substeps, jit).linearised_rollout(horizon)


_SPARSE_SETUP_BYTES_PER_ENTRY = 6 * FLOAT_BYTES


class LtvMpcConfig(
    TightenedConstraints, PlanLinearisation, Relinearisation, OptimisingControllerConfig
):
    """``ltv-mpc``: the optimising controllers' knobs, the SQP's and the tightening."""

    type: Literal[ControllerType.LTV_MPC] = type_field(ControllerType.LTV_MPC)


class LtvMpc(LinearMpc):
    """Condensed MPC on the model linearised along the shifted previous solution."""

    @classmethod
    def memory_need(cls, config, n_inputs: int, n_states: int) -> MemoryNeed:
        """The larger of the condensed QP's arrays and, where the sparse form may be chosen,
        the sparse QP's set-up (solvers/sparse_qp.py): H and A assembled dense with their
        masks and the copies CasADi takes of them."""
        condensed = super().memory_need(config, n_inputs, n_states)
        if config.qp_structure is QpStructure.CONDENSED:
            return condensed
        ny, moves = config.prediction_horizon, len(config.move_schedule()) * n_inputs
        stage = n_states + n_inputs  # [dX_k; p_k]
        columns = (ny + 1) * stage + ny + moves  # + one slack per step, the moves
        rows = ny * (stage + 1) + moves
        # Measured (/usr/bin/time -f %M, paper-ideal, qp_structure sparse): peak 0.20 GB at
        # ny = 30, 1.19 GB at 300, 4.07 GB at 600: 44-45 bytes per entry of H and A.
        n_bytes = _SPARSE_SETUP_BYTES_PER_ENTRY * (columns * columns + rows * columns)
        if n_bytes <= condensed.n_bytes:
            return condensed
        what = f"setting up the sparse QP of {config.type} with ny={ny}"
        return MemoryNeed("controller.prediction_horizon", ny, n_bytes, what)

    def __init__(self, model: VehicleParams, config: LtvMpcConfig) -> None:
        super().__init__(model, config)
        config = self.config  # with what the vehicle decides filled in
        self.trust_region_weights = config.trust_region_weight * _TRUST_REGION_SCALE
        if config.qp_structure is not QpStructure.CONDENSED:
            self.sparse_qp = SparseIncrementalQp(self.ocp, config.qp_iteration_limit)
            self.sparse_only = config.qp_structure is QpStructure.SPARSE
        sampled = horizontal_model(model, config.sample_time, config.model_substeps, config.jit)
        self._sampled = sampled
        self._rollout = sampled.linearised_rollout(config.prediction_horizon)
        self._steps = sampled.linearised_nodes(config.prediction_horizon)

    def prediction_model(
        self, state: np.ndarray, nominal_input: np.ndarray, disturbance: np.ndarray
    ) -> AffinePrediction:
        """Linearised at the plan's predicted states (multiple-shooting nodes) when there is a
        plan, else along a rollout from the measured state.

        A rollout of an open-loop-unstable vehicle runs away over the 15 s horizon (measured:
        BlueROV2 literature parameters on a lawnmower, 195-213 of 300 steps fell back with a
        rollout); the plan's own states stay near the path, and each step's linearisation is
        local. The offsets c_n make the affine model exact at every node.
        """
        ny, n = self.horizon, self.model.n_thrusters
        forces = np.tile(np.reshape(disturbance, (PLANAR_FORCE.size, 1)), (1, ny))
        nodes = self.linearisation_nodes
        rollout, steps = self._rollout, self._steps
        if self.tightening is not None:  # the same, with the Jacobians in the disturbance
            rollout = self._sampled.disturbed_linearised_rollout(ny)
            steps = self._sampled.disturbed_linearised_nodes(ny)
        if nodes is None:
            successors, jac_x, jac_u, *jac_d = rollout(
                state, nominal_input.T, forces, self.effectiveness
            )
            successors = np.asarray(successors).T  # (ny, NX)
            nodes = np.vstack([state, successors[:-1]])
        else:
            nodes = np.vstack([state, nodes[1:ny]])
            successors, jac_x, jac_u, *jac_d = steps(
                nodes.T, nominal_input.T, forces, self.effectiveness
            )
            successors = np.asarray(successors).T
        A = np.asarray(jac_x).reshape(NX, ny, NX).transpose(1, 0, 2)
        B = np.asarray(jac_u).reshape(NX, ny, n).transpose(1, 0, 2)
        c = (
            successors
            - np.einsum("nij,nj->ni", A, nodes)
            - np.einsum("nij,nj->ni", B, nominal_input)
        )
        nominal = np.vstack([nodes, successors[-1:]])  # (ny + 1, NX)
        G = None
        if jac_d:
            G = np.asarray(jac_d[0]).reshape(NX, ny, PLANAR_FORCE.size).transpose(1, 0, 2)
        return AffinePrediction(A=A, B=B, c=c, nominal=nominal, G=G)
