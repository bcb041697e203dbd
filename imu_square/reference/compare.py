"""Every squareness method side by side on one simulated machine, as in Chapman's figures.

For a machine (the simulator's :class:`~imu_square.simulate.MachineModel`) this
runs, on its geometric error map:

a. the ballbar, full circle and 220 deg arc, at one or several locations, and
   the mean over the locations (Chapman's way to a global squareness on a
   machine with unequal axes);
b. the face diagonal test over the whole travel;
c-e. "+", "T" and "L" bi-axial straightness tests in four orientations;

and the IMU circle test on the ballbar's circles through the real chain:
:func:`imu_square.simulate.simulate_run` (machine, sensor, the program moved
onto each circle) then :func:`imu_square.pipeline.squareness.analyze`. The
pipeline measures ``theta_y - theta_x``, the machine's squareness plus the
sensor's non-orthogonality ``beta`` (plus any gravity coupling); the machine
squareness the IMU infers is ``(theta_y - theta_x - beta) / cos 2 eps_c`` with
the simulated sensor's ``beta`` from the simulator's truth (``docs/model.md``,
the measurand), which a user gets from a sensor calibration or a reversal.

Each row carries a one-line note on where and why it departs from the
machine's squareness ``alpha``, computed from the error map:

- straightness without its yaw turns the axes locally, so a local test sees
  ``alpha - f'(x) - g'(y)`` (``f``, ``g``: the X and Y forms); with the yaw
  the turn cancels (Chapman's machines 3 and 5);
- an L or T test sees the axes' yaw where its arms run: ``alpha + f'(x_Y) +
  g'(y_X)``; "+" runs its arms through the middle, where symmetric forms
  have no slope;
- a ballbar's ``sin 2 phi`` term and the IMU's phases read different
  harmonics of a non-quadratic path (:mod:`imu_square.simulate.geometry`);
- through a sensor turned by ``eps_c`` the IMU also sees the local scale
  mismatch ``J_xx - J_yy`` times ``tan 2 eps_c`` (the yaw of one axis
  changes the other's scale away from the middle), and any gravity coupling.

The IMU's "expected" value is this first-order model; the test suite checks
the simulated pipeline against it.
"""

import math
from dataclasses import dataclass, field, replace

import numpy as np

from imu_square.errors import AnalysisError, ImuSquareError
from imu_square.pipeline.squareness import AnalysisOptions, analyze
from imu_square.program import read_program
from imu_square.program.spec import program_from_mapping
from imu_square.reference.ballbar import ballbar_squareness
from imu_square.reference.biaxial import ORIENTATIONS_DEG, biaxial_squareness
from imu_square.reference.diagonal import diagonal_squareness
from imu_square.reference.reference_line import REFERENCE_LINES
from imu_square.simulate import data_path, read_sensor, simulate_run
from imu_square.units import MM, URAD
from imu_square.validation import check_option

# The IMU's default test: the paper's program (15 cycles each way, 180 deg
# overshoot, 2 s dwell) on the ballbar's circle at 2 m/s^2, which resolves
# about 7 um/m per run with the paper's sensor while keeping the circle below
# 1 Hz for radii from 50 mm, where the paper's 4 Hz low-pass is safe.
DEFAULT_CENTRIPETAL_M_S2 = 2.0
ARC_DEG = 220.0
# Below this two deterministic results are "the same" (rounding of the table).
_SAME_RAD = 0.05 * URAD
_L_CORNERS = {0: "lower-left", 90: "upper-left", 180: "upper-right", 270: "lower-right"}
_T_BARS = {0: "top", 90: "right", 180: "bottom", 270: "left"}


