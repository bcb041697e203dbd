"""The health of the link to a board: outages, reconnects, silence and sample rate.

The recorder tells a :class:`LinkHealth` what the
:class:`~acquisition.reader.SerialSupervisor` reports and when samples
arrive. It says how long the port was down at each reconnect, how fast
samples arrive, and when a silent board is to be given up, with the board's
sample counter estimated from the host clock up to that moment.
"""

import math

from imu_square.log import logger

SILENCE_S = 2.0  # host time without samples after which board time is extrapolated [s]
RATE_SPAN_S = 0.5  # host time of samples needed to measure the board's rate [s]


class LinkHealth:
    """How the link to one board is doing, seen from the host.

    Parameters
    ----------
    port : str
        The port, named in the warning when the board is given up.
    silence_timeout_s : float
        Host time without a sample after which the board is given up. [s]

    Attributes
    ----------
    header_seen : bool
        A header from the recorded board arrived on this connection.
    """

    def __init__(self, port, silence_timeout_s):
        self.port = port
        self.silence_timeout_s = silence_timeout_s
        self.header_seen = False
        self._connects = 0
        self._down_since = None  # host time the port was lost, None while it is up [ns]
        self._reconnect = None  # detail of a reconnect not yet reported
        self._data = None  # host times of the first and of the last data received [ns]
        self._samples = 0
        self._alive = None  # [(host s, seq) of the first, of the last samples received]
        self._silent_since = None  # host time of the last sample (or the first header) [s]
        self._nominal_rate_hz = None

    def connected(self, host_ns):
        """The port opened at ``host_ns`` [ns]: after the first time, a reconnect to report."""
        self.header_seen = False
        if self._connects:
            down_ns = host_ns - (self._down_since if self._down_since is not None else host_ns)
            self._reconnect = f"down_s={down_ns * 1e-9:.3f}"
            self._down_since = None
        self._connects += 1

    def disconnected(self, host_ns):
        """The port was lost at ``host_ns`` [ns]; the first loss counts until it reopens."""
        if self._down_since is None:
            self._down_since = host_ns

    def take_reconnect(self):
        """The ``down_s=...`` detail of a reconnect not yet reported, once; else None."""
        detail, self._reconnect = self._reconnect, None
        return detail

    def first_header(self, host_s, sample_rate_hz):
        """The board's first header arrived at ``host_s`` [s]: silence counts from there.

        ``sample_rate_hz`` [Hz], the header's, is the board's rate until it is measured.
        """
        self._silent_since = host_s
        self._nominal_rate_hz = sample_rate_hz

    def data(self, host_ns):
        """Bytes arrived at ``host_ns``. [ns]"""
        self._data = (host_ns if self._data is None else self._data[0], host_ns)

    def count_samples(self, n):
        """Count ``n`` samples taken from the board.

        Returns
        -------
        float
            Samples per second of host time over the run; NaN until the data
            spans some time. [Hz]
        """
        self._samples += n
        first, last = self._data
        return self._samples / ((last - first) * 1e-9) if last > first else math.nan

    def samples_arrived(self, host_s, seq):
        """Samples up to ``seq`` arrived at ``host_s`` [s]: the board is alive, its rate measurable.

        ``seq`` is None while no sample was accepted: nothing is noted.
        """
        if seq is None:
            return
        if self._alive is None:
            self._alive = [(host_s, seq), (host_s, seq)]
        self._alive[1] = (host_s, seq)
        self._silent_since = host_s

    def _board_rate(self):
        """Board samples per host second: measured once samples span a while, else nominal.

        Measured from the end of the first read, which may hold a backlog; the
        nominal rate is the header's, right for any real board (an emulated one
        may run faster than real time).
        """
        if self._alive is not None:
            (t0, s0), (t1, s1) = self._alive
            if t1 - t0 >= RATE_SPAN_S:
                return (s1 - s0) / (t1 - t0)
        return self._nominal_rate_hz

    def board_at(self, now, last_seq):
        """Next sample the board would send at host time ``now`` [s]; None before any.

        ``last_seq`` is the newest sample received, or None.
        """
        if last_seq is None:
            return None
        return last_seq + 1 + round((now - self._silent_since) * self._board_rate())

    def gone(self, now, last_seq, stop_seq):
        """Whether the board is gone at host time ``now`` [s]: silent past the stop, or too long.

        While silent for more than ``SILENCE_S`` the board's sample counter is
        estimated from the host clock; once it passes the planned stop
        ``stop_seq`` (None: open-ended), nothing more can come in time. After
        ``silence_timeout_s`` the board is given up at once.

        Returns
        -------
        tuple of (int or None, str) or None
            The board's next sample by now (None before any sample) and the
            cause, ``"port lost"`` or ``"board silent"``; None while the board
            is not given up.
        """
        if self._silent_since is None:
            return None
        silent_s = now - self._silent_since
        if silent_s <= min(SILENCE_S, self.silence_timeout_s):
            return None
        board_at = self.board_at(now, last_seq)
        at_stop = None not in (board_at, stop_seq) and board_at >= stop_seq
        if silent_s <= self.silence_timeout_s and not at_stop:
            return None
        cause = "port lost" if self._down_since is not None else "board silent"
        logger.warning(
            "no sample from the board on %s for %.1f s (%s): the recording stops, and the "
            "missing time is recorded as a gap; the run is incomplete",
            self.port,
            silent_s,
            "the port stayed lost" if cause == "port lost" else "the port is open but silent",
        )
        return board_at, cause
