"""Reference squareness methods against the numbers of Chapman (TE328) and Renishaw (ISO 230-6).

Error maps are exact polynomials, so the tolerances come from arithmetic:
the L/T/+ traces and the diagonal positioning errors are linear in the error
map (exact to rounding), while a ballbar length and a diagonal length are
Euclidean norms whose second-order part is bounded below.
"""

import json
import math

import numpy as np
import pytest
from numpy.testing import assert_allclose

from imu_square.cli import main
from imu_square.errors import ImuSquareError
from imu_square.reference import (
    ORIENTATIONS_DEG,
    SHAPES,
    ballbar_squareness,
    biaxial_squareness,
    body_diagonal_squareness,
    body_diagonals,
    diagonal_lengths,
    diagonal_squareness,
    diagonal_test,
    face_diagonals,
)
from imu_square.simulate import chapman_machine

ALPHA = 15e-6  # Chapman's machines 1-5: +15 um/m
L_AXIS = 0.8  # 800 mm axes
S = 10e-6  # straightness that gives machine 3's -35..+65 um/m: 4 S / L = 50 um/m
HALF = (-0.4, 0.4)
EXACT = 1e-9  # relative, for results linear in the error map


def chapman_eq(machine):
    """Chapman Appendix I, Eq. 1-4, written out independently of the simulator.

    1: squareness; 2: X straightness (Eq. 4); 3: X straightness with yaw (Eq. 3);
    4: X and Y straightness; 5: X and Y straightness with yaw.
    """
    k = 8 * S / L_AXIS**2
    yaw_x = machine in (3, 5)
    yaw_y = machine == 5
    sx = machine >= 2
    sy = machine >= 4

    def deviation(x, y):
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        dx = -y * (ALPHA + (k * x if yaw_x else 0.0))  # Eq. 2
        dy = np.zeros_like(x + y)
        if sx:
            dy = dy + 4 * S * x**2 / L_AXIS**2  # Eq. 1
        if sy:
            # the Y axis' bow in X and its yaw, by the same reasoning (Appendix I, last lines)
            dx = dx + 4 * S * y**2 / L_AXIS**2
            if yaw_y:
                dy = dy - x * (k * y)
        return dx, dy

    return deviation


def second_order_bound(deviation, pivot, points, length):
    """Bound on |L - L_linear| for lengths ``length`` from ``pivot`` to ``points``.

    For |e| << |p|, |p + e| - |p| - u.e = |e_perp|^2 / (2 |p|) + O(|e|^3 / |p|^2);
    we bound it by |e|^2 / |p| (a factor 2 of margin).
    """
    dx, dy = deviation(points[:, 0], points[:, 1])
    px, py = deviation(np.array([pivot[0]]), np.array([pivot[1]]))
    e2 = (dx - px) ** 2 + (dy - py) ** 2
    return float(e2.max()) / length


def ballbar_tolerance(deviation, centre, radius):
    # the sin(2 phi) least-squares coefficient of a function bounded by M is
    # at most 2 M, and alpha = -2 b2 / R: |error| <= 4 M / R.
    phi = np.linspace(0, 2 * np.pi, 721)
    pts = np.column_stack([centre[0] + radius * np.cos(phi), centre[1] + radius * np.sin(phi)])
    return 4 * second_order_bound(deviation, centre, pts, radius) / radius + 1e-15


def diagonal_tolerance(deviation, x_range, y_range):
    # S = D0 (D1 - D2) / (2XY) is exact for the first-order part of D1 - D2;
    # the second-order part of each length is below |e|^2 / D0.
    corners = np.array([[x, y] for x in x_range for y in y_range])
    dx, dy = deviation(corners[:, 0], corners[:, 1])
    e2 = 4 * float(np.max(dx**2 + dy**2))  # |e_end - e_start| <= 2 max |e|
    xl, yl = x_range[1] - x_range[0], y_range[1] - y_range[0]
    d0 = math.hypot(xl, yl)
    return d0 * 2 * (e2 / d0) / (2 * xl * yl) + 1e-15


