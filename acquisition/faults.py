"""Faults the emulated board injects into its own byte stream, and their exact log.

A pseudo-terminal never loses, corrupts or overruns anything (it blocks the
writer instead), so every link fault a real USB/UART board shows has to come
from the emulator. A fault specification is a comma-separated list, e.g.
``corrupt=0.001,drop=0.0005,garbage=2,disconnect=30:5,clock_ppm=50``:

``corrupt=P``
    each byte sent is replaced by a different random byte with probability P;
``drop=P``
    each byte sent is left out with probability P;
``garbage=N``
    N bursts of 16 to 256 random bytes, at random instants of the run;
``disconnect=T:S``
    at T seconds of device time the board is unplugged for S seconds of
    device time (may be repeated);
``clock_ppm=E``
    the board's sample clock runs E parts per million fast.

The :class:`FaultLog` records, frame by frame, what was sent intact, what was
damaged and what never left the board, so tests can check the recorder's
accounting exactly. Damage reaches beyond the frame it hits: in line mode a
lost newline merges a line with the next, and a garbage burst glues itself to
the start of the next line; in binary mode a frame that loses its closing
delimiter while the next loses its opening one merges with it. So the log is
made exact by construction: :class:`ReadBack` parses the very bytes the board
puts on the wire with the recorder's own :class:`~acquisition.protocol.Parser`
and marks each frame by what came out of it.
"""

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from acquisition.protocol import SEQ_MODULUS, Parser, SampleBlock
from imu_square.errors import ConfigError

GARBAGE_BYTES = (16, 256)

# What became of a frame's samples (FaultLog.fate codes).
SENT = 0  # arrives intact: a parser reading the wire returns it unchanged
DAMAGED = 1  # written with corrupted or dropped bytes, and rejected
NO_HOST = 2  # produced while no host had the port open (unplugged, not yet opened)
OVERFLOW = 3  # the board's transmit buffer was full (the host did not read fast enough)
SWALLOWED = 4  # written intact, but lost with a neighbour's damage (merged, garbage glued on)
FATES = ("sent", "damaged", "no_host", "overflow", "swallowed")


@dataclass(frozen=True)
class FaultPlan:
    """Which faults to inject, and how often.

    Attributes
    ----------
    corrupt_per_byte : float
        Probability that a byte is replaced by a different one.
    drop_per_byte : float
        Probability that a byte is left out.
    garbage_bursts : int
        Bursts of random bytes inserted between frames over the run.
    disconnects : tuple of (float, float)
        ``(at_s, for_s)``: unplug at ``at_s`` seconds of device time for
        ``for_s`` seconds of device time. [s]
    clock_ppm : float
        Sample clock error: the board's clock runs this much fast. [ppm]
    """

    corrupt_per_byte: float = 0.0
    drop_per_byte: float = 0.0
    garbage_bursts: int = 0
    disconnects: tuple = ()
    clock_ppm: float = 0.0

    @property
    def damages_bytes(self):
        """True if any byte of a frame may be changed or left out."""
        return self.corrupt_per_byte > 0 or self.drop_per_byte > 0


def _probability(key, text):
    try:
        value = float(text)
    except ValueError:
        value = None
    if value is None or not 0.0 <= value < 1.0:
        raise ConfigError(f"--faults {key} must be a probability in [0, 1), got {text!r}")
    return value


def parse_faults(spec):
    """Parse a fault specification such as ``"corrupt=0.001,disconnect=30:5"``.

    Parameters
    ----------
    spec : str or None
        Comma-separated ``key=value`` items (see the module docstring); empty
        or None for no faults.

    Returns
    -------
    FaultPlan

    Raises
    ------
    ConfigError
        Naming the item, what is allowed and what was received.
    """
    values = {"disconnects": []}
    for item in (spec or "").split(","):
        item = item.strip()
        if not item:
            continue
        key, sep, text = item.partition("=")
        key, text = key.strip(), text.strip()
        if not sep:
            raise ConfigError(f"--faults item must be key=value, got {item!r}")
        if key == "corrupt":
            values["corrupt_per_byte"] = _probability(key, text)
        elif key == "drop":
            values["drop_per_byte"] = _probability(key, text)
        elif key == "garbage":
            if not text.isdigit():
                raise ConfigError(
                    f"--faults garbage must be a whole number of bursts, got {text!r}"
                )
            values["garbage_bursts"] = int(text)
        elif key == "disconnect":
            at, colon, length = text.partition(":")
            try:
                at_s, for_s = float(at), float(length)
            except ValueError:
                colon = ""
            if not colon or not (at_s >= 0 and for_s > 0):
                raise ConfigError(
                    f"--faults disconnect must be AT:FOR in seconds (AT >= 0, FOR > 0), "
                    f"got {text!r}"
                )
            values["disconnects"].append((at_s, for_s))
        elif key == "clock_ppm":
            try:
                values["clock_ppm"] = float(text)
            except ValueError:
                raise ConfigError(f"--faults clock_ppm must be a number, got {text!r}") from None
            if abs(values["clock_ppm"]) >= 1e4:
                raise ConfigError(f"--faults clock_ppm must be within +-1e4, got {text!r}")
        else:
            raise ConfigError(
                f"--faults has unknown item {key!r}; allowed: corrupt, drop, garbage, "
                f"disconnect, clock_ppm"
            )
    values["disconnects"] = tuple(sorted(values["disconnects"]))
    return FaultPlan(**values)


