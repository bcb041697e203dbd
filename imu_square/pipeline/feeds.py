"""Split the recording of a multi-feed program into one recording per feed.

A program with ``feeds_mm_per_min = [f1, f2, ...]`` runs all its blocks at the
first feed, then all at the second, and so on, with the table at rest for
``dwell_s`` between blocks (:mod:`imu_square.program.spec`). Each feed's blocks
are therefore one stretch of the recording, which :func:`split_feeds` cuts out
as a recording of that feed's one-feed program (:meth:`TestProgram.at_feed`);
:func:`imu_square.pipeline.squareness.analyze` then analyses each stretch as it
analyses any one-feed run.

Where the stretches meet comes from the block markers when the recording has
them, else from the data: the low-passed horizontal acceleration is in motion
where its magnitude about the rest level exceeds half the smallest programmed
``v^2/r``, and each motion interval's circle frequency (the median turn of the
acceleration vector over an eighth of the shortest period) names its feed.
"""

import itertools
from dataclasses import dataclass

import numpy as np

from imu_square.errors import AnalysisError
from imu_square.pipeline.filter import filter_recording
from imu_square.pipeline.options import AnalysisOptions
from imu_square.units import MM, MM_PER_MIN

# Samples kept away from motion when estimating the rest level.
_REST_PAD = 50
# A motion interval whose circle frequency is further than this (relative)
# from every programmed one is not a block of the test (an approach move, a
# bump): it names no feed.
_RATE_TOLERANCE = 0.1


@dataclass(frozen=True)
class FeedRecording:
    """One feed's stretch of a recording.

    Attributes
    ----------
    feed : int
        Index of the feed in the full program's :attr:`TestProgram.feeds`.
    program : TestProgram
        The feed's one-feed program (blocks numbered from 0).
    recording : Recording
        The stretch, with :attr:`program` as its program and its block markers
        renumbered to the feed's blocks.
    """

    feed: int
    program: object
    recording: object

    @property
    def feed_mm_per_min(self):
        """The feed of this stretch. [mm/min]"""
        return self.program.feed_m_per_s / MM_PER_MIN


def _program_of(recording, program):
    prog = program or recording.program
    if prog is None:
        raise AnalysisError("the recording has no test program: give one (--program)")
    return prog


def _boundaries_from_events(recording, program):
    """Times between the feeds' stretches from the block markers, or None if any is missing."""
    t0 = int(recording.time_ns[0])
    starts = {e.block: e.time_ns for e in recording.events if e.kind == "block_start"}
    ends = {e.block: e.time_ns for e in recording.events if e.kind == "block_end"}
    plans = program.blocks()
    cuts = []
    for before, after in itertools.pairwise(plans):
        if before.feed == after.feed:
            continue
        if before.index not in ends or after.index not in starts:
            return None
        cuts.append(0.5 * (ends[before.index] + starts[after.index] - 2 * t0) * 1e-9)
    return cuts


