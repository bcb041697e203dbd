"""A small, strict reader of the NC code that :mod:`imu_square.program.ncgen` writes (tests only).

It understands only the subset the generator uses (G0/G1/G2/G3 in the XY
plane with incremental I/J centres, G4 dwells, M-codes, comments, program
end) and rejects everything else, so that a test can check the path a
control would run: radius, centre, direction and angle of every arc, dwell
durations and markers. It is not a general G-code interpreter.
"""

import math
import re
from dataclasses import dataclass, field

from imu_square.errors import ProgramError
from imu_square.program.ncgen import DIALECTS
from imu_square.validation import check_option

# Largest gap between the start and end radius of an arc, as the controls
# allow (LinuxCNC: 0.0005 in); our coordinates are rounded to 1 um. [mm]
RADIUS_TOLERANCE_MM = 0.005

_WORD = re.compile(r"([A-Z])([-+]?(?:\d+\.?\d*|\.\d+))")
_PREAMBLE_G = {
    "linuxcnc": {"G21", "G17", "G90", "G91.1", "G94", "G40", "G49", "G80", "G64"},
    "fanuc": {"G21", "G17", "G90", "G94", "G40", "G49", "G80", "G64"},
    "sinumerik": {"G71", "G17", "G90", "G94", "G40", "G64"},
}
_METRIC = {"linuxcnc": "G21", "fanuc": "G21", "sinumerik": "G71"}
_DWELL_WORD = {"linuxcnc": "P", "fanuc": "X", "sinumerik": "F"}
_END = {"linuxcnc": "M2", "fanuc": "M30", "sinumerik": "M30"}


@dataclass(frozen=True)
class NcEvent:
    """One thing the program does, in execution order.

    Attributes
    ----------
    kind : str
        ``"comment"``, ``"mcode"``, ``"dwell"``, ``"rapid"``, ``"feed"`` or ``"arc"``.
    line : int
        Line number from 1.
    text : str
        Comment text (``"comment"``), else ``""``.
    value : float
        M number (``"mcode"``), dwell time in s (``"dwell"``), feed in
        mm/min (motions), else 0.
    start, end : tuple of float
        Start and end point of a motion. [mm]
    centre : tuple of float
        Arc centre. [mm]
    sign : int
        +1 for G3 (CCW), -1 for G2 (CW), 0 for other events.
    angle_rad : float
        Angle travelled by an arc, always positive; 2*pi for a full circle. [rad]
    """

    kind: str
    line: int
    text: str = ""
    value: float = 0.0
    start: tuple = (math.nan, math.nan)
    end: tuple = (math.nan, math.nan)
    centre: tuple = (math.nan, math.nan)
    sign: int = 0
    angle_rad: float = 0.0

    @property
    def radius_mm(self):
        """Arc radius at the start point. [mm]"""
        return math.hypot(self.start[0] - self.centre[0], self.start[1] - self.centre[1])


@dataclass
class NcTrace:
    """The events of a parsed program.

    Attributes
    ----------
    events : list of NcEvent
        In execution order.
    ended : bool
        Whether the program-end code was reached.
    """

    events: list = field(default_factory=list)
    ended: bool = False

    def of_kind(self, kind):
        """The events of one kind, in order."""
        return [e for e in self.events if e.kind == kind]


def _fail(line_no, line, what):
    raise ProgramError(f"NC line {line_no}: {what}; got {line!r}")


def _split_comment(dialect, line_no, line):
    """Return (code, comment or None)."""
    if dialect in ("linuxcnc", "fanuc") and "(" in line:
        m = re.fullmatch(r"([^()]*)\(([^()]*)\)\s*", line)
        if m is None:
            _fail(line_no, line, "expected at most one '(...)' comment at the end")
        return m.group(1), m.group(2)
    if dialect in ("linuxcnc", "sinumerik") and ";" in line:
        code, _, comment = line.partition(";")
        return code, comment.strip()
    if ")" in line or ";" in line:
        _fail(line_no, line, f"comment syntax not allowed in {dialect}")
    return line, None


def _words(line_no, line, code):
    code = code.strip()
    words = _WORD.findall(code)
    if re.sub(r"\s+", "", code) != "".join(a + b for a, b in words):
        _fail(line_no, line, "expected only letter-number words")
    return words


def _arc_angle(start, end, centre, sign):
    a0 = math.atan2(start[1] - centre[1], start[0] - centre[0])
    a1 = math.atan2(end[1] - centre[1], end[0] - centre[0])
    if start == end:
        return 2 * math.pi
    return (sign * (a1 - a0)) % (2 * math.pi)