@dataclass
class FaultLog:
    """Exact account of what the emulated board sent, damaged and lost.

    Frames are listed in the order the board produced them; a marker or a
    header is not a frame here (they are never damaged).

    Attributes
    ----------
    seq0 : list of int
        First sequence number (unwrapped) of each frame.
    n : list of int
        Samples in each frame.
    fate : list of int
        :data:`SENT`, :data:`DAMAGED`, :data:`NO_HOST`, :data:`OVERFLOW` or
        :data:`SWALLOWED` for each frame.
    bytes_corrupted, bytes_dropped : int
        Bytes changed and left out over the run.
    garbage_bursts : list of (int, int)
        ``(before_seq, n_bytes)`` of each burst of random bytes.
    disconnects : list of (int, int)
        ``(first_seq_lost, n_lost)`` of each unplugging, as seen by the board.
    undetected : list of (int, int)
        ``(raw seq0, n)`` of each block a parser reading the wire accepted
        although it differs from every frame sent: damage the CRC missed
        (2**-32 per damaged frame, 2**-16 per damaged line). Empty in any
        run a test relies on.
    """

    seq0: list = field(default_factory=list)
    n: list = field(default_factory=list)
    fate: list = field(default_factory=list)
    bytes_corrupted: int = 0
    bytes_dropped: int = 0
    garbage_bursts: list = field(default_factory=list)
    disconnects: list = field(default_factory=list)
    undetected: list = field(default_factory=list)

    def add_frame(self, seq0, n, fate):
        """Record one frame of ``n`` samples from ``seq0`` and what became of it."""
        self.seq0.append(int(seq0))
        self.n.append(int(n))
        self.fate.append(int(fate))

    def seqs(self, fate):
        """Sequence numbers of every sample whose frame had ``fate``.

        Parameters
        ----------
        fate : int
            One of :data:`SENT`, :data:`DAMAGED`, :data:`NO_HOST`, :data:`OVERFLOW`,
            :data:`SWALLOWED`.

        Returns
        -------
        ndarray of int64
        """
        seq0 = np.asarray(self.seq0, np.int64)
        n = np.asarray(self.n, np.int64)
        keep = np.asarray(self.fate, np.int64) == fate
        if not keep.any():
            return np.zeros(0, np.int64)
        runs = zip(seq0[keep], n[keep], strict=True)
        return np.concatenate([np.arange(s, s + k) for s, k in runs])

    def summary(self):
        """Counts per fate and byte faults, for JSON and for people."""
        n = np.asarray(self.n, np.int64)
        fate = np.asarray(self.fate, np.int64)
        out = {f"samples_{name}": int(n[fate == code].sum()) for code, name in enumerate(FATES)}
        out.update({f"frames_{name}": int(np.sum(fate == code)) for code, name in enumerate(FATES)})
        out.update(
            bytes_corrupted=self.bytes_corrupted,
            bytes_dropped=self.bytes_dropped,
            garbage_bursts=len(self.garbage_bursts),
            garbage_bytes=int(sum(b for _, b in self.garbage_bursts)),
            disconnects=[list(d) for d in self.disconnects],
            undetected=[list(u) for u in self.undetected],
        )
        return out

    def as_dict(self):
        """Everything, for the truth JSON."""
        return {
            "summary": self.summary(),
            "frames": {"seq0": self.seq0, "n": self.n, "fate": self.fate, "fates": list(FATES)},
            "garbage_bursts": [list(g) for g in self.garbage_bursts],
        }


