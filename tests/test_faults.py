"""Actuator faults (issue 26): a fault as scenario data acts in the plant exactly, a declared
one reaches the controller at its time, the fault detector finds a dead thruster from the
prediction residual without false alarms on a healthy run, and run.json says what it cost."""

from __future__ import annotations

import numpy as np
import pytest

import auvmpc
from auvmpc.environment.disturbances import DisturbanceConfig, WorldDisturbance
from auvmpc.errors import ConfigError
from auvmpc.estimation.fault_detection import FaultDetector
from auvmpc.experiments.run import RunSession, run_plant
from auvmpc.models.actuators import ActuatorSet
from auvmpc.models.actuators.thruster import FixedThruster
from auvmpc.models.discrete import DISTURBANCE_NAMES, horizontal_model
from auvmpc.models.layout import HORIZONTAL
from auvmpc.models.vehicle import load_vehicle
from auvmpc.scenario.faults import ActuatorFault
from auvmpc.sim.faults import FaultSchedule, FaultyPlant
from auvmpc.sim.loop import run_session
from auvmpc.sim.plant import PlantStepper, SixDofPlant
from tests.test_cli import run_cli

DEAD_F3 = "faults=[{actuator: F3, at: 50.0, effectiveness: 0.0}]"
# paper-ideal's controller samples every 0.5 s: a fault is found within this many samples.
DETECTION_SAMPLES = 2
# The thruster-loss preset's bar (issue 26): found within 2 s, tracking after the fault at
# most twice as far off as before it.
DETECTION_BOUND_S = 2.0
RMS_RATIO_BOUND = 2.0


def _four_thrusters() -> ActuatorSet:
    limits = {"lower": -10.0, "upper": 10.0, "rate": 5.0}
    return ActuatorSet(
        tuple(FixedThruster.planar(f"F{i + 1}", (0.0, 0.0), 0.0, **limits) for i in range(4))
    )


def test_the_schedule_delivers_each_fault_from_its_sample_on():
    """Effectiveness is the share of the force that acts (the command is followed as it is),
    stuck_at replaces the command, from the first sample at or after ``at`` (a time k Te a
    little below ``at`` by round-off counts as reached); the declared ones only are what the
    controller is told, a stuck one as not acting."""
    faults = [
        ActuatorFault(actuator="F2", at=1.5, effectiveness=0.25),
        ActuatorFault(actuator="F4", at=3 * 0.1 * 5, stuck_at=-4.0, declared=True),
    ]
    schedule = FaultSchedule(faults, _four_thrusters(), duration=10.0)
    command = np.array([1.0, 8.0, -2.0, 6.0])
    delivered, effectiveness = schedule.delivered(command, 1.0)
    np.testing.assert_array_equal(delivered, command)
    assert effectiveness is None and schedule.declared(1.0) is None
    delivered, effectiveness = schedule.delivered(command, 15 * 0.1)
    np.testing.assert_array_equal(delivered, [1.0, 8.0, -2.0, -4.0])
    np.testing.assert_array_equal(effectiveness, [1.0, 0.25, 1.0, 1.0])
    np.testing.assert_array_equal(schedule.declared(1.5), [1.0, 1.0, 1.0, 0.0])


def test_a_thrusters_effectiveness_is_the_share_of_its_command_to_the_bit(jmse, bluerov):
    """A thruster's force is linear in its command: a plant stepped with effectiveness e
    (the share of each wrench) is the plant stepped with e F, to the bit, for the 3-DOF
    plant (compiled where there is a compiler) and a thruster vehicle's 6-DOF plant; so
    the thruster presets' faults act as they did when the plant scaled the command."""
    e = np.array([0.0, 0.5, 1.0, 0.3])
    disturbance = WorldDisturbance(
        DisturbanceConfig(current_force_world=(10.0, 5.0)), 0.5, np.random.default_rng(0)
    )
    state, thrust = np.array([7.5, -12.0, 1.57, 0.4, 0.1, 0.06]), np.array([12, -3, 7, 15.0])
    stepper = PlantStepper(jmse, 0.5, 10)
    np.testing.assert_array_equal(
        stepper(state, thrust, 0.0, disturbance, e), stepper(state, e * thrust, 0.0, disturbance)
    )
    plant = SixDofPlant(bluerov, None, 0.25, 0.05)
    six_e = np.array([0.0, 0.5, 1.0, 0.3, 1.0, 0.7, 1.0, 1.0])
    six_state = np.zeros(12)
    six_state[6:9] = [0.3, -0.1, 0.05]
    six_thrust = np.array([10.0, -8.0, 6.0, -4.0, 3.0, -2.0, 1.0, 5.0])
    np.testing.assert_array_equal(
        plant.step(six_state, six_thrust, 0.0, six_e),
        plant.step(six_state, six_e * six_thrust, 0.0),
    )


