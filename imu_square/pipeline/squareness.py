"""From a recording to the squareness: the whole pipeline, one call.

:func:`analyze` runs filter -> segment -> flip/average -> fit and returns a
frozen :class:`RunResult`:

- ``theta_y - theta_x`` of the flipped and averaged CCW and CW traces (paper,
  Eq. 4 [1]_), averaged over the two directions; this cancels the servo
  mismatch, which is half their difference (``docs/model.md``);
- divided by ``cos(2 eps_c)``: the phase of the acceleration along a direction
  ``gamma`` is ``gamma - alpha cos^2(gamma)`` (and ``omega (tau_x cos^2 gamma +
  tau_y sin^2 gamma)`` for the lags), so sensor axes rotated by ``eps_c`` see
  ``theta_y - theta_x = beta + (alpha +- m) cos(2 eps_c)``. Dividing makes the
  machine's squareness and the servo mismatch exact and rescales the constant
  sensor term to ``beta / cos(2 eps_c)`` (a 0.27 % change at the paper's
  2.1 degrees, removed anyway by referencing); ``theta_x_rad`` and
  ``theta_y_rad`` stay as fitted;
- ``eps_c``, the sensor's rotation about Z, as the mean of
  ``(theta_x + theta_y) / 2`` over both directions with phi anchored at each
  block's motion midpoint (the paper's stage 2 is degenerate, see
  :mod:`imu_square.pipeline.fit`; its value is kept as ``eps_c_stage2_rad``);
- uncertainties: type A from the per-cycle scatter (CCW cycle k paired with
  CW cycle k), a bootstrap over cycles, and the Cramér-Rao bound;
- quality flags, and refusal (:class:`AnalysisError`) when the data cannot give
  a trustworthy number.

References
----------
.. [1] K. Szipka, A. Archenti, G. W. Vogl, M. A. Donmez, "Identification of
   machine tool squareness errors via inertial measurements", CIRP Annals 68
   (2019).
"""

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from imu_square.errors import AnalysisError
from imu_square.log import logger
from imu_square.pipeline import quality as q
from imu_square.pipeline.align import cycle_traces
from imu_square.pipeline.filter import lowpass, passband_gain, settling_time_s
from imu_square.pipeline.fit import fit_circle, fit_cross_terms, robust_norm
from imu_square.pipeline.segment import segment
from imu_square.pipeline.uncertainty import (
    bootstrap_means,
    cramer_rao,
    residual_noise_density,
    type_a,
)

# Flag when the type A uncertainty exceeds the white-noise bound by this factor.
_EXCESS_NOISE_FLAG = 3.0
# Below half the Cramer-Rao bound the cycle scatter has come out low by chance.
_SCANT_SCATTER_FLAG = 0.5
# Flag when more than this fraction of the averaged trace gets zero robust weight.
_OUTLIER_FLAG = 0.05
# Refuse a sensor turned within 15 deg of 45 deg to the axes (|cos 2 eps_c| < 0.5).
MIN_COS_2EPS = 0.5
# Flag when the circle period departs from the program's by more than this.
_PERIOD_FLAG = 0.005


