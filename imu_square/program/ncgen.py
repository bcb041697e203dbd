"""NC code for the circle test: LinuxCNC, Fanuc and Sinumerik dialects.

The generated program is the nightly warm-up cycle of a :class:`TestProgram`:

1. a preamble that fixes units (mm), plane (XY), absolute positions, feed
   per minute and continuous-path mode (G64: a control's reset default may
   be exact stop, e.g. G60 on a Sinumerik, which would stop the axes at the
   end of every 360 degree arc);
2. an approach: a rapid move to a point ``approach_mm`` inside the circle on
   the start radius, a feed move onto the start point, and a dwell of
   ``max(program.dwell_s, START_DWELL_S)``, so that block 0 starts from rest
   at its start angle instead of blending the 90 degree corner into the
   first arc (the ``eps_c`` anchor relies on the block starting from rest);
3. every block of ``program.blocks()`` as circular arcs around
   ``program.centre_m`` (G3 for CCW, G2 for CW, centre given by incremental
   I/J), travelling ``overshoot + cycles * 360 + overshoot`` degrees, its
   feed word on its first arc (a multi-feed program runs its feeds one
   after the other, each with its own cycle count);
4. a dwell of ``program.dwell_s`` between blocks;
5. markers: a comment naming block index, run and direction at the start and
   the end of each block and, if asked, a user M-code at both places, which
   an acquisition trigger can use (on LinuxCNC, a user M-code M100-M199 runs
   an executable file of that name found in the user M-code path,
   ``[RS274NGC] USER_M_PATH`` or the program directory; the control stops
   with an error if it is missing);
6. the program end.

Each block is written as an arc of ``180 + overshoot`` degrees, then
``cycles - 1`` full circles (end point equal to start point, which LinuxCNC,
Fanuc and Sinumerik all read as a full circle when the centre is given with
I/J), then another arc of ``180 + overshoot`` degrees; an arc longer than
360 degrees is split into two equal halves. No arc is ever shorter than 180
degrees, so no partial arc can round to a zero-length move that a
control would read as a full circle.

Dialect differences handled here:

=========== =========== =============== ============= ============
dialect     metric      dwell           comment       end
=========== =========== =============== ============= ============
linuxcnc    G21         G4 P<seconds>   ``(...)``     M2
fanuc       G21         G4 X<seconds>   ``(...)``     M30, ``%``
sinumerik   G71         G4 F<seconds>   ``; ...``     M30
=========== =========== =============== ============= ============

All three read a plain ``G64`` as continuous-path mode (LinuxCNC: blend at
the best possible speed; Fanuc: cutting mode; Sinumerik: continuous-path
mode). Inside a block every arc joins the next tangentially, so no blending
tolerance is needed; LinuxCNC's ``G64 P<tol>`` is not used because very
small tolerances are known to make its planner exceed the acceleration
limits (LinuxCNC issue #546).

References
----------
.. [1] LinuxCNC G-code reference: G2/G3 (full circle when end equals start,
   I/J incremental in the default G91.1), G4 P seconds, M50 P0.
.. [2] Fanuc Series 0i-MF operator's manual: G02/G03 with I/J, G04 X/P.
.. [3] Siemens SINUMERIK 840D sl programming manual: G2/G3, G4 F<s>, G71,
   G60/G64.
"""

import math

from imu_square.errors import ProgramError
from imu_square.validation import check_option

DIALECTS = ("linuxcnc", "fanuc", "sinumerik")

# Digits after the decimal point for coordinates, in mm (1 um); every control
# above accepts 3 decimals in metric mode.
COORD_DECIMALS = 3

# The rapid move stops this far inside the circle; the rest is a feed move. [mm]
DEFAULT_APPROACH_MM = 5.0

# Shortest rest at the start point before block 0. [s]
START_DWELL_S = 0.5

# M-codes with a standard meaning that a marker must not reuse.
_RESERVED_MCODES = frozenset({0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 17, 19, 30, 98, 99})

