"""Where the transient windows start: after the feed ramps, as the recording ran them.

A mode rung by the feed ramps rings after each block's start ramp and after
its end of motion, outside the analysed cycles. The ramps themselves are left
out of the comparison: a controller's ramp has its own shape and length,
which the model does not fit, and inside it recording and model differ by up
to a hundred times the noise (the independent generator's 0.2 s raised-cosine
ramp against our 0.15 s trapezoid). Starting the windows a fixed margin after
the model's ramps would have to allow for the longest ramp a controller might
run, and lose most of a ringing that decays in a tenth of a second.

So each window starts where the recording's ramp has ended: the residual of
the starting model (recording minus model, unclipped) is searched from one
ramp before to one ramp after the model's end of the start ramp (or of the
motion), and on for another ramp past each sample found, as long as samples
are found (a controller's ramp of 0.5 s or 1 s runs far past the model's 0.15
s one). A run of samples of one sign beyond :data:`RAMP_SIGMA` white-noise
sigmas, lasting :data:`RUN_S` or longer, marks the ramp as still running, and
the window starts :data:`GUARD_S` after the last such run, or
:data:`GUARD_FRACTION` of how far it ran past the model's edge, or
:data:`TAIL_DECAYS` decay times of the run's tail, if longer (or after the
model's own ramp, if later). A servo's first-order lag ends each ramp in an
exponential tail with the lag's decay time; 15 ms after a 15-40 ms tail
crossed the mark it still stood at several sigmas, and left a false gap. A
raised-cosine ramp of 0.2 s falls from 10 sigmas to nothing in 8 ms (the time
grows as the ramp's length to the power 1.5; a trapezoid or an s-curve stops
within a millisecond). Under the null no sample crosses the mark. A ringing
above 50 Hz crosses it in runs of half its period, and so does not move its
own window past itself (at 80 Hz and a few hundred sigmas it did, by 20 ms). A
slower ringing that crosses the mark still moves its window later, which costs
signal but never a false alarm: the mark is high so that a ringing of a few
times the noise does not.
"""

import math

import numpy as np

# A residual sample this many white-noise sigmas off marks a feed ramp as still running,
RAMP_SIGMA = 10.0
# ... in a run of samples of one sign past the mark lasting this long: a ramp's residual
# is smooth over tens of milliseconds, a ringing above 50 Hz flips sooner. [s]
RUN_S = 0.010
# From the last such run to the window's start, at least; longer than RUN_S, so that a
# shorter run right after it (the ramp's last, cut by a ringing) stays out too. [s]
GUARD_S = 0.015
# ... and this fraction of how far the recording's ramp ran past the model's: a smooth
# ramp's tail, from the mark down to the noise, lasts longer the longer the ramp.
GUARD_FRACTION = 0.25
# ... and this many decay times of the last run's tail, timed from TAIL_RATIO times the
# mark down to it: a servo's first-order lag ends its ramp in an exponential tail, whose
# decay time is the lag's, and ln(RAMP_SIGMA / 0.5) of them take it to half a sigma.
TAIL_RATIO = 3.0
TAIL_DECAYS = math.log(RAMP_SIGMA / 0.5)


def _recording_time(model, state, block, tau):
    """Recording time of simulator time ``tau`` in layout block ``block`` (inverse of the map)."""
    b = model.layout.blocks[block]
    tl = model.timeline(state.machine).blocks[b.index]
    mid = tl.time_at_progress(0.5 * tl.angle_rad)
    scale = 1.0 + state.sensor.clock_ppm * 1e-6
    return b.t_mid_s + (tau - mid - state.anchors_s[block]) * scale


def _last_crossing(model, state, block, t_all, xy_all, sigma, lo, hi):
    """The last run in ``[lo, hi)`` that marks a ramp as running: its end and its decay.

    Returns
    -------
    end : float
        Time of the run's last sample, or -inf without such a run. [s]
    decay : float
        Its tail's decay time: from its last sample :data:`TAIL_RATIO` times
        past the mark (or from its largest, if none is) down to the mark, as
        an exponential's; 0 without one. [s]
    """
    i0, i1 = np.searchsorted(t_all, (lo, hi))
    if i1 <= i0:
        return -math.inf, 0.0
    t = t_all[i0:i1]
    r = xy_all[i0:i1] - model.samples_at(state, t, block)
    last = (-math.inf, 0.0)
    for k in range(2):
        z = np.abs(r[:, k]) / (RAMP_SIGMA * sigma[k])
        side = np.sign(r[:, k]) * (z > 1.0)
        # runs of one sign past the mark; a ramp's last longer than a ringing's half period
        edges = np.flatnonzero(np.diff(side)) + 1
        for a, b in zip(np.r_[0, edges], np.r_[edges, side.size], strict=True):
            if side[a] and t[b - 1] - t[a] >= RUN_S and t[b - 1] > last[0]:
                high = np.flatnonzero(z[a:b] >= TAIL_RATIO)
                j = a + (high[-1] if high.size else int(np.argmax(z[a:b])))
                decay = (t[b - 1] - t[j]) / math.log(max(z[j], 1.0)) if z[j] > 1.5 else 0.0
                last = (float(t[b - 1]), float(decay))
    return last


def _ramp_end(model, state, block, t_all, xy_all, sigma, edge, ramp, lo, hi):
    """The last run past the mark around ``edge``, followed a ramp at a time.

    Returns its end (-inf without one) and its decay (:func:`_last_crossing`). [s]
    """
    last = (-math.inf, 0.0)
    start, stop = max(edge - ramp, lo), min(edge + ramp, hi)
    while start < stop:
        seen = _last_crossing(model, state, block, t_all, xy_all, sigma, start, stop)
        if seen[0] == -math.inf:
            break
        last = seen
        start, stop = stop, min(seen[0] + ramp, hi)
    return last


def transient_windows(model, state, t_all, xy_all, sigma):
    """The transient windows of every block, placed after the recording's ramps.

    Parameters
    ----------
    model : ForwardModel
        The forward model on the analysed samples.
    state : ModelState
        The starting model (anchors aligned).
    t_all : ndarray, shape (n,)
        Times of every recorded sample. [s]
    xy_all : ndarray, shape (n, 2)
        x and y of every recorded sample. [m/s^2]
    sigma : ndarray, shape (2,)
        White-noise standard deviation of x and y per sample. [m/s^2]

    Returns
    -------
    list of tuple
        ``(block position, start, limit, after_end)`` for
        :func:`~imu_square.discrepancy.layout.with_transients`.
    """
    layout = model.layout
    n = layout.n_analysed
    blocks = layout.sample_block[:n]
    motions = []
    for b in range(len(layout.blocks)):
        tl = model.timeline(state.machine).blocks[layout.blocks[b].index]
        start, end = (_recording_time(model, state, b, t) for t in (tl.t_start_s, tl.t_end_s))
        analysed = layout.t_s[:n][blocks == b]
        motions.append((start, end, tl.ramp_s, analysed[0], analysed[-1]))
    out = []
    for b, (start, end, ramp, first, last) in enumerate(motions):
        later = motions[b + 1][0] - motions[b + 1][2] if b + 1 < len(motions) else math.inf
        for edge, lo, hi, after_end in (
            (start + ramp, start, first, False),
            (end, last, later, True),
        ):
            seen, decay = _ramp_end(model, state, b, t_all, xy_all, sigma, edge, ramp, lo, hi)
            guard = max(GUARD_S, GUARD_FRACTION * (seen - edge), TAIL_DECAYS * decay)
            out.append((b, max(edge, seen) + guard, hi, after_end))
    return out