@dataclass(frozen=True)
class AnalysisOptions:
    """Choices of the analysis; the defaults are the paper's.

    Attributes
    ----------
    cutoff_hz : float
        Low-pass cutoff of the designed Butterworth filter. [Hz]
    order : int
        Order of the designed filter (applied forward and backward).
    norm : {"tukey", "huber", "ols"}
        Robust norm of the sine fits; the paper's bisquare is ``"tukey"``.
    tuning : float or None
        Tuning constant of the norm, in robust-scale units; norm default if None.
    maxiter : int
        IRLS iteration limit.
    freeze_scale_after : int
        Iterations after which a fit that has not converged keeps its scale
        fixed: statsmodels' algorithm until then, and a guaranteed descent after
        (the median-based scale can otherwise make single noisy cycles cycle).
    conv : {"coefs", "dev"}
        IRLS convergence criterion. ``statsmodels``' default "dev" compares
        ``rho(resid / s2)`` with ``s2`` the residual *variance*, which for
        residuals of 1e-5 m/s^2 saturates ``rho`` and may never settle; the
        pipeline stops on the change of every coefficient instead.
    tol : float
        IRLS convergence tolerance; for "coefs" in m/s^2 (1e-10 m/s^2 on an
        amplitude of 0.1 m/s^2 is 1e-9 rad of phase).
    grid_points : int
        Points of the common phi grid per cycle.
    bootstrap_n : int
        Bootstrap resamples over cycles (0 to skip).
    seed : int
        Seed of the bootstrap.
    min_cycles : int
        Least usable cycles per direction.
    """

    cutoff_hz: float = 4.0
    order: int = 1
    norm: str = "tukey"
    tuning: float | None = None
    maxiter: int = 200
    freeze_scale_after: int = 50
    conv: str = "coefs"
    tol: float = 1e-10
    grid_points: int = 512
    bootstrap_n: int = 200
    seed: int = 0
    min_cycles: int = 3


@dataclass(frozen=True)
class DirectionResult:
    """Fit of one direction's flipped, averaged cycles.

    Attributes
    ----------
    theta_x_rad, theta_y_rad : float
        Phases in the position-angle domain. [rad]
    squareness_rad : float
        ``(theta_y - theta_x) / cos(2 eps_c)`` of this direction (squareness +- servo
        mismatch). [rad]
    amp_x_m_s2, amp_y_m_s2 : float
        Amplitudes, corrected for the low-pass's gain. [m/s^2]
    cycles : int
        Cycles averaged.
    outlier_fraction : float
        Fraction of the averaged trace with zero robust weight (both axes).
    """

    theta_x_rad: float
    theta_y_rad: float
    squareness_rad: float
    amp_x_m_s2: float
    amp_y_m_s2: float
    cycles: int
    outlier_fraction: float