@pytest.mark.parametrize(
    ("fault", "field", "message"),
    [
        ("{actuator: F9, at: 5, effectiveness: 0}", "faults.0.actuator", "one of F1, F2"),
        ("{actuator: F1, at: 5}", "faults.0.effectiveness", "give exactly one of"),
        ("{actuator: F1, at: 5, effectiveness: 0.5, stuck_at: 1}", "faults.0.stuck_at",
         "give exactly one of"),
        ("{actuator: F1, at: 5, stuck_at: 1e9}", "faults.0.stuck_at", "outside F1's limits"),
        ("{actuator: F1, at: 100}", "faults.0.effectiveness", "give exactly one of"),
        ("{actuator: F1, at: 100, effectiveness: 0}", "faults.0.at", "at or after the run's end"),
        ("{actuator: F2, at: 5, effectiveness: 0}, {actuator: F2, at: 9, stuck_at: 1}",
         "faults.1.actuator", "fails twice"),
        ("{actuator: F1, at: 5, effectiveness: 1.5}", "faults.0.effectiveness", "1"),
    ],
)  # fmt: skip
def test_a_bad_fault_is_refused_in_one_line(monkeypatch, capsys, tmp_path, fault, field, message):
    code, _, err = run_cli(monkeypatch, capsys, "run", "paper-ideal", "--set",
                           f"faults=[{fault}]", "--out", str(tmp_path / "run"))  # fmt: skip
    assert code == 2, err
    assert err.count("\n") == 1 and field in err and message in err, err
    assert not (tmp_path / "run").exists()


def test_the_plant_is_flown_with_what_the_actuators_deliver():
    """A run with F3 dead and F1 stuck: the logged commands through a fresh plant of the same
    scenario with the same faults give the logged states to the bit; without the faults
    they do not (the faults acted in the plant, and only there)."""
    resolved = auvmpc.load_scenario(
        "paper-ideal",
        ["duration=60", "faults=[{actuator: F3, at: 20, effectiveness: 0}, "
         "{actuator: F1, at: 40, stuck_at: 3.0}]"],
        controller="baseline",
    )  # fmt: skip
    log = auvmpc.simulate(resolved).log

    def replayed(plant) -> np.ndarray:
        state, states = log.state[0], [log.state[0]]
        for k, thrust in enumerate(log.thrust):
            state = plant.step(state, thrust, log.t[k])
            states.append(state)
        return np.array(states)

    np.testing.assert_array_equal(replayed(FaultyPlant(run_plant(resolved)[0], resolved.faults)),
                                  log.state)  # fmt: skip
    assert not np.array_equal(replayed(run_plant(resolved)[0]), log.state)


def test_a_declared_fault_reaches_the_controller_at_its_time():
    run = auvmpc.simulate(
        auvmpc.load_scenario(
            "paper-ideal", [DEAD_F3.replace("}]", ", declared: true}]")], controller="nmpc"
        )  # fmt: skip
    )
    told = run.log.effectiveness[:, 2]
    commands = run.log.t[:-1]
    np.testing.assert_array_equal(told, np.where(commands >= 50.0, 0.0, 1.0))
    assert run.metrics["fault_detection_delay_s"] == 0.0
    assert run.metrics["false_fault_detections"] == 0


def test_the_detector_finds_a_dead_thruster_and_the_controller_flies_on():
    """paper-ideal, nmpc, F3 dead at 50 s, nobody told: the detector finds F3 (and nothing
    else) within two samples; after the fault the tracking is within 20 % of before it,
    where not telling the controller costs over three times the error."""
    run = auvmpc.simulate(
        auvmpc.load_scenario("paper-ideal", [DEAD_F3, "fault_detection=true"], controller="nmpc")
    )
    detected = run.metrics
    (found,) = run.run_json()["fault_detections"]  # what it found, kept in run.json
    assert found["actuator"] == "F3" and found["t_s"] == 50.0 + detected["fault_detection_delay_s"]
    assert found["score"] >= 12.0 and 0.5 <= found["lost"] <= 1.5
    untold = auvmpc.simulate(
        auvmpc.load_scenario("paper-ideal", [DEAD_F3], controller="nmpc")
    ).metrics
    sample_time = 0.5
    assert 0 < detected["fault_detection_delay_s"] <= DETECTION_SAMPLES * sample_time
    assert detected["false_fault_detections"] == 0
    assert detected["rms_after_fault_m"] <= 1.2 * detected["rms_before_fault_m"]
    assert untold["fault_detection_delay_s"] is None
    assert untold["rms_after_fault_m"] > 3 * untold["rms_before_fault_m"]


