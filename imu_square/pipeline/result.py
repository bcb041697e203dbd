"""What the analysis of one recording returns: :class:`RunResult`.

The names are those of the table in ``docs/model.md`` ("Quantity names");
``squareness_*`` is always ``theta_y - theta_x`` as the paper's Eq. 4 defines
it (machine plus sensor), never divided by ``cos(2 eps_c)``.
"""

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from imu_square.json_values import json_safe
from imu_square.pipeline.options import AnalysisOptions
from imu_square.units import SQUARENESS_UNIT, URAD


@dataclass(frozen=True)
class DirectionResult:
    """Fit of one direction's flipped, averaged cycles.

    Attributes
    ----------
    theta_x_rad, theta_y_rad : float
        Phases in the position-angle domain. [rad]
    squareness_rad : float
        ``theta_y - theta_x`` of this direction: the squareness plus (CCW) or
        minus (CW) the servo mismatch scaled by ``cos(2 eps_c)``. [rad]
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
        ``theta_y - theta_x``, mean of CCW and flipped CW: E_C0X + E_SC0X
        (paper, Eq. 4). Exactly ``beta + alpha cos(2 eps_c)`` to first order in
        the errors (``docs/model.md``). [rad]
    u_squareness_rad : float
        Type A standard uncertainty from the per-cycle-pair scatter. [rad]
    u_squareness_dof : int
        Degrees of freedom of :attr:`u_squareness_rad` (cycle pairs minus one).
    u_squareness_bootstrap_rad : float
        Standard deviation of the bootstrap over cycles (NaN if skipped). [rad]
    crb_rad : float
        Cramér-Rao bound for the noise at the circle frequency,
        :attr:`noise_density_circle_m_s2_rthz` (:mod:`imu_square.pipeline.noise_floor`). [rad]
    noise_density_m_s2_rthz : float
        White-noise density used for the bound: the sensor's stated one if
        known, else estimated from what the fitted model leaves. [m/s^2/sqrt(Hz)]
    noise_density_source : str
        ``"sensor"`` or ``"residual"``.
    theta_x_rad, theta_y_rad : float
        Phases, circular mean of the directions. [rad]
    eps_c_rad, u_eps_c_rad : float
        Sensor rotation about Z and its standard uncertainty. [rad]
    eps_c_stage2_rad : float
        The paper's stage-2 value (degenerate: ~0 whatever the rotation). [rad]
    amp_x_m_s2, amp_y_m_s2 : float
        Amplitudes, mean of the directions, corrected for the low-pass's gain. [m/s^2]
    servo_mismatch_rad, u_servo_mismatch_rad : float
        Half the CCW minus CW difference of ``theta_y - theta_x`` over
        ``cos(2 eps_c)``: ``omega (tau_y - tau_x)``. [rad]
    ccw, cw : DirectionResult
        Per-direction fits.
    per_cycle : dict of str to ndarray
        For each CCW/CW cycle pair: ``pair``, ``squareness_rad``,
        ``squareness_ccw_rad``, ``squareness_cw_rad``, ``servo_mismatch_rad``,
        ``eps_c_rad`` [rad]; ``t_ccw_s``, ``t_cw_s``, the middle of each cycle
        from the first sample [s]; ``temperature_ccw_c``, ``temperature_cw_c``,
        the sensor's mean temperature over each cycle, NaN without one [degC].
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
    cutoff_hz : float
        Cutoff of the low-pass actually used. [Hz]
    cutoff_source : str
        ``"circle"`` (8 pi times the circle frequency, the default) or
        ``"options"`` (the user's).
    noise_density_circle_m_s2_rthz : float
        Noise density at the circle frequency, 1/f included. [m/s^2/sqrt(Hz)]
    flicker_corner_hz : float
        1/f corner of what the fitted model leaves (0: not significant, NaN:
        stretches too short to tell). [Hz]
    crb_white_rad : float
        Cramér-Rao bound for the white density alone. [rad]
    coverage_factor : float
        Student's t factor for :attr:`u_squareness_dof` at
        ``options.coverage_probability``.
    u_squareness_expanded_rad : float
        ``coverage_factor * u_squareness_rad``. [rad]
    servo_amplitude_bias_bound_rad : float
        The servos' amplitude mismatch, seen through ``eps_c``, shifts
        ``theta_y - theta_x`` by a value between 0 and this (signed), the same
        every run while the servos and the mounting stay
        (:mod:`imu_square.pipeline.servo`). [rad]

    The fields after ``options`` have defaults only so that results built by
    hand stay valid; :func:`~imu_square.pipeline.squareness.analyze` sets them all.
    """

    squareness_rad: float
    u_squareness_rad: float
    u_squareness_dof: int
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
    cutoff_hz: float = math.nan
    cutoff_source: str = ""
    noise_density_circle_m_s2_rthz: float = math.nan
    flicker_corner_hz: float = math.nan
    crb_white_rad: float = math.nan
    coverage_factor: float = math.nan
    u_squareness_expanded_rad: float = math.nan
    servo_amplitude_bias_bound_rad: float = math.nan

    @property
    def cos_2eps_c(self):
        """``cos(2 eps_c)``: how much of a machine's change ``theta_y - theta_x`` shows."""
        return math.cos(2 * self.eps_c_rad)

    def summary(self):
        """Human-readable lines about the result, without naming the recording.

        Returns
        -------
        str
            The squareness with its uncertainties, eps_c, the servo mismatch, the
            cycles used, and one line per quality warning.
        """
        q = self.quality
        unit = SQUARENESS_UNIT
        p = self.options.coverage_probability
        lines = [
            f"squareness {self.squareness_rad / URAD:.1f} ± {self.u_squareness_rad / URAD:.1f} "
            f"{unit} (theta_y - theta_x, type A, k=1, {self.u_squareness_dof} dof; {p:.0%}: "
            f"± {self.u_squareness_expanded_rad / URAD:.1f}, k={self.coverage_factor:.2f}; "
            f"bootstrap {self.u_squareness_bootstrap_rad / URAD:.1f}, "
            f"noise floor {self.crb_rad / URAD:.1f})",
            f"  eps_c {math.degrees(self.eps_c_rad):.3f} ± {math.degrees(self.u_eps_c_rad):.3f}°, "
            f"servo mismatch {self.servo_mismatch_rad / URAD:.1f} ± "
            f"{self.u_servo_mismatch_rad / URAD:.1f} {unit} (its amplitude share: 0 to "
            f"{self.servo_amplitude_bias_bound_rad / URAD:+.1f} {unit}), cycles "
            f"{self.cycles_used['ccw']} CCW + {self.cycles_used['cw']} CW, "
            f"amplitude {q['amplitude_ratio']:.3f} x v²/r, "
            f"period {q['period_disagreement']:+.3%}, "
            f"low-pass {self.cutoff_hz:.3g} Hz"
            f"{' (8 pi x circle frequency)' if self.cutoff_source == 'circle' else ''}",
        ]
        lines += [f"  warning: {w}" for w in q["warnings"]]
        return "\n".join(lines)

    def to_json_dict(self):
        """The result as JSON-ready scalars (µrad for angles but the phases, degrees for eps_c).

        Returns
        -------
        dict
            Keys as in ``docs/model.md`` ("Quantity names").
        """
        pc = self.per_cycle
        return {
            "squareness_urad": self.squareness_rad / URAD,
            "u_squareness_urad": self.u_squareness_rad / URAD,
            "u_squareness_dof": int(self.u_squareness_dof),
            "u_squareness_bootstrap_urad": _finite(self.u_squareness_bootstrap_rad / URAD),
            "crb_urad": self.crb_rad / URAD,
            "noise_density_m_s2_rthz": self.noise_density_m_s2_rthz,
            "noise_density_source": self.noise_density_source,
            "theta_x_rad": self.theta_x_rad,
            "theta_y_rad": self.theta_y_rad,
            "eps_c_deg": math.degrees(self.eps_c_rad),
            "u_eps_c_deg": math.degrees(self.u_eps_c_rad),
            "eps_c_stage2_deg": math.degrees(self.eps_c_stage2_rad),
            "cos_2eps_c": self.cos_2eps_c,
            "amp_x_m_s2": self.amp_x_m_s2,
            "amp_y_m_s2": self.amp_y_m_s2,
            "servo_mismatch_urad": self.servo_mismatch_rad / URAD,
            "u_servo_mismatch_urad": self.u_servo_mismatch_rad / URAD,
            "ccw": asdict(self.ccw),
            "cw": asdict(self.cw),
            "per_cycle_squareness_urad": [v / URAD for v in pc["squareness_rad"]],
            "per_cycle": json_safe(
                {
                    "pair": pc["pair"],
                    "squareness_ccw_urad": pc["squareness_ccw_rad"] / URAD,
                    "squareness_cw_urad": pc["squareness_cw_rad"] / URAD,
                    "eps_c_deg": np.degrees(pc["eps_c_rad"]),
                    "t_ccw_s": pc["t_ccw_s"],
                    "t_cw_s": pc["t_cw_s"],
                    "temperature_ccw_c": pc["temperature_ccw_c"],
                    "temperature_cw_c": pc["temperature_cw_c"],
                }
            ),
            "cycles_used": dict(self.cycles_used),
            "omega_rad_s": self.omega_rad_s,
            "period_s": self.period_s,
            "quality": json_safe(self.quality),
            "options": asdict(self.options),
            "cutoff_hz": self.cutoff_hz,
            "cutoff_source": self.cutoff_source,
            "noise_density_circle_m_s2_rthz": self.noise_density_circle_m_s2_rthz,
            "flicker_corner_hz": _finite(self.flicker_corner_hz),
            "crb_white_urad": self.crb_white_rad / URAD,
            "coverage_factor": _finite(self.coverage_factor),
            "u_squareness_expanded_urad": _finite(self.u_squareness_expanded_rad / URAD),
            "servo_amplitude_bias_bound_urad": self.servo_amplitude_bias_bound_rad / URAD,
        }


def _finite(x):
    return x if math.isfinite(x) else None
