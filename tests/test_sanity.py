"""Physical sanity checks before a run (issue 12, item 4) and run provenance (item 5).

The top speed is checked against analytic truth (thrust equals drag) and against the
plant simulated at full thrust; the warnings against scenarios built to trigger them, on
both vehicles; the paper scenarios must pass without a word."""

from __future__ import annotations

import itertools
import json
import math
import re
from datetime import datetime

import numpy as np
import pytest

from auvmpc.errors import ConfigError
from auvmpc.experiments.run import simulate
from auvmpc.models.vehicle import dynamics
from auvmpc.scenario import load_scenario
from auvmpc.scenario.sanity import (
    check_memory,
    feasible_forces,
    largest_surge_thrust,
    preflight,
    reference_thrust_needs,
    steady_top_speed,
)
from tests.conftest import ROUND_OFF_TOL
from tests.test_cli import run_cli


def test_top_speed_is_where_full_thrust_equals_drag_jmse(jmse):
    # four thrusters at +-45 deg, 15 N each: 4 * 15 cos 45 deg of surge force
    force = 4 * 15.0 * math.cos(math.radians(45))
    a, b = -jmse.Xuu, -jmse.Xu
    expected = (-b + math.sqrt(b * b + 4 * a * force)) / (2 * a)
    assert steady_top_speed(jmse) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("vehicle", ["jmse", "bluerov"])
def test_top_speed_is_a_steady_state_at_the_largest_pure_surge_thrust(vehicle, request):
    """Thrust equals drag there (all accelerations zero), and no other thrusts within the
    limits push harder straight ahead: checked against every vertex of the feasible set
    (n - 2 thrusters at a limit, the other two solving zero sway force and yaw moment),
    an enumeration independent of the linear program."""
    params = request.getfixturevalue(vehicle)
    thrust = largest_surge_thrust(params)
    speed = steady_top_speed(params)
    derivative = dynamics(np.array([0, 0, 0, speed, 0, 0]), thrust, params)
    assert np.allclose(derivative[3:], 0.0, atol=ROUND_OFF_TOL * 100)
    best = _largest_surge_by_vertices(params)
    assert params.T[0] @ thrust == pytest.approx(best, rel=1e-9)


def _largest_surge_by_vertices(params) -> float:
    T, n = params.T, params.n_thrusters
    low, high = params.thrust_limits
    best = -math.inf
    for free in itertools.combinations(range(n), 2):
        fixed = [i for i in range(n) if i not in free]
        for values in itertools.product((low, high), repeat=len(fixed)):
            thrust = np.zeros(n)
            thrust[fixed] = values
            block = T[1:][:, free]
            if abs(np.linalg.det(block)) < 1e-12:
                continue
            thrust[list(free)] = np.linalg.solve(block, -T[1:][:, fixed] @ np.array(values))
            if np.all(thrust >= low - 1e-9) and np.all(thrust <= high + 1e-9):
                best = max(best, float(T[0] @ thrust))
    return best


@pytest.mark.parametrize("vehicle", ["jmse", "bluerov"])
def test_thrust_needs_move_the_model_along_a_circle(vehicle, request):
    """Inverse dynamics round trip: the force the check computes for a steady circle,
    allocated to thrusters, gives zero body accelerations in the model."""
    params = request.getfixturevalue(vehicle)
    speed, radius = 0.5, 8.0
    state = np.array([radius, 0, math.pi / 2, speed, 0, speed / radius])
    tau = reference_thrust_needs(params, np.tile(state, (5, 1)), 0.5)
    derivative = dynamics(state, params.T_pinv @ tau[2], params)
    assert np.allclose(derivative[3:], 0.0, atol=ROUND_OFF_TOL * 100)


@pytest.mark.parametrize("vehicle", ["jmse2210", "bluerov2-heavy"])
@pytest.mark.parametrize("name", ["paper-ideal", "paper-disturbed", "paper-obstacles"])
def test_the_paper_scenarios_pass_without_a_word(name, vehicle):
    assert preflight(load_scenario(name, [f"vehicle={vehicle}"])) == []


def test_reference_faster_than_top_speed_is_an_error_on_any_reference():
    with pytest.raises(ConfigError, match=r"^reference\.speed: the reference moves at 2 m/s"):
        preflight(
            load_scenario(
                "paper-ideal",
                ["reference={type: waypoints, points: [[0, 0], [50, 0]], speed: 2.0}"],
            )
        )
    just_below = 0.999 * steady_top_speed(load_scenario("paper-ideal").plant)
    assert preflight(load_scenario("paper-ideal", [f"reference={{type: line, speed: "
                                                   f"{just_below}}}"])) == []  # fmt: skip


