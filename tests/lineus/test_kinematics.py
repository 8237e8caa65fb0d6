"""Reachable area, arm kinematics, out-of-area clamping and the motion-time model."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fabwire.lineus import kinematics as k


@pytest.mark.parametrize(
    ("x", "y", "inside"),
    [
        (1000, 1000, True),
        (1950, 0, True),
        (1951, 0, False),
        (700, -1000, True),
        (650, -1000, False),
        (1775, 1000, False),
        (1775, -1000, False),
        (500, 0, True),
        (499.9, 0, False),
        (699, -1, False),
        (700, -1, True),
        (819.2, -1573.0, True),
        (819.2, -1580.0, False),
        (0, 0, False),
    ],
)
def test_reference_points(x: float, y: float, inside: bool) -> None:
    assert k.is_reachable(x, y) is inside


def test_app_rectangle_is_not_fully_reachable_but_safe_box_is() -> None:
    xs, ys = np.meshgrid(np.linspace(700, 1800, 45), np.linspace(-700, 700, 45))
    assert k.reachable_mask(xs.ravel(), ys.ravel()).all()
    assert not k.is_reachable(650, -1000)


def test_published_outline_vertices_lie_on_the_boundary() -> None:
    """Each published vertex is within 10 units of both a reachable and an unreachable point."""
    vertices = [(1805.6, -737.3), (1316.7, -1438.3), (819.6, -1570.4), (700.0, -1563.2), (500.0, 1521.0),
                (818.2, 1572.9), (1311.9, 1442.7), (1804.0, 741.2), (1950.0, 0.0)]
    for vx, vy in vertices:
        ring = [(vx + 10 * math.cos(a), vy + 10 * math.sin(a)) for a in np.linspace(0, 2 * math.pi, 72)]
        flags = {k.is_reachable(px, py) for px, py in ring}
        assert flags == {True, False}, (vx, vy)


def test_bounds_and_outline() -> None:
    x0, y0, x1, y1 = k.BOUNDS
    assert (x0, x1) == (500.0, 1950.0)
    assert y1 == pytest.approx(1573.6, abs=0.1)
    assert y0 == -y1
    outline = np.asarray(k.area_outline())
    assert k.reachable_mask(outline[:, 0], outline[:, 1]).all()
    assert outline[0].tolist() == outline[-1].tolist()
    assert outline[:, 0].min() == pytest.approx(x0)
    assert outline[:, 1].max() == pytest.approx(y1, abs=1.0)
    # Off the body edges, points just outside the outline (away from the area's centre) are unreachable.
    centre = np.array([1200.0, 0.0])
    for p in outline[outline[:, 0] > 701][::5]:
        out = p + (p - centre) / np.linalg.norm(p - centre) * 5.0
        assert not k.is_reachable(*out), p


def test_polyline_crossing_the_body_step_is_not_reachable() -> None:
    assert k.is_reachable(500, 100)
    assert k.is_reachable(800, -200)
    assert not k.polyline_reachable([(500, 100), (800, -200)])
    assert k.outside_length([(500, 100), (800, -200)]) == pytest.approx(math.hypot(100, 100), rel=0.02)
    assert k.polyline_reachable([(1000, -500), (1500, 500), (1000, 1000)])
    assert k.outside_length([(1000, 0), (2500, 0)]) == pytest.approx(550, rel=0.01)


@given(st.floats(500, 1950), st.floats(-1580, 1580))
def test_inverse_then_forward_round_trips(x: float, y: float) -> None:
    if not k.is_reachable(x, y):
        return
    joints = k.inverse(x, y)
    fx, fy = k.forward(joints)
    assert fx == pytest.approx(x, abs=1e-6)
    assert fy == pytest.approx(y, abs=1e-6)
    assert joints.shoulder >= -35 - 1e-6
    assert joints.elbow <= 35 + 1e-6


def test_home_configuration() -> None:
    assert k.inverse(*k.HOME) == k.Joints(pytest.approx(90.0), pytest.approx(0.0))  # type: ignore[arg-type]
    assert k.servo_angles(*k.HOME) == (pytest.approx(135.0), pytest.approx(45.0))
    with pytest.raises(ValueError, match="arm spans"):
        k.inverse(2500, 0)
    with pytest.raises(ValueError, match="arm spans"):
        k.inverse(0, 0)


def test_clamp_targets() -> None:
    inside = k.clamp_target(1200, 300)
    assert (inside.x, inside.y, inside.lift_pen) == (1200, 300, False)
    radial = k.clamp_target(2500, 0)
    assert (radial.x, radial.y, radial.lift_pen) == (pytest.approx(1950), pytest.approx(0), True)
    diag = k.clamp_target(2000, 1000)
    assert math.hypot(diag.x, diag.y) == pytest.approx(1950)
    assert diag.y / diag.x == pytest.approx(0.5)
    origin = k.clamp_target(0, 0)
    assert origin.lift_pen
    assert k.is_reachable(origin.x, origin.y)
    assert (origin.x, origin.y) == (500.0, 0.0)
    with pytest.raises(ValueError, match="finite"):
        k.clamp_target(float("nan"), 0)


@given(st.floats(-4000, 4000), st.floats(-4000, 4000))
def test_clamped_points_are_reachable_and_nearest_is_no_farther_than_any_sample(x: float, y: float) -> None:
    c = k.clamp_target(x, y)
    assert k.is_reachable(c.x, c.y)
    assert c.clamped == (not k.is_reachable(x, y))
    nx, ny = k.nearest_reachable(x, y)
    best = math.hypot(nx - x, ny - y)
    outline = np.asarray(k.area_outline(0.5))
    sampled = np.hypot(outline[:, 0] - x, outline[:, 1] - y).min()
    assert best <= sampled + 1.0


def test_motion_model_steps_and_times() -> None:
    s3 = k.MotionModel(draw_step=3)
    assert s3.steps((0, 0), (100, 100), pen_down=True) == 34
    assert k.MotionModel().steps((1000, 0), (1100, 100), pen_down=True) == 20
    assert k.MotionModel().steps((1000, 0), (1100, 100), pen_down=False) == 7
    m = k.MotionModel(step_time=0.01, pen_time=0.2)
    assert m.move_time((1000, 0, 0), (1100, 0, 0)) == pytest.approx(0.2)
    assert m.move_time((1000, 0, 1000), (1100, 0, 1000)) == pytest.approx(0.07)
    # Lifting and then moving: one pen action and the move at the travel step.
    assert m.move_time((1000, 0, 0), (1100, 0, 1000)) == pytest.approx(0.2 + 0.07)
    assert m.move_time((1000, 0), (1100, 0), pen_down=True) == pytest.approx(0.2)
    assert m.move_time((1000, 0, 0), (1000, 0, 0)) == 0
    pts = m.interpolate((1000, 0), (1100, 100), pen_down=True)
    assert len(pts) == 20
    assert pts[-1] == (1100, 100)
    assert m.polyline_time([(1000, 0), (1100, 0), (1100, 50)]) == pytest.approx(0.30)
    with pytest.raises(ValueError, match="draw_step"):
        k.MotionModel(draw_step=0)


def _boundary_probes() -> tuple[list[float], list[float]]:
    """Points on and within a few ulps / micro-units of every boundary piece, corner and clearance step."""
    base = [*k.area_outline(0.25), *k._VERTICES, (500.0, 0.0), (700.0, 0.0), (700.0, -0.0), (1950.0, 0.0),
            (500.0, 1e-300), (700.0, -1e-300), (0.0, 0.0), (2000.0, 0.0), (1000.0, 1000.0)]
    xs: list[float] = []
    ys: list[float] = []
    for x, y in base:
        for dx in (0.0, 1e-6, -1e-6, 2e-6, -2e-6, 1e-9, -1e-9):
            for dy in (0.0, 1e-6, -1e-6, 1e-9, -1e-9):
                xs.append(x + dx)
                ys.append(y + dy)
                xs.append(math.nextafter(x + dx, math.inf))
                ys.append(math.nextafter(y + dy, -math.inf))
    for r in (k.R_MAX, k.R_MAX + k._EPS, math.nextafter(k.R_MAX + k._EPS, math.inf)):
        for a in np.linspace(-0.6, 0.6, 97).tolist():
            xs.append(r * math.cos(a))
            ys.append(r * math.sin(a))
    xs += [math.nan, math.inf, -math.inf, 1000.0, 1000.0]
    ys += [0.0, 0.0, 0.0, math.nan, math.inf]
    return xs, ys


def test_scalar_and_array_reachability_agree_everywhere() -> None:
    rng = np.random.default_rng(7)
    rand_x = rng.uniform(-200, 2200, 50_000).tolist()
    rand_y = rng.uniform(-2200, 2200, 50_000).tolist()
    edge_x, edge_y = _boundary_probes()
    xs = rand_x + edge_x
    ys = rand_y + edge_y
    mask = k.reachable_mask(xs, ys).tolist()
    scalar = [k.is_reachable(x, y) for x, y in zip(xs, ys, strict=True)]
    mismatched = [(x, y) for x, y, a, b in zip(xs, ys, mask, scalar, strict=True) if a != b]
    assert mismatched == []
    assert all(type(v) is bool for v in scalar[:100])
    assert sum(scalar[len(rand_x):]) > 100  # the probes straddle the boundary: many land inside
    assert sum(not v for v in scalar[len(rand_x):]) > 100
