"""From the board's raw sample blocks to SI samples on one unwrapped sequence axis.

The board's 32-bit sequence counter is the time base: it is unwrapped to
int64, a jump forward is a gap (samples lost, never filled in), and a block
that does not move forward (a duplicate or a stale frame) is dropped and
counted. Counts become m/s^2 with the header's scale.
"""

import numpy as np

from acquisition.protocol import unwrap_seq


class SampleStream:
    """Unwraps sequence numbers, finds gaps and converts counts of one board.

    Parameters
    ----------
    scale_m_s2_per_count : float
        Acceleration of one count, from the board's header. [m/s^2]

    Attributes
    ----------
    last_seq : int or None
        Unwrapped sequence number of the newest sample accepted.
    lost : int
        Samples missing between accepted blocks so far.
    stale : int
        Blocks dropped because they did not move the sequence forward.
    """

    def __init__(self, scale_m_s2_per_count):
        self.scale = float(scale_m_s2_per_count)
        self.last_seq = None
        self.lost = 0
        self.stale = 0

    def unwrap(self, raw_seq):
        """Unwrapped sequence number of a raw counter value near the newest sample.

        Parameters
        ----------
        raw_seq : int
            Raw 32-bit counter value.

        Returns
        -------
        int
        """
        if self.last_seq is None:
            return int(raw_seq)
        return unwrap_seq(int(raw_seq), self.last_seq + 1)

    def push(self, raw_seq0, counts, temperature_c):
        """Accept a run of consecutive samples (one or more blocks joined).

        Parameters
        ----------
        raw_seq0 : int
            Raw 32-bit sequence number of the first sample.
        counts : ndarray of int32, shape (n, 3)
            Raw counts. [counts]
        temperature_c : ndarray, shape (n,)
            Temperature of each sample, NaN if absent. [degC]

        Returns
        -------
        seq : ndarray of int64, shape (n,) or None
            Unwrapped sequence numbers; None when the run was stale.
        accel : ndarray of float32, shape (n, 3)
            Acceleration. [m/s^2]
        temperature_c : ndarray of float32, shape (n,)
            Temperature of each sample (NaN if absent). [degC]
        lost : int
            Samples missing just before this run.
        """
        seq0 = self.unwrap(raw_seq0)
        n = len(counts)
        lost = 0
        if self.last_seq is not None:
            if seq0 + n - 1 <= self.last_seq:
                self.stale += 1  # counted per run: one stale frame, or a repeated stretch
                return None, None, None, 0
            if seq0 <= self.last_seq:
                # A repeated frame joined to new ones: keep the new samples only.
                self.stale += 1
                skip = self.last_seq + 1 - seq0
                seq0, counts = seq0 + skip, counts[skip:]
                temperature_c = np.asarray(temperature_c)[skip:]
                n -= skip
            lost = seq0 - self.last_seq - 1
        self.last_seq = seq0 + n - 1
        self.lost += lost
        seq = np.arange(seq0, seq0 + n, dtype=np.int64)
        accel = (counts * self.scale).astype(np.float32)
        return seq, accel, np.asarray(temperature_c, np.float32), lost