@dataclass(frozen=True)
class MethodRow:
    """One line of the comparison.

    Attributes
    ----------
    method : str
        ``"ballbar"``, ``"ballbar_mean"``, ``"diagonal"``, ``"+"``, ``"T"``,
        ``"L"``, ``"imu"`` or ``"imu_mean"``.
    where : str
        Where the test runs, for people.
    machine_squareness_rad : float
        The machine's squareness this test reports. [rad]
    note : str
        Where and why it departs from the machine's squareness, one line.
    u_machine_squareness_rad : float or None
        Standard uncertainty (k = 1), for the IMU rows. [rad]
    location_m : tuple of float or None
        Circle centre or, for L/T/+ and diagonal tests, the middle of the
        tested rectangle. [m]
    arc_deg : float or None
        Ballbar arc. [deg]
    orientation_deg : int or None
        L/T/+ orientation.
    details : dict
        Extra figures in SI (for the IMU: ``squareness_rad`` as the pipeline
        gives it, ``sensor_squareness_rad``, ``eps_c_rad``, ``expected_rad``,
        ``least_squares_rad``, ``ballbar_rad``, ``crb_rad``).
    """

    method: str
    where: str
    machine_squareness_rad: float
    note: str
    u_machine_squareness_rad: float | None = None
    location_m: tuple | None = None
    arc_deg: float | None = None
    orientation_deg: int | None = None
    details: dict = field(default_factory=dict)

    def to_json_dict(self):
        """The row in µrad (= µm/m) and mm."""
        out = {
            "method": self.method,
            "where": self.where,
            "machine_squareness_urad": self.machine_squareness_rad / URAD,
        }
        if self.u_machine_squareness_rad is not None:
            out["u_machine_squareness_urad"] = self.u_machine_squareness_rad / URAD
        if self.location_m is not None:
            out["location_mm"] = [c / MM for c in self.location_m]
        if self.arc_deg is not None:
            out["arc_deg"] = self.arc_deg
        if self.orientation_deg is not None:
            out["orientation_deg"] = self.orientation_deg
        for key, value in self.details.items():
            if key.endswith("_rad"):
                out[key[: -len("_rad")] + "_urad"] = value / URAD
            else:
                out[key] = value
        out["note"] = self.note
        return out


@dataclass(frozen=True)
class Comparison:
    """All methods on one machine.

    Attributes
    ----------
    machine_name : str
        The machine's name.
    x_range_m, y_range_m : tuple of float
        The axes' travel. [m]
    machine_squareness_rad : float
        The model's squareness ``alpha`` at t = 0. [rad]
    radius_m : float
        Ballbar (and IMU circle) radius. [m]
    locations_m : list of tuple
        Circle centres. [m]
    reference_line : str
        Reference line of the L/T/+ tests.
    imu : dict or None
        The IMU set-up: ``sensor``, ``centripetal_m_s2``, ``feed_m_per_s``,
        ``cycles_per_direction``, ``seed``; None when the IMU was not run.
    rows : list of MethodRow
    """

    machine_name: str
    x_range_m: tuple
    y_range_m: tuple
    machine_squareness_rad: float
    radius_m: float
    locations_m: list
    reference_line: str
    imu: dict | None
    rows: list

    def to_json_dict(self):
        """The comparison in µrad (= µm/m) and mm."""
        return {
            "machine_name": self.machine_name,
            "travel_mm": [[v / MM for v in self.x_range_m], [v / MM for v in self.y_range_m]],
            "model_machine_squareness_urad": self.machine_squareness_rad / URAD,
            "radius_mm": self.radius_m / MM,
            "locations_mm": [[c / MM for c in loc] for loc in self.locations_m],
            "reference_line": self.reference_line,
            "imu": self.imu,
            "rows": [r.to_json_dict() for r in self.rows],
        }

    def to_text(self):
        """The table for people, in µm/m."""
        (x0, x1), (y0, y1) = self.x_range_m, self.y_range_m
        head = [
            f"machine {self.machine_name!r}: X {(x1 - x0) / MM:g} mm x Y {(y1 - y0) / MM:g} mm, "
            f"model squareness {self.machine_squareness_rad / URAD:.1f} µm/m",
            f"ballbar and IMU circles r = {self.radius_m / MM:g} mm at "
            + ", ".join(_mm(loc) for loc in self.locations_m)
            + f"; L/T/+ with {self.reference_line.replace('_', '-')} reference lines",
        ]
        if self.imu is not None:
            head.append(
                f"IMU: sensor {self.imu['sensor']!r}, {self.imu['centripetal_m_s2']:g} m/s², "
                f"{self.imu['cycles_per_direction']} cycles each way, seed {self.imu['seed']}; "
                "IMU = (theta_y - theta_x - beta) / cos 2eps_c (the simulated sensor's beta "
                "removed), ± k=2"
            )
        lines = [*head, f"{'method':<18}{'where':<34}{'µm/m':>16}   why"]
        for r in self.rows:
            value = f"{r.machine_squareness_rad / URAD:.1f}"
            if r.u_machine_squareness_rad is not None:
                value += f" ± {2 * r.u_machine_squareness_rad / URAD:.1f}"
            lines.append(f"{_label(r):<18}{r.where:<34}{value:>16}   {r.note}")
        return "\n".join(lines)