# ---- the error model: our independent Eq. 1-4 equals the simulator's --------


@pytest.mark.parametrize("machine", [1, 2, 3, 4, 5])
def test_chapman_equations_match_simulator_geometry(machine):
    rng = np.random.default_rng(machine)
    x, y = rng.uniform(-0.4, 0.4, (2, 50))
    assert_allclose(chapman_machine(machine).deviation(x, y), chapman_eq(machine)(x, y), atol=1e-18)


# ---- global tests: Chapman Figs. 14-18 ---------------------------------------


@pytest.mark.parametrize("machine", [1, 2, 4])
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("orientation", ORIENTATIONS_DEG)
def test_no_yaw_every_biaxial_test_gives_15(machine, shape, orientation):
    # machines 1, 2, 4: "the global squareness result is always 15 um/m
    # irrespective of the test method and equipment orientation"
    r = biaxial_squareness(chapman_eq(machine), shape, orientation, HALF, HALF)
    assert r.machine_squareness_rad == pytest.approx(ALPHA, rel=EXACT)


@pytest.mark.parametrize("machine", [1, 2, 3, 4, 5])
def test_ballbar_diagonal_and_plus_give_15_on_every_machine(machine):
    dev = chapman_eq(machine)
    bb = ballbar_squareness(dev, (0.0, 0.0), 0.4)
    assert bb.machine_squareness_rad == pytest.approx(
        ALPHA, abs=ballbar_tolerance(dev, (0, 0), 0.4)
    )
    assert bb.machine_squareness_ccw_rad == bb.machine_squareness_cw_rad
    tol = diagonal_tolerance(dev, HALF, HALF)
    assert diagonal_squareness(dev, HALF, HALF) == pytest.approx(ALPHA, abs=tol)
    for orientation in ORIENTATIONS_DEG:
        r = biaxial_squareness(dev, "+", orientation, HALF, HALF)
        assert r.machine_squareness_rad == pytest.approx(ALPHA, rel=EXACT)


def test_machine_3_L_and_T_change_with_orientation_and_average_to_15():
    # Machine 3 (X straightness with associated yaw): the Y axis' angle to the X
    # reference line goes from -35 um/m at the left end of X to +65 at the right.
    dev = chapman_eq(3)
    res = {
        (s, o): biaxial_squareness(dev, s, o, HALF, HALF).machine_squareness_rad
        for s in ("L", "T")
        for o in ORIENTATIONS_DEG
    }
    lo, hi = ALPHA - 4 * S / L_AXIS, ALPHA + 4 * S / L_AXIS
    assert (lo, hi) == pytest.approx((-35e-6, 65e-6), rel=1e-12)
    # L: corners lower-left, upper-left, upper-right, lower-right
    expected_l = {0: lo, 90: lo, 180: hi, 270: hi}
    # T: bar top (stem through the middle of X), right, bottom, left
    expected_t = {0: ALPHA, 90: hi, 180: ALPHA, 270: lo}
    for o in ORIENTATIONS_DEG:
        assert res["L", o] == pytest.approx(expected_l[o], rel=EXACT)
        assert res["T", o] == pytest.approx(expected_t[o], rel=EXACT)
    # "if the L or T shaped squareness results from opposing corners or sides
    # are averaged, they match the values given by the other methods"
    for a, b in ((0, 180), (90, 270)):
        assert (res["L", a] + res["L", b]) / 2 == pytest.approx(ALPHA, rel=EXACT)
        assert (res["T", a] + res["T", b]) / 2 == pytest.approx(ALPHA, rel=EXACT)
    # the simulator's Y-to-X axis angle agrees at both ends of the X travel
    g = chapman_machine(3)
    assert g.axis_angle_y_to_x(-0.4) == pytest.approx(res["L", 0], rel=EXACT)
    assert g.axis_angle_y_to_x(0.4) == pytest.approx(res["L", 180], rel=EXACT)


