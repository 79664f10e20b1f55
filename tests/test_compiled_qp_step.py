"""The real-time iteration's QP step compiled to C (solvers/compiled_qp_step.py) against the
same stage functions evaluated by CasADi and solved through CasADi's HPIPM interface: an
independent assembly of the same QP, on vehicles from 2 to 4 thrusters and 15 kg to 1.9 t."""

from __future__ import annotations

import os

import numpy as np
import pytest

import auvmpc.native as native
import auvmpc.solvers.compiled_qp_step as compiled_qp_step
from auvmpc.controllers.base import ObstacleState
from auvmpc.controllers.config import ControllerConfig, ThrustPenalty
from auvmpc.models.vehicle import load_vehicle
from auvmpc.ocp.multiple_shooting import MultipleShootingProgram
from auvmpc.ocp.stage_qp import stage_qp
from auvmpc.solvers.hpipm import hpipm_settings
from auvmpc.solvers.real_time_iteration import RealTimeIteration

pytestmark = pytest.mark.skipif(
    compiled_qp_step.compiler() is None, reason="no C compiler on this machine"
)

# Both solve the same QP to HPIPM's residual tolerance (1e-8) from different formulations of
# the unbounded variables (CasADi boxes them at +-1e4, the driver leaves them free), so their
# steps differ by the interior point's stopping error, relative to the step's size: measured
# up to 1.1e-5 of max |step| over these cases (the predicted states of a 30-step horizon
# amplify the residual); 1e-4 leaves room for other round-off, and is far below what a
# formulation error gives (a wrong sign or transposed block moves the step by O(1)).
SAME_STEP_RTOL = 1e-4

# The compiled step's first pass stops at residuals of 1e-4 (solvers/hpipm.py): on these
# perturbed QPs, warm-started from an unrelated QP's solution, its thrust step was measured
# within 1.4e-2 of the exact one, relative to the step's size.
FAST_STEP_RTOL = 5e-2

CASES = [
    ("jmse2210", ThrustPenalty.ABSOLUTE, 2),
    ("bluerov2-heavy", ThrustPenalty.INCREMENT, 1),
    ("rexrov", ThrustPenalty.ABSOLUTE, 0),  # no obstacle slots: no slack input
    ("videoray-pro3", ThrustPenalty.INCREMENT, 2),
]


def _program(preset: str, penalty: ThrustPenalty, slots: int) -> MultipleShootingProgram:
    config = ControllerConfig(type="nmpc", thrust_penalty=penalty, offset_free=False)
    return MultipleShootingProgram(load_vehicle(preset), config, slots)


def _qp_arguments(program: MultipleShootingProgram, solver, rng: np.random.Generator,
                  effectiveness=None):  # fmt: skip
    """A perturbed iterate (shooting gaps, moved thrusts) near two obstacles, one moving;
    ``effectiveness`` None: every thruster healthy."""
    N, n = program.horizon, program.n_thrusters
    t = program.sample_time * np.arange(N + 1)
    reference = np.zeros((N + 1, 6))
    reference[:, 0], reference[:, 3] = 0.3 * t, 0.3
    state = np.array([0.2, -0.3, 0.1, 0.25, 0.02, -0.01])
    obstacles = (
        ObstacleState(np.array([2.0, 0.4]), 0.5, np.zeros(2)),
        ObstacleState(np.array([4.0, -1.0]), 0.4, np.array([0.0, 0.1])),
    )
    limit = 0.3 * program.ocp.input_upper
    sample = program.sample(
        state, rng.uniform(-limit, limit), reference, np.zeros(3), obstacles, effectiveness
    )
    states = reference + rng.normal(0.0, 0.05, reference.shape)
    states[0] = state
    thrust = rng.uniform(-limit, limit, (N, n))
    previous = np.vstack([sample.previous, thrust])
    used = sample.used.astype(float)
    return (states, previous, thrust, sample.state, sample.previous, sample.reference,
            solver._weights, sample.disturbance, sample.slots, used, solver._movable,
            sample.effectiveness)  # fmt: skip