def _label(row):
    if row.method in ("ballbar", "ballbar_mean"):
        return f"a ballbar {row.arc_deg:g}°"
    if row.method == "diagonal":
        return "b diagonal"
    if row.method in ("+", "T", "L"):
        letter = {"+": "c", "T": "d", "L": "e"}[row.method]
        return f"{letter} {row.method} {row.orientation_deg:>3}°"
    return "IMU circle"


def _mm(loc):
    return f"({loc[0] / MM:g}, {loc[1] / MM:g})"


def _um(value_rad):
    return f"{value_rad / URAD:+.1f}"


def travel(geometry):
    """The X and Y travel of a machine, from its axis lengths and centre.

    Parameters
    ----------
    geometry : Geometry
        The machine's error map.

    Returns
    -------
    x_range, y_range : tuple of float
        ``(min, max)`` of each axis. [m]
    """
    cx, cy = geometry.axis_centre_m
    return (
        (cx - geometry.length_x_m / 2, cx + geometry.length_x_m / 2),
        (cy - geometry.length_y_m / 2, cy + geometry.length_y_m / 2),
    )


def ballbar_locations(geometry, count=None, radius_m=None):
    """Circle centres in a row along the longer axis, evenly spaced, as Chapman lays them.

    Parameters
    ----------
    geometry : Geometry
        The machine's error map (its travel).
    count : int, optional
        Number of circles; by default as many as the longer travel needs,
        ``ceil(long / (2 r))``: 1 on a square machine, 3 on Chapman's 750 x
        250 mm machines (which they fit exactly); more overlap evenly.
    radius_m : float, optional
        Circle radius; by default half the shorter travel. [m]

    Returns
    -------
    centres : list of tuple of float
        [m]
    radius_m : float
        [m]

    Raises
    ------
    ImuSquareError
        If the radius is not positive or the circles cannot fit.
    """
    x_range, y_range = travel(geometry)
    spans = (x_range[1] - x_range[0], y_range[1] - y_range[0])
    if radius_m is None:
        radius_m = min(spans) / 2
    if not radius_m > 0:
        raise ImuSquareError(f"radius must be > 0 mm, got {radius_m / MM!r}")
    long_axis = 0 if spans[0] >= spans[1] else 1
    if count is None:
        count = max(1, math.ceil(spans[long_axis] / (2 * radius_m) - 1e-9))
    if not (isinstance(count, int) and count >= 1):
        raise ImuSquareError(f"the number of locations must be an integer >= 1, got {count!r}")
    ranges = (x_range, y_range)
    middle = [0.5 * (r[0] + r[1]) for r in ranges]
    lo, hi = ranges[long_axis][0] + radius_m, ranges[long_axis][1] - radius_m
    along = [0.5 * (lo + hi)] if count == 1 else list(np.linspace(lo, hi, count))
    centres = []
    for a in along:
        c = list(middle)
        c[long_axis] = float(a)
        centres.append(tuple(c))
    check_locations(geometry, centres, radius_m)
    return centres, radius_m