def test_machine_5_opposite_corners_and_sides_average_to_15():
    dev = chapman_eq(5)
    for shape in ("L", "T"):
        r = [
            biaxial_squareness(dev, shape, o, HALF, HALF).machine_squareness_rad
            for o in ORIENTATIONS_DEG
        ]
        assert max(r) - min(r) > 90e-6  # "changed again": they do vary
        assert (r[0] + r[2]) / 2 == pytest.approx(ALPHA, rel=EXACT)
        assert (r[1] + r[3]) / 2 == pytest.approx(ALPHA, rel=EXACT)


# ---- local tests: Chapman Figs. 19-23 (200 mm of each axis) -----------------

LOCAL_CENTRES = [(0.0, 0.0), (-0.3, -0.3), (0.3, -0.3), (0.3, 0.3), (-0.3, 0.3)]


def local_results(dev, centre):
    """{method: (squareness, absolute tolerance relative to the first-order value)}."""
    cx, cy = centre
    xr, yr = (cx - 0.1, cx + 0.1), (cy - 0.1, cy + 0.1)
    out = {
        "ballbar": (
            ballbar_squareness(dev, centre, 0.1).machine_squareness_rad,
            ballbar_tolerance(dev, centre, 0.1),
        ),
        "diagonal": (diagonal_squareness(dev, xr, yr), diagonal_tolerance(dev, xr, yr)),
    }
    for shape in SHAPES:
        for o in ORIENTATIONS_DEG:
            value = biaxial_squareness(dev, shape, o, xr, yr).machine_squareness_rad
            out[shape, o] = (value, EXACT * abs(value) + 1e-18)
    return out


@pytest.mark.parametrize("machine", [2, 4])
@pytest.mark.parametrize("centre", LOCAL_CENTRES)
def test_local_no_yaw_varies_with_location_all_methods_agree(machine, centre):
    # "local squareness results that vary according to the location of the
    # test, but all test methods give the same results"
    dev = chapman_eq(machine)
    expected = float(chapman_machine(machine).local_machine_squareness(*centre))
    k = 8 * S / L_AXIS**2
    # closed form: alpha - k (x_c [X bow] + y_c [Y bow])
    assert expected == pytest.approx(
        ALPHA - k * centre[0] - (k * centre[1] if machine == 4 else 0.0), rel=1e-12
    )
    for name, (value, tol) in local_results(dev, centre).items():
        assert value == pytest.approx(expected, abs=tol), name


@pytest.mark.parametrize("centre", LOCAL_CENTRES)
def test_local_machine_3_does_not_vary_with_location_but_L_differs(centre):
    # "The ballbar, laser diagonal, + and T shaped bi-axial straightness
    # methods give the same result, but the L shaped bi-axial test gives a
    # different result"; none depends on the location.
    res = local_results(chapman_eq(3), centre)
    k = 8 * S / L_AXIS**2
    for name, (value, tol) in res.items():
        if name[0] == "L":
            # Y arm at the local region's edge, 0.1 m from its middle
            sign = -1 if name[1] in (0, 90) else 1
            assert value == pytest.approx(ALPHA + sign * k * 0.1, abs=tol), name
        elif name[0] == "T" and name[1] in (90, 270):
            sign = 1 if name[1] == 90 else -1
            assert value == pytest.approx(ALPHA + sign * k * 0.1, abs=tol), name
        else:
            assert value == pytest.approx(ALPHA, abs=tol), name
    assert res["L", 0][0] != pytest.approx(ALPHA, rel=0.1)


# ---- ballbar details ---------------------------------------------------------


def test_ballbar_sign_of_pure_squareness():
    # dr(phi) = -(alpha R / 2) sin(2 phi): shorter at 45 deg, longer at 135 deg
    alpha, radius = 100e-6, 0.15
    r = ballbar_squareness(lambda x, y: (-alpha * y, 0 * x), (0.2, -0.1), radius, n=360)
    expected = -(alpha * radius / 2) * np.sin(2 * r.phi_rad)
    # second order: R (sqrt(1 - a sin2phi + a^2 sin^2 phi) - 1) - linear <= a^2 R
    assert_allclose(r.deviation_ccw_m, expected, atol=alpha**2 * radius)
    assert r.deviation_ccw_m[45] < 0 < r.deviation_ccw_m[135]
    assert r.machine_squareness_rad == pytest.approx(alpha, abs=4 * alpha**2)


