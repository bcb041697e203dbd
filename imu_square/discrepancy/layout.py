"""Which samples are compared, and where they sit on the circle.

A :class:`Layout` holds the analysed whole cycles of a test: the samples in
them, each sample's commanded position angle ``phi`` and the axis reversals
around which the drive effects live. For a recording it comes from the
pipeline's own steps (:func:`layout_from_recording`: filter, segment, the
cycles :func:`~imu_square.pipeline.align.cycle_traces` keeps after dropping
those touched by gaps or clipping); for a test that was not run it comes from
the simulator's timeline (:func:`layout_from_timeline`), which is how the
Fisher information of an extra test is computed.

Besides the analysed cycles it can hold *transient* samples, outside them:
windows after each block's start ramp and after its end of motion, where a
mode rung by the feed ramps rings (:func:`with_transients`; where the windows
start is :mod:`imu_square.discrepancy.transients`'s choice). The transient
samples come after the analysed ones in :attr:`Layout.t_s` and the other
per-sample arrays.
"""

import math
from dataclasses import dataclass, field, replace

import numpy as np

from imu_square.pipeline.squareness import filter_and_segment, trace_cycles

# Window around each axis reversal for the reversal view: before and after it. [s]
REVERSAL_BEFORE_S = 0.05
REVERSAL_AFTER_S = 0.25
REVERSAL_BIN_S = 0.005
# Length of each transient window and its bins. [s]
TRANSIENT_WINDOW_S = 0.25
TRANSIENT_BIN_S = 0.002
# The motion midpoint's uncertainty is never taken below this (a tenth of a 1 kHz sample). [s]
MIN_U_T_MID_S = 1e-5


@dataclass(frozen=True)
class BlockInfo:
    """One block of the layout.

    Attributes
    ----------
    index : int
        Block number in the program.
    run : int
        Run number.
    direction : str
        ``"ccw"`` or ``"cw"``.
    sign : int
        +1 for CCW, -1 for CW.
    t_mid_s : float
        Motion midpoint on the recording's clock, from its first sample. [s]
    phi_mid_rad : float
        Commanded position angle at ``t_mid_s``. [rad]
    u_t_mid_s : float
        Standard uncertainty of ``t_mid_s`` (motion detection). [s]
    """

    index: int
    run: int
    direction: str
    sign: int
    t_mid_s: float
    phi_mid_rad: float
    u_t_mid_s: float


@dataclass(frozen=True)
class Layout:
    """The analysed samples of a test and their place on the circle.

    Attributes
    ----------
    program : TestProgram
        The program.
    blocks : tuple of BlockInfo
        Blocks with at least one analysed cycle, in time order.
    omega_rad_s : float
        Angular speed of the time-to-angle map. [rad/s]
    dt_s : float
        Nominal sample spacing. [s]
    t_s : ndarray, shape (m,)
        Times of the analysed samples, from the recording's first sample. [s]
    index : ndarray of int, shape (m,)
        Their indices in the recording.
    phi : ndarray, shape (m,)
        Their commanded position angle. [rad]
    sample_block : ndarray of int, shape (m,)
        Position in :attr:`blocks` of each analysed sample.
    cycle_edges : ndarray of int, shape (n_cycles + 1,)
        Cycle ``c`` holds analysed samples ``cycle_edges[c]:cycle_edges[c + 1]``.
    cycle_block : ndarray of int, shape (n_cycles,)
        Position in :attr:`blocks` of each cycle.
    cycle_t0_s : ndarray, shape (n_cycles,)
        Exact start of each cycle (a whole period from the anchor). [s]
    period_s : float
        Period of the time-to-angle map. [s]
    reversal_bin : ndarray of int, shape (2, m)
        For the x and the y channel, the reversal bin of each analysed sample
        (-1 outside every window); bin ``g * n_bins + j`` is bin ``j`` of group
        ``g = 2 * axis + (direction after the reversal > 0)``.
    n_bins : int
        Bins per reversal window.
    dropped : tuple of dict
        Cycles the pipeline dropped, with the reason.
    transient_bin : ndarray of int, shape (m,)
        Transient bin of each sample (-1 for the analysed ones, which come
        first): bin ``g * n_transient_bins + j`` is bin ``j`` of group
        ``g = 2 * (after the end of motion) + (CW)``. Empty: none.
    n_transient_bins : int
        Bins per transient window.
    """

    program: object
    blocks: tuple
    omega_rad_s: float
    dt_s: float
    t_s: np.ndarray
    index: np.ndarray
    phi: np.ndarray
    sample_block: np.ndarray
    cycle_edges: np.ndarray
    cycle_block: np.ndarray
    cycle_t0_s: np.ndarray
    period_s: float
    reversal_bin: np.ndarray
    n_bins: int
    dropped: tuple = ()
    transient_bin: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))
    n_transient_bins: int = 1

    @property
    def n_analysed(self):
        """Number of analysed samples (the transient ones follow them)."""
        return int(self.cycle_edges[-1])

    @property
    def n_cycles(self):
        """Number of analysed cycles."""
        return self.cycle_block.size

    @property
    def frequency_hz(self):
        """Circle frequency of the time-to-angle map. [Hz]"""
        return self.omega_rad_s / (2 * math.pi)


