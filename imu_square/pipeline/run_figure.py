"""Figures: flipped and averaged traces with their fits (paper, Fig. 5 [1]_),
per-cycle values, and the convergence over runs (Fig. 6).

References
----------
.. [1] K. Szipka, A. Archenti, G. W. Vogl, M. A. Donmez, CIRP Annals 68 (2019).
"""

import numpy as np

from imu_square.pipeline.sine_fit import sine_design
from imu_square.units import MM, URAD

_COLOURS = {"ccw": "tab:blue", "cw": "tab:orange", "mean": "black"}


def plot_results(results, path, convergence=None, title=""):
    """Write a PNG summarising the last result, and the convergence over runs.

    Parameters
    ----------
    results : sequence of RunResult
        One result per run; the traces shown are those of the last.
    path : str or Path
        PNG file to write.
    convergence : Convergence, optional
        Running mean and uncertainty over the runs; drawn when it has more
        than one run.
    title : str
        What the figure shows, e.g. the recording's name; "run" if empty.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    res = results[-1]
    tr = res.traces
    many = convergence is not None and convergence.n_runs.size > 1
    rows = 4 if many else 3
    fig, axes = plt.subplots(rows, 2, figsize=(11, 3.0 * rows), constrained_layout=True)
    phi = tr["phi_grid"]
    deg = np.degrees(phi)
    design = sine_design(phi)
    for col, axis in enumerate(("x", "y")):
        top, bottom = axes[0, col], axes[1, col]
        for d in ("ccw", "cw"):
            data = tr[f"{d}_{axis}"]
            fit = design @ tr[f"{d}_{axis}_params"]
            label = "CCW" if d == "ccw" else "CW flipped"
            top.plot(deg, data, color=_COLOURS[d], lw=2.5, alpha=0.45, label=f"{label} mean")
            top.plot(deg, fit, color=_COLOURS[d], lw=1, ls="--", label=f"{label} fit")
            bottom.plot(deg, (data - fit) / MM, color=_COLOURS[d], lw=0.8, label=label)
        theta = res.theta_x_rad if axis == "x" else res.theta_y_rad
        top.set_title(
            f"a_{axis}: flipped, averaged, fitted (theta_{axis} = {theta / URAD:.1f} µrad)"
        )
        top.set_ylabel(f"a_{axis} [m/s²]")
        bottom.set_ylabel("residual [mm/s²]")
        bottom.set_title(f"a_{axis}: residuals of the bisquare fit")
        for ax in (top, bottom):
            ax.set_xlim(0, 360)
            ax.set_xticks(range(0, 361, 45))
            ax.grid(alpha=0.3)
        bottom.set_xlabel("commanded position angle phi [deg]")
        top.legend(fontsize=7, loc="best")
    pc = res.per_cycle
    k = np.arange(1, pc["pair"].size + 1)
    ax = axes[2, 0]
    ax.plot(k, pc["squareness_ccw_rad"] / URAD, "o", color=_COLOURS["ccw"], ms=4, label="CCW")
    ax.plot(k, pc["squareness_cw_rad"] / URAD, "s", color=_COLOURS["cw"], ms=4, label="CW flipped")
    ax.plot(k, pc["squareness_rad"] / URAD, "D", color="black", ms=4, label="pair mean")
    s, u = res.squareness_rad / URAD, res.u_squareness_rad / URAD
    ax.axhline(s, color="black", lw=1)
    ax.axhspan(s - u, s + u, color="grey", alpha=0.25, label=f"{s:.1f} ± {u:.1f} µm/m (k=1)")
    ax.set_xlabel("cycle pair")
    ax.set_ylabel("theta_y - theta_x [µm/m]")
    ax.set_title("per-cycle squareness (CCW and CW differ by twice the servo mismatch)")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    ax = axes[2, 1]
    ax.plot(k, np.degrees(pc["eps_c_rad"]), "o", color="tab:green", ms=4)
    e, ue = np.degrees(res.eps_c_rad), np.degrees(res.u_eps_c_rad)
    ax.axhline(e, color="black", lw=1)
    ax.axhspan(e - ue, e + ue, color="grey", alpha=0.25, label=f"eps_c = {e:.3f} ± {ue:.3f}°")
    ax.set_xlabel("cycle pair")
    ax.set_ylabel("eps_c [deg]")
    ax.set_title("per-cycle sensor rotation about Z")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    if many:
        n = convergence.n_runs
        ax = axes[3, 0]
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.plot(n, convergence.mean_rad / URAD, "o-", ms=3)
        ax.set_xlabel("number of runs")
        ax.set_ylabel("mean squareness [µm/m]")
        ax.set_title("convergence of the mean")
        ax.grid(alpha=0.3)
        ax = axes[3, 1]
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.plot(n, convergence.u_mean_rad / URAD, "o-", ms=3)
        ax.set_xlabel("number of runs")
        ax.set_ylabel("type A u of the mean [µm/m]")
        ax.set_title("type A standard uncertainty")
        ax.grid(alpha=0.3)
    fig.suptitle(
        f"{title or 'run'}: squareness {s:.1f} ± {u:.1f} µm/m, "
        f"servo mismatch {res.servo_mismatch_rad / URAD:.0f} µm/m, "
        f"cycles {res.cycles_used['ccw']} CCW + {res.cycles_used['cw']} CW",
        wrap=True,  # a recording's long path stays inside the figure
    )
    fig.savefig(path, dpi=110)
    plt.close(fig)
