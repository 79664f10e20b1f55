"""Scenario files: built-ins load, overrides apply, every kind of bad input names its field."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from auvmpc.errors import ConfigError
from auvmpc.scenario import apply_override, builtin_scenarios, load_scenario

PAPER_SCENARIOS = ("paper-ideal", "paper-disturbed", "paper-obstacles")


def write_scenario(tmp_path: Path, **changes) -> Path:
    """paper-ideal's YAML with top-level fields replaced, written to a temp file."""
    from importlib import resources

    text = (resources.files("auvmpc.presets") / "scenarios" / "paper-ideal.yaml").read_text()
    data = yaml.safe_load(text)
    data.update(changes)
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_builtins_are_listed_with_descriptions():
    found = builtin_scenarios()
    for name in PAPER_SCENARIOS:
        assert name in found and found[name]


def test_paper_values_from_the_spec():
    ideal = load_scenario("paper-ideal").scenario
    assert ideal.duration == 100.0
    assert ideal.controller.Q == (5, 5, 5, 1, 1, 1)
    assert ideal.controller.S == (10, 10, 10, 2, 2, 2)
    assert ideal.controller.R == (0.01,) * 4
    assert (ideal.controller.prediction_horizon, ideal.controller.control_horizon) == (30, 2)
    assert ideal.controller.sample_time == 0.5
    assert ideal.initial_state[:2] == (7.5, -12.0)  # spec section 5 decision: y0 = -12
    disturbed = load_scenario("paper-disturbed")
    assert disturbed.scenario.disturbance.current_force_world == (10.0, 5.0)
    assert disturbed.plant.Iz_rb == pytest.approx(1.3 * 0.75)
    assert disturbed.plant.Iz_added == pytest.approx(0.7 * 0.65)
    assert disturbed.model.Iz == 2.0  # the controller's model is nominal
    obstacles = load_scenario("paper-obstacles").scenario.obstacles
    assert [(o.center, o.radius) for o in obstacles] == [((2.0, 8.0), 1.0), ((8.0, -6.0), 0.5)]


def test_overrides_reach_nested_fields_and_lists():
    resolved = load_scenario(
        "paper-obstacles",
        ["controller.control_horizon=30", "obstacles.1.radius=0.75", "plant.scale.Iz_rb=0.9"],
    )
    assert resolved.scenario.controller.control_horizon == 30
    assert resolved.scenario.obstacles[1].radius == 0.75
    assert resolved.plant.Iz_rb == pytest.approx(1.17)


def test_apply_override_creates_missing_mappings():
    data = {"plant": None}
    apply_override(data, "plant.scale.Iz_added=0.5")
    assert data == {"plant": {"scale": {"Iz_added": 0.5}}}


@pytest.mark.parametrize(
    ("overrides", "field", "value"),
    [
        (["controller.horizon=3"], "controller.horizon", "3"),  # unknown key
        (["duration=long"], "duration", "long"),  # wrong type
        (["duration=.nan"], "duration", "nan"),  # non-finite
        (["initial_state=[1, 2, .inf, 0, 0, 0]"], "initial_state.2", "inf"),
        (["vehicle=no-such-boat"], "vehicle", "no-such-boat"),  # unknown preset
        (["reference.type=spiral"], "reference", "spiral"),  # unknown reference type
        (["controller.type=pid"], "controller.type", "pid"),  # unknown controller
        (["controller.R=[1, 2]"], "controller.R", "[1.0, 2.0]"),  # wrong count for 4 thrusters
        (["controller.control_horizon=40"], "controller.control_horizon", "40"),  # nc > ny
        (["plant.scale.Iz_rb=-0.5"], "plant.scale.Iz_rb", "-0.5"),
        (["plant.scale.hull_colour=2"], "plant.scale.hull_colour", "2"),
        (["obstacles.0.radius=-1"], "obstacles.0.radius", "-1"),
        (["initial_thrust=[20, 0, 0, 0]"], "initial_thrust", "20"),  # above the 15 N limit
        (["seed=-1"], "seed", "-1"),
        (["nonsense"], "--set", "nonsense"),
        (["obstacles.7.radius=1"], "obstacles.7", "7"),
    ],
)
def test_bad_input_names_field_and_value(overrides, field, value):
    with pytest.raises(ConfigError) as caught:
        load_scenario("paper-obstacles", overrides)
    message = str(caught.value)
    assert message.startswith(field), message
    assert value in message, message
    assert "\n" not in message