def _reversal_bins(t, phi, sample_block, blocks, omega, dt):
    """Reversal bin of each analysed sample, per channel (see :class:`Layout`)."""
    bin_s = max(REVERSAL_BIN_S, dt)
    half_turn = math.pi / omega
    after = min(REVERSAL_AFTER_S, 0.8 * half_turn - REVERSAL_BEFORE_S)
    n_bins = max(1, math.ceil((REVERSAL_BEFORE_S + after) / bin_s))
    out = np.full((2, t.size), -1, dtype=np.int64)
    for b, block in enumerate(blocks):
        lo, hi = np.searchsorted(sample_block, (b, b + 1))
        if hi <= lo:
            continue
        tb, pb = t[lo:hi], phi[lo:hi]
        p0, p1 = float(min(pb[0], pb[-1])), float(max(pb[0], pb[-1]))
        for axis, offset in ((0, 0.0), (1, 0.5 * math.pi)):
            m = np.arange(
                math.ceil((p0 - offset) / math.pi), math.floor((p1 - offset) / math.pi) + 1
            )
            for phi_rev in offset + math.pi * m:
                t_rev = block.t_mid_s + (phi_rev - block.phi_mid_rad) / (block.sign * omega)
                after_phi = phi_rev + block.sign * 1e-3
                rate = -math.sin(after_phi) if axis == 0 else math.cos(after_phi)
                group = 2 * axis + int(rate * block.sign > 0)
                i0, i1 = np.searchsorted(tb, (t_rev - REVERSAL_BEFORE_S, t_rev + after))
                j = np.floor((tb[i0:i1] - t_rev + REVERSAL_BEFORE_S) / bin_s).astype(np.int64)
                j = np.clip(j, 0, n_bins - 1)
                out[axis, lo + i0 : lo + i1] = group * n_bins + j
    return out, n_bins


def with_transients(layout, t_all, windows):
    """The layout with transient samples added after its analysed ones.

    Parameters
    ----------
    layout : Layout
        Analysed samples only.
    t_all : ndarray
        Times of every recorded sample, from the first. [s]
    windows : list of tuple
        ``(block position, start, limit, after_end)``: a window of
        :data:`TRANSIENT_WINDOW_S` from ``start`` (cut at ``limit``) after the
        block's start ramp, or after its end of motion if ``after_end``. [s]

    Returns
    -------
    Layout
    """
    bin_s = max(TRANSIENT_BIN_S, layout.dt_s)
    n_bins = max(1, math.ceil(TRANSIENT_WINDOW_S / bin_s))
    index, block, bins = [], [], []
    for b, t0, limit, after_end in windows:
        group = 2 * int(after_end) + int(layout.blocks[b].sign < 0)
        # a ramp that runs up to the limit leaves its window empty
        i0, i1 = np.searchsorted(t_all, (t0, max(t0, min(t0 + n_bins * bin_s, limit))))
        j = np.floor((t_all[i0:i1] - t0) / bin_s).astype(np.int64)
        index.append(np.arange(i0, i1, dtype=np.int64))
        block.append(np.full(i1 - i0, b, dtype=np.int64))
        bins.append(group * n_bins + np.clip(j, 0, n_bins - 1))
    index, block, bins = (np.concatenate([np.empty(0, np.int64), *x]) for x in (index, block, bins))
    n = layout.t_s.size
    t = t_all[index]
    phi = np.array([layout.blocks[b].phi_mid_rad for b in block]) + np.array(
        [layout.blocks[b].sign * layout.omega_rad_s for b in block]
    ) * (t - np.array([layout.blocks[b].t_mid_s for b in block]))
    return replace(
        layout,
        t_s=np.concatenate([layout.t_s, t]),
        index=np.concatenate([layout.index, index]),
        phi=np.concatenate([layout.phi, phi]),
        sample_block=np.concatenate([layout.sample_block, block]),
        reversal_bin=np.concatenate(
            [layout.reversal_bin, np.full((2, index.size), -1, dtype=np.int64)], axis=1
        ),
        transient_bin=np.concatenate([np.full(n, -1, dtype=np.int64), bins]),
        n_transient_bins=n_bins,
    )


