"""Least-squares, end-point and minimum-zone reference lines (ISO 230-1), alone and in L/T/+.

The minimum-zone line is checked against a brute force that needs no
optimiser: the optimal zone is bounded by a line through two readings (an edge
of their convex hull), so trying the slope of every pair and keeping the
narrowest zone finds it. On distinct positions the Chebyshev line is unique
(``{1, s}`` is a Haar system), so the slopes must agree too.
"""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from imu_square.errors import ImuSquareError
from imu_square.reference import REFERENCE_LINES, biaxial_squareness, reference_line


def brute_force_zone(s, r):
    """(width, slope) of the narrowest zone over the slopes of all pairs of readings."""
    best = (math.inf, 0.0)
    for i in range(len(s)):
        for j in range(i + 1, len(s)):
            b = (r[j] - r[i]) / (s[j] - s[i])
            d = r - b * s
            best = min(best, (d.max() - d.min(), b))
    return best


@st.composite
def traces(draw):
    n = draw(st.integers(3, 12))
    s = draw(
        st.lists(
            st.floats(-1.0, 1.0, allow_nan=False).map(lambda v: round(v, 4)),
            min_size=n,
            max_size=n,
            unique=True,
        )
    )
    r = draw(st.lists(st.floats(-50.0, 50.0, allow_nan=False), min_size=n, max_size=n))
    scale = draw(st.sampled_from([1e-6, 1e-3, 1.0]))
    return np.array(s), np.array(r) * scale


@settings(max_examples=80, deadline=None)
@given(traces())
def test_minimum_zone_equals_brute_force(trace):
    s, r = trace
    width, slope = brute_force_zone(s, r)
    line = reference_line(s, r, "minimum_zone")
    span = max(np.ptp(r), 1e-300)
    assert line.zone_m == pytest.approx(width, abs=1e-9 * span)
    # the slope is unique; near-degenerate sets (almost collinear readings) only
    # pin it to the zone's tolerance divided by the positions' spread
    assert line.slope == pytest.approx(slope, abs=1e-7 * span / np.ptp(s))


@settings(max_examples=80, deadline=None)
@given(traces(), st.floats(-1e3, 1e3), st.floats(-1e3, 1e3))
def test_zone_is_the_narrowest_and_lines_follow_an_added_line(trace, a, b):
    s, r = trace
    lines = {m: reference_line(s, r, m) for m in REFERENCE_LINES}
    span = max(np.ptp(r), 1e-300)
    for m in ("least_squares", "end_point"):
        assert lines["minimum_zone"].zone_m <= lines[m].zone_m + 1e-9 * span
    # adding a + b s to the readings tilts every reference line by b
    scale = np.ptp(r) if np.ptp(r) > 0 else 1.0
    a, b = a * scale, b * scale
    for m, line in lines.items():
        moved = reference_line(s, r + a + b * s, m)
        assert moved.slope == pytest.approx(line.slope + b, abs=1e-7 * (abs(b) + scale) / np.ptp(s))


def test_lines_differ_on_a_cubic_and_agree_on_a_symmetric_form():
    s = np.linspace(-0.4, 0.4, 81)
    cubic = 1e-5 * (s / 0.4) ** 3
    u = s / 0.4
    slopes = {m: reference_line(s, cubic, m).slope * 0.4 / 1e-5 for m in REFERENCE_LINES}
    # least squares sum(u^4) / sum(u^2) (-> 3/5 continuous); x^3 - 3x/4 equioscillates
    # on [-1, 1] at -1, -1/2, 1/2, 1 (all on the grid): 3/4; end point 1
    assert slopes["least_squares"] == pytest.approx(np.sum(u**4) / np.sum(u**2), rel=1e-12)
    assert slopes["minimum_zone"] == pytest.approx(0.75, rel=1e-9)
    assert slopes["end_point"] == pytest.approx(1.0, rel=1e-12)
    assert reference_line(s, cubic, "minimum_zone").zone_m == pytest.approx(0.5e-5, rel=1e-9)
    bow = 1e-5 * u**2
    for m in REFERENCE_LINES:
        assert reference_line(s, bow, m).slope == pytest.approx(0.0, abs=1e-15)


@pytest.mark.parametrize(
    ("method", "factor"),
    [("least_squares", None), ("minimum_zone", 0.75), ("end_point", 1.0)],
)
def test_biaxial_squareness_with_each_reference_line(method, factor):
    # dy = c X^3 on the X axis (an asymmetric form): every shape's X arm reads
    # it, so the squareness is alpha - m_X with m_X = factor c h^2
    alpha, c, h = 15e-6, 3e-4, 0.4

    def dev(x, y):
        x = np.asarray(x, dtype=float)
        return -alpha * np.asarray(y, dtype=float), c * x**3

    u = np.linspace(-1, 1, 81)
    if factor is None:
        factor = np.sum(u**4) / np.sum(u**2)
    for shape in ("L", "T", "+"):
        r = biaxial_squareness(dev, shape, 0, (-h, h), (-h, h), reference_line=method)
        assert r.reference_line == method
        assert r.machine_squareness_rad == pytest.approx(alpha - factor * c * h**2, rel=1e-9)
    assert_allclose(r.straightness_y_m, 0.0, atol=1e-18)
    assert r.straightness_x_m > 0


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (
            lambda: reference_line([0, 1], [0, 1], "chebyshev"),
            r"method must be one of .*'chebyshev'",
        ),
        (lambda: reference_line([0, 1, 2], [0, 1], "end_point"), r"shapes \(3,\) and \(2,\)"),
        (lambda: reference_line([0], [0]), r">= 2 finite readings, got 1"),
        (lambda: reference_line([1, 1, 1], [0, 1, 2]), r"two distinct positions"),
        (lambda: reference_line([0, np.nan], [0, 1]), r"finite readings"),
        (
            lambda: biaxial_squareness(lambda x, y: (x, y), "L", reference_line="lsq"),
            r"reference_line must be one of .*got 'lsq'",
        ),
    ],
)
def test_bad_arguments(call, match):
    with pytest.raises(ImuSquareError, match=match):
        call()


def test_minimum_zone_follows_a_steep_added_line_to_rounding():
    # Found by hypothesis: with a steep trend dominating HiGHS's scaling, the LP alone
    # placed the slope 2e-10 off; the hull-edge polish makes it exact.
    s = np.array([0.0, 0.5, 0.75, 0.25, 0.375, 0.125, -0.75, 1.0, -0.5, -1.0])
    r = np.zeros(10)
    r[7], r[8], r[9] = 1e-6, 1.5e-5, -1.953125e-9
    base = reference_line(s, r, "minimum_zone")
    b = 109.0 * np.ptp(r)
    moved = reference_line(s, r + b * s, "minimum_zone")
    assert moved.slope == pytest.approx(base.slope + b, abs=1e-12 * b)
    assert moved.zone_m == pytest.approx(base.zone_m, rel=1e-9)