@pytest.mark.parametrize(
    ("vehicle", "speed", "radius"), [("jmse2210", 1.5, 1.0), ("bluerov2-heavy", 0.8, 0.3)]
)
def test_a_turn_too_tight_for_its_speed_is_a_warning(vehicle, speed, radius):
    resolved = load_scenario(
        "paper-ideal",
        [f"vehicle={vehicle}", f"reference={{type: circle, radius: {radius}, speed: {speed}}}",
         "duration=10"],
    )  # fmt: skip
    warnings = preflight(resolved)
    assert len(warnings) == 1
    assert re.match(
        rf"reference: needs more thrust than {vehicle}'s limits .* at 21 of 21 samples, "
        rf"first at t = 0 s \(speed {speed:g} m/s, turn radius {radius:g} m\)",
        warnings[0],
    ), warnings


def _besides_the_mission_end(warnings: list[str]) -> list[str]:
    """The warnings other than a path ending before or after the run (tested on its own)."""
    ends = ("reference: the path ends at", "duration: ")
    return [warning for warning in warnings if not warning.startswith(ends)]


def test_a_corner_sharper_than_the_rate_limit_allows_is_a_warning():
    resolved = load_scenario(
        "paper-ideal",
        ["reference={type: waypoints, points: [[0, 0], [20, 0], [20, 20]], speed: 1.0}"],
    )
    # paper-ideal flies the paper's mpc: the corner is also said of it (tested below)
    (corner, warning) = _besides_the_mission_end(preflight(resolved))
    assert corner.startswith("controller.type: mpc on a path with 1 corner:")
    assert warning.startswith("vehicle.thrust_rate_limit: the reference's thrust needs change")
    assert "thrust_rate_limit x sample_time = 2.5 N" in warning


def test_a_depth_the_planar_plant_cannot_follow_is_a_warning():
    """A 3-D path in a horizontal-plane scenario: the run tracks its horizontal path and says
    that the depth is not followed, where the depth changes; a constant depth is no news."""
    lawnmower = "reference={type: lawnmower, leg_length: 10, spacing: 4, legs: 2, speed: 0.5"
    nmpc = ["duration=40", "controller.type=nmpc"]  # not the corner warning of paper's mpc
    changing = load_scenario("paper-ideal", [*nmpc, f"{lawnmower}, depths_m: [1, 3]}}"])
    (warning,) = _besides_the_mission_end(preflight(changing))
    assert warning.startswith("reference: its depth changes (1 to 3 m)")
    assert "kind: six-dof" in warning
    constant = load_scenario("paper-ideal", [*nmpc, f"{lawnmower}, depths_m: [2]}}"])
    assert _besides_the_mission_end(preflight(constant)) == []
    assert preflight(load_scenario("bluerov2-helix")) == []  # 6-DOF: the depth is tracked


@pytest.mark.parametrize("vehicle", ["jmse", "bluerov"])
def test_feasibility_agrees_with_a_linear_program(vehicle, request):
    """The closed-form null-space interval test against scipy's LP on random forces."""
    from scipy.optimize import linprog

    params = request.getfixturevalue(vehicle)
    rng = np.random.default_rng(7)
    reach = np.abs(params.T).sum(axis=1) * max(np.abs(params.thrust_limits))  # per axis
    tau = rng.uniform(-0.7, 0.7, size=(300, 3)) * reach
    fast = feasible_forces(params, tau)
    slow = [
        linprog(np.zeros(params.n_thrusters), A_eq=params.T, b_eq=row,
                bounds=[params.thrust_limits] * params.n_thrusters, method="highs").status == 0
        for row in tau
    ]  # fmt: skip
    assert fast.tolist() == slow
    assert 30 < fast.sum() < 270  # both outcomes are exercised


def test_start_inside_keep_out_disc_is_a_warning_for_obstacles_there_at_t0():
    inside = "initial_state=[2.0, 9.4, 0, 0, 0, 0]"  # 1.4 m from obstacle 0: radius 1 + 0.5
    (warning,) = preflight(load_scenario("paper-obstacles", [inside]))
    assert warning.startswith(
        "obstacles.0: the start position (2, 9.4) is 1.4 m from its centre, inside its "
        "keep-out disc (radius 1 + vehicle_radius 0.5 m)"
    )
    later = load_scenario("paper-obstacles", [inside, "obstacles.0.appear_time=5"])
    assert preflight(later) == []
    outside = "initial_state=[2.0, 9.6, 0, 0, 0, 0]"
    assert preflight(load_scenario("paper-obstacles", [outside])) == []


