"""The gap of every view, step by step, and where the gap left lies.

Four panels: each view's gap after each step (1.0 = noise floor); the final
residual's cycle-averaged trace against the position angle (axis reversals
marked); the mean residual against the time since each axis reversal; and the
excess of each harmonic over the noise against frequency. The headline is the
figure's title, so the figure says whether a gap is left.
"""

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

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
        ax.semilogy(f[1:], np.maximum(curves.excess[a, 1:] / null[1:], 1e-2), lw=0.9, label=axis)
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    for g in left:
        band = g.details.get("band")
        if band:
            ax.axvspan(*band["band_hz"], color="r", alpha=0.1)
    ax.set_xscale("log")
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("power / noise")
    ax.set_title("residual by harmonic (shaded: band of a gap left)", fontsize="medium")
    ax.legend(fontsize="x-small")


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
    fig, axes = plt.subplots(2, 2, figsize=(12.0, 8.5), layout="constrained")
    _gaps_panel(axes[0, 0], result)
    if result.curves is not None:
        _residual_panels([axes[0, 1], axes[1, 0], axes[1, 1]], result.curves, result.gap_left)
    else:
        for ax in (axes[0, 1], axes[1, 0], axes[1, 1]):
            ax.set_axis_off()
    head = result.headline()
    fig.suptitle(f"{title or 'model discrepancy'}\n{head}", fontsize="medium")
    fig.savefig(path, dpi=100)
    plt.close(fig)
