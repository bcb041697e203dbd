"""The circle test program: validation, units and nominal timing.

A program file is TOML in the units machinists use (mm, mm/min, degrees)::

    [program]
    plane = "XY"
    radius_mm = 100.0
    feed_mm_per_min = 6000.0
    cycles_per_direction = 15
    overshoot_deg = 180.0
    start_angle_deg = 0.0
    order = ["ccw", "cw"]
    dwell_s = 2.0
    runs = 1
    centre_mm = [0.0, 0.0]      # optional: circle centre in machine coordinates

A program may run the same circle at several feeds, to separate what scales
with the feed (the inertial signal, ``v^2/r``) from what does not (gravity
coupling through a table tilt that changes with position)::

    feeds_mm_per_min = [6000.0, 3000.0]   # instead of feed_mm_per_min
    cycles_per_direction = [15, 8]        # one count per feed, or one for all

The blocks run feed by feed: every run of ``order`` at the first feed, then
at the second, and so on, so that each feed's blocks form one stretch of the
recording (a logger that writes one file per feed cuts there).

Inside the code everything is SI. Position angle ``phi`` is the commanded
angle of the tool on the circle, measured from +X towards +Y; a CCW block
increases it, a CW block decreases it. Each block runs
``overshoot + cycles_per_direction * 360 + overshoot`` degrees and starts
where the previous block ended; only the middle whole cycles are analysed.
"""

import itertools
import math
from dataclasses import asdict, dataclass, field, replace

from imu_square.errors import ProgramError
from imu_square.textfile import parse_toml, read_text
from imu_square.validation import TomlTable, interval

DIRECTIONS = ("ccw", "cw")
SUPPORTED_PLANES = ("XY",)

# Plausible centripetal acceleration for a circle test on a machine tool.
# Below ~5 mm/s^2 the signal drowns in a MEMS sensor's noise and drift; above
# ~2 g no machine tool runs a stable circle.
MIN_CENTRIPETAL_M_S2 = 0.005
MAX_CENTRIPETAL_M_S2 = 20.0
MAX_RADIUS_M = 1.0
MAX_FEED_M_PER_S = 2.0
# A multi-feed program: at most this many feeds, and each feed at least this
# factor from every other (their v^2/r then differ by 10 %; closer feeds
# cannot separate a feed-independent term: its uncertainty grows as
# A1 / (A1 - A2)).
MAX_FEEDS = 8
MIN_FEED_RATIO = 1.05
# Between the blocks of a multi-feed program the table must come to rest for
# this long, so that the analysis tells the feeds apart (longer than the
# settling of its low-pass, 0.27 s at the paper's 4 Hz). [s]
MIN_FEEDS_DWELL_S = 0.5


@dataclass(frozen=True)
class BlockPlan:
    """One CCW or CW block of the program at nominal (constant) feed.

    Attributes
    ----------
    index : int
        Block number from 0, counting over all runs.
    run : int
        Run number from 0.
    direction : str
        ``"ccw"`` or ``"cw"``.
    sign : int
        +1 for CCW (position angle increases), -1 for CW.
    start_angle_rad : float
        Commanded position angle where the block starts. [rad]
    t_start_s, t_end_s : float
        Nominal start and end of motion from the start of the first block. [s]
    analysed_start_rad : float
        Position angle where the first analysed cycle starts (after the
        overshoot). [rad]
    feed : int
        Index of the block's feed in :attr:`TestProgram.feeds_m_per_s` (0 for a
        one-feed program).
    """

    index: int
    run: int
    direction: str
    sign: int
    start_angle_rad: float
    t_start_s: float
    t_end_s: float
    analysed_start_rad: float
    feed: int = 0

    @property
    def duration_s(self):
        """Nominal duration of the block's motion. [s]"""
        return self.t_end_s - self.t_start_s

    @property
    def t_mid_s(self):
        """Nominal middle of the block's motion. [s]"""
        return 0.5 * (self.t_start_s + self.t_end_s)