def test_watching_a_healthy_run_changes_nothing():
    """The detector only watches: with no fault it finds nothing on the BlueROV2 figure-eight
    (noise, vectored thrusters) and the run is the same to the bit as without it."""
    scenario = "bluerov2-figure-eight"
    watched = RunSession(auvmpc.load_scenario(scenario, ["fault_detection=true"]))
    plant, sensor = run_plant(watched.resolved)
    run_session(watched, plant, sensor)
    assert watched.faults_found == []
    plain = auvmpc.simulate(auvmpc.load_scenario(scenario))
    np.testing.assert_array_equal(watched.stepped_log.thrust, plain.log.thrust)
    np.testing.assert_array_equal(watched.stepped_log.state, plain.log.state)
    assert "fault_time_s" not in plain.metrics  # fault metrics only for runs with faults
    assert "fault_detections" not in plain.run_json()  # and the list only with a detector


@pytest.mark.slow
def test_the_bluerov2_heavy_keeps_tracking_after_losing_a_thruster():
    """The preset (6-DOF BlueROV2 Heavy, lawnmower at 2 m, current, noise, F1 dead at 90 s
    found by the detector): issue 26's bar."""
    metrics = auvmpc.simulate(auvmpc.load_scenario("bluerov2-heavy-thruster-loss")).metrics
    assert 0 < metrics["fault_detection_delay_s"] <= DETECTION_BOUND_S
    assert metrics["false_fault_detections"] == 0
    assert metrics["rms_after_fault_m"] <= RMS_RATIO_BOUND * metrics["rms_before_fault_m"]
    assert metrics["verdict"] != "lost"


def test_a_fault_on_an_input_the_plant_does_not_have_is_refused_before_the_run():
    with pytest.raises(ConfigError, match=r"faults\.0\.actuator: .*one of F1"):
        auvmpc.load_scenario("bluerov2-helix", ["faults=[{actuator: F9, at: 1, effectiveness: 0}]"])


def test_the_detector_finds_the_thruster_and_the_sample_it_failed_on():
    """Against known truth: the jmse2210's sampled model as the plant, random commands, small
    velocity noise and a constant unknown force (which the window's constant must take up);
    thruster 2 delivers nothing from sample 40. Nothing is found before; F3 (index 2) is
    found, within the detector's window of the onset, and nothing else."""
    vehicle = load_vehicle("jmse2210")
    sample_time, substeps, noise = 0.5, 2, 0.002
    step = horizontal_model(vehicle, sample_time, substeps, jit=False).numeric_step
    detector = FaultDetector(vehicle, sample_time, substeps, np.full(3, noise))
    rng = np.random.default_rng(7)
    n = vehicle.n_thrusters
    healthy, dead_from = np.ones(n), 40
    force = np.array([4.0, -3.0, 1.0])[: len(DISTURBANCE_NAMES)]  # an unknown current force
    state, found = np.zeros(HORIZONTAL.size), []
    low, high = vehicle.thrust_limits
    for k in range(80):
        measured = state.copy()
        measured[HORIZONTAL.nu] += rng.normal(0, noise, 3)
        result = detector.check(measured)
        if result is not None:
            found.append((k, result.index))
        command = rng.uniform(0.3 * low, 0.3 * high, n)
        detector.held(command, healthy if not found else np.where(np.arange(n) == 2, 0.0, 1.0))
        acting = command * np.where((np.arange(n) == 2) & (k >= dead_from), 0.0, 1.0)
        state = np.asarray(step(state, acting, force, np.ones(n))).ravel()
    # Found while the onset is still inside the window (the fit's unknown onset); on this
    # vehicle two thrusters push alike, so telling them apart takes a few samples (5 here).
    assert found and found[0][1] == 2 and dead_from < found[0][0] <= dead_from + detector.window
    assert len(found) == 1
