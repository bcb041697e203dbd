"""Checks that stop a wrong number: amplitude, period, clipping, cycles.

A measurement that cannot be trusted raises :class:`AnalysisError` with a
message a machinist can act on; an oddity that leaves the result usable
becomes a quality flag on the result, which the CLI prints.
"""

import numpy as np

from imu_square.errors import AnalysisError
from imu_square.units import SQUARENESS_UNIT, URAD

# The measured amplitude must lie within this factor of v^2/r, else refuse.
AMPLITUDE_LIMIT = 1.5
# Flag when the amplitude departs from v^2/r by more than this fraction.
AMPLITUDE_FLAG = 0.05
# Refuse when the period departs from the program's by more than this fraction.
PERIOD_LIMIT = 0.05
# Flag when the circle period departs from the program's by more than this.
PERIOD_FLAG = 0.005
# Flag when the type A uncertainty exceeds the white-noise bound by this factor.
EXCESS_NOISE_FLAG = 3.0
# Below half the Cramer-Rao bound the cycle scatter has come out low by chance.
SCANT_SCATTER_FLAG = 0.5
# Flag when more than this fraction of the averaged trace gets zero robust weight.
OUTLIER_FLAG = 0.05
# Flag a user's cutoff below this multiple of the circle frequency.
MIN_CUTOFF_MARGIN = 10.0


def format_accel(value):
    """Two significant digits, trailing zeros kept: 0.4 -> '0.40'. [m/s^2]"""
    return f"{value:#.2g}" if abs(value) < 100 else f"{value:.0f}"


def check_amplitude(measured_m_s2, program):
    """Refuse an amplitude far from ``v^2/r``.

    Parameters
    ----------
    measured_m_s2 : float
        Fitted amplitude, mean of both axes. [m/s^2]
    program : TestProgram
        The program the machine ran.

    Returns
    -------
    float
        Ratio of the measured amplitude to ``v^2/r``.

    Raises
    ------
    AnalysisError
        If the ratio is outside ``[1/AMPLITUDE_LIMIT, AMPLITUDE_LIMIT]``.
    """
    implied = program.centripetal_m_s2
    ratio = measured_m_s2 / implied
    if not 1 / AMPLITUDE_LIMIT <= ratio <= AMPLITUDE_LIMIT:
        raise AnalysisError(
            f"measured {format_accel(measured_m_s2)} m/s² but the program implies "
            f"{format_accel(implied)} m/s²: check the feed, the radius or the units"
        )
    return float(ratio)


def check_period(disagreement, measured_s, program):
    """Refuse a circle period far from the program's.

    Parameters
    ----------
    disagreement : float
        Measured period over the program's, minus 1.
    measured_s : float
        Measured period. [s]
    program : TestProgram
        The program the machine ran.

    Raises
    ------
    AnalysisError
        If ``|disagreement| > PERIOD_LIMIT``.
    """
    if abs(disagreement) > PERIOD_LIMIT:
        raise AnalysisError(
            f"the circles take {measured_s:.3f} s but the program implies "
            f"{program.period_s:.3f} s ({disagreement:+.1%}): check the feed override "
            f"or the sensor's sample rate"
        )


def check_cycles(n_ccw, n_cw, program, min_cycles, dropped):
    """Refuse too few usable cycles in either direction.

    Parameters
    ----------
    n_ccw, n_cw : int
        Usable cycles per direction.
    program : TestProgram
        The program.
    min_cycles : int
        Least usable cycles per direction.
    dropped : sequence of dict
        The dropped cycles with their reasons.

    Raises
    ------
    AnalysisError
    """
    if min(n_ccw, n_cw) < min_cycles:
        reasons = sorted({d["reason"] for d in dropped})
        why = f"; dropped: {', '.join(reasons)}" if reasons else ""
        raise AnalysisError(
            f"too few usable cycles: {n_ccw} CCW and {n_cw} CW of "
            f"{program.cycles_per_direction * program.runs} each, min_cycles={min_cycles}{why}"
        )


def outlier_fractions(mean_fit):
    """Fraction of each direction's averaged trace that the robust fit rejected.

    Parameters
    ----------
    mean_fit : MeanFit
        Fits of the CCW and the flipped CW mean traces.

    Returns
    -------
    list of float
        ``[ccw, cw]``: points of both axes holding data with zero weight,
        over all that hold data.
    """
    fit = mean_fit.fit
    out = []
    for i in range(2):
        held = np.concatenate([fit.x.prior_weights[i], fit.y.prior_weights[i]]) > 0
        zero = np.concatenate([fit.x.weights[i], fit.y.weights[i]]) == 0.0
        out.append(float(np.mean(zero[held])))
    return out


def _clipping_warning(clipped, shown=3):
    """The line naming the clipped samples by time (the first ``shown`` of them)."""
    where = ", ".join(f"{t:.3f}" for t in clipped[:shown])
    more = f" and {clipped.size - shown} more" if clipped.size > shown else ""
    return (
        f"{clipped.size} sample(s) at the sensor's full scale (clipping), at {where} s{more}: "
        f"left out as lost, and any cycle they touch dropped"
    )


