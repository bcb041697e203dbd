"""Cut the analysed cycles, flip CW into increasing phi, resample, average.

Each block's analysed cycles are the ``cycles_per_direction`` whole cycles
after the start overshoot (program). Every sample is mapped to its commanded
position angle (:meth:`Segmentation.phi`); CW cycles, which run towards
decreasing phi, are time-reversed ("flipped", paper Section 4 [1]_) so that
both directions are functions of increasing phi. Each cycle is resampled by
linear interpolation on one common grid of position angles in [0, 2 pi)
(fine after the low-pass: the grid is far denser than the filter's
bandwidth). Cycles touched by a gap that was not bridged, by clipping, or
reaching outside the detected motion or into the filter's settling time after
its start or before its stop are dropped with a reason, never interpolated
across. Grid points inside a bridged gap are kept as missing (``valid``
False, NaN): the fits use the samples that survive (``docs/model.md``, gaps).

References
----------
.. [1] K. Szipka, A. Archenti, G. W. Vogl, M. A. Donmez, CIRP Annals 68 (2019).
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Cycles:
    """Flipped, resampled cycles of one direction.

    Attributes
    ----------
    direction : str
        ``"ccw"`` or ``"cw"``.
    x, y : ndarray, shape (n_cycles, n_grid)
        Sensor x and y acceleration on :attr:`CycleTraces.phi_grid`; NaN where
        not ``valid``. [m/s^2]
    valid : ndarray of bool, shape (n_cycles, n_grid)
        False at grid points inside a bridged gap, which hold no data.
    block : ndarray of int, shape (n_cycles,)
        Block index of each cycle.
    pair : ndarray of int, shape (n_cycles,)
        Pairing key: ``k + cycles_per_direction * i`` for the k-th cycle in time
        of the i-th block of this direction; CCW and CW cycles with the same key
        form a pair.
    t_start_s : ndarray, shape (n_cycles,)
        Start time of each cycle, from the first sample. [s]
    """

    direction: str
    x: np.ndarray
    y: np.ndarray
    valid: np.ndarray
    block: np.ndarray
    pair: np.ndarray
    t_start_s: np.ndarray

    @property
    def n(self):
        """Number of cycles."""
        return self.x.shape[0]

    @property
    def complete(self):
        """Whether every grid point of every cycle holds data."""
        return bool(np.all(self.valid))


@dataclass(frozen=True)
class CycleTraces:
    """Both directions on a common phi grid.

    Attributes
    ----------
    phi_grid : ndarray, shape (n_grid,)
        Position angles in [0, 2 pi). [rad]
    ccw, cw : Cycles
        The usable cycles of each direction.
    dropped : tuple of dict
        ``{"direction", "block", "cycle", "reason"}`` for each dropped cycle.
    """

    phi_grid: np.ndarray
    ccw: Cycles
    cw: Cycles
    dropped: tuple


def interpolation_gain(frequency_hz, sample_rate_hz):
    """Mean amplitude gain of linear interpolation between samples at one frequency.

    Resampling a sinusoid at points spread uniformly between the samples
    averages to ``sinc^2(f / fs)`` of its amplitude (no phase): ``1 - (omega
    dt)^2 / 12``, 2e-5 at a 2.5 Hz circle sampled at 1 kHz.

    Parameters
    ----------
    frequency_hz : float
        Frequency, e.g. the circle's. [Hz]
    sample_rate_hz : float
        Sample rate. [Hz]

    Returns
    -------
    float
    """
    return float(np.sinc(frequency_hz / sample_rate_hz) ** 2)


def bad_intervals(gap_spans_s, clipped_t_s):
    """Stretches of untrustworthy data as ``(start, end)`` rows.

    Parameters
    ----------
    gap_spans_s : sequence of tuple (float, float)
        Last sample before and first after each gap. [s]
    clipped_t_s : ndarray
        Times of clipped samples, each a zero-length stretch. [s]

    Returns
    -------
    ndarray, shape (n_bad, 2)
        For :func:`cycle_traces`. [s]
    """
    rows = [*gap_spans_s, *((t, t) for t in np.asarray(clipped_t_s, dtype=float))]
    return np.array(rows, dtype=np.float64).reshape(-1, 2)


def _inside(t, spans):
    """Which of the times ``t`` lie strictly inside one of the sorted ``spans``."""
    if spans.size == 0:
        return np.zeros(t.shape, dtype=bool)
    k = np.searchsorted(spans[:, 0], t, side="right") - 1
    return (k >= 0) & (t < spans[np.maximum(k, 0), 1])


def cycle_traces(
    t_s,
    accel_xy,
    seg,
    bad_intervals_s=(),
    margin_s=0.0,
    grid_points=512,
    missing_s=(),
    onset_margin_s=None,
):
    """Flip, cut and resample every analysed cycle on a common phi grid.

    Parameters
    ----------
    t_s : ndarray, shape (n_samples,)
        Sample times from the first sample. [s]
    accel_xy : ndarray, shape (n_samples, 2)
        Low-passed sensor x and y acceleration. [m/s^2]
    seg : Segmentation
        The blocks and the time-to-angle map.
    bad_intervals_s : array_like, shape (n_bad, 2)
        Start and end of each stretch of bad data: a gap runs from the last
        sample before it to the first after it, a clipped sample is a zero-length
        stretch. A cycle that comes within ``margin_s`` of one is dropped; a gap
        can be longer than a cycle, so whole stretches are checked, not points. [s]
    margin_s : float
        Settling time of the filter. [s]
    grid_points : int
        Points of the common phi grid per cycle.
    missing_s : array_like, shape (n_missing, 2)
        ``(last sample before, first sample after)`` of each bridged gap: grid
        points strictly inside one are marked missing. [s]
    onset_margin_s : float, optional
        A cycle that starts less than this after the detected start of motion,
        or ends less than this before its stop, holds the filter's response to
        the start or stop, and is dropped; ``margin_s`` if None. [s]

    Returns
    -------
    CycleTraces
    """
    prog = seg.program
    n_cyc = prog.cycles_per_direction
    two_pi = 2 * np.pi
    grid = two_pi * (np.arange(grid_points) + 0.5) / grid_points
    bad = np.asarray(bad_intervals_s, dtype=np.float64).reshape(-1, 2)
    missing = np.asarray(sorted(missing_s), dtype=np.float64).reshape(-1, 2)
    onset = margin_s if onset_margin_s is None else onset_margin_s
    out = {"ccw": [], "cw": []}
    dropped = []
    seen = {"ccw": 0, "cw": 0}
    for block in seg.blocks:
        d = block.direction
        nth = seen[d]
        seen[d] += 1
        a0 = block.plan.analysed_start_rad
        a1 = a0 + block.sign * two_pi * n_cyc
        lo = min(a0, a1)
        ta, tb = sorted([float(seg.time_at(block, a0)), float(seg.time_at(block, a1))])
        i0 = max(int(np.searchsorted(t_s, ta)) - 2, 0)
        i1 = min(int(np.searchsorted(t_s, tb)) + 2, t_s.size)
        phi = seg.phi(block, t_s[i0:i1])
        ax, ay = accel_xy[i0:i1, 0], accel_xy[i0:i1, 1]
        if block.sign < 0:
            phi, ax, ay = phi[::-1], ax[::-1], ay[::-1]
        # np.interp copies strided or reversed arrays on every call: copy them once here.
        phi, ax, ay = (np.ascontiguousarray(v) for v in (phi, ax, ay))
        for j in range(n_cyc):  # j counts cycles in increasing phi
            k = j if block.sign > 0 else n_cyc - 1 - j  # k counts cycles in time
            c0, c1 = sorted(
                [
                    float(seg.time_at(block, lo + two_pi * j)),
                    float(seg.time_at(block, lo + two_pi * (j + 1))),
                ]
            )
            reason = None
            if c0 < block.t_start_s or c1 > block.t_stop_s or phi.size < 2:
                reason = "outside the detected motion"
            elif c0 < block.t_start_s + onset or c1 > block.t_stop_s - onset:
                reason = "within the filter's settling time of the start or stop of motion"
            elif c0 < t_s[0] or c1 > t_s[-1]:
                reason = "outside the recording"
            else:
                if np.any((bad[:, 0] <= c1 + margin_s) & (bad[:, 1] >= c0 - margin_s)):
                    reason = "gap or clipping"
            if reason:
                dropped.append(
                    {"direction": d, "block": block.plan.index, "cycle": k, "reason": reason}
                )
                continue
            pts = lo + two_pi * j + np.mod(grid - lo, two_pi)
            ok = ~_inside(seg.time_at(block, pts), missing)
            out[d].append(
                (
                    np.where(ok, np.interp(pts, phi, ax), np.nan),
                    np.where(ok, np.interp(pts, phi, ay), np.nan),
                    ok,
                    block.plan.index,
                    k + n_cyc * nth,
                    c0,
                )
            )

    def pack(d):
        rows = sorted(out[d], key=lambda r: r[5])
        if not rows:
            empty = np.empty((0, grid_points))
            none = np.empty((0, grid_points), dtype=bool)
            return Cycles(d, empty, empty, none, np.empty(0, int), np.empty(0, int), np.empty(0))
        x, y, ok, b, p, t0 = zip(*rows, strict=True)
        return Cycles(
            d, np.array(x), np.array(y), np.array(ok), np.array(b), np.array(p), np.array(t0)
        )

    return CycleTraces(phi_grid=grid, ccw=pack("ccw"), cw=pack("cw"), dropped=tuple(dropped))