def test_memory_check_names_the_horizon_and_counts_moves():
    resolved = load_scenario("paper-ideal", ["controller.control_horizon=null",
                                             "controller.prediction_horizon=2000"])  # fmt: skip
    check_memory(resolved, available=10 * 2**30)  # ~ 4.9 GiB: fits in 10 GiB
    with pytest.raises(ConfigError, match=r"^controller\.prediction_horizon: .* ny=2000, nc=2000"):
        check_memory(resolved, available=2**30)


def test_memory_check_covers_the_nonlinear_mpc():
    resolved = load_scenario("paper-ideal", ["controller.type=nmpc",
                                             "controller.prediction_horizon=100000"])  # fmt: skip
    with pytest.raises(ConfigError, match=r"^controller\.prediction_horizon: building the nmpc"):
        check_memory(resolved, available=64 * 2**30)
    check_memory(load_scenario("paper-ideal", ["controller.type=nmpc"]), available=2**30)


def test_memory_check_covers_the_sparse_qp_of_ltv_mpc():
    """ltv-mpc may choose its sparse QP, whose set-up assembles H and A dense: measured
    4.07 GB at ny = 600 (controllers/ltv.py). At ny = 3000 it needs tens of GiB: refused
    in one line, before the run, where it used to be a MemoryError or the OOM killer."""
    resolved = load_scenario("paper-ideal", ["controller.type=ltv-mpc",
                                             "controller.prediction_horizon=3000"])  # fmt: skip
    with pytest.raises(ConfigError, match=r"^controller\.prediction_horizon: setting up the"):
        check_memory(resolved, available=24 * 2**30)
    # the preset's ny = 30 needs a few MiB
    check_memory(load_scenario("paper-ideal", ["controller.type=ltv-mpc"]), available=2**30)


def test_warnings_are_printed_and_stored(monkeypatch, capsys, tmp_path):
    out = tmp_path / "run"
    code, _, stderr = run_cli(
        monkeypatch, capsys, "run", "paper-ideal", "--controller", "baseline", "--no-figures",
        "--set", "reference={type: circle, radius: 1, speed: 1.5}", "--set", "duration=3",
        "--out", str(out),
    )  # fmt: skip
    assert code == 0
    dropped, short = stderr.strip().splitlines()
    # the file's mpc knobs that the baseline has not, dropped by --controller
    assert dropped.startswith("warning: controller.type: mpc changed to baseline by an override")
    assert short.startswith("warning: reference: needs more thrust than jmse2210's limits")
    info = json.loads((out / "run.json").read_text())
    assert info["warnings"] == [line.removeprefix("warning: ") for line in (dropped, short)]


@pytest.mark.parametrize(
    ("controller", "solver"), [("mpc", "daqp"), ("baseline", None), ("nmpc", None)]
)
def test_run_json_carries_provenance(monkeypatch, capsys, tmp_path, controller, solver):
    out = tmp_path / "run"
    args = ("run", "paper-ideal", "--controller", controller, "--set", "duration=2",
            "--no-figures", "--out", str(out))  # fmt: skip
    assert run_cli(monkeypatch, capsys, *args)[0] == 0
    provenance = json.loads((out / "run.json").read_text())["provenance"]
    assert set(provenance) == {
        "started_utc", "wall_s", "command", "auvmpc_version", "git_revision", "libraries",
    }  # fmt: skip
    assert datetime.fromisoformat(provenance["started_utc"]).utcoffset().total_seconds() == 0
    assert provenance["wall_s"] > 0
    assert provenance["command"].startswith("auvmpc run paper-ideal --controller")
    revision = provenance["git_revision"]
    assert revision is None or re.fullmatch(r"[0-9a-f]{40}(\+dirty)?", revision)
    expected = {"numpy", "scipy", "casadi"} | ({solver} if solver else set())
    assert set(provenance["libraries"]) == expected
    assert all(isinstance(v, str) for v in provenance["libraries"].values())


def test_depth_runs_carry_provenance_too():
    result = simulate(load_scenario("paper-depth-calm", ["duration=11"]))
    assert result.run_json()["provenance"]["libraries"]["daqp"]