def check_locations(geometry, centres, radius_m):
    """Refuse circles that leave the machine's travel.

    Parameters
    ----------
    geometry : Geometry
        The machine's error map (its travel).
    centres : list of tuple of float
        Circle centres. [m]
    radius_m : float
        Circle radius. [m]

    Raises
    ------
    ImuSquareError
        Naming the first circle that leaves the travel.
    """
    if not centres:
        raise ImuSquareError("locations must list at least one circle centre, got none")
    x_range, y_range = travel(geometry)
    slack = 1e-9
    for c in centres:
        for axis, value, (lo, hi) in (("X", c[0], x_range), ("Y", c[1], y_range)):
            if value - radius_m < lo - slack or value + radius_m > hi + slack:
                raise ImuSquareError(
                    f"location {_mm(c)} mm with radius {radius_m / MM:g} mm leaves the {axis} "
                    f"travel [{lo / MM:g}, {hi / MM:g}] mm"
                )


def imu_program(base, centre_m, radius_m):
    """The IMU's program on one ballbar circle: ``base`` moved there, at its acceleration.

    Parameters
    ----------
    base : TestProgram
        Cycles, overshoot, dwell, order and centripetal acceleration to keep.
    centre_m : tuple of float
        Circle centre. [m]
    radius_m : float
        Circle radius. [m]

    Returns
    -------
    TestProgram
        Validated like a program file (feed and acceleration limits).
    """
    feed = math.sqrt(base.centripetal_m_s2 * radius_m)
    moved = replace(base, radius_m=radius_m, feed_m_per_s=feed, centre_m=tuple(centre_m))
    return program_from_mapping(moved.to_mapping(), "<compare program>")


def _x_slope(g, x):
    """Slope ``f'(X)`` of the X form: the X carriage's associated yaw there. [rad]"""
    X = x - g.axis_centre_m[0]
    return g.k_x * X + 4 * g.q_x * X**3


def _y_slope(g, y):
    """Slope ``g'(Y)`` of the Y form. [rad]"""
    return g.k_y * (y - g.axis_centre_m[1])


def _local_note(g, centre, alpha):
    """Why the local squareness at ``centre`` differs from alpha: straightness without yaw."""
    turn_x = 0.0 if g.yaw_x else -_x_slope(g, centre[0])
    turn_y = 0.0 if g.yaw_y else -_y_slope(g, centre[1])
    parts = []
    if abs(turn_x) >= _SAME_RAD:
        parts.append(f"X straightness without yaw turns X here by {_um(turn_x)}")
    if abs(turn_y) >= _SAME_RAD:
        parts.append(f"Y straightness without yaw turns Y here by {_um(turn_y)}")
    rest = float(g.local_machine_squareness(*centre)) - alpha - turn_x - turn_y
    if abs(rest) >= _SAME_RAD:
        parts.append(f"other local terms {_um(rest)}")
    return parts


