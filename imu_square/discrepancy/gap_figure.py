"""The gap of every view, step by step, and where the gap left lies.

Six panels: each view's gap after each step (1.0 = noise floor); the final
residual's cycle-averaged trace against the position angle (axis reversals
marked); the mean residual against the time since each axis reversal; the
excess of each harmonic over the noise against frequency, with the transient
windows' periodogram; and the mean residual against the time into the
transient windows after the start ramps and after the ends of motion. Where a
gap left lies is marked in red: angle, time, band. The headline is the
figure's title, so the figure says whether a gap is left.
"""

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from imu_square.discrepancy.transients import GUARD_S
from imu_square.discrepancy.views import VIEWS


def _gaps_panel(ax, result):
    labels = ["base"] + [
        s.effect if len(s.one_of) == 1 else f"{s.effect} (one of {len(s.one_of)})"
        for s in result.steps
    ]
    rows = [result.base_gap] + [s.gap_after for s in result.steps]
    x = range(len(labels))
    for view in VIEWS:
        y = [r[view].gap if math.isfinite(r[view].gap) else math.nan for r in rows]
        ax.plot(x, y, marker="o", label=view)
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.axhline(1.2, color="0.6", lw=0.8, ls=":")
    ax.set_yscale("log")
    ax.set_xticks(list(x), labels, rotation=20, ha="right")
    ax.set_ylabel("gap / noise floor")
    ax.set_title("gap per view, step by step", fontsize="medium")
    ax.legend(fontsize="x-small", ncols=2)


def _residual_panels(axes, curves, left):
    ax = axes[0]
    for (direction, axis), y in curves.trace.items():
        ax.plot(curves.angle_deg, y * 1e3, lw=0.9, label=f"{direction.upper()} {axis}")
    for deg, axis in ((0, "x"), (90, "y"), (180, "x"), (270, "y")):
        ax.axvline(deg, color="0.7", lw=0.6)
        ax.text(deg, 1.0, f" {axis} rev.", transform=ax.get_xaxis_transform(), fontsize="x-small")
    for g in left:
        pos = g.details.get("position")
        if pos:
            ax.axvline(pos["angle_deg"], color="r", lw=0.8, ls="--")
    ax.set_xlabel("position angle [deg]")
    ax.set_ylabel("residual [mm/s²]")
    ax.set_title("final residual, cycle-averaged", fontsize="medium")
    ax.legend(fontsize="x-small")
    ax = axes[1]
    for (axis, after), y in curves.reversal.items():
        ax.plot(curves.reversal_ms, y * 1e3, lw=0.9, label=f"{axis} reversal to {after}{axis}")
    ax.axvline(0.0, color="0.7", lw=0.6)
    ax.set_xlabel("time since the axis reversal [ms]")
    ax.set_ylabel("mean residual [mm/s²]")
    ax.set_title("around the reversals", fontsize="medium")
    ax.legend(fontsize="x-small")
    ax = axes[2]
    f = curves.frequency_hz
    null = np.where(np.arange(f.size) == 0, 1.0, 2.0) * curves.n_blocks
    for a, axis in enumerate(("x", "y")):
        y = np.maximum(curves.excess[a, 1:] / null[1:], 1e-2)
        ax.semilogy(f[1:], y, lw=0.7, alpha=0.6, label=f"circle harmonics, {axis}")
    ft = curves.transient_frequency_hz
    if np.any(curves.transient_power > 0):
        ax.semilogy(
            ft[1:],
            np.maximum(curves.transient_power[1:], 1e-2),
            color="k",
            lw=1.2,
            label="transient windows, x and y",
        )
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    # the log axis starts at the lowest frequency drawn; a band from 0 Hz is shaded from it
    lowest = min(f[1] if f.size > 1 else 1.0, ft[1] if ft.size > 1 else 1.0)
    for g in left:
        band = g.details.get("band")
        if band:
            lo, hi = band["band_hz"]
            ax.axvspan(max(lo, lowest), max(hi, lowest), color="r", alpha=0.1)
    ax.set_xscale("log")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("power / noise")
    ax.set_title("residual by frequency (shaded: band of a gap left)", fontsize="medium")
    ax.legend(fontsize="x-small")
    gap = next((g for g in left if g.view == "transients"), None)
    for ax, window, name in (
        (axes[3], "start", "after the start ramp"),
        (axes[4], "end", "after the end of motion"),
    ):
        _transient_panel(ax, curves, window, name, gap)


def _transient_panel(ax, curves, window, name, gap):
    """Mean residual against the time into the windows ``window`` (marked: a gap left there)."""
    for direction, axis in (("ccw", "x"), ("ccw", "y"), ("cw", "x"), ("cw", "y")):
        y = curves.transient.get((window, direction, axis))
        if y is not None and not np.all(np.isnan(y)):
            ax.plot(curves.transient_ms, y * 1e3, lw=0.9, label=f"{direction.upper()} {axis}")
    ax.axhline(0.0, color="0.7", lw=0.6)
    loc = gap.details.get("transient") if gap else None
    if loc and loc["window"] == name:
        ax.axvline(loc["time_into_window_ms"], color="r", lw=0.8, ls="--")
    band = gap.details.get("band") if gap else None
    if band:
        ax.text(
            0.98,
            0.03,
            f"gap left: the windows' power peaks at {band['strongest_hz']:.3g} Hz",
            transform=ax.transAxes,
            ha="right",
            color="r",
            fontsize="small",
        )
    ax.set_xlabel(f"time into the window {name} [ms]")
    ax.set_ylabel("mean residual [mm/s²]")
    ax.set_title(
        f"transients {name}\n(each window opens {GUARD_S * 1e3:.0f} ms or more after the "
        "recording's ramp)",
        fontsize="medium",
    )
    if ax.lines[1:]:
        ax.legend(fontsize="x-small", ncols=2)


def plot_gaps(result, path, title=""):
    """Write a PNG: each view's gap step by step, and where the residual left lies.

    Parameters
    ----------
    result : DiscrepancyResult
        The workflow's result.
    path : str or Path
        Output PNG.
    title : str
        Figure title, e.g. the recording's name.
    """
    fig, axes = plt.subplots(2, 3, figsize=(16.0, 9.0), layout="constrained")
    _gaps_panel(axes[0, 0], result)
    rest = [axes[0, 1], axes[0, 2], axes[1, 0], axes[1, 1], axes[1, 2]]
    if result.curves is not None:
        _residual_panels(rest, result.curves, result.gap_left)
    else:
        for ax in rest:
            ax.set_axis_off()
    head = result.headline()
    fig.suptitle(f"{title or 'model discrepancy'}\n{head}", fontsize="medium")
    fig.savefig(path, dpi=100)
    plt.close(fig)