@dataclass(frozen=True)
class RunResult:
    """Squareness of one recording, with its uncertainty and quality.

    Attributes
    ----------
    squareness_rad : float
        ``(theta_y - theta_x) / cos(2 eps_c)``, mean of CCW and flipped CW:
        E_C0X + E_SC0X / cos(2 eps_c) (module docstring). [rad]
    u_squareness_rad : float
        Type A standard uncertainty from the per-cycle scatter. [rad]
    u_squareness_bootstrap_rad : float
        Standard deviation of the bootstrap over cycles (NaN if skipped). [rad]
    crb_rad : float
        Cramér-Rao bound for white noise of density :attr:`noise_density_m_s2_rthz`. [rad]
    noise_density_m_s2_rthz : float
        Noise density used for the bound: the sensor's stated one if known,
        else estimated from the data. [m/s^2/sqrt(Hz)]
    noise_density_source : str
        ``"sensor"`` or ``"residual"``.
    theta_x_rad, theta_y_rad : float
        Phases, mean of the directions. [rad]
    eps_c_rad, u_eps_c_rad : float
        Sensor rotation about Z and its standard uncertainty. [rad]
    eps_c_stage2_rad : float
        The paper's stage-2 value (degenerate: ~0 whatever the rotation). [rad]
    amp_x_m_s2, amp_y_m_s2 : float
        Amplitudes, mean of the directions, corrected for the low-pass's gain. [m/s^2]
    servo_mismatch_rad, u_servo_mismatch_rad : float
        Half the CCW minus CW difference of ``theta_y - theta_x``. [rad]
    ccw, cw : DirectionResult
        Per-direction fits.
    per_cycle : dict of str to ndarray
        ``pair``, ``squareness_rad``, ``servo_mismatch_rad``, ``eps_c_rad``,
        ``ccw_squareness_rad``, ``cw_squareness_rad`` for each CCW/CW pair.
    cycles_used : dict
        ``{"ccw": n, "cw": n}``.
    omega_rad_s : float
        Measured angular speed. [rad/s]
    period_s : float
        Measured period. [s]
    quality : dict
        Flags and the human-readable ``warnings`` list.
    traces : dict of str to ndarray
        ``phi_grid`` and the low-passed mean traces ``ccw_x``, ``ccw_y``, ``cw_x``,
        ``cw_y`` with their fit coefficients ``*_params`` (``[c, cos, sin]``), and
        the overall means ``mean_x``, ``mean_y``. [m/s^2]
    options : AnalysisOptions
        The options used.
    source : str
        Where the recording came from.
    """

    squareness_rad: float
    u_squareness_rad: float
    u_squareness_bootstrap_rad: float
    crb_rad: float
    noise_density_m_s2_rthz: float
    noise_density_source: str
    theta_x_rad: float
    theta_y_rad: float
    eps_c_rad: float
    u_eps_c_rad: float
    eps_c_stage2_rad: float
    amp_x_m_s2: float
    amp_y_m_s2: float
    servo_mismatch_rad: float
    u_servo_mismatch_rad: float
    ccw: DirectionResult
    cw: DirectionResult
    per_cycle: dict
    cycles_used: dict
    omega_rad_s: float
    period_s: float
    quality: dict
    traces: dict = field(repr=False)
    options: AnalysisOptions = field(default_factory=AnalysisOptions)
    source: str = ""

    def to_json_dict(self):
        """The result as JSON-ready scalars (µrad for squareness, degrees for eps_c)."""
        return {
            "source": self.source,
            "squareness_urad": self.squareness_rad * 1e6,
            "u_squareness_urad": self.u_squareness_rad * 1e6,
            "u_squareness_bootstrap_urad": _finite(self.u_squareness_bootstrap_rad * 1e6),
            "crb_urad": self.crb_rad * 1e6,
            "noise_density_m_s2_rthz": self.noise_density_m_s2_rthz,
            "noise_density_source": self.noise_density_source,
            "theta_x_rad": self.theta_x_rad,
            "theta_y_rad": self.theta_y_rad,
            "eps_c_deg": math.degrees(self.eps_c_rad),
            "u_eps_c_deg": math.degrees(self.u_eps_c_rad),
            "eps_c_stage2_deg": math.degrees(self.eps_c_stage2_rad),
            "amp_x_m_s2": self.amp_x_m_s2,
            "amp_y_m_s2": self.amp_y_m_s2,
            "servo_mismatch_urad": self.servo_mismatch_rad * 1e6,
            "u_servo_mismatch_urad": self.u_servo_mismatch_rad * 1e6,
            "ccw": asdict(self.ccw),
            "cw": asdict(self.cw),
            "per_cycle_squareness_urad": [v * 1e6 for v in self.per_cycle["squareness_rad"]],
            "cycles_used": dict(self.cycles_used),
            "omega_rad_s": self.omega_rad_s,
            "period_s": self.period_s,
            "quality": _jsonable(self.quality),
            "options": asdict(self.options),
        }


def _finite(x):
    return x if math.isfinite(x) else None


def _jsonable(obj):
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def _wrap(angle):
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def _circmean(a, b):
    return float(np.angle(np.exp(1j * a) + np.exp(1j * b)))