def _ballbar_rows(machine, centres, radius_m, alpha):
    g = machine.geometry
    lash = (machine.backlash_x_m, machine.backlash_y_m)
    rows, full = [], []
    for arc in (360.0, ARC_DEG):
        values = []
        for c in centres:
            r = ballbar_squareness(g.deviation, c, radius_m, backlash=lash, arc_deg=arc)
            v = r.machine_squareness_rad
            values.append(v)
            local = float(g.local_machine_squareness(*c))
            if arc == 360.0:
                parts = _local_note(g, c, alpha)
                harm = v - local
                if abs(harm) >= _SAME_RAD:
                    parts.append(
                        f"{_um(harm)} from the form's 3rd harmonic in the sin 2φ term"
                        if g.q_x
                        else f"{_um(harm)} beyond the local squareness"
                    )
                note = "; ".join(parts) or "= the machine's squareness: no local turn here"
            else:
                d = v - full[len(values) - 1]
                note = "= the full circle: no odd harmonic about +Y in the trace"
                if abs(d) >= _SAME_RAD:
                    note = (
                        f"{_um(d)} from the full circle: over -20° to 200° the trace's 3rd and "
                        "higher harmonics are not orthogonal to sin 2φ"
                    )
            rows.append(
                MethodRow(
                    method="ballbar",
                    where=f"{_mm(c)} mm",
                    machine_squareness_rad=v,
                    note=note,
                    location_m=tuple(c),
                    arc_deg=arc,
                    details={"local_squareness_rad": local},
                )
            )
        if arc == 360.0:
            full = values
        if len(centres) > 1:
            mean = float(np.mean(values))
            turns = float(np.mean(full)) - alpha
            arc_bias = mean - float(np.mean(full))
            parts = []
            if abs(turns) >= _SAME_RAD:
                parts.append(f"the local departures leave {_um(turns)} across these circles")
            if abs(arc_bias) >= _SAME_RAD:
                parts.append(f"the arcs' own departure from full circles {_um(arc_bias)}")
            rows.append(
                MethodRow(
                    method="ballbar_mean",
                    where=f"mean of {len(centres)}",
                    machine_squareness_rad=mean,
                    note="; ".join(parts)
                    or "= the machine's squareness: the local departures cancel across the row",
                    arc_deg=arc,
                )
            )
    return rows, full


def _diagonal_row(g, x_range, y_range, alpha, where):
    v = diagonal_squareness(g.deviation, x_range, y_range)
    d = v - alpha
    note = (
        "= the machine's squareness: corner errors symmetric about the middle cancel in D1 - D2"
        if abs(d) < _SAME_RAD
        else f"{_um(d)}: the corners' errors do not cancel in D1 - D2"
    )
    mid = (0.5 * (x_range[0] + x_range[1]), 0.5 * (y_range[0] + y_range[1]))
    return MethodRow(
        method="diagonal", where=where, machine_squareness_rad=v, note=note, location_m=mid
    )


def _biaxial_rows(g, x_range, y_range, alpha, reference_line, suffix=""):
    rows = []
    mid = (0.5 * (x_range[0] + x_range[1]), 0.5 * (y_range[0] + y_range[1]))
    for shape in ("+", "T", "L"):
        for o in ORIENTATIONS_DEG:
            r = biaxial_squareness(
                g.deviation, shape, o, x_range, y_range, reference_line=reference_line
            )
            v = r.machine_squareness_rad
            xy, yx = r.y_line_x_m, r.x_line_y_m
            if shape == "L":
                where = f"corner {_L_CORNERS[o]} {_mm((xy, yx))}"
            elif shape == "T":
                where = f"bar {_T_BARS[o]}, arms x {xy / MM:g}, y {yx / MM:g}"
            else:
                where = f"arms through {_mm((xy, yx))}"
            parts = []
            yaw_x = _x_slope(g, xy) if g.yaw_x else 0.0
            yaw_y = _y_slope(g, yx) if g.yaw_y else 0.0
            if abs(yaw_x) >= _SAME_RAD:
                parts.append(f"X yaw {_um(yaw_x)} at x = {xy / MM:g} mm")
            if abs(yaw_y) >= _SAME_RAD:
                parts.append(f"Y yaw {_um(yaw_y)} at y = {yx / MM:g} mm")
            rest = v - alpha - yaw_x - yaw_y
            if abs(rest) >= _SAME_RAD:
                parts.append(f"{_um(rest)} from the forms' reference-line slopes")
            if parts:
                note = "sees " + ", ".join(parts)
            elif shape == "+" or not (g.yaw_x or g.yaw_y):
                note = "= the machine's squareness: no yaw where the arms run"
            else:
                note = "= the machine's squareness: the axes' yaw is zero where the arms run"
            rows.append(
                MethodRow(
                    method=shape,
                    where=where + suffix,
                    machine_squareness_rad=v,
                    note=note,
                    location_m=mid,
                    orientation_deg=o,
                )
            )
    return rows


