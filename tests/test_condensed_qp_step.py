"""The real-time iteration's QP condensed (solvers/condensed_qp_step.py) against the same stage
QP kept sparse and solved by HPIPM through CasADi: two ways to the one QP's solution."""

from __future__ import annotations

import numpy as np
import pytest

import auvmpc.solvers.condensed_qp_step as condensed_qp_step
from auvmpc.solvers.real_time_iteration import RealTimeIteration
from tests.test_compiled_qp_step import CASES, _program, _qp_arguments

# The condensed QP is solved by DAQP (an active set, exact to round-off), the sparse one by
# an interior point to residuals of 1e-8. Measured: the steps agree within 3.7e-6 of
# max |step| (the 1.9 t rexrov; 3e-9 to 2e-6 on the others); 2e-5 leaves room for round-off
# on other machines and is far below what a formulation error gives (a wrong sign or a
# missed block moves the step by O(1)).
SAME_STEP_RTOL = 2e-5


@pytest.mark.parametrize(("preset", "penalty", "slots"), CASES)
def test_the_condensed_step_solves_the_same_qp_as_the_sparse_one(
    preset, penalty, slots, monkeypatch
):
    """Without the damping the condensed step adds to its Hessian (a Levenberg-Marquardt term
    on the step, which moved it by up to 2e-3 of its size here), both solve the very same
    QP."""
    monkeypatch.setattr(condensed_qp_step, "_RELATIVE_REGULARISATION", 0.0)
    monkeypatch.setattr(condensed_qp_step, "_HESSIAN_REGULARISATION", 0.0)
    program = _program(preset, penalty, slots)
    sparse = RealTimeIteration(program, compiled=False)
    condensed = RealTimeIteration(program, condensed=True)
    rng = np.random.default_rng(11)
    for _ in range(3):
        arguments = _qp_arguments(program, sparse, rng)
        assert sparse._step(*arguments)[0] == condensed._step(*arguments)[0] == 0
        assert np.abs(sparse._step.dv).max() > 0.1, "a step that moves the thrust"
        for ours, theirs in ((condensed._step.dz, sparse._step.dz),
                             (condensed._step.dv, sparse._step.dv)):  # fmt: skip
            scale = np.abs(theirs).max()
            np.testing.assert_allclose(ours, theirs, rtol=0, atol=SAME_STEP_RTOL * scale)
