"""Fuzzing the files and options a user hands auvmpc (issue 28, item 5): scenario, vehicle
and campaign files, CSV tracks and ``--set`` overrides, generated hostile (wrong types,
extreme floats, huge integers, unicode and control characters, deep nesting, anchors,
aliases and bombs, duplicate and unknown keys, text cut short or with flipped bytes).

Each input goes through the in-process command line and is held to
:func:`tests.fuzzing.assert_clean`: success or one clean refusal, within 10 s, no traceback.
Scenarios are checked with ``explain`` (load, resolve and the checks before a run, no
simulation); one input in eight is also run for 1 s. Campaigns go through ``campaign`` up to
the end of its checks, where a stub stops it before the first run. The profiles and the
count of inputs: :mod:`tests.fuzzing`; ``make fuzz`` runs the long profile.
"""

from __future__ import annotations

import copy
import shutil

import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from auvmpc.experiments.campaign import execute
from tests.fuzzing import (
    EXAMPLES,
    FUZZ,
    GENERATED,
    RAW_SCALARS,
    Pairs,
    assert_clean,
    damaged_text,
    mutated_document,
    run_cli,
    strings,
    values,
    yaml_document,
    yaml_flow,
)
from tests.test_properties import VEHICLE as PROPERTY_VEHICLE