def _imu_row(machine, sensor, program, centre, radius_m, seed, options, ballbar_rad):
    g = machine.geometry
    recording, truth = simulate_run(program, machine, sensor, seed=seed)
    try:
        result = analyze(recording, options)
    except AnalysisError as exc:
        raise AnalysisError(f"IMU circle at {_mm(centre)} mm: {exc}") from None
    cos2 = math.cos(2 * result.eps_c_rad)
    beta = truth["sensor_squareness_rad"]
    # theta_y - theta_x = beta + alpha cos(2 eps_c) (docs/model.md, the measurand)
    value = (result.squareness_rad - beta) / cos2
    ols = result
    if options.norm != "ols":
        ols = analyze(recording, replace(options, norm="ols", bootstrap_n=0))
    value_ols = (ols.squareness_rad - beta) / math.cos(2 * ols.eps_c_rad)
    # first-order model: the truth's theta_y - theta_x (local Jacobian, form
    # harmonics, gravity, exact in the sensor's turn) without beta
    eps_true = truth["eps_c_rad"] + truth["carriage_yaw_rad"]
    cos2_true = math.cos(2 * eps_true)
    local = truth["local_machine_squareness_rad"]
    harmonics = float(g.circle_squareness(*centre, radius_m)) - local
    expected = (truth["expected_squareness_rad"] - beta) / cos2_true
    gravity = truth["gravity_phase_rad"] / cos2_true
    turn = expected - local - harmonics - gravity
    u = result.u_squareness_rad / abs(cos2)
    parts = []
    if abs(harmonics - (ballbar_rad - local)) >= _SAME_RAD:
        parts.append(f"form harmonics {_um(harmonics - (ballbar_rad - local))}")
    if abs(turn) >= _SAME_RAD:
        parts.append(
            f"local scale mismatch through eps_c {math.degrees(eps_true):.1f}° {_um(turn)}"
        )
    if abs(gravity) >= _SAME_RAD:
        parts.append(f"gravity coupling {_um(gravity)}")
    d = value - ballbar_rad
    note = f"{_um(d)} from the ballbar; expected {_um(expected - ballbar_rad)}"
    note += f" ({', '.join(parts)})" if parts else " (same local squareness)"
    if abs(value - value_ols) > 2 * u:
        note += (
            f"; the robust fit is {_um(value - value_ols)} from least squares: it down-weights "
            "part of the trace (reversal spikes, or harmonics the sine model lacks)"
        )
    return MethodRow(
        method="imu",
        where=f"{_mm(centre)} mm",
        machine_squareness_rad=value,
        note=note,
        u_machine_squareness_rad=u,
        location_m=tuple(centre),
        details={
            "squareness_rad": result.squareness_rad,
            "sensor_squareness_rad": beta,
            "eps_c_deg": math.degrees(result.eps_c_rad),
            "expected_rad": expected,
            "least_squares_rad": value_ols,
            "ballbar_rad": ballbar_rad,
            "crb_rad": result.crb_rad,
            "seed": seed,
        },
    )


