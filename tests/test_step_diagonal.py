"""The step-diagonal test's mirror limit, against the numbers of Renishaw's diagonal paper.

"If the plane mirror is misaligned by an angle of just 40 arcseconds or
0.2 mm/m (a typical alignment tolerance) and the X axis step size is 50 mm,
then the laser will record an extra 7 um of displacement during the movement
of the X axis. This measurement error will occur during every step of the X
axis and will thus accumulate to 140 um per metre of X axis travel." On the Z
steps it is -7 um and -140 um per metre; the reverse run gives the same; the
step diagonal still gives valid squareness. Machine C: a -33.3 um/m
compensation of all three axes makes the diagonals good and leaves Z at
+66.7 um/m, X and Y at -33.3 um/m.

The paper rounds: the exact values are 50 mm x 0.2e-3 / sqrt(2) = 7.07 um and
141.4 um/m, asserted exactly here and rounded as the paper rounds them.
"""

import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from imu_square.errors import ImuSquareError
from imu_square.reference import (
    body_diagonals,
    diagonal_lengths,
    squareness_from_diagonals,
    step_diagonal_test,
)

TILT = 0.2e-3  # 0.2 mm/m
STEP = 0.05  # 50 mm


def perfect(a, b):
    return 0 * np.asarray(a, dtype=float), 0 * np.asarray(b, dtype=float)


def test_forty_arcseconds_is_two_tenths_of_a_millimetre_per_metre():
    arcsec = math.degrees(TILT) * 3600
    assert arcsec == pytest.approx(41.25, abs=0.01)
    assert round(arcsec / 10) * 10 == 40  # "just 40 arcseconds or 0.2 mm/m"


def test_seven_micrometres_per_step_and_140_per_metre():
    # 1:1 XZ face, 1 m each way, 50 mm steps: 20 steps of each axis
    r = step_diagonal_test(perfect, (0.0, 0.0), (1.0, 1.0), 20, mirror_tilt_rad=TILT)
    x_steps = r.step_error_m[r.moved_axis == 0]
    z_steps = r.step_error_m[r.moved_axis == 1]
    exact = STEP * TILT / math.sqrt(2)  # s sin(45 deg) tan(phi), tan to 1e-8
    assert_allclose(x_steps, exact, rtol=1e-7)
    assert_allclose(z_steps, -exact, rtol=1e-7)
    assert round(x_steps[0] * 1e6) == 7 and round(z_steps[0] * 1e6) == -7
    ex, ez = r.error_per_travel
    assert ex == pytest.approx(TILT / math.sqrt(2), rel=1e-7)  # 141.4 um/m
    assert round(ex * 1e6, -1) == 140 and round(ez * 1e6, -1) == -140
    # it accumulates: after the X step of target k the error is +7 um
    assert_allclose(r.error_m[1::2], exact, rtol=1e-6)
    # and the targets on the diagonal are exact: a move along the beam reads its length
    assert_allclose(r.diagonal_error_m, 0.0, atol=1e-15)


def test_reverse_run_with_opposite_sequence_has_the_same_error():
    fwd = step_diagonal_test(perfect, (0.0, 0.0), (1.0, 1.0), 20, mirror_tilt_rad=TILT)
    rev = step_diagonal_test(
        perfect, (0.0, 0.0), (1.0, 1.0), 20, mirror_tilt_rad=TILT, reverse=True
    )
    assert rev.moved_axis[0] == 1  # "the opposite axis movement sequence"
    # X moving back: the reading falls by more than it should, "still too large"
    x_back = np.flatnonzero(rev.moved_axis == 0)[0]
    assert np.diff(rev.reading_m)[x_back] < -STEP / math.sqrt(2)
    assert_allclose(rev.error_per_travel, fwd.error_per_travel, rtol=1e-9)


