"""The gap of every view, step by step: each view shrinking as effects are added."""

import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from imu_square.discrepancy.views import VIEWS


def plot_gaps(result, path, title=""):
    """Write a PNG: one line per view, its gap (1.0 = noise floor) after each step.

    Parameters
    ----------
    result : DiscrepancyResult
        The workflow's result.
    path : str or Path
        Output PNG.
    title : str
        Figure title, e.g. the recording's name.
    """
    labels = ["base"] + [
        s.effect if len(s.one_of) == 1 else f"{s.effect} (one of {len(s.one_of)})"
        for s in result.steps
    ]
    rows = [result.base_gap] + [s.gap_after for s in result.steps]
    fig, ax = plt.subplots(figsize=(max(6.0, 1.6 * len(labels) + 3), 4.5), layout="constrained")
    x = range(len(labels))
    for view in VIEWS:
        y = [r[view].gap if math.isfinite(r[view].gap) else math.nan for r in rows]
        ax.plot(x, y, marker="o", label=view)
    ax.axhline(1.0, color="k", lw=0.8, ls="--")
    ax.axhline(1.2, color="0.6", lw=0.8, ls=":")
    ax.set_yscale("log")
    ax.set_xticks(list(x), labels, rotation=20, ha="right")
    ax.set_ylabel("gap / noise floor")
    ax.set_title(title or "model discrepancy")
    ax.legend(fontsize="small", ncols=2)
    fig.savefig(path, dpi=110)
    plt.close(fig)