class FaultInjector:
    """Applies a :class:`FaultPlan` to the board's frames, logging every change.

    Parameters
    ----------
    plan : FaultPlan
        What to inject.
    n_samples : int
        Samples in the whole run, to place the garbage bursts.
    rng : numpy.random.Generator
        Source of randomness (seeded by the emulator).
    """

    def __init__(self, plan, n_samples, rng):
        self.plan = plan
        self.rng = rng
        self.log = FaultLog()
        self._garbage_at = sorted(rng.integers(0, max(n_samples, 1), plan.garbage_bursts).tolist())

    def garbage_before(self, seq_index, seq):
        """Random bytes to send before the frame starting at sample ``seq_index``.

        Parameters
        ----------
        seq_index : int
            Index of the frame's first sample from the start of the run.
        seq : int
            Its sequence number, for the log.

        Returns
        -------
        bytes
            Empty when no burst is due.
        """
        out = b""
        while self._garbage_at and self._garbage_at[0] <= seq_index:
            self._garbage_at.pop(0)
            size = int(self.rng.integers(GARBAGE_BYTES[0], GARBAGE_BYTES[1] + 1))
            out += self.rng.integers(0, 256, size, dtype=np.uint8).tobytes()
            self.log.garbage_bursts.append((int(seq), size))
        return out

    def damage(self, frame, delimited=False):
        """Corrupt and drop bytes of one encoded frame.

        Parameters
        ----------
        frame : bytes
            The frame as it would go on the wire.
        delimited : bool
            The first and last bytes are 0x00 delimiters (binary mode). Losing
            one of them does not damage the frame (the neighbours' delimiters
            still close it); changing one into another byte does.

        Returns
        -------
        bytes
            The frame as it goes on the wire.
        bool
            True if the frame cannot arrive intact.
        """
        if not self.plan.damages_bytes or not frame:
            return frame, False
        data = np.frombuffer(frame, np.uint8).copy()
        corrupt = self.rng.random(data.size) < self.plan.corrupt_per_byte
        drop = self.rng.random(data.size) < self.plan.drop_per_byte
        n_corrupt = int(corrupt.sum())
        if n_corrupt:
            # XOR with 1..255 always gives a different byte.
            data[corrupt] ^= self.rng.integers(1, 256, n_corrupt, dtype=np.uint8)
        n_drop = int(drop.sum())
        if n_drop:
            data = data[~drop]
        self.log.bytes_corrupted += n_corrupt
        self.log.bytes_dropped += n_drop
        if delimited:
            drop[[0, -1]] = False
        return data.tobytes(), bool(n_corrupt or drop.any())


class ReadBack:
    """Marks every frame by what a parser reading the board's wire gets from it.

    The board feeds it each byte string it queues for the host, in order, and
    calls :meth:`restart` whenever a host connection starts (the recorder then
    starts a fresh parser too). A frame is settled once the parser has read
    past its last byte: :data:`SENT` if the parser returned its samples
    unchanged; otherwise :data:`DAMAGED` if its own bytes were damaged, or
    :data:`SWALLOWED` if they were intact. A frame already marked
    :data:`NO_HOST` or :data:`OVERFLOW` (its bytes never reached a host)
    keeps that mark.

    Parameters
    ----------
    log : FaultLog
        The log whose ``fate`` entries are settled.
    mode : {"binary", "line"}
        Wire mode.
    """

    def __init__(self, log, mode):
        self.log = log
        self.mode = mode
        self._parser = Parser(mode)
        self._fed = 0
        self._open = deque()  # (end offset in the stream, log entry, raw seq0), in order
        self._expected = {}  # raw seq0 -> (log entry, counts sent)

    def restart(self):
        """A new host connection: what the old parser still held can never arrive."""
        self._settle(everything=True)
        self._parser = Parser(self.mode)
        self._fed = 0

    def feed(self, data, entry=None, seq0=None, counts=None):
        """Parse the next bytes on the wire.

        Parameters
        ----------
        data : bytes
            Bytes as queued for the host (damaged already).
        entry : int, optional
            Log entry of the frame these bytes carry; None for a header, a
            marker or garbage.
        seq0 : int, optional
            Unwrapped sequence number of the frame's first sample.
        counts : ndarray of int32, shape (n, 3), optional
            The samples the frame was made from. [counts]
        """
        if entry is not None:
            raw = int(seq0) % SEQ_MODULUS
            self._expected[raw] = (entry, counts)
            self._open.append((self._fed + len(data), entry, raw))
        self._fed += len(data)
        for message in self._parser.feed(data):
            if isinstance(message, SampleBlock):
                self._received(message)
        self._settle()

    def finish(self):
        """The board stopped: settle what is left unterminated."""
        self._settle(everything=True)

    def _received(self, block):
        hit = self._expected.pop(block.seq0, None)
        if hit is None or not np.array_equal(block.counts, hit[1]):
            self.log.undetected.append((int(block.seq0), int(block.n_samples)))
            if hit is not None:
                self._expected[block.seq0] = hit  # not the frame sent: still unreceived
            return
        if self.log.fate[hit[0]] in (SENT, DAMAGED):
            self.log.fate[hit[0]] = SENT

    def _settle(self, everything=False):
        consumed = self._fed - self._parser.buffered_bytes
        while self._open and (everything or self._open[0][0] <= consumed):
            _, entry, raw = self._open.popleft()
            hit = self._expected.get(raw)
            if hit is None or hit[0] != entry:
                continue  # received
            del self._expected[raw]
            if self.log.fate[entry] == SENT:
                self.log.fate[entry] = SWALLOWED