def _runs(mask):
    """Start (inclusive) and stop (exclusive) indices of True runs."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def _motion(t_s, xy, threshold):
    """Magnitude of the horizontal acceleration about the rest level, and its motion runs."""
    base = np.median(xy, axis=0)
    for _ in range(2):
        env = np.hypot(*(xy - base).T)
        moving = env > threshold
        rest = np.ones(t_s.size, dtype=bool)
        for a, b in zip(*_runs(moving), strict=True):
            rest[max(a - _REST_PAD, 0) : b + _REST_PAD] = False
        if np.count_nonzero(rest) <= _REST_PAD:
            break
        base = np.median(xy[rest], axis=0)
    rel = xy - base
    return rel, _runs(np.hypot(*rel.T) > threshold)


def _rate(t_s, rel, lag):
    """Angular speed of the acceleration vector (median turn over ``lag`` samples). [rad/s]"""
    z = rel[:, 0] + 1j * rel[:, 1]
    if z.size <= lag + 2:
        return 0.0
    dt = float(np.median(np.diff(t_s)))
    return abs(float(np.median(np.angle(z[lag:] * np.conj(z[:-lag]))))) / (lag * dt)


def _boundaries_from_data(recording, program, options):
    """Times between the feeds' stretches, from where the table moves at which rate."""
    feeds = [program.at_feed(f) for f in range(program.n_feeds)]
    omegas = np.array([p.omega_rad_s for p in feeds])
    shortest = min(p.period_s for p in feeds)
    # the fastest circle's cutoff keeps every feed's circle
    fastest = max(p.frequency_hz for p in feeds)
    data = filter_recording(recording, options.cutoff_hz, options.order, fastest)
    t_s = data.t_s
    threshold = 0.5 * min(p.centripetal_m_s2 for p in feeds)
    rel, (starts, stops) = _motion(t_s, data.xy, threshold)
    lag = max(1, round(shortest / 8 * data.sample_rate_hz))
    found = []  # (t_start, t_stop, feed)
    rates = []
    for a, b in zip(starts, stops, strict=True):
        if t_s[b - 1] - t_s[a] < 0.5 * shortest:
            continue
        quarter = (b - a) // 4
        rate = _rate(t_s, rel[a + quarter : b - quarter], lag)
        rates.append(rate)
        miss = np.abs(np.log(rate / omegas)) if rate > 0 else np.full(omegas.size, np.inf)
        f = int(np.argmin(miss))
        if miss[f] <= np.log1p(_RATE_TOLERANCE):
            found.append((float(t_s[a]), float(t_s[b - 1]), f))
    labels = [f for _, _, f in found]
    programmed = ", ".join(f"{p.feed_m_per_s / MM_PER_MIN:g}" for p in feeds)
    seen = ", ".join(f"{r * program.radius_m / MM_PER_MIN:.0f}" for r in rates) or "none"
    missing = sorted(set(range(len(feeds))) - set(labels))
    if missing:
        raise AnalysisError(
            f"no motion at {feeds[missing[0]].feed_m_per_s / MM_PER_MIN:g} mm/min: the program "
            f"runs {programmed} mm/min on r = {program.radius_m / MM:g} mm; the motion found "
            f"runs at {seen} mm/min"
        )
    if labels != sorted(labels):
        raise AnalysisError(
            f"the feeds do not run one after the other in the program's order "
            f"({programmed} mm/min): found motion at {seen} mm/min in that order"
        )
    cuts = []
    for f in range(1, len(feeds)):
        end = max(t1 for _, t1, g in found if g == f - 1)
        start = min(t0 for t0, _, g in found if g == f)
        cuts.append(0.5 * (end + start))
    return cuts


def _stretch(recording, program, feed, t_from, t_to):
    """The samples and markers of one feed between two times from the first sample. [s]"""
    t_s = recording.time_s
    i0, i1 = np.searchsorted(t_s, (t_from, t_to), side="left")
    plans = [b for b in program.blocks() if b.feed == feed]
    first, last = plans[0].index, plans[-1].index
    lo, hi = int(recording.time_ns[i0]), int(recording.time_ns[i1 - 1])
    events = []
    for e in recording.events:
        if not lo <= e.time_ns <= hi:
            continue
        if e.kind in ("block_start", "block_end"):
            if not first <= e.block <= last:
                continue
            e = type(e)(e.time_ns, e.kind, e.direction, e.block - first, e.detail)
        events.append(e)
    sub = program.at_feed(feed)
    temperature = None if recording.temperature_c is None else recording.temperature_c[i0:i1]
    speed = sub.feed_m_per_s / MM_PER_MIN
    return recording.with_processing(
        f"split_feeds: feed {feed} ({speed:g} mm/min), samples {i0}-{i1 - 1}",
        accel=recording.accel[i0:i1],
        time_ns=recording.time_ns[i0:i1],
        seq=recording.seq[i0:i1],
        temperature_c=temperature,
        events=events,
        program=sub,
    )


def split_feeds(recording, program=None, options=None):
    """Cut a recording of a multi-feed program into one recording per feed.

    Parameters
    ----------
    recording : Recording
        The recording; a one-feed program gives the recording back whole.
    program : TestProgram, optional
        Overrides ``recording.program``.
    options : AnalysisOptions, optional
        Its low-pass (``cutoff_hz``, ``order``) smooths the data in which the
        motion is found when the recording has no block markers.

    Returns
    -------
    list of FeedRecording
        One per feed, in the program's order.

    Raises
    ------
    AnalysisError
        No program; a feed with no motion at its rate in the data; feeds in
        another order than the program's.
    """
    prog = _program_of(recording, program)
    if prog.n_feeds == 1:
        sub = (
            recording
            if recording.program is prog
            else recording.with_processing("program set", program=prog)
        )
        return [FeedRecording(0, prog, sub)]
    opts = options or AnalysisOptions()
    cuts = _boundaries_from_events(recording, prog)
    if cuts is None:
        cuts = _boundaries_from_data(recording, prog, opts)
    edges = [-np.inf, *cuts, np.inf]
    return [
        FeedRecording(f, prog.at_feed(f), _stretch(recording, prog, f, edges[f], edges[f + 1]))
        for f in range(prog.n_feeds)
    ]