def test_mirror_error_looks_like_linear_errors_of_the_axes():
    # a machine with X over-travel e and Z under-travel -e, perfect mirror,
    # reads like a perfect machine with the mirror turned by e*sqrt(2)... to first order
    e = TILT / math.sqrt(2)

    def linear(a, b):
        return e * np.asarray(a, dtype=float), -e * np.asarray(b, dtype=float)

    machine = step_diagonal_test(linear, (0.0, 0.0), (1.0, 1.0), 20)
    mirror = step_diagonal_test(perfect, (0.0, 0.0), (1.0, 1.0), 20, mirror_tilt_rad=TILT)
    # the per-step reading errors agree to second order (e^2 ~ 1e-8 of the step)
    assert_allclose(machine.step_error_m * math.sqrt(2), mirror.step_error_m, atol=1e-9)


@pytest.mark.parametrize(("x", "z"), [(1.0, 1.0), (2.0, 1.0), (0.6, 1.5)])
def test_relative_error_is_tan_phi_tan_theta(x, z):
    theta = math.atan2(z, x)
    r = step_diagonal_test(perfect, (0.0, 0.0), (x, z), 10, mirror_tilt_rad=TILT)
    # per unit X travel sin(theta) tan(phi); per unit Z travel -cos(theta) tan(phi)
    assert r.error_per_travel[0] == pytest.approx(math.sin(theta) * math.tan(TILT), rel=1e-9)
    assert r.error_per_travel[1] == pytest.approx(-math.cos(theta) * math.tan(TILT), rel=1e-9)
    # relative to the X step's nominal reading (s cos theta): tan(phi) tan(theta)
    nominal = (x / 10) * math.cos(theta)
    ratio = r.step_error_m[0] / nominal
    assert ratio == pytest.approx(math.tan(TILT) * math.tan(theta), rel=1e-9)


def test_step_diagonal_squareness_is_valid_with_a_misaligned_mirror():
    # "The step diagonal method does produce valid results ... for machine
    # squareness errors": the readings at the diagonal targets are exact
    alpha, x, y = 20e-6, 0.8, 0.5

    def dev(a, b):
        return -alpha * np.asarray(b, dtype=float), 0 * np.asarray(a, dtype=float)

    d1 = step_diagonal_test(dev, (x, 0.0), (0.0, y), 16, mirror_tilt_rad=TILT)
    d2 = step_diagonal_test(dev, (0.0, 0.0), (x, y), 16, mirror_tilt_rad=-TILT)
    d0 = math.hypot(x, y)
    lengths = [d0 + d.diagonal_error_m[-1] for d in (d1, d2)]
    # the mirror reads the end point's error across the beam (<= alpha y) times
    # tan(phi): second order, bounded per length, and the lengths' own second
    # order |e|^2 / D0
    per_length = alpha * y * math.tan(TILT) + (alpha * y) ** 2 / d0
    tol = d0 * 2 * per_length / (2 * x * y)
    assert squareness_from_diagonals(*lengths, (x, y)) == pytest.approx(alpha, abs=tol)
    assert tol < 1e-3 * alpha


def test_machine_c_compensation_fixes_the_diagonals_not_the_machine():
    cube = ((0.0, 1.0),) * 3
    z_over = 100e-6
    comp = -z_over / 3  # "-33.3 um/m linear error correction to all three axes"
    assert round(comp * 1e6, 1) == -33.3
    left = (comp, comp, z_over + comp)
    assert [round(v * 1e6, 1) for v in left] == [-33.3, -33.3, 66.7]

    def compensated(x, y, z):
        return tuple(e * np.asarray(v, dtype=float) for e, v in zip(left, (x, y, z), strict=True))

    lengths = diagonal_lengths(compensated, body_diagonals(*cube))
    # a good diagonal result: every body diagonal 1.732051 m to the micrometre
    assert [round(v, 6) for v in lengths] == [round(math.sqrt(3), 6)] * 4
    # while the X-Y plane, perfect before, now under-travels by 33.3 um/m
    assert max(abs(v) for v in left[:2]) * 1e6 == pytest.approx(33.3, abs=0.05)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_steps": 0}, r"n_steps must be an integer >= 1, got 0"),
        ({"end": (1.0, 0.0)}, r"must move both axes"),
    ],
)
def test_bad_arguments(kwargs, match):
    args = {"deviation": perfect, "start": (0.0, 0.0), "end": (1.0, 1.0), "n_steps": 4}
    args.update(kwargs)
    with pytest.raises(ImuSquareError, match=match):
        step_diagonal_test(**args)