def test_ballbar_scale_mismatch_backlash_and_offset():
    sx, sy, alpha = 20e-6, -10e-6, -7e-6

    def dev(x, y):
        return sx * x - alpha * y + 3e-6, sy * y + 2e-6

    clean = ballbar_squareness(dev, (0.0, 0.0), 0.1)
    lashed = ballbar_squareness(dev, (0.0, 0.0), 0.1, backlash=(4e-6, 6e-6))
    tol = ballbar_tolerance(dev, (0.0, 0.0), 0.1)
    for r in (clean, lashed):
        assert r.machine_squareness_rad == pytest.approx(alpha, abs=tol)
        assert r.scale_mismatch == pytest.approx(sx - sy, abs=tol)
        # the pivot was set by the same machine: a constant offset cancels
        assert r.centre_offset_m == pytest.approx((0.0, 0.0), abs=1e-15)
    # backlash biases each direction by -+ 8 (b_x - b_y) / (3 pi R); the mean
    # is free of it. Sampling the steps at n points: relative error ~ 1/(2n).
    assert np.max(np.abs(lashed.deviation_ccw_m - lashed.deviation_cw_m)) > 3e-6
    bias = -8 * (4e-6 - 6e-6) / (3 * np.pi * 0.1)
    assert lashed.machine_squareness_ccw_rad - alpha == pytest.approx(bias, rel=1 / 3600)
    assert lashed.machine_squareness_cw_rad - alpha == pytest.approx(-bias, rel=1 / 3600)
    assert clean.machine_squareness_ccw_rad == pytest.approx(alpha, abs=tol)
    # clean: only the second-order part of the length is left (bound M = tol R / 4)
    assert clean.residual_rms_m < tol * 0.1 / 4 < 1e-7 < lashed.residual_rms_m


# ---- diagonals: Renishaw white paper -----------------------------------------


def linear_errors(ex, ey, ez):
    return lambda x, y, z: (ex * np.asarray(x), ey * np.asarray(y), ez * np.asarray(z))


def test_renishaw_cancellation_example_2m_1m_half_m():
    # 2 m x 1 m x 0.5 m, +25 um/m X, -100 um/m Y: every body diagonal still
    # 2.291288 m to the micrometre, changed by less than 0.1 um
    diag = body_diagonals((0, 2.0), (0, 1.0), (0, 0.5))
    nominal = math.sqrt(2**2 + 1**2 + 0.5**2)
    assert round(nominal, 6) == 2.291288
    lengths = diagonal_lengths(linear_errors(25e-6, -100e-6, 0.0), diag)
    assert [round(v, 6) for v in lengths] == [2.291288] * 4
    assert np.all(np.abs(lengths - nominal) < 0.1e-6)
    # while the volumetric error (worst corner) is over 100 um
    assert math.hypot(25e-6 * 2, 100e-6 * 1) > 100e-6


@pytest.mark.parametrize(
    ("errors", "e_um", "volumetric_um"),
    [
        ((50e-6, 0.0, 0.0), 28.9, 50),  # machine A
        ((100e-6, -50e-6, -25e-6), 14.4, 115),  # machine B
    ],
)
def test_renishaw_machines_a_and_b(errors, e_um, volumetric_um):
    cube = ((0.0, 1.0),) * 3
    result = diagonal_test(linear_errors(*errors), body_diagonals(*cube), n_targets=11)
    # E grows linearly to sum(e_i)/sqrt(3) at the end of each diagonal
    exact = abs(sum(errors)) / math.sqrt(3)
    for d in result.diagonals:
        assert d.e_m == pytest.approx(exact, rel=EXACT)
        assert d.b_m == 0.0
    assert round(result.e_d_m * 1e6, 1) == e_um
    assert round(math.hypot(*errors) * 1e6) == volumetric_um


