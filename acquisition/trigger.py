"""When a recording starts: at once, on a marker from the board, or on motion.

A trigger watches the samples (and markers) as they arrive and names the
sequence number at which the test starts; the recorder keeps a pre-trigger
buffer so the file begins a few seconds earlier and nothing of the motion's
start is lost.
"""

import math

import numpy as np

from imu_square.validation import check_option

TRIGGERS = ("immediate", "motion", "marker")


class ImmediateTrigger:
    """Starts at the first sample received."""

    def update(self, seq, accel):
        """Return the first sequence number of the first block seen.

        Parameters
        ----------
        seq : ndarray of int64, shape (n,)
            Unwrapped sequence numbers of a run of samples.
        accel : ndarray, shape (n, 3)
            Their accelerations. [m/s^2]

        Returns
        -------
        int or None
            The trigger's sequence number, or None when not (yet) triggered.
        """
        return int(seq[0]) if len(seq) else None

    def on_marker(self, seq, text):
        """Markers do not matter to this trigger; returns None."""
        return None


class MarkerTrigger:
    """Starts at the first marker the board sends (e.g. a CNC ``block_start`` line)."""

    def update(self, seq, accel):
        """Samples do not matter to this trigger; returns None."""
        return None

    def on_marker(self, seq, text):
        """Return the marker's sequence number.

        Parameters
        ----------
        seq : int
            Unwrapped sequence number the marker refers to.
        text : str
            Marker text.

        Returns
        -------
        int
        """
        return int(seq)


class MotionTrigger:
    """Starts when the horizontal acceleration leaves its rest level.

    The first ``baseline_s`` seconds give the rest level and the scatter of
    ``window_s`` window means of x and y. The trigger fires when, for
    ``hold_s`` seconds of consecutive windows, a window mean of x or y
    deviates from the rest level by more than ``k_sigma`` times that scatter;
    the trigger's sequence number is the first sample of the first such
    window. The table must be at rest during the baseline.

    Parameters
    ----------
    dt_s : float
        Sample spacing. [s]
    k_sigma : float
        Threshold in units of the window-mean scatter at rest.
    baseline_s : float
        Length of the rest period that sets the level. [s]
    window_s : float
        Averaging window. [s]
    hold_s : float
        How long the deviation must last. [s]
    floor_m_s2 : float
        Smallest scatter assumed (one ADC step: a quantised, noiseless
        baseline has zero scatter). [m/s^2]
    """

    def __init__(
        self, dt_s, *, k_sigma=6.0, baseline_s=1.0, window_s=0.02, hold_s=0.1, floor_m_s2=0.0
    ):
        self.window = max(1, round(window_s / dt_s))
        self.n_baseline = max(2, math.ceil(baseline_s / (self.window * dt_s)))
        self.n_hold = max(1, math.ceil(hold_s / (self.window * dt_s)))
        self.k_sigma = k_sigma
        self.floor = floor_m_s2 / math.sqrt(self.window)
        self._seq = np.zeros(0, np.int64)
        self._xy = np.zeros((0, 2))
        self._baseline = []
        self._level = None
        self._scale = None
        self._run_start = None
        self._run_length = 0
        self.level_m_s2 = None

    def update(self, seq, accel):
        """Feed a run of consecutive samples; return the trigger's sequence number once fired.

        Parameters
        ----------
        seq : ndarray of int64, shape (n,)
            Unwrapped sequence numbers.
        accel : ndarray, shape (n, 3)
            Accelerations. [m/s^2]

        Returns
        -------
        int or None
        """
        self._seq = np.concatenate([self._seq, seq])
        self._xy = np.concatenate([self._xy, np.asarray(accel, np.float64)[:, :2]])
        n_win = self._seq.size // self.window
        if n_win == 0:
            return None
        used = n_win * self.window
        means = self._xy[:used].reshape(n_win, self.window, 2).mean(axis=1)
        starts = self._seq[: used : self.window]
        self._seq, self._xy = self._seq[used:], self._xy[used:]
        for start, mean in zip(starts, means, strict=True):
            fired = self._window(int(start), mean)
            if fired is not None:
                return fired
        return None

    def _window(self, start, mean):
        if self._level is None:
            self._baseline.append(mean)
            if len(self._baseline) >= self.n_baseline:
                base = np.asarray(self._baseline)
                self._level = base.mean(axis=0)
                self._scale = np.maximum(base.std(axis=0, ddof=1), self.floor)
                self.level_m_s2 = tuple(float(v) for v in self._level)
            return None
        if np.any(np.abs(mean - self._level) > self.k_sigma * self._scale):
            if self._run_length == 0:
                self._run_start = start
            self._run_length += 1
            if self._run_length >= self.n_hold:
                return self._run_start
        else:
            self._run_length = 0
        return None

    def on_marker(self, seq, text):
        """Markers do not matter to this trigger; returns None."""
        return None


def make_trigger(kind, dt_s, floor_m_s2=0.0):
    """The trigger called ``kind``.

    Parameters
    ----------
    kind : str
        ``"immediate"``, ``"motion"`` or ``"marker"``.
    dt_s : float
        Sample spacing. [s]
    floor_m_s2 : float
        One ADC step, the smallest scatter the motion trigger assumes. [m/s^2]

    Returns
    -------
    ImmediateTrigger or MotionTrigger or MarkerTrigger
    """
    check_option("trigger", kind, TRIGGERS)
    if kind == "motion":
        return MotionTrigger(dt_s, floor_m_s2=floor_m_s2)
    return ImmediateTrigger() if kind == "immediate" else MarkerTrigger()
