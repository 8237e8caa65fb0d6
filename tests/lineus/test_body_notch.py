"""The body notch (x < 700 below y = 0): crossing tests, detours round its corner, and planned hops that use them."""

from __future__ import annotations

import itertools

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from fabwire.lineus import kinematics as kin
from fabwire.lineus.plot import MoveTo, Plan

COORD = st.floats(-1600, 2000, allow_nan=False).map(lambda v: round(v, 1))
POINT = st.tuples(COORD, COORD)


def sampled_in_zone(a: tuple[float, float], b: tuple[float, float], n: int = 4000) -> bool:
    t = np.linspace(0.0, 1.0, n)
    xs = a[0] + (b[0] - a[0]) * t
    ys = a[1] + (b[1] - a[1]) * t
    return bool(np.any((xs < kin.X_MIN_LOWER - 0.5) & (ys < -0.5)))


@given(POINT, POINT)
def test_crossing_agrees_with_dense_sampling(a: tuple[float, float], b: tuple[float, float]) -> None:
    if sampled_in_zone(a, b):  # clearly inside somewhere (half a unit of slack for sampling)
        assert kin.crosses_body_zone(a, b)


@given(POINT, POINT)
def test_detour_keeps_out_of_the_notch(a: tuple[float, float], b: tuple[float, float]) -> None:
    path = [a, *kin.body_detour(a, b)]
    assert path[-1] == b
    if kin.in_body_zone(*a) or kin.in_body_zone(*b):
        return  # nothing can keep a hop that starts or ends in the notch out of it
    for p, q in itertools.pairwise(path):
        assert not kin.crosses_body_zone(p, q)


def test_planned_hops_go_round_the_notch() -> None:
    first = np.array([[550.0, 600.0], [550.0, 100.0]])
    second = np.array([[1000.0, -600.0], [1200.0, -600.0]])
    plan = Plan((first, second))
    hop = plan.stroke_moves(1)
    assert hop[:2] == [MoveTo(kin.X_MIN_LOWER, 0.0), MoveTo(1000.0, -600.0)]
    straight = Plan((second, first)).stroke_moves(1)  # (1200, -600) to (550, 600) misses the notch
    assert straight[0] == MoveTo(550.0, 600.0)
    assert list(plan.moves())[: len(plan.stroke_moves(0))] == plan.stroke_moves(0)


def test_firmware1_area_reaches_into_the_notch() -> None:
    assert not kin.is_reachable(600, -300)
    assert kin.is_reachable(600, -300, x_min_lower=kin.X_MIN_LOWER_FW1)
    assert kin.clamp_target(600, -300) == kin.Clamped(700, -300, True)
    assert kin.clamp_target(600, -300, x_min_lower=kin.X_MIN_LOWER_FW1) == kin.Clamped(600, -300, False)
    out = kin.clamp_target(300, -100, x_min_lower=kin.X_MIN_LOWER_FW1)
    assert out.clamped
    assert out.x == 500