def test_renishaw_machine_c_diagonals_58um_long():
    lengths = diagonal_lengths(
        linear_errors(0.0, 0.0, 100e-6), body_diagonals((0, 1.0), (0, 1.0), (0, 1.0))
    )
    assert round(math.sqrt(3), 6) == 1.732051
    assert [round(v, 6) for v in lengths] == [1.732109] * 4
    assert [round((v - math.sqrt(3)) * 1e6) for v in lengths] == [58] * 4


def test_renishaw_fig10_squareness_stretches_one_diagonal():
    # 10 um/m squareness over 1 m x 1 m: D1 ("green") stretched, positive
    # slope; D2 ("red") compressed, negative slope; both ends at
    # alpha X Y / D0 = 7.07 um
    alpha = 10e-6
    test = diagonal_test(
        lambda x, y: (-alpha * y, 0 * x), face_diagonals((0, 1.0), (0, 1.0)), n_targets=21
    )
    green, red = test.diagonals
    end = alpha / math.sqrt(2)
    frac = np.linspace(0, 1, 21)
    assert_allclose(green.forward_error_m, end * frac, rtol=EXACT, atol=1e-20)
    assert_allclose(red.forward_error_m, -end * frac, rtol=EXACT, atol=1e-20)
    assert green.length_m > math.sqrt(2) > red.length_m
    assert test.e_d_m == pytest.approx(end, rel=EXACT)
    assert diagonal_squareness(lambda x, y: (-alpha * y, 0 * x), (0, 1.0), (0, 1.0)) == (
        pytest.approx(alpha, rel=2 * alpha)
    )


def test_diagonal_squareness_unequal_travels_closed_form():
    # D1^2 - D2^2 = 4 alpha X Y exactly, so S = 2 D0 alpha / (D1 + D2)
    alpha, x, y = 40e-6, 2.0, 0.5
    dev = lambda px, py: (-alpha * py, 0 * px)  # noqa: E731
    d1, d2 = diagonal_lengths(dev, face_diagonals((0, x), (0, y)))
    assert d1**2 - d2**2 == pytest.approx(4 * alpha * x * y, rel=1e-9)
    d0 = math.hypot(x, y)
    assert diagonal_squareness(dev, (0, x), (0, y)) == pytest.approx(
        2 * d0 * alpha / (d1 + d2), rel=1e-12
    )


def test_reversal_gives_b_and_widens_e():
    alpha = 10e-6
    test = diagonal_test(
        lambda x, y: (-alpha * y, 0 * x),
        face_diagonals((0, 1.0), (0, 1.0)),
        n_targets=5,
        reversal_m=2e-6,
    )
    for d in test.diagonals:
        assert d.b_m == pytest.approx(2e-6, rel=EXACT)
        assert d.e_m == pytest.approx(alpha / math.sqrt(2) + 2e-6, rel=EXACT)
    assert test.b_d_m == pytest.approx(2e-6, rel=EXACT)


@pytest.mark.parametrize("plane", ["XY", "ZX"])
def test_body_diagonal_squareness(plane):
    beta = 25e-6
    if plane == "XY":
        dev = lambda x, y, z: (-beta * np.asarray(y), 0 * x, 0 * z)  # noqa: E731
    else:
        # ZX: angle between +Z and +X over 90 deg -> dz = -beta x
        dev = lambda x, y, z: (0 * x, 0 * y, -beta * np.asarray(x))  # noqa: E731
    ranges = ((0, 1.0), (0, 0.8), (0, 0.6))
    for p in ("XY", "YZ", "ZX"):
        s = body_diagonal_squareness(dev, *ranges, plane=p)
        assert s == pytest.approx(beta if p == plane else 0.0, abs=4 * beta**2)


