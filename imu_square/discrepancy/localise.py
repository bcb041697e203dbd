"""Where an unexplained gap lies: view, position angle, time since a reversal, frequency band.

When a view's gap stays above its null after the last step, the user is told
where the residual (recording minus final model) is, in terms that let them
name the effect themselves:

- the *position angle* of the largest excursion of the cycle-averaged residual
  trace of each direction and axis (harmonics 0 to ``K``), with the nearest
  axis reversal and the time since it (negative: before it);
- the *time since a reversal* of the largest bin of the reversal view, with the
  axis, the direction after the reversal and the sign (along or against the
  new direction of motion);
- the *frequency band*: the octave of circle harmonics that holds the largest
  excess over the noise (sum of ``z^2 - 2`` over its harmonics), in Hz;
- for the transient view, the window (after the start ramp or after the end of
  motion), direction, axis and time into it of its largest bin, and the
  frequency at which the mean residual of the windows has most power over the
  noise (a periodogram of the bin means, up to the bins' Nyquist frequency),
  with a band of one Rayleigh resolution ``1 / TRANSIENT_WINDOW_S`` either side;
- for the trend and the timing views, the time in the test of the cycle that
  departs most from its block.

Everything is computed from the residual's features
(:mod:`imu_square.discrepancy.features`) and their noise model
(:class:`~imu_square.discrepancy.views.FeatureSpace`); the curves for the
``--plot`` figure come with it.
"""

import math
from dataclasses import dataclass, field

import numpy as np

from imu_square.discrepancy.layout import (
    REVERSAL_BEFORE_S,
    REVERSAL_BIN_S,
    TRANSIENT_BIN_S,
    TRANSIENT_WINDOW_S,
)

# A view whose p-value with the final model is below this holds a gap left unexplained.
GAP_LEFT_P = 1e-3
# Points of the residual trace over one turn of the position angle (for the peak and the plot).
TRACE_POINTS = 720
# A harmonic of the residual trace is shrunk by max(0, 1 - SHRINK_Z2 / z^2) (z^2 its power
# over the noise's, 2 on average for noise alone): noise harmonics vanish, a gap's stay.
SHRINK_Z2 = 6.0
# The transient periodogram is evaluated this many times more finely than its resolution.
TRANSIENT_ZERO_PAD = 4
# Transient groups (layout.with_transients): 2 * after_end + (direction is CW).
TRANSIENT_GROUPS = (("start", "ccw"), ("start", "cw"), ("end", "ccw"), ("end", "cw"))


@dataclass(frozen=True)
class GapLocation:
    """Where one view's unexplained gap lies.

    Attributes
    ----------
    view : str
        The view.
    gap : float
        Its gap with the final model (1.0 = noise floor).
    p_value : float
        Its p-value under the null.
    where : str
        One line for a person.
    details : dict
        The same as numbers (JSON-ready): angle [deg], time since the nearest
        reversal [ms], axis, band [Hz], ... as apply to the view.
    """

    view: str
    gap: float
    p_value: float
    where: str
    details: dict = field(default_factory=dict)

    def to_json_dict(self):
        """As JSON-ready values."""
        return {
            "view": self.view,
            "gap": self.gap,
            "p_value": self.p_value,
            "where": self.where,
            **self.details,
        }