def _spans_holding(spans, times):
    """How many of the sorted ``(start, end)`` spans hold one of the sorted ``times``."""
    if not len(spans) or not times.size:
        return 0
    spans = np.asarray(spans, dtype=np.float64)
    k = np.minimum(np.searchsorted(times, spans[:, 0], side="right"), times.size - 1)
    return int(np.count_nonzero((times[k] > spans[:, 0]) & (times[k] < spans[:, 1])))


def quality_flags(
    recording,
    seg,
    cyc,
    clipped,
    amplitude_ratio,
    outliers,
    u_rad,
    floor,
    filtered,
    speed_warning=None,
):
    """Quality flags of a result that stands, each oddity with a line a machinist can act on.

    Parameters
    ----------
    recording : Recording
        The recording analysed.
    seg : Segmentation
        The blocks found.
    cyc : CycleTraces
        The cycles kept and dropped.
    clipped : ndarray
        Times of clipped samples. [s]
    amplitude_ratio : float
        Measured amplitude over that of the circle analysed (``v^2/r``, or
        ``omega^2 r`` when the circles ran at another speed than programmed).
    outliers : list of float
        Rejected fraction of each direction's mean trace.
    u_rad : float
        Type A uncertainty of the result. [rad]
    floor : NoiseFloor
        The noise floor.
    filtered : FilteredRecording
        The samples as filtered (cutoff, bridged gaps).
    speed_warning : str, optional
        Why the circles were analysed at the speed they ran at rather than
        the programmed one (:mod:`imu_square.pipeline.circle_speed`); it
        replaces the period flag.

    Returns
    -------
    dict
        Flags, and the human-readable ``warnings`` list.
    """
    warnings = []
    crb = floor.crb_rad
    n_gaps = recording.gap_count
    if clipped.size:
        warnings.append(_clipping_warning(clipped))
    n_bridged = len(filtered.bridged_spans_s) - _spans_holding(filtered.bridged_spans_s, clipped)
    if n_gaps:
        bridged = (
            f" ({n_bridged} short one(s) bridged, their samples left out)" if n_bridged else ""
        )
        warnings.append(f"{n_gaps} gap(s), {recording.lost_in_all} samples lost{bridged}")
    for block in seg.blocks:
        if block.lost_end is not None:
            label, (a, b) = block.lost_end
            other = "stop" if label == "start" else "start"
            what = "clipping" if _spans_holding([(a, b)], clipped) else "a gap"
            warnings.append(
                f"block {block.plan.index} ({block.direction}): {what} ({a:.2f}-{b:.2f} s) hides "
                f"its {label} of motion; anchored by its {other} and the other blocks' length "
                f"of motion (midpoint u {block.u_t_mid_s * 1e3:.1f} ms)"
            )
    f0 = 1 / seg.period_s
    if filtered.cutoff_hz < MIN_CUTOFF_MARGIN * f0:
        warnings.append(
            f"low-pass cutoff {filtered.cutoff_hz:.3g} Hz is only "
            f"{filtered.cutoff_hz / f0:.1f} x the circle frequency {f0:.3g} Hz (below "
            f"{MIN_CUTOFF_MARGIN:g} x): few independent samples per cycle unsettle the robust "
            f"fit; the default ties the cutoff to 8 pi x the circle frequency"
        )
    if cyc.dropped:
        reasons = sorted({d["reason"] for d in cyc.dropped})
        warnings.append(f"{len(cyc.dropped)} cycle(s) dropped: {', '.join(reasons)}")
    if abs(amplitude_ratio - 1) > AMPLITUDE_FLAG:
        warnings.append(
            f"amplitude is {amplitude_ratio:.3f} x v^2/r: feed override, radius or sensor gain "
            f"differ from the program"
        )
    if speed_warning is not None:
        warnings.append(speed_warning)
    elif abs(seg.period_disagreement) > PERIOD_FLAG:
        warnings.append(
            f"circle period differs from the program by {seg.period_disagreement:+.2%}: "
            f"feed override or sample clock error"
        )
    if max(outliers) > OUTLIER_FLAG:
        warnings.append(
            f"{max(outliers):.1%} of the averaged trace rejected by the robust fit "
            f"(reversal spikes or vibration)"
        )
    if u_rad < SCANT_SCATTER_FLAG * crb:
        pairs = min(cyc.ccw.n, cyc.cw.n)
        warnings.append(
            f"the type A uncertainty is only {u_rad / crb:.2f} x the noise floor: from "
            f"{pairs} cycle pairs the scatter is itself uncertain, and no estimate beats the "
            f"bound; quote at least {crb / URAD:.1f} {SQUARENESS_UNIT}"
        )
    if u_rad > EXCESS_NOISE_FLAG * crb:
        warnings.append(
            f"cycle-to-cycle scatter is {u_rad / crb:.1f} x the noise floor "
            f"({floor.source} noise density, 1/f included): vibration or drift"
        )
    return {
        "clipped_samples": int(clipped.size),
        "gaps": n_gaps,
        "gaps_bridged": n_bridged,
        "lost_samples": int(recording.lost_in_all),
        "cycles_dropped": [dict(d) for d in cyc.dropped],
        "amplitude_ratio": float(amplitude_ratio),
        "period_disagreement": float(seg.period_disagreement),
        "outlier_fraction": float(max(outliers)),
        "noise_density_residual_m_s2_rthz": float(floor.residual_density_m_s2_rthz),
        "warnings": warnings,
    }