@dataclass(frozen=True)
class TestProgram:
    """A validated circle test program, in SI units.

    Build one with :func:`read_program` or :func:`program_from_mapping`; the
    constructor assumes validated values.

    Attributes
    ----------
    plane : str
        Plane of the circle; only ``"XY"`` is supported.
    radius_m : float
        Circle radius. [m]
    feed_m_per_s : float
        Programmed path speed; the first feed of a multi-feed program. [m/s]
    cycles_per_direction : int
        Whole analysed cycles in each block; the first feed's in a multi-feed
        program.
    overshoot_rad : float
        Extra motion at the start and at the end of each block. [rad]
    start_angle_rad : float
        Position angle where the first block starts. [rad]
    order : tuple of str
        Directions of the blocks in one run, e.g. ``("ccw", "cw")``.
    dwell_s : float
        Pause between blocks. [s]
    runs : int
        Number of repetitions of ``order``.
    centre_m : tuple of float
        Circle centre in machine coordinates. [m]
    feeds_m_per_s : tuple of float
        Every feed of a multi-feed program, in the order they run; empty for a
        one-feed program (a single feed is normalised to empty). [m/s]
    cycles_per_feed : tuple of int
        Whole analysed cycles per block at each feed; empty when every feed
        runs ``cycles_per_direction`` (equal counts are normalised to empty).

    Notes
    -----
    The quantities of one circle (:attr:`omega_rad_s`, :attr:`period_s`,
    :attr:`centripetal_m_s2`, :attr:`block_angle_rad`, ...) exist only for a
    one-feed program; a multi-feed program raises :class:`ProgramError` for
    them rather than answer for one of its feeds. :meth:`at_feed` gives the
    one-feed program of each feed.
    """

    __test__ = False  # not a pytest test class, despite the name

    plane: str = "XY"
    radius_m: float = 0.1
    feed_m_per_s: float = 0.1
    cycles_per_direction: int = 15
    overshoot_rad: float = math.pi
    start_angle_rad: float = 0.0
    order: tuple = ("ccw", "cw")
    dwell_s: float = 2.0
    runs: int = 1
    centre_m: tuple = field(default=(0.0, 0.0))
    feeds_m_per_s: tuple = ()
    cycles_per_feed: tuple = ()

    def __post_init__(self):
        feeds = tuple(float(v) for v in self.feeds_m_per_s)
        if len(feeds) == 1:
            object.__setattr__(self, "feed_m_per_s", feeds[0])
            feeds = ()
        elif feeds:
            object.__setattr__(self, "feed_m_per_s", feeds[0])
        object.__setattr__(self, "feeds_m_per_s", feeds)
        cycles = tuple(int(c) for c in self.cycles_per_feed)
        if cycles:
            if len(cycles) != max(len(feeds), 1):
                raise ValueError(
                    f"cycles_per_feed needs one count per feed ({max(len(feeds), 1)}), "
                    f"got {cycles!r}"
                )
            object.__setattr__(self, "cycles_per_direction", cycles[0])
            if len(set(cycles)) == 1:
                cycles = ()
        object.__setattr__(self, "cycles_per_feed", cycles)

    @property
    def n_feeds(self):
        """Number of feeds the circle runs at."""
        return max(len(self.feeds_m_per_s), 1)

    @property
    def feeds(self):
        """Every feed, in the order they run (one for a one-feed program). [m/s]"""
        return self.feeds_m_per_s or (self.feed_m_per_s,)

    @property
    def feed_cycles(self):
        """Whole analysed cycles per block at each feed."""
        return self.cycles_per_feed or (self.cycles_per_direction,) * self.n_feeds

    def _one_feed(self, name):
        if self.n_feeds > 1:
            feeds = ", ".join(f"{v * 6e4:g}" for v in self.feeds)
            raise ProgramError(
                f"{name}: the program runs {self.n_feeds} feeds ({feeds} mm/min) and has no "
                f"single {name}; take each feed's program (at_feed) or analyse the feeds "
                f"together (analyze --separate-gravity)"
            )

    def at_feed(self, feed):
        """The one-feed program of one feed's blocks.

        Parameters
        ----------
        feed : int
            Index into :attr:`feeds`.

        Returns
        -------
        TestProgram
            Same circle, ``order``, ``runs``, overshoot and dwell, at that feed
            with its cycle count, starting at the angle where that feed's first
            block starts; its blocks are that feed's blocks, numbered from 0.
        """
        if not 0 <= feed < self.n_feeds:
            raise ProgramError(f"feed index must be in [0, {self.n_feeds - 1}], got {feed!r}")
        if self.n_feeds == 1:
            return self
        first = next(b for b in self.blocks() if b.feed == feed)
        return replace(
            self,
            feed_m_per_s=self.feeds[feed],
            cycles_per_direction=self.feed_cycles[feed],
            start_angle_rad=first.start_angle_rad,
            feeds_m_per_s=(),
            cycles_per_feed=(),
        )

    @property
    def omega_rad_s(self):
        """Angular speed of the tool on the circle (one-feed program). [rad/s]"""
        self._one_feed("omega_rad_s")
        return self.feed_m_per_s / self.radius_m

    @property
    def frequency_hz(self):
        """Circle frequency (one-feed program). [Hz]"""
        self._one_feed("frequency_hz")
        return self.omega_rad_s / (2 * math.pi)

    @property
    def period_s(self):
        """Time for one full cycle at the programmed feed (one-feed program). [s]"""
        self._one_feed("period_s")
        return 2 * math.pi / self.omega_rad_s

    @property
    def centripetal_m_s2(self):
        """Centripetal acceleration v^2/r at the programmed feed (one-feed program). [m/s^2]"""
        self._one_feed("centripetal_m_s2")
        return self.feed_m_per_s**2 / self.radius_m

    @property
    def block_angle_rad(self):
        """Total angle travelled in one block, overshoots included (one-feed program). [rad]"""
        self._one_feed("block_angle_rad")
        return 2 * math.pi * self.cycles_per_direction + 2 * self.overshoot_rad

    @property
    def block_duration_s(self):
        """Nominal duration of one block at constant feed (one-feed program). [s]"""
        self._one_feed("block_duration_s")
        return self.block_angle_rad / self.omega_rad_s

    @property
    def n_blocks(self):
        """Number of blocks over all runs and feeds."""
        return len(self.order) * self.runs * self.n_feeds

    @property
    def duration_s(self):
        """Nominal duration from the start of the first block to the end of the last. [s]"""
        return self.blocks()[-1].t_end_s

    def blocks(self):
        """Nominal plan of every block, in execution order (feed by feed).

        Returns
        -------
        list of BlockPlan
            One plan per block, in the order the machine runs them.
        """
        plans = []
        angle = self.start_angle_rad
        t = 0.0
        for feed, (speed, cycles) in enumerate(zip(self.feeds, self.feed_cycles, strict=True)):
            block_angle = 2 * math.pi * cycles + 2 * self.overshoot_rad
            block_s = block_angle * self.radius_m / speed
            for run in range(self.runs):
                for direction in self.order:
                    sign = 1 if direction == "ccw" else -1
                    plans.append(
                        BlockPlan(
                            index=len(plans),
                            run=run,
                            direction=direction,
                            sign=sign,
                            start_angle_rad=angle,
                            t_start_s=t,
                            t_end_s=t + block_s,
                            analysed_start_rad=angle + sign * self.overshoot_rad,
                            feed=feed,
                        )
                    )
                    angle += sign * block_angle
                    t += block_s + self.dwell_s
        return plans

    def describe(self):
        """The circle in a few words: radius, feed(s) and cycles each way.

        Returns
        -------
        str
            For example ``r = 100 mm at 6000 mm/min, 15 cycles each way``.
        """
        from imu_square.units import MM, MM_PER_MIN

        feeds = " and ".join(f"{v / MM_PER_MIN:g}" for v in self.feeds)
        cycles = " and ".join(str(n) for n in self.feed_cycles)
        runs = f", {self.runs} runs" if self.runs > 1 else ""
        return f"r = {self.radius_m / MM:g} mm at {feeds} mm/min, {cycles} cycles each way{runs}"

    def to_mapping(self):
        """The program as a ``[program]`` table in file units (mm, mm/min, degrees).

        Returns
        -------
        dict of str to object
            The fields of the program file and their values.
        """
        if self.n_feeds > 1:
            feed = {"feeds_mm_per_min": [v * 6e4 for v in self.feeds]}
        else:
            feed = {"feed_mm_per_min": self.feed_m_per_s * 6e4}
        return {
            "plane": self.plane,
            "radius_mm": self.radius_m * 1e3,
            **feed,
            "cycles_per_direction": list(self.cycles_per_feed) or self.cycles_per_direction,
            "overshoot_deg": math.degrees(self.overshoot_rad),
            "start_angle_deg": math.degrees(self.start_angle_rad),
            "order": list(self.order),
            "dwell_s": self.dwell_s,
            "runs": self.runs,
            "centre_mm": [c * 1e3 for c in self.centre_m],
        }

    def to_toml(self):
        """The program as TOML text that :func:`read_program` reads back exactly.

        Returns
        -------
        str
            The ``[program]`` table, one field a line.
        """
        lines = ["[program]"]
        for key, value in self.to_mapping().items():
            lines.append(f"{key} = {_toml_value(value)}")
        return "\n".join(lines) + "\n"

    def as_dict(self):
        """All fields in SI units, for JSON.

        Returns
        -------
        dict of str to object
            Every field of the program by its name.
        """
        return asdict(self)