def _exact_step(program: MultipleShootingProgram) -> compiled_qp_step.CompiledQpStep:
    """The compiled step with its robust pass alone: every QP solved to 1e-8."""
    N, n, slots = program.horizon, program.n_thrusters, program.n_slots
    settings = hpipm_settings(robust_only=True)
    return compiled_qp_step.compiled_qp_step(stage_qp(program), N, n, slots, settings)


@pytest.mark.parametrize(("preset", "penalty", "slots"), CASES)
def test_compiled_step_solves_the_same_qp_as_casadi(preset, penalty, slots):
    program = _program(preset, penalty, slots)
    compiled = _exact_step(program)
    reference = RealTimeIteration(program, compiled=False)
    assert not reference.compiled
    rng = np.random.default_rng(7)
    weak_and_dead = np.ones(program.n_thrusters)
    weak_and_dead[:2] = (0.5, 0.0)
    for effectiveness in (None, None, weak_and_dead):  # the last through the runtime input
        arguments = _qp_arguments(program, reference, rng, effectiveness)
        status, iterations = compiled(*arguments)
        expected_status, _ = reference._step(*arguments)
        assert status == expected_status == 0
        assert iterations > 0
        assert np.abs(reference._step.dv).max() > 0.1, "a step that moves the thrust"
        for ours, theirs in ((compiled.dz, reference._step.dz),
                             (compiled.dv, reference._step.dv)):  # fmt: skip
            scale = np.abs(theirs).max()
            np.testing.assert_allclose(ours, theirs, rtol=0, atol=SAME_STEP_RTOL * scale)


@pytest.mark.parametrize(("preset", "penalty", "slots"), CASES)
def test_the_fast_first_pass_lands_near_the_exact_step(preset, penalty, slots):
    program = _program(preset, penalty, slots)
    fast = RealTimeIteration(program, compiled=True)
    exact = _exact_step(program)
    rng = np.random.default_rng(7)
    for _ in range(3):  # each warm-started from the previous, unrelated, QP's solution
        arguments = _qp_arguments(program, fast, rng)
        assert fast._step(*arguments)[0] == exact(*arguments)[0] == 0
        n = program.n_thrusters
        ours = fast._step.dz[:-1, 6:] + fast._step.dv[:, :n]  # the thrust step dF
        theirs = exact.dz[:-1, 6:] + exact.dv[:, :n]
        scale = np.abs(theirs).max()
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=FAST_STEP_RTOL * scale)


def _step_with(program: MultipleShootingProgram, settings) -> compiled_qp_step.CompiledQpStep:
    N, n, slots = program.horizon, program.n_thrusters, program.n_slots
    return compiled_qp_step.compiled_qp_step(stage_qp(program), N, n, slots, tuple(settings))


# hpipm_settings(): the bound for infinity, the number of passes, then per pass the mode,
# iteration limit, mu0, tolerance, warm start and hot-start limit: the fast pass first.
_GENERAL, _HOT_LIMIT = 2, 5


@pytest.mark.parametrize(("preset", "penalty", "slots"), CASES[:2])
def test_a_hot_try_that_fails_leaves_no_trace(preset, penalty, slots):
    """The driver keeps the previous solution while the hot-started try runs and puts it back
    when the try does not solve: the fast pass then starts where it would have without it,
    and the step is the same to the bit."""
    program = _program(preset, penalty, slots)
    settings = list(hpipm_settings())
    assert settings[_GENERAL + _HOT_LIMIT] == 3, "the fast pass has a hot try"
    settings[_GENERAL + _HOT_LIMIT] = 1  # one iteration from an unrelated QP's solution
    tried, plain = _step_with(program, settings), _step_with(program, settings)
    solver, rng = RealTimeIteration(program, compiled=False), np.random.default_rng(3)
    for _ in range(3):  # each started from the previous, unrelated, QP's solution
        arguments = _qp_arguments(program, solver, rng)
        status, iterations = tried(*arguments, hot_start=True)
        plain_status, plain_iterations = plain(*arguments, hot_start=False)
        assert status == plain_status == 0
        assert iterations == plain_iterations + 1, "the try ran one iteration and failed"
        np.testing.assert_array_equal(tried.dz, plain.dz)
        np.testing.assert_array_equal(tried.dv, plain.dv)