_PREAMBLE = {
    "linuxcnc": ["G21 G17 G90 G91.1 G94 G40 G49 G80 G64"],
    "fanuc": ["G21 G17 G90 G94 G40 G49 G80 G64"],
    "sinumerik": ["G71 G17 G90 G94 G40 G64"],
}
_END = {"linuxcnc": ["M2"], "fanuc": ["M30", "%"], "sinumerik": ["M30"]}


def _check_dialect(dialect):
    check_option("dialect", dialect, DIALECTS, error=ProgramError)


def check_marker_mcode(marker_mcode, dialect):
    """Validate a user M-code for block markers.

    Parameters
    ----------
    marker_mcode : int
        The M number.
    dialect : str
        One of :data:`DIALECTS`.

    Returns
    -------
    int
        ``marker_mcode`` unchanged.

    Raises
    ------
    ProgramError
        If the number is reserved, out of range, or (LinuxCNC) outside the
        user M-code range M100-M199.
    """
    _check_dialect(dialect)
    if isinstance(marker_mcode, bool) or not isinstance(marker_mcode, int):
        raise ProgramError(f"marker M-code must be a whole number, got {marker_mcode!r}")
    if dialect == "linuxcnc":
        if not 100 <= marker_mcode <= 199:
            raise ProgramError(
                f"marker M-code for linuxcnc must be a user M-code in 100-199, got {marker_mcode!r}"
            )
    elif not 1 <= marker_mcode <= 999 or marker_mcode in _RESERVED_MCODES:
        raise ProgramError(
            f"marker M-code for {dialect} must be in 1-999 and not one of "
            f"{sorted(_RESERVED_MCODES)}, got {marker_mcode!r}"
        )
    return marker_mcode


def _comment(dialect, text):
    return f"; {text}" if dialect == "sinumerik" else f"({text})"


def _dwell(dialect, seconds):
    word = {"linuxcnc": "P", "fanuc": "X", "sinumerik": "F"}[dialect]
    return f"G4 {word}{seconds:.3f}"


def _fmt(value_mm):
    text = f"{value_mm:.{COORD_DECIMALS}f}"
    return "0.000" if text == "-0.000" else text


def _point_mm(program, angle_rad):
    cx, cy = program.centre_m
    r = program.radius_m
    return (
        _fmt((cx + r * math.cos(angle_rad)) * 1e3),
        _fmt((cy + r * math.sin(angle_rad)) * 1e3),
    )


def block_arcs_deg(program, feed=0):
    """Signless arc angles of one block, in execution order.

    Parameters
    ----------
    program : TestProgram
        The program.
    feed : int
        Index of the block's feed (its cycle count) in a multi-feed program.

    Returns
    -------
    list of float
        Arc angles, each in [180, 360]; their sum is
        ``2 * overshoot + 360 * cycles`` with the feed's cycles per direction. [deg]
    """
    edge = 180.0 + math.degrees(program.overshoot_rad)
    edge_arcs = [edge] if edge <= 360.0 else [edge / 2, edge / 2]
    return [*edge_arcs, *([360.0] * (program.feed_cycles[feed] - 1)), *edge_arcs]