def test_start_in_an_obstacle_is_printed_and_stored(monkeypatch, capsys, tmp_path):
    out = tmp_path / "run"
    code, _, stderr = run_cli(
        monkeypatch, capsys, "run", "paper-obstacles", "--set", "duration=2", "--no-figures",
        "--set", "initial_state=[2.0, 8.3, 0, 0, 0, 0]", "--out", str(out),
    )  # fmt: skip
    assert code == 0
    assert stderr.startswith("warning: obstacles.0: the start position (2, 8.3) is 0.3 m")
    assert json.loads((out / "run.json").read_text())["warnings"][0].startswith("obstacles.0")


# The before-stop smoke's light-yaw vehicle: yaw turn-up 0.009 s, 54 of them in 0.5 s.
LIGHT_YAW = (
    "vehicle={name: light, mass: 20.0, m11: 26.0, m22: 34.0, Iz_rb: 0.12, Iz_added: 0.06, "
    "Xu: -5.0, Xuu: -120.0, Yv: -8.0, Yvv: -60.0, Nr: -0.1, Nrr: -0.5, thrust_limits: "
    "[-150, 150], thrust_rate_limit: 300, thrusters: [{position: [0.18, 0.12], angle_deg: -45},"
    " {position: [0.18, -0.12], angle_deg: 45}, {position: [-0.18, 0.12], angle_deg: -135},"
    " {position: [-0.18, -0.12], angle_deg: 135}]}"
)


@pytest.mark.parametrize("controller", ["ltv-mpc", "mpc"])
def test_a_linearised_controller_too_slow_for_the_yaw_is_warned_in_one_line(controller):
    from auvmpc.models.vehicle import turn_up_time
    from auvmpc.scenario.sanity import LINEARISED_TURN_UP_SAMPLES

    resolved = load_scenario("paper-ideal", [LIGHT_YAW, f"controller.type={controller}"])
    turn_up = turn_up_time(resolved.model)
    assert 0.5 > LINEARISED_TURN_UP_SAMPLES * turn_up  # the case the rule is for
    warnings = [w for w in preflight(resolved) if "linearises" in w]
    assert len(warnings) == 1 and "\n" not in warnings[0]
    assert f"{turn_up:.3g} s" in warnings[0] and controller in warnings[0]
    # the default controller predicts on the exact model: only the spin within a sample
    nmpc = load_scenario("paper-ideal", [LIGHT_YAW, "controller.type=nmpc"])
    assert [w for w in preflight(nmpc) if "linearises" in w] == []


def test_a_sample_time_that_lets_the_yaw_spin_within_it_is_warned_with_the_default():
    from auvmpc.controllers.config import HEADING_PER_SAMPLE_RAD, default_sample_time
    from auvmpc.models.vehicle import heading_turn_time

    # paper-ideal pins 0.5 s; the light vehicle's 127 N m spins it up to 15.8 rad/s, so it
    # turns half a turn in 0.198 s
    pinned = load_scenario("paper-ideal", [LIGHT_YAW, "controller.type=nmpc"])
    spin = heading_turn_time(pinned.model, HEADING_PER_SAMPLE_RAD)
    assert spin < 0.5
    warnings = [w for w in preflight(pinned) if "half a turn" in w]
    assert len(warnings) == 1 and "\n" not in warnings[0]
    assert f"longer than the {spin:.3g} s" in warnings[0]
    assert f"omit it for {default_sample_time(pinned.model):g} s" in warnings[0]
    # omitted, the chosen sample keeps the turn within half a turn: nothing to warn of
    chosen = load_scenario("paper-ideal", [LIGHT_YAW, "controller.sample_time=null"])
    assert chosen.scenario.controller.sample_time == default_sample_time(chosen.model) <= spin
    assert not [w for w in preflight(chosen) if "half a turn" in w]
    # the paper's own vehicle at its own 0.5 s turns 1.2 rad: the paper runs are not warned
    paper = load_scenario("paper-ideal")
    assert not [w for w in preflight(paper) if "half a turn" in w]