def compare_methods(
    machine,
    locations_m=None,
    radius_m=None,
    *,
    program=None,
    sensor=None,
    seed=0,
    reference_line="least_squares",
    local=False,
    imu=True,
    options=None,
):
    """Run every reference method and the IMU on a simulated machine.

    Parameters
    ----------
    machine : MachineModel
        The simulated machine.
    locations_m : list of tuple of float or int, optional
        Circle centres [m], or the number of circles in a row along the
        longer axis (:func:`ballbar_locations`); by default that function's
        count.
    radius_m : float, optional
        Circle radius; by default half the shorter travel. [m]
    program : TestProgram, optional
        The IMU test, moved onto each circle at its centripetal acceleration
        (:func:`imu_program`); by default the paper's program at
        ``DEFAULT_CENTRIPETAL_M_S2``.
    sensor : SensorModel, optional
        The simulated accelerometer; by default the paper's
        (``sensor_paper.toml``: 7 µg/√Hz, turned 2.1 deg).
    seed : int
        Noise seed of the first circle; circle ``i`` uses ``seed + i``.
    reference_line : {"least_squares", "end_point", "minimum_zone"}
        Reference line of the L/T/+ tests.
    local : bool
        Also run the diagonal and L/T/+ tests on the square of side ``2 r``
        around each circle (Chapman's local tests), not only over the whole
        travel.
    imu : bool
        Run the IMU rows (the slow part).
    options : AnalysisOptions, optional
        Pipeline options; by default the pipeline's, without the bootstrap
        (the rows report the type A uncertainty).

    Returns
    -------
    Comparison

    Raises
    ------
    ImuSquareError
        Circles outside the travel, a bad radius or count, an unknown
        reference line, or a program the moved circle makes invalid.
    """
    check_option("reference_line", reference_line, REFERENCE_LINES)
    g = machine.geometry
    if locations_m is None or isinstance(locations_m, int):
        centres, radius_m = ballbar_locations(g, locations_m, radius_m)
    else:
        centres = [tuple(float(v) for v in c) for c in locations_m]
        if radius_m is None:
            _, radius_m = ballbar_locations(g, 1)
        if not radius_m > 0:
            raise ImuSquareError(f"radius must be > 0 mm, got {radius_m / MM!r}")
        check_locations(g, centres, radius_m)
    alpha = float(g.machine_squareness_at(0.0))
    x_range, y_range = travel(g)

    rows, ballbar_full = _ballbar_rows(machine, centres, radius_m, alpha)
    rows.append(_diagonal_row(g, x_range, y_range, alpha, "whole travel"))
    if local:
        for c in centres:
            square = ((c[0] - radius_m, c[0] + radius_m), (c[1] - radius_m, c[1] + radius_m))
            rows.append(_diagonal_row(g, *square, alpha, f"square around {_mm(c)}"))
    rows += _biaxial_rows(g, x_range, y_range, alpha, reference_line)
    if local:
        for c in centres:
            square = ((c[0] - radius_m, c[0] + radius_m), (c[1] - radius_m, c[1] + radius_m))
            rows += _biaxial_rows(g, *square, alpha, reference_line, f" (square {_mm(c)})")

    imu_setup = None
    if imu:
        options = AnalysisOptions(bootstrap_n=0) if options is None else options
        if sensor is None:
            sensor = read_sensor(data_path("sensor_paper.toml"))
        if program is None:
            paper = read_program(data_path("program_paper.toml"))
            feed = math.sqrt(DEFAULT_CENTRIPETAL_M_S2 * paper.radius_m)
            program = replace(paper, feed_m_per_s=feed)
        imu_rows = []
        for i, (c, bb) in enumerate(zip(centres, ballbar_full, strict=True)):
            prog = imu_program(program, c, radius_m)
            imu_rows.append(_imu_row(machine, sensor, prog, c, radius_m, seed + i, options, bb))
        rows += imu_rows
        if len(imu_rows) > 1:
            mean = float(np.mean([r.machine_squareness_rad for r in imu_rows]))
            u = math.sqrt(sum(r.u_machine_squareness_rad**2 for r in imu_rows)) / len(imu_rows)
            bb_mean = float(np.mean(ballbar_full))
            rows.append(
                MethodRow(
                    method="imu_mean",
                    where=f"mean of {len(imu_rows)}",
                    machine_squareness_rad=mean,
                    note=f"{_um(mean - bb_mean)} from the ballbar mean",
                    u_machine_squareness_rad=u,
                )
            )
        imu_setup = {
            "sensor": sensor.model,
            "centripetal_m_s2": program.centripetal_m_s2,
            "cycles_per_direction": program.cycles_per_direction,
            "seed": seed,
            "options": {"norm": options.norm, "cutoff_hz": options.cutoff_hz},
        }
    return Comparison(
        machine_name=machine.name,
        x_range_m=x_range,
        y_range_m=y_range,
        machine_squareness_rad=alpha,
        radius_m=radius_m,
        locations_m=centres,
        reference_line=reference_line,
        imu=imu_setup,
        rows=rows,
    )