def _toml_value(value):
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    if isinstance(value, float):
        return repr(value)
    return str(value)


_FIELDS = (
    "plane",
    "radius_mm",
    "feed_mm_per_min",
    "feeds_mm_per_min",
    "cycles_per_direction",
    "overshoot_deg",
    "start_angle_deg",
    "order",
    "dwell_s",
    "runs",
    "centre_mm",
)
_REQUIRED = ("radius_mm", "cycles_per_direction")


def _feeds(t):
    """The feeds in mm/min: ``[feed_mm_per_min]`` or the checked ``feeds_mm_per_min``."""
    top = MAX_FEED_M_PER_S * 6e4
    if t.has("feed_mm_per_min"):
        return [t.number("feed_mm_per_min", 0.0, top, lo_open=True)]
    what = f"a list of 1 to {MAX_FEEDS} feeds in mm/min"
    feeds = list(
        t.numbers("feeds_mm_per_min", range(1, MAX_FEEDS + 1), what, 0.0, top, lo_open=True)
    )
    for slow, fast in itertools.pairwise(sorted(feeds)):
        if fast < MIN_FEED_RATIO * slow:
            t.error(
                f"feeds_mm_per_min must differ from each other by at least "
                f"{MIN_FEED_RATIO - 1:.0%} (v^2/r by {MIN_FEED_RATIO**2 - 1:.0%}) to separate "
                f"what scales with the feed from what does not, got {feeds!r}"
            )
    return feeds