def test_the_yaw_rule_on_vehicles_without_yaw_damping_or_yaw_moment():
    """Without yaw damping there is no top rate: half a turn from rest takes
    sqrt(2 pi Iz / M) (exact then); a vehicle without yaw moment cannot spin itself."""
    from auvmpc.controllers.config import HEADING_PER_SAMPLE_RAD
    from auvmpc.models.vehicle import heading_turn_time, load_vehicle

    paper = load_vehicle("jmse2210")
    undamped = paper.model_copy(update={"Nr": 0.0, "Nrr": 0.0})
    moment = float(paper.thrust_authority[2])
    assert heading_turn_time(undamped, HEADING_PER_SAMPLE_RAD) == pytest.approx(
        math.sqrt(2.0 * math.pi * paper.Iz / moment), rel=ROUND_OFF_TOL
    )
    centred = [{"position": [0.0, 0.0], "angle_deg": a} for a in (0.0, 90.0)]
    no_moment = load_scenario(
        "paper-ideal",
        ["controller.type=nmpc", "controller.R=null", "reference={type: line, speed: 0.2}",
         f"vehicle={{name: centred, mass: 10, m11: 12, m22: 14, Iz_rb: 1, Iz_added: 0.5, "
         f"Xu: -5, Xuu: -10, Yv: -5, Yvv: -10, Nr: -1, Nrr: -1, thrust_limits: [-20, 20], "
         f"thrust_rate_limit: 100, thrusters: {centred}}}"],
    )  # fmt: skip
    assert heading_turn_time(no_moment.model, HEADING_PER_SAMPLE_RAD) == math.inf
    assert not [w for w in preflight(no_moment) if w.startswith("controller.sample_time")]


WAYPOINTS = "reference={type: waypoints, points: [[0, 0], [12, 0], [12, 4], [0, 4]], speed: 0.3}"


@pytest.mark.parametrize("controller", ["ltv-mpc", "mpc"])
def test_a_linearised_controller_on_a_path_with_corners_is_warned_in_one_line(controller):
    resolved = load_scenario("paper-ideal", [WAYPOINTS, f"controller.type={controller}"])
    warnings = [w for w in preflight(resolved) if "corners" in w]
    assert len(warnings) == 1 and "\n" not in warnings[0]
    assert warnings[0].startswith(f"controller.type: {controller} on a path with 2 corners")
    # the default follows corners; a linearised controller on the paper's oval is not warned
    nmpc = load_scenario("paper-ideal", [WAYPOINTS, "controller.type=nmpc"])
    assert not [w for w in preflight(nmpc) if "corners" in w]
    oval = load_scenario("paper-ideal", [f"controller.type={controller}"])
    assert not [w for w in preflight(oval) if "corners" in w]


def test_fewer_sqp_steps_than_an_agile_vehicle_needs_are_warned():
    """The light vehicle's 424 N changes its 26-34 kg speed by 0.5 m/s in 0.031 s: the rule
    gives 2 SQP steps; asking for 1 is warned, the default and 2 are not."""
    from auvmpc.controllers.config import default_sqp_iterations

    base = [LIGHT_YAW, "controller.type=nmpc", "controller.sample_time=null"]
    asked = load_scenario("paper-ideal", [*base, "controller.linearisation_iterations=1"])
    assert default_sqp_iterations(asked.model) == 2
    warnings = [w for w in preflight(asked) if w.startswith("controller.linearisation")]
    assert len(warnings) == 1 and "\n" not in warnings[0] and "omit it for 2" in warnings[0]
    for given in ([], ["controller.linearisation_iterations=2"]):
        fine = load_scenario("paper-ideal", [*base, *given])
        assert not [w for w in preflight(fine) if w.startswith("controller.linearisation")]
    # the paper's vehicle needs one step: the paper runs are not warned
    paper = load_scenario("paper-ideal", ["controller.type=nmpc"])
    assert not [w for w in preflight(paper) if w.startswith("controller.linearisation")]


@pytest.mark.parametrize(
    ("duration", "says"),
    [(200, "before the run's duration 200 s"), (60, "ends the run before the path does")],
)
def test_a_path_that_ends_before_or_after_the_run_is_warned_with_both_times(duration, says):
    """issue 30: a lawnmower that ends before the duration held still without a word."""
    from auvmpc.references import make_reference
    from auvmpc.scenario.sanity import preflight

    lawnmower = "{type: lawnmower, leg_length: 20, spacing: 4, legs: 4, speed: 0.5}"
    resolved = load_scenario("paper-ideal", [f"reference={lawnmower}", f"duration={duration}"])
    end = make_reference(resolved.scenario.reference, resolved.base_dir).end_time
    warnings = [w for w in preflight(resolved) if says in w]
    assert len(warnings) == 1 and f"{end:.4g} s" in warnings[0]