@pytest.mark.parametrize(("preset", "penalty", "slots"), CASES)
def test_the_hot_try_solves_a_repeated_qp_without_iterating(preset, penalty, slots):
    """Hot-started from the solution of the same QP, the try starts inside the fast pass's
    tolerance and needs no iteration (the first solve, warm from zero, took 8-17), and the
    step is the same, within that tolerance."""
    program = _program(preset, penalty, slots)
    solver = RealTimeIteration(program, compiled=True)
    step = solver._step
    arguments = _qp_arguments(program, solver, np.random.default_rng(5))
    assert step(*arguments, hot_start=True)[0] == 0
    first = step.dz.copy(), step.dv.copy()
    assert step(*arguments, hot_start=True) == (0, 0)
    for again, before in zip((step.dz, step.dv), first, strict=True):
        scale = np.abs(before).max()
        np.testing.assert_allclose(again, before, rtol=0, atol=FAST_STEP_RTOL * scale)


def test_non_finite_iterate_is_refused_before_the_solver():
    program = _program("jmse2210", ThrustPenalty.ABSOLUTE, 1)
    solver = RealTimeIteration(program, compiled=True)
    arguments = list(_qp_arguments(program, solver, np.random.default_rng(1)))
    arguments[0] = arguments[0].copy()
    arguments[0][5, 3] = np.nan
    assert solver._step(*arguments) == (-1, 0)


def test_library_is_built_once_and_then_loaded(tmp_path, monkeypatch):
    monkeypatch.setenv("AUVMPC_CACHE_DIR", str(tmp_path))
    program = _program("bluerov2-heavy", ThrustPenalty.ABSOLUTE, 1)
    assert RealTimeIteration(program).compiled
    built = list(tmp_path.glob("rti-*.so"))
    assert len(built) == 1

    def no_compiler(*args, **kwargs):
        raise AssertionError("compiled again")

    monkeypatch.setattr(compiled_qp_step.subprocess, "run", no_compiler)
    assert RealTimeIteration(program).compiled
    assert list(tmp_path.glob("*")) == built, "no partial or second file left behind"


def test_without_a_compiler_the_casadi_step_is_used(monkeypatch):
    program = _program("jmse2210", ThrustPenalty.ABSOLUTE, 1)
    monkeypatch.setattr(native, "compiler", lambda: None)
    assert not RealTimeIteration(program).compiled
    with pytest.raises(RuntimeError, match="no C compiler"):
        RealTimeIteration(program, compiled=True)


def test_jit_off_keeps_the_casadi_step():
    config = ControllerConfig(type="nmpc", jit=False, offset_free=False)
    program = MultipleShootingProgram(load_vehicle("jmse2210"), config, 1)
    assert not RealTimeIteration(program).compiled


def test_an_unwritable_cache_folder_falls_back_to_the_temporary_folder(tmp_path, monkeypatch):
    blocked = tmp_path / "not-a-folder"
    blocked.write_text("a file where the cache folder would be")
    monkeypatch.setenv("AUVMPC_CACHE_DIR", str(blocked))
    (tmp_path / "tmp").mkdir()
    monkeypatch.setattr(compiled_qp_step.tempfile, "tempdir", str(tmp_path / "tmp"))
    program = _program("jmse2210", ThrustPenalty.INCREMENT, 1)
    assert RealTimeIteration(program).compiled
    assert blocked.read_text() == "a file where the cache folder would be"
    assert len(list((tmp_path / "tmp").glob("auvmpc-*/rti-*.so"))) == 1


