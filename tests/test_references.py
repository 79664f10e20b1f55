"""Reference trajectories against analytic truth, finite differences and bad input."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from pydantic import TypeAdapter, ValidationError

from auvmpc.errors import ConfigError
from auvmpc.references import (
    REFERENCE_TYPES,
    Circle,
    CircleConfig,
    CsvConfig,
    FigureEight,
    FigureEightConfig,
    HelixConfig,
    Lawnmower,
    LawnmowerConfig,
    Line,
    LineConfig,
    PaperOval,
    PaperOvalConfig,
    Reference,
    ReferenceConfig,
    SampledPath,
    WaypointPath,
    Waypoints3DConfig,
    WaypointsConfig,
    make_reference,
)

# Closed forms evaluated two ways agree to round-off on values of order 10-100.
EXACT_TOL = 1e-12
# Same quantity from a batch query and a one-time query: allows a few ulp from SIMD vs scalar
# libm paths, far below the 2 pi that a wrong unwrapping would show.
QUERY_TOL = 1e-9
# Central-difference step, s: truncation h^2 |f'''|/6 ~ 1e-9 and round-off eps |f|/h ~ 1e-10.
FD_STEP = 1e-4
# Agreement of u, r, psi with central differences of position and heading.
FD_TOL = 1e-6
# Dense grid step, s, for continuity checks: a sample-to-sample change may be max|rate| * step.
DENSE_STEP = 0.01
# Cubic-spline round trip of a circle sampled every 0.5 s (omega h = 0.025 rad), 5 s from the
# not-a-knot ends: observed errors are 1e-8 m, 1e-7 rad, 1e-9 m/s, 3e-6 rad/s; bounds allow ~10x.
CSV_POS_TOL = 1e-7
CSV_PSI_TOL = 1e-6
CSV_SPEED_TOL = 1e-8
CSV_RATE_TOL = 3e-5

PAPER_ARC_SPEED = 8.0 * 2.0 * math.pi / 100.0  # 0.16 pi m/s
PAPER_ARC_RATE = 2.0 * math.pi / 100.0  # 0.02 pi rad/s


def _wrap(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _circle_track(radius: float, speed: float, t: np.ndarray) -> np.ndarray:
    omega = speed / radius
    return np.column_stack((radius * np.cos(omega * t), radius * np.sin(omega * t)))


def _laps_track() -> SampledPath:
    """Three counter-clockwise laps of a wobbly loop, sampled every 0.5 s, as data."""
    t = np.arange(0.0, 3 * 60.0 + 0.25, 0.5)
    phase = 2 * np.pi * t / 60.0
    radius = 6.0 + 1.0 * np.sin(3 * phase)
    return SampledPath(t, np.column_stack((radius * np.cos(phase), radius * np.sin(phase))))


# Every type, with the window of times the generic tests scan (includes before/after the path).
CASES: dict[str, tuple[Reference, float, float]] = {
    "paper-oval": (PaperOval(), -10.0, 110.0),
    "circle-ccw": (Circle(CircleConfig(center=(1.0, -2.0), radius=5.0, speed=0.7)), -20.0, 120.0),
    "circle-cw": (
        Circle(CircleConfig(radius=3.0, speed=0.4, direction="cw", start_angle_deg=135.0)),
        -20.0,
        120.0,
    ),
    "figure-eight": (FigureEight(FigureEightConfig(size=8.0, period=90.0)), -30.0, 200.0),
    "line": (Line(LineConfig(start=(3.0, 4.0), heading_deg=200.0, speed=0.6)), -10.0, 30.0),
    "waypoints": (
        WaypointPath(
            WaypointsConfig(
                points=((0.0, 0.0), (10.0, 0.0), (12.0, 8.0), (-5.0, 9.0), (-4.0, -6.0)),
                speed=0.5,
                corner_radius=2.0,
            )
        ),
        -5.0,
        120.0,
    ),
    "sampled": (_laps_track(), -5.0, 185.0),
}


def _away_from_joints(ref: Reference, t: np.ndarray) -> np.ndarray:
    near = np.zeros(t.shape, dtype=bool)
    for b in ref.breakpoints:
        near |= np.abs(t - b) < 3 * FD_STEP
    return t[~near]


# ------------------------------------------------------------------------------------------------
# Every type
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", CASES)
def test_state_agrees_with_finite_differences(name: str) -> None:
    ref, t_a, t_b = CASES[name]
    t = _away_from_joints(ref, np.linspace(t_a, t_b, 2001))
    mid, plus, minus = ref.states(t), ref.states(t + FD_STEP), ref.states(t - FD_STEP)
    velocity = (plus[:, :2] - minus[:, :2]) / (2 * FD_STEP)
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    np.testing.assert_allclose(mid[:, 3], speed, atol=FD_TOL)
    np.testing.assert_allclose(mid[:, 5], (plus[:, 2] - minus[:, 2]) / (2 * FD_STEP), atol=FD_TOL)
    np.testing.assert_array_equal(mid[:, 4], 0.0)
    moving = mid[:, 3] > 0.0
    assert moving.sum() > 100  # the check below must have something to check
    heading_error = _wrap(mid[moving, 2] - np.arctan2(velocity[moving, 1], velocity[moving, 0]))
    np.testing.assert_allclose(heading_error, 0.0, atol=FD_TOL)


@pytest.mark.parametrize("name", CASES)
def test_heading_independent_of_query_grid(name: str) -> None:
    ref, t_a, t_b = CASES[name]
    dense_t = np.linspace(t_a, t_b, 40001)
    dense = ref.states(dense_t)
    step = dense_t[1] - dense_t[0]
    max_rate = np.max(np.abs(dense[:, 5]))
    # Dense psi is continuous: no jump beyond what the yaw rate allows (plus a tiny slack).
    assert np.max(np.abs(np.diff(dense[:, 2]))) <= max_rate * step + 1e-9
    # Controller-style horizons (0.5 s x 31) starting anywhere agree with the dense grid.
    for k in range(0, int((t_b - t_a) / 0.5) - 31, 7):
        horizon = ref.preview(t_a + 0.5 * k, 0.5, 31)
        t_h = t_a + 0.5 * k + 0.5 * np.arange(31)
        interp = np.interp(t_h, dense_t, dense[:, 2])
        np.testing.assert_allclose(horizon[:, 2], interp, atol=max_rate * step + 1e-9)
    # A single-time query gives the same row as a batch containing it, in any order.
    picks = np.array([t_b, t_a, 0.5 * (t_a + t_b), t_a + 0.37 * (t_b - t_a)])
    batch = ref.states(picks)
    for i, ti in enumerate(picks):
        np.testing.assert_allclose(ref.state(float(ti)), batch[i], atol=QUERY_TOL)


@pytest.mark.parametrize("name", CASES)
def test_position_continuous_at_breakpoints(name: str) -> None:
    ref, _, _ = CASES[name]
    for b in ref.breakpoints:
        left, right = ref.state(b - 1e-9), ref.state(b)
        np.testing.assert_allclose(left[:2], right[:2], atol=1e-8)
        np.testing.assert_allclose(left[2], right[2], atol=1e-8)  # heading continuous too


def test_states_rejects_bad_time_arrays() -> None:
    ref = PaperOval()
    with pytest.raises(ValueError, match="1-D"):
        ref.states(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="finite"):
        ref.states([0.0, np.nan])
    with pytest.raises(ValueError, match="dt > 0"):
        ref.preview(0.0, 0.0, 5)


def test_preview_uses_integer_steps() -> None:
    ref = Circle(CircleConfig())
    horizon = ref.preview(1000.0, 0.1, 31)
    np.testing.assert_array_equal(horizon, ref.states(1000.0 + 0.1 * np.arange(31)))
    assert ref.preview(0.0, 0.5, 0).shape == (0, 6)


# ------------------------------------------------------------------------------------------------
# Paper oval (paper-model.md section 5)
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("t", "expected"),
    [
        (0.0, [8.0, -12.0, math.pi / 2, 0.5, 0.0, 0.0]),
        (12.0, [8.0, -6.0, math.pi / 2, 0.5, 0.0, 0.0]),
        # arc quarter: angle 2 pi 25/100 = pi/2 -> (0, 8), heading pi
        (49.0, [0.0, 8.0, math.pi, PAPER_ARC_SPEED, 0.0, PAPER_ARC_RATE]),
        # arc at angle 2 pi 40/100 = 0.8 pi
        (
            64.0,
            [8 * math.cos(0.8 * math.pi), 8 * math.sin(0.8 * math.pi), 1.3 * math.pi]
            + [PAPER_ARC_SPEED, 0.0, PAPER_ARC_RATE],
        ),
        (87.0, [-8.0, -6.5, 1.5 * math.pi, 0.5, 0.0, 0.0]),
        (100.0, [-8.0, -13.0, 1.5 * math.pi, 0.5, 0.0, 0.0]),
        # the straights' formulas continue outside 0..100
        (-4.0, [8.0, -14.0, math.pi / 2, 0.5, 0.0, 0.0]),
        (110.0, [-8.0, -18.0, 1.5 * math.pi, 0.5, 0.0, 0.0]),
    ],
)
def test_paper_oval_matches_section_5(t: float, expected: list[float]) -> None:
    np.testing.assert_allclose(PaperOval().state(t), expected, atol=EXACT_TOL)


def test_paper_oval_joints() -> None:
    ref = PaperOval()
    for joint in (24.0, 74.0):
        np.testing.assert_allclose(ref.state(joint - 1e-9)[:2], ref.state(joint)[:2], atol=1e-8)
    np.testing.assert_allclose(ref.state(24.0)[:2], [8.0, 0.0], atol=EXACT_TOL)
    np.testing.assert_allclose(ref.state(74.0)[:2], [-8.0, 0.0], atol=EXACT_TOL)
    # Derivatives from the right: t = 24 is on the arc, t = 74 on the last straight.
    assert ref.state(24.0)[3] == pytest.approx(0.16 * math.pi, abs=EXACT_TOL)
    assert ref.state(24.0)[5] == pytest.approx(PAPER_ARC_RATE, abs=EXACT_TOL)
    assert ref.state(24.0 - 1e-9)[3] == pytest.approx(0.5, abs=EXACT_TOL)
    assert ref.state(74.0)[3] == pytest.approx(0.5, abs=EXACT_TOL)
    assert ref.state(74.0)[5] == 0.0
    assert ref.state(74.0 - 1e-9)[5] == pytest.approx(PAPER_ARC_RATE, abs=EXACT_TOL)
    assert ref.end_time == 100.0


def test_paper_oval_heading_unwrapped_over_the_run() -> None:
    ref = PaperOval()
    psi = ref.states(np.arange(0, 10001) * DENSE_STEP)[:, 2]  # 0..100 s
    assert np.max(np.abs(np.diff(psi))) <= PAPER_ARC_RATE * DENSE_STEP + EXACT_TOL
    # pi/2 on the first straight, +pi through the CCW arc: 3 pi/2 (not -pi/2) at the end.
    assert psi[0] == pytest.approx(math.pi / 2, abs=EXACT_TOL)
    assert psi[-1] == pytest.approx(1.5 * math.pi, abs=EXACT_TOL)


# ------------------------------------------------------------------------------------------------
# Circle, figure-eight, line
# ------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("direction", "sign"), [("ccw", 1.0), ("cw", -1.0)])
def test_circle_speed_rate_and_lap(direction: str, sign: float) -> None:
    radius, speed = 4.0, 0.8
    ref = Circle(CircleConfig(center=(2.0, 3.0), radius=radius, speed=speed, direction=direction))
    t = np.linspace(-10.0, 60.0, 701)
    s = ref.states(t)
    np.testing.assert_allclose(s[:, 3], speed, atol=EXACT_TOL)
    np.testing.assert_allclose(s[:, 5], sign * speed / radius, atol=EXACT_TOL)
    np.testing.assert_allclose(np.hypot(s[:, 0] - 2.0, s[:, 1] - 3.0), radius, atol=EXACT_TOL)
    lap = 2 * math.pi * radius / speed
    after = ref.states(t + lap)
    np.testing.assert_allclose(after[:, 2] - s[:, 2], sign * 2 * math.pi, atol=QUERY_TOL)
    np.testing.assert_allclose(after[:, :2], s[:, :2], atol=QUERY_TOL)
    np.testing.assert_allclose(ref.state(0.0)[:3], [6.0, 3.0, sign * math.pi / 2], atol=EXACT_TOL)


def test_circle_start_heading_in_principal_range() -> None:
    # start angle 180 deg, ccw: tangent is 3 pi/2, reported as -pi/2 at t = 0
    ref = Circle(CircleConfig(radius=2.0, start_angle_deg=180.0))
    np.testing.assert_allclose(ref.state(0.0)[:3], [-2.0, 0.0, -math.pi / 2], atol=EXACT_TOL)


def test_figure_eight_shape_and_periodic_heading() -> None:
    a, period = 6.0, 80.0
    ref = FigureEight(FigureEightConfig(center=(1.0, 2.0), size=a, period=period))
    t = np.linspace(0.0, period, 801)
    w = 2 * math.pi / period
    s = ref.states(t)
    np.testing.assert_allclose(s[:, 0], 1.0 + a * np.sin(w * t), atol=EXACT_TOL)
    np.testing.assert_allclose(s[:, 1], 2.0 + 0.5 * a * np.sin(2 * w * t), atol=EXACT_TOL)
    assert s[0, 2] == pytest.approx(math.pi / 4, abs=EXACT_TOL)
    # The two loops turn opposite ways: heading returns to its value after one period.
    np.testing.assert_allclose(ref.states(t + 3 * period)[:, 2], s[:, 2], atol=QUERY_TOL)
    assert np.min(s[:, 3]) > 0.0  # never stops, so the heading is always defined


def test_line() -> None:
    ref = Line(LineConfig(start=(1.0, 1.0), heading_deg=270.0, speed=2.0))
    np.testing.assert_allclose(ref.state(3.0), [1.0, -5.0, -math.pi / 2, 2.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(ref.state(-1.0)[:2], [1.0, 3.0], atol=EXACT_TOL)


# ------------------------------------------------------------------------------------------------
# Waypoints
# ------------------------------------------------------------------------------------------------


def test_waypoints_square_geometry() -> None:
    radius, speed = 2.0, 0.5
    points = ((0.0, 0.0), (20.0, 0.0), (20.0, 20.0), (0.0, 20.0))
    ref = WaypointPath(WaypointsConfig(points=points, speed=speed, corner_radius=radius))
    # straights 18 + 16 + 18 m, two quarter arcs of radius 2
    assert ref.end_time == pytest.approx((52.0 + 2 * math.pi) / speed, abs=EXACT_TOL)
    np.testing.assert_allclose(ref.corner_radii, radius)
    t = np.arange(0, int(ref.end_time / DENSE_STEP) + 1) * DENSE_STEP
    s = ref.states(t)
    moving = t < ref.end_time
    np.testing.assert_allclose(s[moving, 3], speed, atol=EXACT_TOL)
    # The arc's closest approach to a 90 deg corner is R (1/cos 45 deg - 1) = R (sqrt 2 - 1), at
    # the arc's midpoint; pieces are line, arc, line, arc, line, so arcs span breakpoints 1-2, 3-4.
    closest = radius * (math.sqrt(2) - 1)
    b = ref.breakpoints
    for corner, mid_t in zip(points[1:-1], [0.5 * (b[1] + b[2]), 0.5 * (b[3] + b[4])], strict=True):
        gap = np.hypot(s[:, 0] - corner[0], s[:, 1] - corner[1])
        assert np.min(gap) >= closest - EXACT_TOL  # never closer than the arc allows
        assert np.hypot(*(ref.state(mid_t)[:2] - corner)) == pytest.approx(closest, abs=EXACT_TOL)
    assert set(np.round(np.unique(s[moving, 5]), 12)) == {0.0, round(speed / radius, 12)}
    assert ref.corners == 2


def test_waypoints_hold_at_both_ends() -> None:
    points = ((0.0, 0.0), (20.0, 0.0), (20.0, 20.0), (0.0, 20.0))
    ref = WaypointPath(WaypointsConfig(points=points, speed=0.5, corner_radius=2.0))
    after = ref.states(ref.end_time + np.array([0.0, 1.0, 100.0]))
    # Final leg heads -x after two left turns: unwrapped heading pi.
    np.testing.assert_allclose(after, np.tile([0.0, 20.0, math.pi, 0.0, 0.0, 0.0], (3, 1)))
    before = ref.states(np.array([-50.0, -1e-9]))
    np.testing.assert_allclose(before, np.zeros((2, 6)), atol=EXACT_TOL)
    np.testing.assert_allclose(ref.state(0.0), [0.0, 0.0, 0.0, 0.5, 0.0, 0.0], atol=EXACT_TOL)


def test_waypoints_shrink_corner_on_short_leg() -> None:
    speed = 0.5
    points = ((0.0, 0.0), (10.0, 0.0), (10.0, 1.0), (0.0, 1.0))
    ref = WaypointPath(WaypointsConfig(points=points, speed=speed, corner_radius=2.0))
    # The 1 m leg is shared by two 90 deg corners: tangent length 0.5 m each, so radius 0.5 m.
    np.testing.assert_allclose(ref.corner_radii, [0.5, 0.5], atol=EXACT_TOL)
    s = ref.states(np.arange(0, int(ref.end_time / DENSE_STEP) + 1) * DENSE_STEP)
    assert np.max(np.abs(s[:, 5])) == pytest.approx(speed / 0.5, abs=EXACT_TOL)
    assert np.max(np.hypot(*np.diff(s[:, :2], axis=0).T)) <= speed * DENSE_STEP + EXACT_TOL
    # A first or last leg has a corner at one end only, so that corner may use all of it.
    hook = ((0.0, 0.0), (1.0, 0.0), (1.0, 10.0), (-9.0, 10.0), (-9.0, 9.0))
    ref = WaypointPath(WaypointsConfig(points=hook, speed=speed, corner_radius=2.0))
    np.testing.assert_allclose(ref.corner_radii, [1.0, 2.0, 1.0], atol=EXACT_TOL)
    np.testing.assert_allclose(ref.state(ref.end_time)[:2], hook[-1], atol=EXACT_TOL)


def test_waypoints_collinear_and_two_points() -> None:
    straight = WaypointPath(WaypointsConfig(points=((0.0, 0.0), (5.0, 0.0), (10.0, 0.0))))
    s = straight.states(np.linspace(0.0, 19.9, 200))
    np.testing.assert_array_equal(s[:, 5], 0.0)
    np.testing.assert_allclose(s[:, 1:3], 0.0, atol=EXACT_TOL)
    assert straight.corners == 0  # the middle waypoint is passed, not turned at
    bend = WaypointPath(WaypointsConfig(points=((0.0, 0.0), (5.0, 0.0), (10.0, 1.0))))
    assert bend.corners == 0  # an 11-degree bend is no corner (CORNER_TURN_DEG)
    pair = WaypointPath(WaypointsConfig(points=((1.0, 1.0), (1.0, -3.0)), speed=2.0))
    assert pair.end_time == pytest.approx(2.0)
    np.testing.assert_allclose(pair.state(1.0), [1.0, -1.0, -math.pi / 2, 2.0, 0.0, 0.0])


# ------------------------------------------------------------------------------------------------
# CSV track
# ------------------------------------------------------------------------------------------------


def _write_csv(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_csv_round_trip_of_a_circle(tmp_path: Path) -> None:
    radius, speed = 10.0, 0.5
    t = np.arange(0, 301) * 0.5  # 150 s, more than one lap (125.7 s)
    xy = _circle_track(radius, speed, t)
    lines = ["t,x,y,note"] + [
        f"{ti!r},{x!r},{y!r},lap" for ti, (x, y) in zip(t.tolist(), xy.tolist(), strict=True)
    ]
    _write_csv(tmp_path / "track.csv", "\n".join(lines) + "\n")
    ref = make_reference(CsvConfig(path="track.csv"), base_dir=tmp_path)
    truth = Circle(CircleConfig(radius=radius, speed=speed))
    # Interior times: the not-a-knot end conditions are least accurate near the ends.
    q = np.linspace(5.0, 145.0, 2801)
    got, want = ref.states(q), truth.states(q)
    np.testing.assert_allclose(got[:, :2], want[:, :2], atol=CSV_POS_TOL)
    np.testing.assert_allclose(got[:, 2], want[:, 2], atol=CSV_PSI_TOL)  # same unwrapping
    np.testing.assert_allclose(got[:, 3], speed, atol=CSV_SPEED_TOL)
    np.testing.assert_allclose(got[:, 5], speed / radius, atol=CSV_RATE_TOL)
    assert ref.end_time == 150.0


def test_csv_holds_outside_its_times() -> None:
    t = np.arange(0, 21) * 0.5 + 3.0
    ref = SampledPath(t, _circle_track(5.0, 0.5, t))
    last = ref.state(t[-1] - 1e-12)
    for late in (t[-1], t[-1] + 1.0, t[-1] + 1e4):
        np.testing.assert_allclose(ref.state(late)[:3], last[:3], atol=1e-9)
        np.testing.assert_array_equal(ref.state(late)[3:], 0.0)
    early = ref.state(-100.0)
    np.testing.assert_allclose(early[:3], ref.state(t[0])[:3], atol=EXACT_TOL)
    np.testing.assert_array_equal(early[3:], 0.0)


def test_sampled_track_unwraps_through_several_laps() -> None:
    ref = _laps_track()
    start, end = ref.state(0.0)[2], ref.state(180.0)[2]
    # Three CCW laps of a star-free loop: the heading gains 6 pi.
    assert end - start == pytest.approx(6 * math.pi, abs=1e-3)


def test_sampled_track_that_never_moves() -> None:
    ref = SampledPath([0.0, 1.0, 2.0, 3.0], [[1.0, 2.0]] * 4)
    np.testing.assert_allclose(ref.states([-1.0, 1.5, 9.0]), [[1.0, 2.0, 0, 0, 0, 0]] * 3)


def test_csv_relative_to_base_dir_and_absolute(tmp_path: Path) -> None:
    sub = tmp_path / "scenarios"
    sub.mkdir()
    _write_csv(sub / "a.csv", "t,x,y\n0,0,0\n1,1,0\n2,2,0\n3,3,0\n")
    rel = make_reference(CsvConfig(path="a.csv"), base_dir=sub)
    absolute = make_reference(CsvConfig(path=str(sub / "a.csv")), base_dir=tmp_path)
    np.testing.assert_allclose(rel.state(1.5), [1.5, 0.0, 0.0, 1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_array_equal(rel.states([0.5, 2.5]), absolute.states([0.5, 2.5]))
    with pytest.raises(ConfigError, match=r"reference\.path: no such CSV track"):
        make_reference(CsvConfig(path="a.csv"), base_dir=tmp_path)


GOOD_ROWS = "0,0,0\n1,1,0\n2,2,1\n3,3,3\n"


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("", r"^reference\.path: empty file"),
        ("\n\n", r"^reference\.path: empty file"),
        ("t,x\n0,0\n1,1\n2,2\n3,3\n", r"^reference\.path: missing column 'y'"),
        ("t,x,y,x\n0,0,0,0\n", r"^reference\.path: column 'x' appears more than once"),
        ("t,x,y\n" + GOOD_ROWS + "4,abc,0\n", r"^reference\.path:6: column 'x' is not a number"),
        ("t,x,y\n0,0,0\n1,nan,0\n2,2,1\n3,3,3\n", r"^reference\.path:3: column 'x' is not finite"),
        ("t,x,y\n0,0,0\n1,1,-inf\n2,2,1\n3,3,3\n", r"^reference\.path:3: column 'y' is not finite"),
        ("t,x,y\n0,0,0\n2,1,0\n1,2,1\n3,3,3\n", r"^reference\.path:4: t must be strictly"),
        ("t,x,y\n0,0,0\n1,1,0\n1,2,1\n3,3,3\n", r"^reference\.path:4: t must be strictly"),
        ("t,x,y\n0,0,0\n1,1e300,0\n2,2,1\n3,3,3\n", r"^reference\.path:3: column 'x' is beyond"),
        ("t,x,y\n0,0,0\n1,1,0\n2,2,-2e7\n3,3,3\n", r"^reference\.path:4: column 'y' is beyond"),
        ("t,x,y\n0,0,0\n1e300,1,0\n2e300,2,1\n3e300,3,3\n", r"^reference\.path:3: column 't'"),
        ("t,x,y\n0,0,0\n1e-300,1,0\n2e-300,2,1\n1,3,3\n", r"^reference\.path:3: t must be at"),
        ("t,x,y\n0,0,0\n1,1,0\nNaN,2,1\n3,3,3\n", r"^reference\.path:4: column 't' is not finite"),
        ("t,x,y\n0,0,0\n1,1\n2,2,1\n3,3,3\n", r"^reference\.path:3: expected 3 fields"),
        ("t,x,y\n0,0,0\n1,1,0\n2,2,1\n", r"^reference\.path: needs at least 4 data rows, found 3"),
        ("t,x,y\n", r"^reference\.path: needs at least 4 data rows, found 0"),
    ],
)
def test_csv_bad_files(tmp_path: Path, text: str, match: str) -> None:
    _write_csv(tmp_path / "bad.csv", text)
    with pytest.raises(ConfigError, match=match) as info:
        make_reference(CsvConfig(path="bad.csv"), base_dir=tmp_path)
    assert "\n" not in str(info.value)  # one line for the CLI


def test_csv_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"^reference\.path: no such CSV track.*missing\.csv"):
        make_reference(CsvConfig(path="missing.csv"), base_dir=tmp_path)
    (tmp_path / "folder.csv").mkdir()
    with pytest.raises(ConfigError, match=r"^reference\.path: is a folder"):
        make_reference(CsvConfig(path="folder.csv"), base_dir=tmp_path)
    (tmp_path / "binary.csv").write_bytes(b"t,x,y\n\xff\xfe,0,0\n")
    with pytest.raises(ConfigError, match=r"^reference\.path: is not UTF-8"):
        make_reference(CsvConfig(path="binary.csv"), base_dir=tmp_path)


# ------------------------------------------------------------------------------------------------
# Config models and factory
# ------------------------------------------------------------------------------------------------

ADAPTER = TypeAdapter(ReferenceConfig)


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"type": "circle", "radius": -1.0}, "radius"),
        ({"type": "circle", "radius": 0.0}, "radius"),
        ({"type": "circle", "speed": -0.5}, "speed"),
        ({"type": "circle", "radius": float("nan")}, "radius"),
        ({"type": "circle", "radus": 3.0}, "radus"),
        ({"type": "circle", "direction": "left"}, "direction"),
        ({"type": "circle", "center": [1.0]}, "center"),
        ({"type": "spiral"}, "spiral"),
        ({"radius": 3.0}, "type"),
        ({"type": "paper-oval", "speed": 1.0}, "speed"),
        ({"type": "figure-eight", "period": 0.0}, "period"),
        ({"type": "figure-eight", "size": -2.0}, "size"),
        ({"type": "line", "speed": 0.0}, "speed"),
        ({"type": "line", "heading_deg": float("inf")}, "heading_deg"),
        ({"type": "waypoints", "points": [[0, 0]]}, "points"),
        ({"type": "waypoints", "points": [[0, 0], [1, 1]], "corner_radius": -1}, "corner_radius"),
        ({"type": "waypoints", "points": [[0, 0], [1, 1], [1, 1]]}, r"points\[2\].*equals"),
        ({"type": "waypoints", "points": [[0, 0], [4, 0], [1, 0]]}, "reverses"),
        ({"type": "waypoints", "speed": 1.0}, "points"),
        ({"type": "csv"}, "path"),
        ({"type": "csv", "path": ""}, "path"),
    ],
)
def test_config_validation(data: dict, match: str) -> None:
    with pytest.raises(ValidationError, match=match):
        ADAPTER.validate_python(data)


def test_configs_documented_and_types_listed() -> None:
    models = (
        PaperOvalConfig,
        CircleConfig,
        FigureEightConfig,
        LineConfig,
        WaypointsConfig,
        CsvConfig,
        HelixConfig,
        LawnmowerConfig,
        Waypoints3DConfig,
    )
    assert REFERENCE_TYPES == (
        "paper-oval", "circle", "figure-eight", "line", "waypoints", "csv",
        "helix", "lawnmower", "waypoints-3d",
    )  # fmt: skip
    for model, name in zip(models, REFERENCE_TYPES, strict=True):
        assert model.model_fields["type"].default == name
        for field_name, field in model.model_fields.items():
            assert field.description, f"{model.__name__}.{field_name} has no description"


@pytest.mark.parametrize(
    ("data", "cls"),
    [
        ({"type": "paper-oval"}, PaperOval),
        ({"type": "circle", "center": [0, 0], "radius": 10, "speed": 0.5}, Circle),
        ({"type": "figure-eight"}, FigureEight),
        ({"type": "line", "heading_deg": 45}, Line),
        ({"type": "waypoints", "points": [[0, 0], [20, 0], [20, 5]], "speed": 0.5}, WaypointPath),
    ],
)
def test_make_reference_builds_each_type(data: dict, cls: type) -> None:
    ref = make_reference(ADAPTER.validate_python(data))
    assert isinstance(ref, cls)
    assert ref.states(np.linspace(0.0, 10.0, 5)).shape == (5, 6)


def test_make_reference_rejects_other_objects() -> None:
    with pytest.raises(TypeError, match="not a reference config"):
        make_reference({"type": "circle"})  # type: ignore[arg-type]


# --- 3-D references: depth with exact derivatives ------------------------------------------


@pytest.mark.parametrize(
    "data",
    [
        {"type": "helix", "radius": 3.0, "speed": 0.3, "descent_per_turn_m": 1.0},
        {"type": "lawnmower", "depths_m": [1.0, 2.0, 3.0, 2.0], "legs": 4},
        {"type": "waypoints-3d", "points": [[0, 0, 1], [10, 0, 2], [10, 10, 2], [0, 10, 0.5]]},
        {
            "type": "paper-oval",
            "depth": {"start_m": 1.0, "changes": [{"time_s": 10, "depth_m": 2, "duration_s": 20}]},
        },
    ],
)
def test_depth_derivatives_are_exact(data: dict) -> None:
    """z' and z'' agree with central differences of z and z' (so they are the derivatives)."""
    ref = make_reference(ADAPTER.validate_python(data))
    assert ref.has_depth
    h = 1e-4
    t = np.linspace(-5.0, 200.0, 4001)
    rows, ahead, behind = ref.depths(t), ref.depths(t + h), ref.depths(t - h)
    assert np.allclose((ahead[:, 0] - behind[:, 0]) / (2 * h), rows[:, 1], atol=1e-7)
    assert np.allclose((ahead[:, 1] - behind[:, 1]) / (2 * h), rows[:, 2], atol=1e-6)


def test_helix_descends_one_turn_depth_per_turn() -> None:
    ref = make_reference(
        ADAPTER.validate_python(
            {"type": "helix", "radius": 3.0, "speed": 0.3, "descent_per_turn_m": 1.0}
        )
    )
    turn = 2 * math.pi * 3.0 / 0.3
    assert ref.depths([0.0, turn])[:, 0] == pytest.approx([1.0, 2.0])
    assert np.allclose(ref.states([0.0, turn])[:, :2], ref.states([0.0, 0.0])[:, :2])


def test_lawnmower_changes_depth_in_the_turns_only() -> None:
    ref = make_reference(
        ADAPTER.validate_python({"type": "lawnmower", "legs": 2, "depths_m": [1.0, 2.0]})
    )
    assert isinstance(ref, Lawnmower)
    t = np.linspace(0.0, ref.end_time, 2001)
    straight = ref.states(t)[:, 5] == 0.0
    depth = ref.depths(t)
    assert np.all(depth[straight, 1] == 0.0)
    assert depth[0, 0] == 1.0 and depth[-1, 0] == 2.0
    assert ref.corners == 2  # one half-circle turn: two quarter-circle corners


def test_waypoints_3d_reach_each_depth_at_each_waypoint() -> None:
    ref = make_reference(
        ADAPTER.validate_python(
            {"type": "waypoints-3d", "points": [[0, 0, 1], [10, 0, 3], [10, 10, 2]]}
        )
    )
    passing = ref._path.corner_times.mean(axis=1)
    assert ref.depths([0.0, *passing, ref.end_time])[:, 0] == pytest.approx([1.0, 3.0, 2.0])


def test_planar_reference_has_no_depth_and_is_unchanged() -> None:
    planar = make_reference(ADAPTER.validate_python({"type": "paper-oval"}))
    deep = make_reference(ADAPTER.validate_python({"type": "paper-oval", "depth": {"start_m": 2}}))
    assert not planar.has_depth
    with pytest.raises(ValueError, match="planar reference has no depth"):
        planar.depths([0.0])
    t = np.linspace(0.0, 100.0, 201)
    assert np.array_equal(planar.states(t), deep.states(t))


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"type": "lawnmower", "legs": 3, "depths_m": [1, 2]}, "need 1 or 3 values"),
        ({"type": "lawnmower", "leg_length": 3, "spacing": 4}, "must exceed spacing"),
        ({"type": "waypoints-3d", "points": [[0, 0, 1], [0, 0, 2]]}, "equals points"),
        (
            {
                "type": "line",
                "depth": {
                    "start_m": 1,
                    "changes": [
                        {"time_s": 0, "depth_m": 2, "duration_s": 10},
                        {"time_s": 5, "depth_m": 1, "duration_s": 10},
                    ],
                },
            },
            "before changes",
        ),
    ],
)
def test_3d_config_validation(data: dict, match: str) -> None:
    with pytest.raises(ValidationError, match=match):
        ADAPTER.validate_python(data)