def analyze(recording, options=None, program=None):
    """Squareness, sensor rotation and servo mismatch of one recording.

    Parameters
    ----------
    recording : Recording
        The test as recorded; all its blocks (every run) are analysed together.
    options : AnalysisOptions, optional
        The paper's choices if None.
    program : TestProgram, optional
        Overrides ``recording.program``.

    Returns
    -------
    RunResult

    Raises
    ------
    AnalysisError
        No program; no circle matching the program; a block turning the wrong
        way; an amplitude or a period far from the program's; too few usable
        cycles.
    """
    opts = options or AnalysisOptions()
    prog = program or recording.program
    source = str(recording.metadata.get("source", ""))
    if prog is None:
        raise AnalysisError(
            f"recording {source or '<recording>'!s} has no test program: give one (--program)"
        )
    fs = recording.sample_rate_hz
    if recording.n_samples < 10 or recording.duration_s < prog.period_s:
        raise AnalysisError(
            f"recording {source!s} lasts {recording.duration_s:.1f} s, shorter than one "
            f"circle ({prog.period_s:.2f} s): no motion to analyse"
        )
    t_s = recording.time_s
    raw = recording.accel.astype(np.float64)
    gaps = recording.gaps()
    breaks = [i for i, _ in gaps]
    xy = lowpass(raw[:, :2], opts.cutoff_hz, opts.order, fs, breaks)
    events = [
        ((e.time_ns - int(recording.time_ns[0])) * 1e-9, e.kind, e.block)
        for e in recording.events
        if e.kind in ("block_start", "block_end")
    ]
    margin = settling_time_s(opts.cutoff_hz, opts.order)
    seg = segment(t_s, xy, prog, events, guard_s=margin)
    q.check_period(seg.period_disagreement, seg.period_s, prog)

    clipped = q.clipped_times(t_s, raw, recording.sensor.range_m_s2)
    gap_spans = [(t_s[i - 1], t_s[i]) for i in breaks]
    bad = np.array([*gap_spans, *((t, t) for t in clipped)]).reshape(-1, 2)
    cyc = cycle_traces(t_s, xy, seg, bad, margin, opts.grid_points)
    q.check_cycles(cyc.ccw.n, cyc.cw.n, prog, opts.min_cycles, cyc.dropped)

    norm = robust_norm(opts.norm, opts.tuning)
    irls = {
        "maxiter": opts.maxiter,
        "tol": opts.tol,
        "conv": opts.conv,
        "freeze_scale_after": opts.freeze_scale_after,
    }
    phi = cyc.phi_grid
    mean_x = np.stack([cyc.ccw.x.mean(axis=0), cyc.cw.x.mean(axis=0)])
    mean_y = np.stack([cyc.ccw.y.mean(axis=0), cyc.cw.y.mean(axis=0)])
    main = fit_circle(phi, mean_x, mean_y, norm, **irls)
    # Amplitudes corrected for the low-pass's gain |H|^2 at the circle frequency.
    gain = passband_gain(seg.omega_rad_s / (2 * np.pi), opts.cutoff_hz, opts.order, fs)
    amp_x, amp_y = main.amp_x / gain, main.amp_y / gain
    amp = float(np.mean([amp_x, amp_y]))
    ratio = q.check_amplitude(amp, prog)

    eps_c = _circmean(main.mean_phase[0], main.mean_phase[1])
    # Seen through sensor axes rotated by eps_c, the machine's terms shrink:
    # theta_y - theta_x = beta + (alpha + m) cos(2 eps_c) (module docstring).
    if abs(math.cos(2 * eps_c)) < MIN_COS_2EPS:
        raise AnalysisError(
            f"the sensor is turned {math.degrees(eps_c):.1f} deg from the machine's axes: near "
            f"45 deg the machine's squareness is seen scaled by cos(2 eps_c) = "
            f"{math.cos(2 * eps_c):.2f} and the sensor's own terms swamp it; mount the sensor "
            f"within 30 deg of square to the X and Y axes"
        )
    rotation = 1.0 / math.cos(2 * eps_c)
    sq_dir = _wrap(main.squareness) * rotation
    squareness = 0.5 * float(sq_dir[0] + sq_dir[1])
    servo = 0.5 * float(sq_dir[0] - sq_dir[1])
    stage2 = fit_cross_terms(phi, main, norm, **irls)

    # Per-cycle fits, and the bootstrap over cycles, in one batch.
    rng = np.random.default_rng(opts.seed)
    nb = opts.bootstrap_n
    rows_x = [cyc.ccw.x, cyc.cw.x]
    rows_y = [cyc.ccw.y, cyc.cw.y]
    if nb > 0:
        rows_x += [bootstrap_means(cyc.ccw.x, nb, rng), bootstrap_means(cyc.cw.x, nb, rng)]
        rows_y += [bootstrap_means(cyc.ccw.y, nb, rng), bootstrap_means(cyc.cw.y, nb, rng)]
    # Start every row from its direction's fit of the mean: same fixed point, fewer steps.
    n_rows = [cyc.ccw.n, cyc.cw.n] + ([nb, nb] if nb > 0 else [])
    which = np.repeat([0, 1, 0, 1][: len(n_rows)], n_rows)
    batch = fit_circle(
        phi,
        np.concatenate(rows_x),
        np.concatenate(rows_y),
        norm,
        start_params=(main.x.params[which], main.y.params[which]),
        **irls,
    )
    n1, n2 = cyc.ccw.n, cyc.cw.n
    sq_all = _wrap(batch.squareness) * rotation
    mp_all = batch.mean_phase
    sq_ccw, sq_cw = sq_all[:n1], sq_all[n1 : n1 + n2]
    if nb > 0:
        b = n1 + n2
        boot = 0.5 * (sq_all[b : b + nb] + sq_all[b + nb : b + 2 * nb])
        u_boot = float(np.std(boot, ddof=1))
    else:
        u_boot = float("nan")
    common, i1, i2 = np.intersect1d(cyc.ccw.pair, cyc.cw.pair, return_indices=True)
    per_sq = 0.5 * (sq_ccw[i1] + sq_cw[i2])
    per_servo = 0.5 * (sq_ccw[i1] - sq_cw[i2])
    per_eps = 0.5 * (mp_all[:n1][i1] + mp_all[n1 : n1 + n2][i2])
    u_sq = type_a(per_sq)
    if common.size < 2:
        raise AnalysisError(
            f"too few CCW/CW cycle pairs for an uncertainty: {common.size} "
            f"(cycles used: {n1} CCW, {n2} CW)"
        )

    # eps_c: cycle scatter plus the timing uncertainty of the block anchors.
    u_anchor = {}
    for d in ("ccw", "cw"):
        u = [b.u_t_mid_s for b in seg.blocks if b.direction == d]
        u_anchor[d] = seg.omega_rad_s * float(np.sqrt(np.sum(np.square(u)))) / len(u)
    u_eps = float(np.hypot(type_a(per_eps), 0.5 * np.hypot(u_anchor["ccw"], u_anchor["cw"])))

    # Noise floor.
    period = seg.period_s
    analysed = (n1 + n2) * period
    stated = recording.sensor.noise_density_m_s2_rthz
    first = seg.blocks[0]  # its steady middle, away from the ramps' transients
    sel = np.abs(t_s - first.t_mid_s) < 0.45 * prog.cycles_per_direction * period
    d_resid = residual_noise_density(raw[sel, :2], opts.cutoff_hz, opts.order, fs)
    if np.isfinite(stated) and stated > 0:
        density, density_source = float(stated), "sensor"
    else:
        density, density_source = d_resid, "residual"
    crb = cramer_rao(density, amp, analysed) * abs(rotation)

    outliers = [
        float(np.mean(np.concatenate([main.x.weights[i], main.y.weights[i]]) == 0.0))
        for i in range(2)
    ]
    directions = [
        DirectionResult(
            theta_x_rad=float(main.theta_x[i]),
            theta_y_rad=float(main.theta_y[i]),
            squareness_rad=float(sq_dir[i]),
            amp_x_m_s2=float(amp_x[i]),
            amp_y_m_s2=float(amp_y[i]),
            cycles=int(n),
            outlier_fraction=outliers[i],
        )
        for i, n in enumerate((n1, n2))
    ]
    quality = _quality(
        recording, seg, cyc, clipped, ratio, outliers, u_sq, crb, d_resid, density_source
    )
    for w in quality["warnings"]:
        logger.debug("quality: %s", w)
    traces = {
        "phi_grid": phi,
        "ccw_x": mean_x[0],
        "ccw_y": mean_y[0],
        "cw_x": mean_x[1],
        "cw_y": mean_y[1],
        "mean_x": mean_x.mean(axis=0),
        "mean_y": mean_y.mean(axis=0),
        "ccw_x_params": main.x.params[0],
        "ccw_y_params": main.y.params[0],
        "cw_x_params": main.x.params[1],
        "cw_y_params": main.y.params[1],
    }
    return RunResult(
        squareness_rad=squareness,
        u_squareness_rad=u_sq,
        u_squareness_bootstrap_rad=u_boot,
        crb_rad=crb,
        noise_density_m_s2_rthz=density,
        noise_density_source=density_source,
        theta_x_rad=_circmean(main.theta_x[0], main.theta_x[1]),
        theta_y_rad=_circmean(main.theta_y[0], main.theta_y[1]),
        eps_c_rad=eps_c,
        u_eps_c_rad=u_eps,
        eps_c_stage2_rad=float(np.mean(stage2.eps_c)),
        amp_x_m_s2=float(np.mean(amp_x)),
        amp_y_m_s2=float(np.mean(amp_y)),
        servo_mismatch_rad=servo,
        u_servo_mismatch_rad=type_a(per_servo),
        ccw=directions[0],
        cw=directions[1],
        per_cycle={
            "pair": common,
            "squareness_rad": per_sq,
            "servo_mismatch_rad": per_servo,
            "eps_c_rad": per_eps,
            "ccw_squareness_rad": sq_ccw[i1],
            "cw_squareness_rad": sq_cw[i2],
        },
        cycles_used={"ccw": int(n1), "cw": int(n2)},
        omega_rad_s=seg.omega_rad_s,
        period_s=period,
        quality=quality,
        traces=traces,
        options=opts,
        source=source,
    )