def test_negative_mass_in_inline_vehicle(tmp_path):
    from auvmpc.models.vehicle import load_vehicle

    vehicle = load_vehicle("jmse2210").model_dump(mode="json")
    vehicle["mass"] = -16.5
    path = write_scenario(tmp_path, vehicle=vehicle)
    with pytest.raises(ConfigError, match=r"^vehicle\.mass.*-16\.5"):
        load_scenario(path)


def test_vehicle_file_relative_to_scenario(tmp_path):
    from auvmpc.models.vehicle import load_vehicle

    vehicle = load_vehicle("jmse2210").model_dump(mode="json")
    vehicle["name"] = "heavier"
    vehicle["m11"] = 25.0
    (tmp_path / "boat.yaml").write_text(yaml.safe_dump(vehicle))
    resolved = load_scenario(write_scenario(tmp_path, vehicle="boat.yaml"))
    assert resolved.model.m11 == 25.0


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(ConfigError, match=r"^scenario: no such file.*nope\.yaml"):
        load_scenario(tmp_path / "nope.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text("name: x\nduration: [1, 2\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_scenario(broken)
    listing = tmp_path / "list.yaml"
    listing.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="expected a mapping"):
        load_scenario(listing)


def test_missing_vehicle_file_is_named(tmp_path):
    with pytest.raises(ConfigError, match=r"^vehicle: vehicle file not found"):
        load_scenario(write_scenario(tmp_path, vehicle="absent.yaml"))


def test_new_scenarios_default_to_the_better_tracker_paper_ones_keep_the_papers(tmp_path):
    data = {
        "name": "fresh",
        "duration": 10.0,
        "reference": {"type": "line", "start": [0, 0], "heading_deg": 0, "speed": 0.5},
        "initial_state": [0, 0, 0, 0, 0, 0],
    }
    path = tmp_path / "fresh.yaml"
    path.write_text(yaml.safe_dump(data))
    resolved = load_scenario(path)
    fresh = resolved.scenario.controller
    assert fresh.type == "nmpc" and fresh.nmpc_mode == "real-time"
    assert resolved.choices["type"]["value"] == "nmpc"  # said, with its reason
    assert fresh.move_schedule() == tuple(range(fresh.prediction_horizon))
    for name in PAPER_SCENARIOS:
        paper = load_scenario(name).scenario.controller
        assert paper.type == "mpc" and paper.move_schedule() == (0, 1)


def test_a_duration_between_samples_is_rounded_up_with_a_note():
    """A user types 100.2 s at 0.5 s samples: the run lasts 100.5 s and says so."""
    from auvmpc.scenario.sanity import preflight

    resolved = load_scenario("paper-obstacles", ["duration=100.2"])
    assert resolved.scenario.duration == 100.5
    notes = [w for w in preflight(resolved) if w.startswith("duration:")]
    assert len(notes) == 1 and "100.2" in notes[0] and "100.5" in notes[0]


def test_a_depth_duration_between_samples_is_rounded_up_with_a_note():
    """The same in the tank: 40.05 s at 0.1 s samples lasts 40.1 s, and the run says so."""
    from auvmpc.scenario.sanity import preflight

    resolved = load_scenario("paper-depth-calm", ["duration=40.05"])
    assert resolved.scenario.duration == pytest.approx(40.1, abs=1e-12)
    (note,) = preflight(resolved)
    assert note.startswith("duration: 40.05 s") and "40.1 s (401 samples)" in note
    assert preflight(load_scenario("paper-depth-calm")) == []  # its 40 s is whole


def test_a_knob_of_another_controller_type_is_refused_unless_an_override_changed_the_type():
    """The file's own type: refused in one line naming the types that have it. A type
    changed by an override (--controller): the old type's knobs dropped, and said so."""
    with pytest.raises(
        ConfigError, match=r"^controller\.nmpc_mode: a knob of nmpc, not of controller type mpc"
    ):
        load_scenario("paper-ideal", ["controller.nmpc_mode=full"])
    resolved = load_scenario("paper-ideal", ["controller.type=baseline"])
    assert resolved.notes[0] == (
        "controller.type: mpc changed to baseline by an override; dropped what baseline has "
        "no knob for: prediction_horizon, control_horizon, Q, S, R, thrust_penalty, offset_free"
    )
    assert resolved.scenario.controller.vehicle_radius == 0.5  # a knob both have: kept