@dataclass(frozen=True)
class ResidualCurves:
    """The final residual's curves for the ``--plot`` figure.

    Attributes
    ----------
    angle_deg : ndarray, shape (n,)
        Position angle. [deg]
    trace : dict of (str, str) to ndarray
        ``(direction, axis)``: cycle-averaged residual trace of that direction,
        each harmonic shrunk by :data:`SHRINK_Z2`. [m/s^2]
    reversal_ms : ndarray, shape (n_bins,)
        Bin centres of the reversal view, time since the reversal. [ms]
    reversal : dict of (str, str) to ndarray
        ``(axis, "+" | "-")``: mean residual in each bin, per direction after
        the reversal. [m/s^2]
    frequency_hz : ndarray, shape (K + 1,)
        Frequencies of the harmonics. [Hz]
    excess : ndarray, shape (2, K + 1)
        ``z^2`` of each harmonic summed over blocks, per axis (2 per harmonic
        under the null, 1 for the offset, times the blocks).
    n_blocks : int
        Blocks summed in :attr:`excess`.
    transient_ms : ndarray, shape (n_transient_bins,)
        Bin centres of the transient windows, time into the window (which
        starts where the recording's feed ramp has ended). [ms]
    transient : dict of (str, str, str) to ndarray
        ``("start" | "end", direction, axis)``: mean residual in each bin of
        the windows after the start ramps or after the ends of motion of the
        blocks of that direction (NaN where a bin holds no sample). [m/s^2]
    transient_frequency_hz : ndarray, shape (m,)
        Frequencies of :attr:`transient_power`, up to the bins' Nyquist
        frequency. [Hz]
    transient_power : ndarray, shape (m,)
        Periodogram of the transient bin means over the noise's, averaged over
        the windows' groups and axes (1 on average under the null).
    """

    angle_deg: np.ndarray
    trace: dict
    reversal_ms: np.ndarray
    reversal: dict
    frequency_hz: np.ndarray
    excess: np.ndarray
    n_blocks: int
    transient_ms: np.ndarray
    transient: dict
    transient_frequency_hz: np.ndarray
    transient_power: np.ndarray


def gaps_left(gaps):
    """The views whose gap is above their null (p below :data:`GAP_LEFT_P`), worst first."""
    left = [v for v in gaps.values() if math.isfinite(v.gap) and v.p_value < GAP_LEFT_P]
    return sorted(left, key=lambda v: (v.p_value, -v.gap))


def _trace(coef, angles):
    """Real trace ``c0 + 2 sum Re(c_k e^{ik phi})`` from position-angle harmonics."""
    k = np.arange(coef.shape[-1])
    w = np.where(k == 0, 1.0, 2.0)
    return np.real(np.exp(1j * angles[:, None] * k[None, :]) @ (w * coef))


def _nearest_reversal(phi, sign, omega):
    """The nearest axis reversal to position angle ``phi``: axis, angle, time since it. [s]"""
    best = None
    for axis, offset in (("x", 0.0), ("y", 0.5 * math.pi)):
        rev = offset + math.pi * round((phi - offset) / math.pi)
        d = math.remainder(phi - rev, 2 * math.pi)
        if best is None or abs(d) < abs(best[2]):
            best = (axis, rev % (2 * math.pi), d)
    axis, rev, d = best
    return axis, math.degrees(rev), sign * d / omega


def _band(excess_k, freq, k0, k1):
    """The octave of harmonics in ``k0..k1`` with the largest excess over the null."""
    best = None
    lo = max(k0, 1)
    while lo <= k1:
        hi = min(2 * lo - 1, k1)
        e = float(np.sum(excess_k[lo : hi + 1] - 2.0))
        if best is None or e > best[0]:
            best = (e, lo, hi)
        lo = hi + 1
    if best is None:
        return None
    _, lo, hi = best
    strongest = lo + int(np.argmax(excess_k[lo : hi + 1]))
    return {
        "band_hz": [float(freq[lo]), float(freq[hi])],
        "strongest_hz": float(freq[strongest]),
        "harmonics": [lo, hi],
    }