def _quality(recording, seg, cyc, clipped, ratio, outliers, u_sq, crb, d_resid, source):
    warnings = []
    n_gaps = len(recording.gaps())
    if clipped.size:
        warnings.append(f"{clipped.size} samples at the sensor's full scale (clipping)")
    if n_gaps:
        warnings.append(f"{n_gaps} gap(s), {recording.lost_samples} samples lost")
    if cyc.dropped:
        reasons = sorted({d["reason"] for d in cyc.dropped})
        warnings.append(f"{len(cyc.dropped)} cycle(s) dropped: {', '.join(reasons)}")
    if abs(ratio - 1) > q.AMPLITUDE_FLAG:
        warnings.append(
            f"amplitude is {ratio:.3f} x v^2/r: feed override, radius or sensor gain differ "
            f"from the program"
        )
    if abs(seg.period_disagreement) > _PERIOD_FLAG:
        warnings.append(
            f"circle period differs from the program by {seg.period_disagreement:+.2%}: "
            f"feed override or sample clock error"
        )
    if max(outliers) > _OUTLIER_FLAG:
        warnings.append(
            f"{max(outliers):.1%} of the averaged trace rejected by the robust fit "
            f"(reversal spikes or vibration)"
        )
    if u_sq < _SCANT_SCATTER_FLAG * crb:
        pairs = min(cyc.ccw.n, cyc.cw.n)
        warnings.append(
            f"the type A uncertainty is only {u_sq / crb:.2f} x the white-noise bound: from "
            f"{pairs} cycle pairs the scatter is itself uncertain, and no estimate beats the "
            f"bound; quote at least {crb * 1e6:.1f} um/m"
        )
    if u_sq > _EXCESS_NOISE_FLAG * crb:
        warnings.append(
            f"cycle-to-cycle scatter is {u_sq / crb:.1f} x the white-noise bound ({source} "
            f"noise density): vibration, 1/f noise or drift"
        )
    return {
        "clipped_samples": int(clipped.size),
        "gaps": n_gaps,
        "lost_samples": int(recording.lost_samples),
        "cycles_dropped": [dict(d) for d in cyc.dropped],
        "amplitude_ratio": float(ratio),
        "period_disagreement": float(seg.period_disagreement),
        "outlier_fraction": float(max(outliers)),
        "noise_density_residual_m_s2_rthz": float(d_resid),
        "warnings": warnings,
    }