def test_the_cache_keeps_the_most_recently_used_libraries(tmp_path, monkeypatch):
    monkeypatch.setenv("AUVMPC_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(native, "_CACHE_LIMIT", 2)
    old = [tmp_path / f"rti-{i:024x}.so" for i in range(3)]  # named as auvmpc names them
    for age, library in enumerate(old):
        library.write_bytes(b"")
        os.utime(library, (1e9 + age, 1e9 + age))
    mine = tmp_path / "notes.txt"
    mine.write_text("not auvmpc's")
    assert RealTimeIteration(_program("jmse2210", ThrustPenalty.ABSOLUTE, 1)).compiled
    kept = sorted(p.name for p in tmp_path.glob("rti-*.so"))
    assert len(kept) == 2 and old[2].name in kept, "the newest old one and the new one"
    assert mine.read_text() == "not auvmpc's"


def test_a_run_without_a_compiler_says_it_took_the_slower_path(monkeypatch):
    from auvmpc.api import load_scenario, simulate

    monkeypatch.setattr(native, "compiler", lambda: None)
    every_move_free = {"duration": 5.0, "controller.control_horizon": 30}
    run = simulate(load_scenario("paper-ideal", every_move_free, controller="nmpc"))
    assert any("no C compiler" in warning for warning in run.warnings)
    assert run.metrics["fallback_steps"] == 0


def test_cache_pruning_deletes_only_libraries_auvmpc_named(tmp_path):
    """Beyond the cache limit the least recently used libraries go; a user's file that
    merely starts like one (kind-something.so) stays."""
    import auvmpc.native as native

    user = tmp_path / "rti-mine.so"
    user.write_text("not ours")
    ours = [tmp_path / f"rti-{i:024x}.so" for i in range(native._CACHE_LIMIT + 3)]
    for age, path in enumerate(ours):
        path.write_text("")
        os.utime(path, (age, age))
    native._prune(tmp_path, "rti")
    assert user.exists()
    assert sum(path.exists() for path in ours) == native._CACHE_LIMIT
    assert not ours[0].exists()  # the oldest went


def test_the_stage_qp_thrust_columns_scale_exactly_with_effectiveness():
    """Effectiveness is a runtime input of the stage QP: B's thrust columns (and the
    obstacle rows' D, through them) are the healthy ones times each thruster's
    effectiveness, evaluated at the thrust that acts."""
    program = _program("jmse2210", ThrustPenalty.ABSOLUTE, 1)
    qp, n = stage_qp(program), program.n_thrusters
    rng = np.random.default_rng(2)
    X, X_next = rng.normal(0.0, 0.3, 6), rng.normal(0.0, 0.3, 6)
    P, F = rng.uniform(-5.0, 5.0, n), rng.uniform(-5.0, 5.0, n)
    common = (X, X_next, P, P, F, np.zeros(6), np.ones(6), np.zeros(3), np.zeros((5, 1)),
              np.zeros(1), 1.0, 1.0)  # fmt: skip
    effectiveness = np.array([1.0, 0.5, 0.0, 1.0])[:n]
    _, B, *_ = qp.stage(*common, effectiveness)
    # The healthy Jacobian at the thrust that acts, e * F, times e: the chain rule, exactly.
    acting = qp.stage(*common[:4], effectiveness * F, *common[5:], np.ones(n))
    expected = np.asarray(acting[1])[:6, :n] * effectiveness
    np.testing.assert_array_equal(np.asarray(B)[:6, :n], expected)
    assert not np.asarray(B)[:6, 2].any(), "a dead thruster moves nothing"
    assert np.asarray(B)[:6, 1].any() and np.asarray(B)[:6, 3].any()