def generate_nc(program, dialect, marker_mcode=None, feed_override_safe=False, approach_mm=None):
    """NC code for the circle test.

    Parameters
    ----------
    program : TestProgram
        The validated program.
    dialect : {"linuxcnc", "fanuc", "sinumerik"}
        Control dialect.
    marker_mcode : int, optional
        User M-code written at the start and the end of every block, for an
        acquisition trigger.
    feed_override_safe : bool
        Lock the feed override at 100 % during the blocks, so that the path
        speed is the programmed one whatever the operator's dial says. Only
        LinuxCNC has a standard code for it (M50 P0 ... M50 P1); on Fanuc
        and Sinumerik it is machine-builder specific and this raises.
    approach_mm : float, optional
        Distance inside the circle, on the start radius, that the rapid move
        stops short of the start point; the rest is a feed move. Default
        ``min(5, radius_mm / 2)``. [mm]

    Returns
    -------
    str
        The program text, one block per line, ending with a newline.

    Raises
    ------
    ProgramError
        Unknown dialect, bad marker M-code, an approach that does not fit in
        the circle, or a feed-override lock the dialect cannot express.
    """
    _check_dialect(dialect)
    if marker_mcode is not None:
        check_marker_mcode(marker_mcode, dialect)
    if feed_override_safe and dialect != "linuxcnc":
        raise ProgramError(
            f"--feed-override-safe: {dialect} has no standard code to lock the feed override "
            f"(it is machine-builder specific); allowed only for 'linuxcnc', got {dialect!r}"
        )
    radius_mm = program.radius_m * 1e3
    if approach_mm is None:
        approach_mm = min(DEFAULT_APPROACH_MM, radius_mm / 2)
    if not 0 < approach_mm < radius_mm:
        raise ProgramError(
            f"approach_mm must be in (0, radius_mm={radius_mm:g}), got {approach_mm!r}"
        )

    feeds = [f"F{v * 6e4:.3f}" for v in program.feeds]
    cx_mm, cy_mm = (c * 1e3 for c in program.centre_m)
    lines = []
    if dialect == "fanuc":
        lines += ["%", "O1000 (IMU-SQUARE WARM-UP)"]
    else:
        lines.append(_comment(dialect, "IMU-SQUARE WARM-UP"))
    speeds = " ".join(f"{v * 6e4:g}" for v in program.feeds)
    lines.append(
        _comment(
            dialect,
            f"R {radius_mm:g} MM FEED{'S' if program.n_feeds > 1 else ''} {speeds} MM/MIN "
            f"CENTRE X{cx_mm:g} Y{cy_mm:g} - SET Z TO A SAFE HEIGHT BEFORE START",
        )
    )
    if marker_mcode is not None and dialect == "linuxcnc":
        lines.append(
            _comment(
                dialect,
                f"M{marker_mcode} RUNS AN EXECUTABLE FILE NAMED M{marker_mcode} THAT MUST BE "
                "IN THE USER M-CODE PATH - RS274NGC USER_M_PATH OR THE PROGRAM DIRECTORY",
            )
        )
    lines += _PREAMBLE[dialect]

    start = program.start_angle_rad
    inner = radius_mm - approach_mm
    ax = _fmt(cx_mm + inner * math.cos(start))
    ay = _fmt(cy_mm + inner * math.sin(start))
    x, y = _point_mm(program, start)
    lines.append(f"G0 X{ax} Y{ay}")
    lines.append(f"G1 X{x} Y{y} {feeds[0]}")
    lines.append(_dwell(dialect, max(program.dwell_s, START_DWELL_S)))
    if feed_override_safe:
        lines.append("M50 P0")

    for block in program.blocks():
        arcs = block_arcs_deg(program, block.feed)
        if block.index > 0 and program.dwell_s > 0:
            lines.append(_dwell(dialect, program.dwell_s))
        tag = f"BLOCK {block.index} RUN {block.run} {block.direction.upper()}"
        if program.n_feeds > 1:
            tag += f" FEED {program.feeds[block.feed] * 6e4:g}"
        lines.append(_comment(dialect, f"IMU-SQUARE START {tag}"))
        if marker_mcode is not None:
            lines.append(f"M{marker_mcode}")
        gword = "G3" if block.sign > 0 else "G2"
        angle = block.start_angle_rad
        for i, arc_deg in enumerate(arcs):
            i_mm = _fmt(cx_mm - float(x))
            j_mm = _fmt(cy_mm - float(y))
            angle += block.sign * math.radians(arc_deg)
            if arc_deg < 360.0:
                x, y = _point_mm(program, angle)
            words = f"{gword} X{x} Y{y} I{i_mm} J{j_mm}"
            lines.append(f"{words} {feeds[block.feed]}" if i == 0 else words)
        if marker_mcode is not None:
            lines.append(f"M{marker_mcode}")
        lines.append(_comment(dialect, f"IMU-SQUARE END {tag}"))

    if feed_override_safe:
        lines.append("M50 P1")
    lines += _END[dialect]
    return "\n".join(lines) + "\n"