def _transient_curves(space, residual):
    """Mean residual per transient bin and its periodogram over the noise's.

    Each group and axis's bin means ``m_j``, whitened by their standard
    deviation ``sqrt(sigma^2 / n_j)``, give ``|sum_j z_j exp(-2 pi i f t_j)|^2 / J``
    (mean 1 under the null at every ``f``); the mean over the groups and axes
    that hold samples is returned. The bin means sample the residual every
    bin, so frequencies above the bins' Nyquist frequency alias below it, and
    a sinusoid at ``f`` is scaled by about ``sinc(f * bin)`` (0.76 at 0.4 of the bin rate).
    """
    layout = space.layout
    n = layout.n_transient_bins
    bin_s = max(TRANSIENT_BIN_S, layout.dt_s)
    centres = (np.arange(n) + 0.5) * bin_s
    count = np.bincount(layout.transient_bin[layout.transient_bin >= 0], minlength=4 * n)
    count = count.reshape(4, n).astype(float)
    df = 1.0 / (TRANSIENT_ZERO_PAD * n * bin_s)
    freq = np.arange(0.0, 0.5 / bin_s + 0.5 * df, df)
    phasor = np.exp(-2j * math.pi * np.outer(freq, centres))
    curves, power = {}, []
    for a, axis in enumerate(("x", "y")):
        sums = residual.transient[a].reshape(4, n)
        for g, (window, direction) in enumerate(TRANSIENT_GROUPS):
            used = count[g] > 0
            with np.errstate(invalid="ignore", divide="ignore"):
                curves[window, direction, axis] = np.where(used, sums[g] / count[g], np.nan)
            if used.any():
                z = sums[g][used] / np.sqrt(space.noise.sigma2[a] * count[g][used])
                power.append(np.abs(phasor[:, used] @ z) ** 2 / used.sum())
    mean_power = np.mean(power, axis=0) if power else np.zeros(freq.size)
    return centres * 1e3, curves, freq, mean_power


def residual_curves(space, residual):
    """The final residual's curves (:class:`ResidualCurves`)."""
    layout = space.layout
    angles = np.linspace(0.0, 2 * math.pi, TRACE_POINTS, endpoint=False)
    trace = {}
    k = np.arange(residual.block.shape[-1])
    for d in ("ccw", "cw"):
        blocks = [b for b, blk in enumerate(layout.blocks) if blk.direction == d]
        if not blocks:
            continue
        for a, axis in enumerate(("x", "y")):
            coef = residual.block[blocks, a].mean(axis=0)
            var = space.block_var[blocks, a].mean(axis=0) / len(blocks)
            z2 = np.abs(coef) ** 2 / np.where(k == 0, var, var / 2)
            # shrunk towards zero where a harmonic is not above its noise: the trace
            # shows the gap, not the noise of a hundred harmonics
            shrink = np.clip(1.0 - SHRINK_Z2 / np.maximum(z2, 1e-300), 0.0, 1.0)
            trace[d, axis] = _trace(coef * shrink, angles)
    n_bins = layout.n_bins
    bin_s = max(REVERSAL_BIN_S, layout.dt_s)
    centres = (np.arange(n_bins) + 0.5) * bin_s - REVERSAL_BEFORE_S
    reversal = {}
    for a, axis in enumerate(("x", "y")):
        # channel a holds the groups 2 a (to the negative direction) and 2 a + 1
        counts = space._rev_count[a].reshape(4, n_bins)[2 * a : 2 * a + 2]
        sums = residual.reversal[a].reshape(4, n_bins)[2 * a : 2 * a + 2]
        for g, after in enumerate(("-", "+")):
            with np.errstate(invalid="ignore", divide="ignore"):
                reversal[axis, after] = np.where(counts[g] > 0, sums[g] / counts[g], np.nan)
    var = space.block_var  # (n_blocks, 2, K + 1)
    z2 = np.abs(residual.block) ** 2 / np.where(k == 0, var, var / 2)
    transient_ms, transient, transient_hz, transient_power = _transient_curves(space, residual)
    return ResidualCurves(
        angle_deg=np.degrees(angles),
        trace=trace,
        reversal_ms=centres * 1e3,
        reversal=reversal,
        frequency_hz=k * layout.frequency_hz,
        excess=z2.sum(axis=0),
        n_blocks=len(layout.blocks),
        transient_ms=transient_ms,
        transient=transient,
        transient_frequency_hz=transient_hz,
        transient_power=transient_power,
    )