# ---- input checks -----------------------------------------------------------


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: biaxial_squareness(chapman_eq(1), "V"), r"shape must be one of .*got 'V'"),
        (lambda: biaxial_squareness(chapman_eq(1), "L", 45), r"orientation_deg .*got 45"),
        (lambda: biaxial_squareness(chapman_eq(1), "L", n=2), r"n must be an integer >= 3, got 2"),
        (lambda: ballbar_squareness(chapman_eq(1), (0, 0), 0.0), r"radius must be > 0 m, got 0.0"),
        (lambda: ballbar_squareness(chapman_eq(1), (0, 0), 0.1, n=8), r">= 16, got 8"),
        (lambda: diagonal_test(chapman_eq(1), face_diagonals(HALF, HALF), 1), r">= 2, got 1"),
        (
            lambda: body_diagonal_squareness(None, HALF, HALF, HALF, plane="XZ"),
            r"plane must be one of .*got 'XZ'",
        ),
    ],
)
def test_bad_arguments(call, match):
    with pytest.raises(ImuSquareError, match=match):
        call()


def test_instrument_rotation_cancels():
    dev = chapman_eq(3)
    a = biaxial_squareness(dev, "L", 90, HALF, HALF)
    b = biaxial_squareness(dev, "L", 90, HALF, HALF, instrument_rotation_rad=1e-3)
    # the readings tilt by 1 mrad, the difference of slopes does not (to second order)
    assert b.slope_x_rad == pytest.approx(a.slope_x_rad - 1e-3, rel=1e-3)
    assert b.machine_squareness_rad == pytest.approx(a.machine_squareness_rad, abs=1e-3 * 1e-4)


# ---- CLI ----------------------------------------------------------------------


def test_cli_reference_machine_3(tmp_path, capsys):
    path = tmp_path / "m3.toml"
    path.write_text(
        "[geometry]\nmachine_squareness_um_per_m = 15.0\naxis_length_mm = [800.0, 800.0]\n"
        "[straightness_yaw]\nx_um = 10.0\nyaw_x = true\n"
    )
    assert main(["reference", "--machine", str(path), "--json"]) == 0
    captured = capsys.readouterr()
    doc = json.loads(captured.out)
    assert doc["reference_line"] == "least_squares"
    out = doc["methods"]
    for method in ("ballbar", "diagonal"):
        assert out[method]["machine_squareness_rad"] == pytest.approx(15e-6, rel=1e-6)
        # the old key stays for one release, with the same value
        assert out[method]["squareness_rad"] == out[method]["machine_squareness_rad"]
    assert out["L"] == pytest.approx(
        {"0deg": -35e-6, "90deg": -35e-6, "180deg": 65e-6, "270deg": 65e-6}, rel=1e-9
    )
    assert all(v == pytest.approx(15e-6, rel=1e-9) for v in out["+"].values())
    assert "diagonal     15.000" in captured.err
    assert main(["reference", "--machine", str(path), "--method", "T"]) == 0
    err = capsys.readouterr().out  # the table is the result: on stdout without --json
    assert "90deg    65.000" in err and "ballbar" not in err and "µm/m" in err


def test_cli_reference_line_option(tmp_path, capsys):
    # a machine file's forms are symmetric about the middle of the travel, so
    # the global tests read the same with every reference line (compare --local
    # shows where they differ)
    path = tmp_path / "m7.toml"
    path.write_text(
        "[geometry]\nmachine_squareness_um_per_m = 15.0\naxis_length_mm = [750.0, 250.0]\n"
        "[straightness_yaw]\nx_um = 32.14\nx_quartic_um = -25.82\ny_um = 5.0\n"
    )
    for line in ("least_squares", "end_point", "minimum_zone"):
        args = ["reference", "--machine", str(path), "--method", "L", "--json"]
        assert main([*args, "--reference-line", line]) == 0
        doc = json.loads(capsys.readouterr().out)
        assert doc["reference_line"] == line
        assert doc["methods"]["L"]["0deg"] == pytest.approx(15e-6, rel=1e-9)
    with pytest.raises(SystemExit):
        main(["reference", "--machine", str(path), "--reference-line", "lsq"])


def test_cli_reference_bad_radius(tmp_path, capsys):
    path = tmp_path / "m.toml"
    path.write_text("[geometry]\nmachine_squareness_um_per_m = 15.0\n")
    assert main(["reference", "--machine", str(path), "--radius-mm", "-5"]) == 2
    assert "--radius-mm must be > 0, got -5.0" in capsys.readouterr().err