def _cycles(t, n_feeds):
    """Cycles per direction at each feed, from one count or a list of one per feed."""
    value = t.get("cycles_per_direction")
    if not isinstance(value, list):
        value = [value] * n_feeds
    elif len(value) != n_feeds:
        what = f"one whole number, or a list of one per feed ({n_feeds})"
        t.fail("cycles_per_direction", what, value)
    return [t.integer("cycles_per_direction", 2, 1000, value=c) for c in value]


def program_from_mapping(table, source="<program>"):
    """Validate a ``[program]`` table and convert it to SI.

    Parameters
    ----------
    table : dict
        The ``[program]`` table, in file units (mm, mm/min, degrees, s).
    source : str
        Where the table came from, for error messages.

    Returns
    -------
    TestProgram

    Raises
    ------
    ProgramError
        Naming the field, the value received and what is allowed.
    """
    t = TomlTable(table, "[program]", _FIELDS, source, error=ProgramError, terse=True)
    for key in _REQUIRED:
        t.get(key)
    if t.has("feed_mm_per_min") == t.has("feeds_mm_per_min"):
        t.error(
            "needs exactly one of 'feed_mm_per_min' (one feed) and 'feeds_mm_per_min' (a list "
            f"of feeds), got {'both' if t.has('feed_mm_per_min') else 'neither'}"
        )
    d = TestProgram()
    plane = t.choice("plane", SUPPORTED_PLANES, default=d.plane)
    radius_mm = t.number("radius_mm", 0.0, MAX_RADIUS_M * 1e3, lo_open=True)
    feeds = _feeds(t)
    cycles = _cycles(t, len(feeds))
    overshoot = t.number("overshoot_deg", 0.0, 360.0, default=180.0)
    start = t.number("start_angle_deg", default=0.0)
    order = t.get("order", list(d.order))
    if (
        not isinstance(order, list)
        or not order
        or any(o not in DIRECTIONS for o in order)
        or set(order) != set(DIRECTIONS)
    ):
        t.error(f"order must list 'ccw' and 'cw' (each at least once), got {order!r}")
    dwell = t.number("dwell_s", 0.0, 600.0, default=d.dwell_s)
    if len(feeds) > 1 and dwell < MIN_FEEDS_DWELL_S:
        t.fail(
            "dwell_s",
            f"at least {MIN_FEEDS_DWELL_S:g} s with several feeds (the table rests between the "
            "feeds so that they are told apart)",
            dwell,
        )
    runs = t.integer("runs", default=d.runs)
    if not 1 <= runs <= 1000:  # the program file's own wording, older than check_int's
        t.fail("runs", f"in {interval(1, 1000)}", runs)
    centre = t.numbers("centre_mm", (2,), "[x, y] in mm", default=[0.0, 0.0])

    radius_m = radius_mm * 1e-3
    key = "feed_mm_per_min" if t.has("feed_mm_per_min") else "feeds_mm_per_min"
    for feed in feeds:
        centripetal = (feed / 6e4) ** 2 / radius_m
        if not MIN_CENTRIPETAL_M_S2 <= centripetal <= MAX_CENTRIPETAL_M_S2:
            t.error(
                f"{key}={feed:g} with radius_mm={radius_mm:g} gives a centripetal acceleration "
                f"of {centripetal:.3g} m/s^2; a machine-tool circle test needs "
                f"{MIN_CENTRIPETAL_M_S2:g} to {MAX_CENTRIPETAL_M_S2:g} m/s^2"
            )
    return TestProgram(
        plane=plane,
        radius_m=radius_m,
        feed_m_per_s=feeds[0] / 6e4,
        cycles_per_direction=cycles[0],
        feeds_m_per_s=tuple(f / 6e4 for f in feeds) if len(feeds) > 1 else (),
        cycles_per_feed=tuple(cycles) if len(feeds) > 1 else (),
        overshoot_rad=math.radians(overshoot),
        start_angle_rad=math.radians(start),
        order=tuple(order),
        dwell_s=dwell,
        runs=runs,
        centre_m=(centre[0] * 1e-3, centre[1] * 1e-3),
    )


def parse_program(text, source="<program>"):
    """Parse program TOML text.

    Parameters
    ----------
    text : str
        TOML with a ``[program]`` table.
    source : str
        Where the text came from, for error messages.

    Returns
    -------
    TestProgram
    """
    doc = parse_toml(text, source, ProgramError)
    if "program" not in doc:
        raise ProgramError(f"{source}: no [program] table; see the README for the layout")
    return program_from_mapping(doc["program"], source)


def read_program(path):
    """Read and validate a program file.

    Parameters
    ----------
    path : str or Path
        The TOML file.

    Returns
    -------
    TestProgram
    """
    return parse_program(read_text(path, ProgramError, "program file"), str(path))


def default_program():
    """The paper's test: r = 100 mm, 6000 mm/min, 15 cycles each way, 180 deg overshoot.

    Returns
    -------
    TestProgram
    """
    return TestProgram()