def _assemble(program, blocks, omega, dt, t_all, cycles, dropped):
    """Build a Layout from blocks and cycle windows ``(block position, i0, i1, t0)``."""
    cycles = sorted(cycles, key=lambda c: (c[0], c[1]))
    index = np.concatenate([np.arange(i0, i1) for _, i0, i1, _ in cycles]).astype(np.int64)
    sizes = np.array([i1 - i0 for _, i0, i1, _ in cycles])
    edges = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    cycle_block = np.array([b for b, _, _, _ in cycles], dtype=np.int64)
    sample_block = np.repeat(cycle_block, sizes)
    t = t_all[index]
    phi = np.empty_like(t)
    for b, block in enumerate(blocks):
        sel = sample_block == b
        phi[sel] = block.phi_mid_rad + block.sign * omega * (t[sel] - block.t_mid_s)
    bins, n_bins = _reversal_bins(t, phi, sample_block, blocks, omega, dt)
    return Layout(
        program=program,
        blocks=tuple(blocks),
        omega_rad_s=float(omega),
        dt_s=float(dt),
        t_s=t,
        index=index,
        phi=phi,
        sample_block=sample_block,
        cycle_edges=edges,
        cycle_block=cycle_block,
        cycle_t0_s=np.array([c[3] for c in cycles], dtype=np.float64),
        period_s=2 * math.pi / omega,
        reversal_bin=bins,
        n_bins=n_bins,
        dropped=tuple(dropped),
        transient_bin=np.full(index.size, -1, dtype=np.int64),
    )


def layout_from_recording(recording, program, options):
    """The analysed cycles of a recording, found by the pipeline's own steps.

    Parameters
    ----------
    recording : Recording
        The test as recorded.
    program : TestProgram
        The program it ran.
    options : AnalysisOptions
        Filter settings for the segmentation (the pipeline's).

    Returns
    -------
    Layout

    Raises
    ------
    AnalysisError
        Where the pipeline refuses the recording (no circle, wrong direction, ...).
    """
    data, seg = filter_and_segment(recording, program, options.cutoff_hz, options.order)
    cyc = trace_cycles(data, seg, grid_points=8)
    prog = seg.program
    # the recorded samples only: the filter's bridged ones are not data
    t_all = recording.time_s
    period = seg.period_s
    positions = {}
    blocks = []
    for block in seg.blocks:
        positions[block.plan.index] = len(blocks)
        phi_mid = block.plan.start_angle_rad + block.sign * prog.block_angle_rad / 2
        blocks.append(
            BlockInfo(
                block.plan.index,
                block.plan.run,
                block.direction,
                block.sign,
                block.t_mid_s,
                phi_mid,
                max(block.u_t_mid_s, MIN_U_T_MID_S),
            )
        )
    cycles = []
    for part in (cyc.ccw, cyc.cw):
        for b, t0 in zip(part.block, part.t_start_s, strict=True):
            i0, i1 = np.searchsorted(t_all, (t0, t0 + period))
            if i1 - i0 > 8:
                cycles.append((positions[int(b)], int(i0), int(i1), float(t0)))
    used = sorted({c[0] for c in cycles})
    remap = {old: new for new, old in enumerate(used)}
    blocks = [blocks[b] for b in used]
    cycles = [(remap[b], i0, i1, t0) for b, i0, i1, t0 in cycles]
    dt = recording.dt_ns * 1e-9
    return _assemble(prog, blocks, seg.omega_rad_s, dt, t_all, cycles, cyc.dropped)


def layout_from_timeline(program, timeline, sample_rate_hz, u_t_mid_s=1e-4):
    """The analysed cycles of a simulated test, placed by the simulator's timeline.

    Parameters
    ----------
    program : TestProgram
        The program.
    timeline : Timeline
        The simulator's commanded timeline of it (``lead_in_s`` included).
    sample_rate_hz : float
        Sample rate. [Hz]
    u_t_mid_s : float
        How well the motion midpoints would be detected. [s]

    Returns
    -------
    Layout
        Sample times from the timeline's start; each block anchored at its
        commanded motion midpoint.
    """
    dt = 1.0 / sample_rate_hz
    t_all = np.arange(math.floor(timeline.duration_s / dt) + 1) * dt
    omega = program.omega_rad_s
    period = 2 * math.pi / omega
    blocks, cycles, windows = [], [], []
    plans = program.blocks()
    for b, (blk, plan) in enumerate(zip(timeline.blocks, plans, strict=True)):
        mid = blk.t_start_s + 0.5 * blk.duration_s
        phi_mid = blk.start_angle_rad + blk.sign * blk.angle_rad / 2
        blocks.append(
            BlockInfo(blk.index, plan.run, blk.direction, blk.sign, mid, phi_mid, u_t_mid_s)
        )
        # the model is the truth here: its windows start right after its ramps
        later = timeline.blocks[b + 1].t_start_s if b + 1 < len(timeline.blocks) else math.inf
        windows.append((b, blk.t_start_s + blk.ramp_s, blk.analysed_window_s[0], False))
        windows.append((b, blk.t_end_s, later, True))
        a0, _ = blk.analysed_window_s
        for j in range(program.cycles_per_direction):
            t0 = a0 + j * period
            i0, i1 = np.searchsorted(t_all, (t0, t0 + period))
            cycles.append((b, int(i0), int(i1), t0))
    layout = _assemble(program, blocks, omega, dt, t_all, cycles, ())
    return with_transients(layout, t_all, windows)