def _trace_location(space, curves, channels):
    """Largest excursion of the residual trace over ``channels`` ((direction, axis) pairs)."""
    layout = space.layout
    best = None
    for key in channels:
        if key not in curves.trace:
            continue
        y = curves.trace[key]
        i = int(np.argmax(np.abs(y)))
        if best is None or abs(y[i]) > abs(best[2]):
            best = (key, i, float(y[i]))
    if best is None:
        return None
    (direction, axis), i, value = best
    sign = 1.0 if direction == "ccw" else -1.0
    phi = math.radians(curves.angle_deg[i])
    rev_axis, rev_deg, since = _nearest_reversal(phi, sign, layout.omega_rad_s)
    return {
        "direction": direction,
        "channel": axis,
        "angle_deg": round(float(curves.angle_deg[i]), 1),
        "peak_m_s2": value,
        "nearest_reversal": {"axis": rev_axis, "angle_deg": rev_deg, "time_since_ms": since * 1e3},
    }


def _trace_text(loc):
    r = loc["nearest_reversal"]
    when = f"{abs(r['time_since_ms']):.0f} ms " + ("after" if r["time_since_ms"] >= 0 else "before")
    return (
        f"largest at position angle {loc['angle_deg']:.0f}° ({loc['direction'].upper()}, "
        f"{loc['channel']} channel, {loc['peak_m_s2'] * 1e3:+.2g} mm/s²), {when} the "
        f"{r['axis']} reversal at {r['angle_deg']:.0f}°"
    )


def _band_text(band):
    lo, hi = band["band_hz"]
    if band["harmonics"][0] == band["harmonics"][1]:
        return f"at {lo:.3g} Hz (harmonic {band['harmonics'][0]} of the circle)"
    return f"band {lo:.3g}–{hi:.3g} Hz (strongest {band['strongest_hz']:.3g} Hz)"


def _reversal_location(curves):
    best = None
    for (axis, after), y in curves.reversal.items():
        if np.all(np.isnan(y)):
            continue
        i = int(np.nanargmax(np.abs(y)))
        if best is None or abs(y[i]) > abs(best[2]):
            best = (axis, after, float(y[i]), i)
    if best is None:
        return None
    axis, after, value, i = best
    along = value * (1.0 if after == "+" else -1.0)
    return {
        "axis": axis,
        "direction_after": after,
        "time_since_reversal_ms": float(curves.reversal_ms[i]),
        "peak_m_s2": value,
        "sense": "along" if along > 0 else "against",
    }


def _transient_location(curves):
    """The transient bin with the largest mean residual: which window, direction, channel, when."""
    best = None
    for (window, direction, axis), y in curves.transient.items():
        if np.all(np.isnan(y)):
            continue
        i = int(np.nanargmax(np.abs(y)))
        if best is None or abs(y[i]) > abs(best[3]):
            best = (window, direction, axis, float(y[i]), i)
    if best is None:
        return None
    window, direction, axis, value, i = best
    return {
        "window": "after the end of motion" if window == "end" else "after the start ramp",
        "direction": direction,
        "channel": axis,
        "time_into_window_ms": float(curves.transient_ms[i]),
        "peak_m_s2": value,
    }


def _transient_band(curves):
    """The frequency of the transient periodogram's peak, one resolution either side."""
    f, p = curves.transient_frequency_hz, curves.transient_power
    if not np.any(p > 0):
        return None
    i = int(np.argmax(p))
    peak, resolution = float(f[i]), 1.0 / TRANSIENT_WINDOW_S
    return {
        "band_hz": [max(0.0, peak - resolution), min(float(f[-1]), peak + resolution)],
        "strongest_hz": peak,
        "power_over_noise": float(p[i]),
        "nyquist_hz": float(f[-1]),
    }