def parse_nc(text, dialect):
    """Read NC code of the generator's subset, strictly.

    Parameters
    ----------
    text : str
        The program.
    dialect : {"linuxcnc", "fanuc", "sinumerik"}
        The control dialect the text claims to be.

    Returns
    -------
    NcTrace

    Raises
    ------
    ProgramError
        On anything outside the subset, a motion before the units, plane,
        absolute mode and continuous-path mode (G64) are set, an arc whose
        end radius differs from its start radius, a missing feed, or code
        after the program end.
    """
    check_option("dialect", dialect, DIALECTS, error=ProgramError)
    trace = NcTrace()
    modes = set()
    pos = None
    feed = None
    lines = text.splitlines()
    for line_no, raw in enumerate(lines, start=1):
        line = raw.strip()
        if not line:
            continue
        if trace.ended:
            if dialect == "fanuc" and line == "%":
                continue
            _fail(line_no, line, "nothing may follow the program end")
        if line == "%":
            if dialect != "fanuc" or line_no != 1:
                _fail(line_no, line, "'%' only as the first and last line of a fanuc program")
            continue
        code, comment = _split_comment(dialect, line_no, line)
        if comment is not None:
            trace.events.append(NcEvent("comment", line_no, text=comment))
        words = _words(line_no, line, code)
        if not words:
            continue
        letters = [w[0] for w in words]
        if len(set(letters) - {"G"}) != len(letters) - letters.count("G"):
            _fail(line_no, line, "a word letter repeats")
        if letters[0] == "O":
            if dialect != "fanuc" or len(words) != 1 or trace.events[:-1] != []:
                _fail(line_no, line, "a program number only at the top of a fanuc program")
            continue
        gcodes = ["G" + n for letter, n in words if letter == "G"]
        values = {letter: n for letter, n in words if letter != "G"}
        if "M" in values:
            if len(words) != 1 and not (
                dialect == "linuxcnc" and values["M"] == "50" and set(values) == {"M", "P"}
            ):
                _fail(line_no, line, "an M-code must stand alone in its block")
            number = int(values["M"])
            if f"M{number}" == _END[dialect]:
                trace.ended = True
                continue
            trace.events.append(NcEvent("mcode", line_no, value=float(number)))
            continue
        if set(gcodes) <= _PREAMBLE_G[dialect] and not values:
            modes |= set(gcodes)
            continue
        if len(gcodes) != 1:
            _fail(line_no, line, "expected one motion or dwell G-code per block")
        g = gcodes[0]
        if g == "G4":
            word = _DWELL_WORD[dialect]
            if set(values) != {word}:
                _fail(line_no, line, f"{dialect} dwell is 'G4 {word}<seconds>' alone")
            trace.events.append(NcEvent("dwell", line_no, value=float(values[word])))
            continue
        missing = {_METRIC[dialect], "G17", "G90", "G64"} - modes
        if missing:
            _fail(line_no, line, f"motion before {sorted(missing)} is set")
        if "F" in values:
            feed = float(values["F"])
        if g in ("G0", "G1"):
            if set(values) - {"X", "Y", "F"} or not {"X", "Y"} <= set(values):
                _fail(line_no, line, f"{g} takes X, Y (and F)")
            end = (float(values["X"]), float(values["Y"]))
            if g == "G1" and feed is None:
                _fail(line_no, line, "feed move before any F")
            kind = "rapid" if g == "G0" else "feed"
            rate = 0.0 if g == "G0" else feed
            trace.events.append(NcEvent(kind, line_no, value=rate, start=pos or end, end=end))
            pos = end
            continue
        if g not in ("G2", "G3"):
            _fail(line_no, line, "only G0, G1, G2, G3 and G4 are in the generator's subset")
        if set(values) - {"X", "Y", "I", "J", "F"} or not {"X", "Y", "I", "J"} <= set(values):
            _fail(line_no, line, f"{g} takes X, Y, I, J (and F)")
        if pos is None or feed is None:
            _fail(line_no, line, "arc before a start position and a feed are known")
        end = (float(values["X"]), float(values["Y"]))
        centre = (pos[0] + float(values["I"]), pos[1] + float(values["J"]))
        sign = 1 if g == "G3" else -1
        r0 = math.hypot(pos[0] - centre[0], pos[1] - centre[1])
        r1 = math.hypot(end[0] - centre[0], end[1] - centre[1])
        if abs(r1 - r0) > RADIUS_TOLERANCE_MM:
            _fail(line_no, line, f"end radius {r1:.6f} differs from start radius {r0:.6f}")
        trace.events.append(
            NcEvent(
                "arc",
                line_no,
                value=feed,
                start=pos,
                end=end,
                centre=centre,
                sign=sign,
                angle_rad=_arc_angle(pos, end, centre, sign),
            )
        )
        pos = end
    if not trace.ended:
        raise ProgramError(f"NC program has no {_END[dialect]} program end")
    return trace
