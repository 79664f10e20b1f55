"""`auvmpc animate` (issue 13): a GIF with at least one frame per simulated second, arrows
that are the logged thrust, obstacles that move and vanish, MP4 when an ffmpeg exists."""

from __future__ import annotations

import math

import numpy as np
import pytest
from PIL import Image

from auvmpc.animation import AnimationSettings, _Scene, frame_rows
from auvmpc.experiments.run import read_run, simulate, write_run
from auvmpc.models.vehicle import VehicleParams
from auvmpc.scenario import Scenario, load_scenario
from tests.test_cli import run_cli

DURATION_S = 10.0


@pytest.fixture(scope="module", params=["jmse2210", "bluerov2-heavy"])
def obstacle_run(request, tmp_path_factory):
    overrides = [f"duration={DURATION_S}", f"vehicle={request.param}"]
    result = simulate(load_scenario("paper-obstacles", overrides))
    return write_run(result, tmp_path_factory.mktemp("run") / "obs", figures=False)


def _loaded(run_dir):
    info, log = read_run(run_dir)
    return (
        log,
        Scenario.model_validate(info["scenario"]),
        VehicleParams.model_validate(info["model"]),
    )


def test_animate_writes_a_gif_with_a_frame_per_simulated_second(monkeypatch, capsys, obstacle_run):
    code, out, err = run_cli(monkeypatch, capsys, "animate", str(obstacle_run))
    assert code == 0, err
    gif = Image.open(obstacle_run / "animation.gif")
    log, *_ = _loaded(obstacle_run)
    assert gif.n_frames == len(frame_rows(log, AnimationSettings()))
    assert gif.n_frames >= DURATION_S  # the bar: >= 1 frame per simulated second
    assert gif.info["duration"] == 50  # ms per frame at the default 20 fps
    # Running it again replaces auvmpc's own animation.gif in the run folder.
    code, _, err = run_cli(monkeypatch, capsys, "animate", str(obstacle_run))
    assert code == 0, err


def test_frame_rows_follow_speed_and_keep_the_last_row(obstacle_run):
    log, *_ = _loaded(obstacle_run)
    rows = frame_rows(log, AnimationSettings(fps=10, speed=30))  # every 3 s = 6 samples
    assert list(rows) == [0, 6, 12, 18, 20]


def test_thrust_arrows_are_the_logged_thrust_in_the_world_frame(obstacle_run):
    log, scenario, model = _loaded(obstacle_run)
    scene = _Scene(log, scenario, model, AnimationSettings())
    k = 7
    scene.draw(k)
    x, y, psi = log.state[k, :3]
    quiver = scene.parts["zoom"]["quiver"]
    length = scene.arrow_length["zoom"]
    peak = max(abs(v) for v in model.thrust_limits)
    for i, thruster in enumerate(model.thrusters):
        px, py = thruster.position
        origin = (
            x + px * math.cos(psi) - py * math.sin(psi),
            y + px * math.sin(psi) + py * math.cos(psi),
        )
        heading = psi + math.radians(thruster.angle_deg)
        vector = log.thrust[k, i] / peak * length * np.array([math.cos(heading), math.sin(heading)])
        np.testing.assert_allclose(quiver.get_offsets()[i], origin, atol=1e-12)
        np.testing.assert_allclose([quiver.U[i], quiver.V[i]], vector, atol=1e-12)


def test_a_moving_obstacle_moves_and_vanishes(tmp_path):
    scenario = load_scenario(
        "paper-ideal",
        [
            "duration=4",
            "obstacles=[{center: [30, 0], radius: 0.5, velocity: [1, 0], vanish_time: 2}]",
        ],
    )
    run_dir = write_run(simulate(scenario), tmp_path / "run", figures=False)
    log, scenario, model = _loaded(run_dir)
    scene = _Scene(log, scenario, model, AnimationSettings())
    (disc,) = scene.parts["main"]["discs"]
    scene.draw(2)  # t = 1 s
    assert disc.center == pytest.approx((31.0, 0.0)) and disc.get_visible()
    scene.draw(6)  # t = 3 s, after vanish_time
    assert not disc.get_visible()


def test_mp4_when_an_ffmpeg_is_there(monkeypatch, capsys, tmp_path, obstacle_run):
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    out = tmp_path / "run.mp4"
    code, _, err = run_cli(monkeypatch, capsys, "animate", str(obstacle_run), "--out", str(out))
    assert code == 0, err
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(out))
    log, *_ = _loaded(obstacle_run)
    assert frames == len(frame_rows(log, AnimationSettings()))


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--out", "a.avi"], "--out: must end in .gif or .mp4 (got 'a.avi')"),
        (["--fps", "0"], "--fps: must be between 1 and 60 (got 0.0)"),
        (["--speed", "-1"], "--speed: must be between 0.1 and 1000 (got -1.0)"),
    ],
)
def test_bad_options_are_one_line(monkeypatch, capsys, tmp_path, obstacle_run, extra, message):
    monkeypatch.chdir(tmp_path)
    code, _, err = run_cli(monkeypatch, capsys, "animate", str(obstacle_run), *extra)
    assert code == 2
    assert message in err and len(err.strip().splitlines()) == 1


def test_an_existing_out_file_is_never_replaced(monkeypatch, capsys, tmp_path, obstacle_run):
    mine = tmp_path / "mine.gif"
    mine.write_bytes(b"mine")
    code, _, err = run_cli(monkeypatch, capsys, "animate", str(obstacle_run), "--out", str(mine))
    assert code == 2 and "--out: exists" in err
    assert mine.read_bytes() == b"mine"


def test_a_depth_run_is_refused(monkeypatch, capsys, tmp_path):
    scenario = load_scenario("paper-depth-calm", ["duration=2", "reference.step_time_s=1"])
    run_dir = write_run(simulate(scenario), tmp_path / "depth", figures=False)
    code, _, err = run_cli(monkeypatch, capsys, "animate", str(run_dir))
    assert code == 2 and "a depth run; animate takes horizontal and 6-DOF runs" in err