def _cycle_location(space, residual, name):
    """The cycle that departs most from its block's mean (trend: offset and circle; timing)."""
    layout = space.layout
    worst = None
    for b in range(len(layout.blocks)):
        idx = np.flatnonzero(layout.cycle_block == b)
        if idx.size < 2:
            continue
        c = residual.cycle[idx]
        if name == "timing":
            c = (1j * c[:, :, 1] / space._timing_ref[idx]).real[:, :, None]
        dev = np.abs(c - c.mean(axis=0))
        scale = dev.std(axis=0) + 1e-300
        score = (dev / scale).max(axis=(1, 2))
        j = int(np.argmax(score))
        if worst is None or score[j] > worst[0]:
            worst = (float(score[j]), int(idx[j]), b)
    if worst is None:
        return None
    _, i, b = worst
    return {
        "cycle": i,
        "time_s": float(layout.cycle_t0_s[i] - layout.cycle_t0_s[0]),
        "block": b,
        "direction": layout.blocks[b].direction,
    }


def locate_gaps(space, residual, gaps):
    """Where each view's unexplained gap lies.

    Parameters
    ----------
    space : FeatureSpace
        The noise model and views.
    residual : Features
        Features of recording minus the final model.
    gaps : dict of str to ViewGap
        The final model's gaps.

    Returns
    -------
    locations : tuple of GapLocation
        One per view with a gap left (:func:`gaps_left`), worst first.
    curves : ResidualCurves
        The residual's curves.
    """
    curves = residual_curves(space, residual)
    kt, k_max = space.k_trace, space.k_max
    out = []
    for v in gaps_left(gaps):
        details, parts = {}, []
        if v.name in ("trace_x", "trace_y", "cw_vs_ccw", "harmonics", "band"):
            axis = {"trace_x": ("x",), "trace_y": ("y",)}.get(v.name, ("x", "y"))
            loc = _trace_location(space, curves, [(d, a) for d in ("ccw", "cw") for a in axis])
            if loc:
                details["position"] = loc
                parts.append(_trace_text(loc))
            k0, k1 = {"harmonics": (2, min(10, k_max)), "band": (kt + 1, k_max)}.get(
                v.name, (0, kt)
            )
            chans = [0] if v.name == "trace_x" else [1] if v.name == "trace_y" else [0, 1]
            band = _band(curves.excess[chans].sum(axis=0), curves.frequency_hz, k0, k1)
            if band:
                details["band"] = band
                parts.append(_band_text(band))
        elif v.name == "reversals":
            loc = _reversal_location(curves)
            if loc:
                details["reversal"] = loc
                parts.append(
                    f"largest {loc['time_since_reversal_ms']:+.0f} ms from the {loc['axis']} "
                    f"reversals to {loc['direction_after']}{loc['axis']} "
                    f"({loc['peak_m_s2'] * 1e3:+.2g} mm/s², {loc['sense']} the new direction)"
                )
            band = _band(curves.excess.sum(axis=0), curves.frequency_hz, 1, k_max)
            if band:
                details["band"] = band
                parts.append(_band_text(band))
        elif v.name == "transients":
            loc = _transient_location(curves)
            if loc:
                details["transient"] = loc
                parts.append(
                    f"largest {loc['time_into_window_ms']:.1f} ms into the window "
                    f"{loc['window']} ({loc['direction'].upper()}, {loc['channel']} channel, "
                    f"{loc['peak_m_s2'] * 1e3:+.2g} mm/s²)"
                )
            band = _transient_band(curves)
            if band:
                details["band"] = band
                parts.append(
                    f"its windows' power peaks at {band['strongest_hz']:.3g} Hz "
                    f"({band['power_over_noise']:.2g}x the noise; bins alias above "
                    f"{band['nyquist_hz']:.3g} Hz)"
                )
        else:  # trend, timing
            loc = _cycle_location(space, residual, v.name)
            if loc:
                details["cycle"] = loc
                parts.append(
                    f"cycle {loc['cycle']} ({loc['direction'].upper()}, {loc['time_s']:.0f} s into "
                    "the analysed cycles) departs most from its block"
                )
            f = space.layout.frequency_hz
            details["band"] = {"band_hz": [0.0, f], "strongest_hz": f, "harmonics": [0, 1]}
            parts.append(f"offset and circle harmonic ({f:.3g} Hz) of each cycle")
        out.append(GapLocation(v.name, v.gap, v.p_value, "; ".join(parts), details))
    return tuple(out), curves