HORIZONTAL = {
    "name": "fuzz",
    "description": "a generated scenario",
    "duration": 1.0,
    "vehicle": "jmse2210",
    "reference": {"type": "circle", "center": [0.0, 0.0], "radius": 5.0, "speed": 0.5},
    "initial_state": [5.0, 0.0, 1.5708, 0.0, 0.0, 0.0],
    "obstacles": [{"center": [0.0, 5.0], "radius": 0.5, "velocity": [0.1, 0.0]}],
    "controller": {"type": "baseline", "sample_time": 0.5},
    "plant": {"scale": {"Iz_rb": 1.1}, "max_step": 0.05},
    "disturbance": {"current_force_world": [1.0, 0.5]},
    "seed": 1,
    "transient_s": 0.5,
}
MPC = {
    **HORIZONTAL,
    "reference": {"type": "waypoints", "points": [[0, 0], [5, 0], [5, 5]], "speed": 0.4},
    "initial_state": [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    "controller": {
        "type": "mpc", "sample_time": 0.5, "prediction_horizon": 10, "control_horizon": 2,
        "Q": [5, 5, 5, 1, 1, 1], "R": [0.01, 0.01, 0.01, 0.01],
    },
}  # fmt: skip
DEPTH = {
    "kind": "depth",
    "name": "fuzz-depth",
    "duration": 1.0,
    "vehicle": "jmse2210",
    "tank": {"length_m": 4.2, "width_m": 2.0, "depth_m": 1.25},
    "reference": {"initial_depth_m": -0.3, "final_depth_m": -0.5, "step_time_s": 0.5},
    "sensor": {"noise_std_m": 0.002, "rate_hz": 10.0},
    "controller": {"type": "depth-mpc", "sample_time": 0.1, "prediction_horizon": 10},
    "seed": 0,
}
SIX_DOF = {
    "kind": "six-dof",
    "name": "fuzz-6dof",
    "duration": 1.0,
    "vehicle": "jmse2210",
    "reference": {
        "type": "paper-oval",
        "depth": {"start_m": 1.0, "changes": [{"time_s": 0.5, "depth_m": 2.0, "duration_s": 1}]},
    },
    "initial_state": [7.5, -12.0, 1.5708, 0.4, 0.1, 0.06],
    "disturbance": {"water_current": {"velocity_m_per_s": [0.1, 0.05, 0.0]}},
    "sensing": {"std": [0.02, 0.02, 0.01, 0.01, 0.01, 0.005], "depth_std_m": 0.01},
    "controller": {"type": "mpc", "sample_time": 0.5, "prediction_horizon": 10},
    "depth_controller": {"type": "depth-mpc", "prediction_horizon": 10},
    "seed": 0,
}
SCENARIOS = [HORIZONTAL, MPC, DEPTH, SIX_DOF]
# Fields the bases leave out, worth setting too.
SCENARIO_EXTRA = [
    ("controller", "prediction_horizon"), ("controller", "vehicle_radius"),
    ("controller", "thrust_penalty"), ("plant", "vehicle"), ("initial_thrust",),
    ("obstacle_sensor",), ("sensing", "std"), ("reference", "depth"), ("kind",),
]  # fmt: skip

# The property tests' vehicle, with a size and a heave section, so that every field a
# vehicle file may hold is there to be damaged.
VEHICLE = {
    **PROPERTY_VEHICLE,
    "name": "fuzz-vehicle",
    "size": {"length": 1.0, "width": 0.2, "height": 0.2},
    "heave": {
        "m_heave": 33.0,
        "Zw": -10.0,
        "Zww": -75.0,
        "net_buoyancy_N": 1.0,
        "thruster_count": 2,
        "thrust_limits": [-15.0, 15.0],
        "thrust_rate_limit": 5.0,
    },
}

CAMPAIGN = {
    "name": "fuzz-campaign",
    "description": "a generated campaign",
    "base": "base.yaml",
    "overrides": ["controller.sample_time=0.5"],
    "runs": 3,
    "seed": 7,
    "parameters": {
        "plant.scale.Iz_rb": {"type": "uniform", "low": 0.75, "high": 1.25},
        "initial_state.0": {"type": "normal", "mean": 0.0, "std": 0.5, "apply": "add"},
        "disturbance.current_force_world": {
            "type": "polar",
            "magnitude": {"type": "uniform", "low": 0.0, "high": 5.0},
            "direction_deg": {"type": "choice", "values": [0, 90, 180]},
        },
    },
    "criterion": "max_position_error_m < 1.0 and thrust_limit_violations == 0",
}

# Paths and values for --set: the scenario's own fields, wrong ones and hostile ones.
SET_PATHS = st.one_of(
    st.sampled_from(
        [
            "duration", "seed", "name", "vehicle", "reference", "reference.type",
            "reference.speed", "initial_state", "initial_state.0", "initial_state.9",
            "controller", "controller.type", "controller.Q", "controller.Q.x",
            "controller.Q.0", "controller.sample_time", "controller.prediction_horizon",
            "controller.control_horizon", "plant.scale.Iz_rb", "plant.max_step", "plant.vehicle",
            "obstacles", "obstacles.0.radius", "obstacles.99999999999999999999.radius",
            "disturbance.current_force_world", "kind", "transient_s", "a.b.c", "", ".", "..",
            "duration.x", "reference.type.x", "-1", "initial_state.-1", "initial_state.٣",
        ]
    ),
    st.lists(st.one_of(strings, st.integers(0, 12).map(str)), min_size=1, max_size=4).map(
        ".".join
    ),
)  # fmt: skip
SET_VALUES = st.one_of(
    st.sampled_from(RAW_SCALARS),
    values.map(yaml_flow),
    strings,
    st.builds(lambda n: "[" * n + "]" * n, st.integers(1, 2000)),
)
CONTROLLER_LABELS = st.one_of(
    st.none(),
    st.sampled_from(["baseline", "mpc", "ltv-mpc-nc30", "nmpc", "do-mpc", "pid", "", "mpc@x=1"]),
    strings,
)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz-inputs")


@pytest.fixture
def quiet_cwd(folder, monkeypatch):
    """Any default output lands in the test's folder, never in the checkout."""
    monkeypatch.chdir(folder)
    return folder


def _scenario_check(monkeypatch, capsys, folder, path, run: bool) -> None:
    code, stderr = run_cli(monkeypatch, capsys, "explain", str(path))
    assert_clean(code, stderr)
    if run and code == 0:  # it resolved: a short run must answer as cleanly
        out = folder / "run-out"
        shutil.rmtree(out, ignore_errors=True)
        code, stderr = run_cli(
            monkeypatch, capsys, "run", str(path), "--no-figures", "--out", str(out),
            "--set", "duration=1", "--set", "transient_s=0",
        )  # fmt: skip
        assert_clean(code, stderr, may_fail_run=True)
        shutil.rmtree(out, ignore_errors=True)


@settings(FUZZ, max_examples=EXAMPLES["scenario"])
# a key "\ud800\udc00" (two lone surrogates): a UnicodeEncodeError traceback in pydantic
@example(
    document=Pairs((*HORIZONTAL.items(), ("\U00010000", []))), ascii_only=True, damage=None, run=0
)
@given(
    document=mutated_document(SCENARIOS, SCENARIO_EXTRA),
    ascii_only=st.booleans(),
    damage=st.data(),
    run=st.integers(0, 7),
)
def test_fuzz_scenario_files(monkeypatch, capsys, quiet_cwd, document, ascii_only, damage, run):
    GENERATED["scenario"] += 1
    path = quiet_cwd / "scenario.yaml"
    text = yaml_document(document, ascii_only)
    path.write_bytes(text.encode() if damage is None else damage.draw(damaged_text(text)))
    _scenario_check(monkeypatch, capsys, quiet_cwd, path, run == 0)


@settings(FUZZ, max_examples=EXAMPLES["vehicle"])
@given(
    document=mutated_document([VEHICLE]),
    kind=st.sampled_from([HORIZONTAL, MPC, DEPTH, SIX_DOF]),
    as_plant=st.booleans(),
    damage=st.data(),
)
def test_fuzz_vehicle_files(monkeypatch, capsys, quiet_cwd, document, kind, as_plant, damage):
    GENERATED["vehicle"] += 1
    (quiet_cwd / "vehicle.yaml").write_bytes(damage.draw(damaged_text(yaml_document(document))))
    scenario = copy.deepcopy(kind)
    if as_plant and kind.get("kind") is None:  # the simulated vehicle, the model a preset
        scenario["plant"] = {"vehicle": "vehicle.yaml"}
    else:
        scenario["vehicle"] = "vehicle.yaml"
    path = quiet_cwd / "with-vehicle.yaml"
    path.write_text(yaml_document(scenario))
    _scenario_check(monkeypatch, capsys, quiet_cwd, path, run=False)


class _Checked(BaseException):
    """Raised by the stub after a campaign's checks: the campaign would start here."""


@settings(FUZZ, max_examples=EXAMPLES["campaign"])
# 10^8 runs: hours of checking every run before the first started, without a word
@example(
    document=Pairs(tuple({**CAMPAIGN, "runs": 10**8}.items())),
    base=Pairs(tuple(HORIZONTAL.items())),
    runs=None,
    controller=None,
    damage=None,
)
@given(
    document=mutated_document([CAMPAIGN]),
    base=mutated_document([HORIZONTAL]),
    runs=st.one_of(st.none(), st.integers(-1, 5), st.sampled_from([10**6, 10**30])),
    controller=CONTROLLER_LABELS,
    damage=st.data(),
)
def test_fuzz_campaign_files(
    monkeypatch, capsys, quiet_cwd, document, base, runs, controller, damage
):
    GENERATED["campaign"] += 1
    validate = execute.validate_campaign

    def checked_then_stop(campaign, *options):
        validate(campaign, *options)
        raise _Checked

    monkeypatch.setattr(execute, "validate_campaign", checked_then_stop)
    (quiet_cwd / "base.yaml").write_text(yaml_document(base))
    path = quiet_cwd / "campaign.yaml"
    text = yaml_document(document)
    path.write_bytes(text.encode() if damage is None else damage.draw(damaged_text(text)))
    out = quiet_cwd / "campaign-out"
    shutil.rmtree(out, ignore_errors=True)
    args = ["campaign", str(path), "--out", str(out), "--workers", "1", "--no-report"]
    args += [] if runs is None else ["--runs", str(runs)]
    args += [] if controller is None else ["--controller", controller]
    code, stderr = run_cli(monkeypatch, capsys, *args, stop=_Checked)
    assert_clean(code, stderr)
    assert code != 0, "the stub stops every campaign that passes its checks"


CSV_CELLS = st.one_of(
    st.floats(-1e3, 1e3).map(repr),
    st.sampled_from(
        [
            "nan", "inf", "-inf", "1e308", "-1e308", "1e400", "-0.0", "", " ", "x", "1,5",
            "0x10", "1_0", "9" * 400, "1e7", "10000001", "1e9", "1000000001", "١", '"1"', '"',
            "\x00", "\u202e1", "1e-300", "+1", " 1 ", "\t2",
        ]
    ),
    strings,
)  # fmt: skip


@st.composite
def csv_tracks(draw) -> str:
    """A t, x, y track: mostly well-formed rows, some cells hostile, the header varied."""
    header = draw(
        st.sampled_from(
            ["t,x,y", "t,x,y,z", "x,y,t", "t,x", "t,x,x,y", " t , x , y ", "T,X,Y", "", "t;x;y"]
        )
    )
    columns = len(header.split(",")) if header else 3
    rows = [header]
    t = draw(st.floats(-10, 10))
    for _ in range(draw(st.integers(0, 40))):
        t += draw(st.one_of(st.floats(1e-3, 5), st.sampled_from([0.0, -1.0, 1e-7, 1e6])))
        cells = [repr(t)] + [repr(draw(st.floats(-50, 50))) for _ in range(columns - 1)]
        if draw(st.integers(0, 5)) == 0:
            cells[draw(st.integers(0, len(cells) - 1))] = draw(CSV_CELLS)
        if draw(st.integers(0, 15)) == 0:
            cells = cells[: draw(st.integers(0, len(cells)))]
        rows.append(",".join(cells))
    end = draw(st.sampled_from(["\n", "\r\n", "\r", ""]))
    return end.join(rows) + end


CSV_PATHS = st.sampled_from(
    ["track.csv"] * 12 + ["", "missing.csv", ".", "/dev/null", "/dev/zero", "/proc/self/status",
     "fifo.csv", "track.csv/x", "\x00", "é.csv"]
)  # fmt: skip


@settings(FUZZ, max_examples=EXAMPLES["csv"])
# a pipe or a device as the track: open() waited forever before
@example(track="t,x,y\n0,0,0\n1,1,0\n2,2,0\n3,3,0\n", where="fifo.csv", damage=None)
@example(track="t,x,y\n0,0,0\n1,1,0\n2,2,0\n3,3,0\n", where="/dev/zero", damage=None)
@example(track="t,x,y\n0,0,0\n1,1,0\n2,2,0\n3,3,0\n", where="\x00", damage=None)  # ValueError
@given(track=csv_tracks(), where=CSV_PATHS, damage=st.data())
def test_fuzz_csv_tracks(monkeypatch, capsys, quiet_cwd, track, where, damage):
    GENERATED["csv"] += 1
    fifo = quiet_cwd / "fifo.csv"
    if not fifo.exists():
        import os

        os.mkfifo(fifo)
    data = track.encode() if damage is None else damage.draw(damaged_text(track))
    (quiet_cwd / "track.csv").write_bytes(data)
    scenario = copy.deepcopy(HORIZONTAL)
    scenario["reference"] = {"type": "csv", "path": where}
    scenario["initial_state"] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    path = quiet_cwd / "csv-scenario.yaml"
    path.write_text(yaml_document(scenario))
    _scenario_check(monkeypatch, capsys, quiet_cwd, path, run=False)


@settings(FUZZ, max_examples=EXAMPLES["set"])
# 1e308 s at 0.5 s is inf samples: an OverflowError traceback before
@example(scenario="paper-ideal", overrides=[("duration", "1e308")], separator="=", controller=None)
# newlines in the path split the error into several lines
@example(scenario="paper-ideal", overrides=[("\n.\n.0", "1e308")], separator="=", controller=None)
@given(
    scenario=st.sampled_from(["paper-ideal", "paper-obstacles", "paper-depth-calm", "paper-6dof"]),
    overrides=st.lists(st.tuples(SET_PATHS, SET_VALUES), min_size=1, max_size=3),
    separator=st.sampled_from(["="] * 8 + ["", "=="]),
    controller=CONTROLLER_LABELS,
)
def test_fuzz_set_overrides(
    monkeypatch, capsys, quiet_cwd, scenario, overrides, separator, controller
):
    GENERATED["set"] += 1
    args = ["explain", scenario]
    for path, value in overrides:
        args += ["--set", f"{path}{separator}{value}"]
    args += [] if controller is None else ["--controller", controller]
    code, stderr = run_cli(monkeypatch, capsys, *args)
    assert_clean(code, stderr)
