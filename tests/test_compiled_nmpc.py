"""The compiled nmpc is its C controller (controllers/compiled_nmpc.py): held sample for sample to
the Python NonlinearMpc of the same configuration (the same estimator, SQP steps and retries,
warm start and shell), through a failure window, a thruster told dead and a spinning start;
and where the C does not cover a configuration, nmpc stays the Python controller."""

from __future__ import annotations

import numpy as np
import pytest

from auvmpc.controllers import compiled_nmpc
from auvmpc.controllers.base import ControlStatus, Observation
from auvmpc.controllers.compiled_nmpc import CompiledNmpc, runs_in_c
from auvmpc.controllers.nmpc import NonlinearMpc
from auvmpc.controllers.shell import PLAN_FALLBACK_STEPS
from auvmpc.environment.obstacles import visible_obstacles
from auvmpc.experiments.run import make_controller
from auvmpc.references import make_reference
from auvmpc.scenario import load_scenario

_NMPC = ["controller.type=nmpc", "controller.control_horizon=null"]  # every move free


def _covered(name: str, *overrides: str) -> bool:
    resolved = load_scenario(name, [*_NMPC, *overrides])
    return runs_in_c(resolved.model, resolved.scenario.controller.for_vehicle(resolved.model))


pytestmark = pytest.mark.skipif(
    not _covered("paper-ideal"),
    reason="no C compiler or no HPIPM in the casadi wheel: nmpc is the Python controller",
)

# Beside the disc, spinning at 3 rad/s (tests/test_export_c.py's recovering start), with the
# estimator: every part of the C runs. 20 samples are 10 s.
_OVERRIDES = [
    *_NMPC,
    "initial_state=[0.0, -12.0, 1.57, 0.0, 0.0, 3.0]",
    "controller.offset_free=true",
]
_STEPS = 40
# No reference over these samples (a planner's glitch): each step fails (non-finite data are
# never solved), the shell follows the plan, then its feedback (which cannot steer towards NaN:
# it holds the command).
_BLIND = range(12, 17)
_DEAD_FROM, _DEAD = 25, 2  # the third thruster is told dead from this sample on


def _controllers(monkeypatch):
    resolved = load_scenario("paper-obstacles", _OVERRIDES)
    scenario, model = resolved.scenario, resolved.model
    compiled = make_controller(scenario, model)
    monkeypatch.setattr(compiled_nmpc, "runs_in_c", lambda model, config: False)
    python = make_controller(scenario, model)
    return resolved, compiled, python


def test_the_c_controller_is_the_python_one_sample_for_sample(monkeypatch):
    """Same commands to the bit, same statuses, same estimate, on a loop closed through the
    model's own RK4 step (the plant need not be auvmpc's for the two to agree)."""
    resolved, compiled, python = _controllers(monkeypatch)
    assert isinstance(compiled, CompiledNmpc) and isinstance(python, NonlinearMpc)
    scenario, model = resolved.scenario, resolved.model
    reference = make_reference(scenario.reference)
    obstacles = visible_obstacles(scenario.obstacles, 0.0)  # fixed discs
    state = np.array(scenario.initial_state, dtype=float)
    thrust = np.zeros(model.n_thrusters)
    for controller in (compiled, python):
        controller.reset(state, thrust)
    Te, N = compiled.sample_time, compiled.preview_steps
    effectiveness = np.ones(model.n_thrusters)
    statuses = []
    for k in range(_STEPS):
        t = k * Te
        if k == _DEAD_FROM:
            effectiveness[_DEAD] = 0.0
        preview = reference.states(t + Te * np.arange(N + 1))
        if k in _BLIND:
            preview = np.full_like(preview, np.nan)
        observation = Observation(
            k, t, state, preview, obstacles, effectiveness=effectiveness.copy()
        )
        c, p = compiled.compute(observation), python.compute(observation)
        np.testing.assert_array_equal(c.thrust, p.thrust, err_msg=f"sample {k}")
        assert c.status == p.status, f"sample {k}"
        assert _same_but_timing_and_iterations(c.info, p.info), f"sample {k}"
        statuses.append(c.status)
        state = np.asarray(
            compiled.program.numeric_step(state, c.thrust, np.zeros(3), effectiveness)
        ).ravel()
    assert statuses[0] is ControlStatus.RECOVERY  # the spinning start
    blind = [statuses[k] for k in _BLIND]
    assert blind[:PLAN_FALLBACK_STEPS] == [ControlStatus.FALLBACK] * PLAN_FALLBACK_STEPS
    assert set(blind[PLAN_FALLBACK_STEPS:]) == {ControlStatus.RECOVERY}
    assert statuses[-1] is not ControlStatus.FALLBACK  # the optimiser is back


def _same_but_timing_and_iterations(c: dict, p: dict) -> bool:
    """The info entries agree except the solve time and the iteration count (the C counts
    every try's QP iterations, the Python the last try's)."""
    skip = {"solve_ms", "solver_iterations"}
    return c.keys() == p.keys() and all(c[key] == p[key] for key in c.keys() - skip)


@pytest.mark.parametrize(
    "override",
    [
        "controller.control_horizon=5",  # move blocking: condensed
        "controller.nmpc_mode=full",  # IPOPT
        "controller.solver_time_limit_ms=100",  # the C has no clock
        "controller.jit=false",
    ],
)
def test_what_the_c_does_not_cover_stays_the_python_controller(override):
    assert not _covered("paper-ideal", override)
