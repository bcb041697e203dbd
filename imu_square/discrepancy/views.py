"""Where the model and the recording disagree: the gap views, each against the noise floor.

Every view is a set of components computed linearly from the features of
the residual (recording minus model, :mod:`imu_square.discrepancy.features`),
each divided by its standard deviation under the noise model, so that with
the model right and the noise as estimated the components are independent
standard normal variables. A view's statistic is the sum of their squares,

    S = sum z^2 ~ chi-square(nu - h),     gap = sqrt(S / (nu - h)),

where ``nu`` is the number of components and ``h`` the degrees of freedom
the fitted parameters take out of the view (the trace of the hat matrix
seen through the view). A gap of 1.0 means "explained down to the noise";
its spread under the null is about ``1 / sqrt(2 (nu - h))``.

The views (``K`` harmonics reach 0.45 of the sample rate, ``Kt`` is the
harmonic of the pipeline's 4 Hz low-pass, at least 10):

``trace_x``, ``trace_y``
    The cycle-averaged trace of one axis against position angle, each block,
    harmonics 0 to ``Kt``: what the pipeline's fit sees.
``cw_vs_ccw``
    Half the difference of the CCW and the flipped CW averaged traces
    (blocks of a direction averaged), harmonics 0 to ``Kt``, both axes: the
    part of the gap that changes sign with the direction (time lags).
``harmonics``
    Harmonics 2 to 10 of the circle frequency of each block's averaged
    traces, both axes (geometry: straightness, yaw).
``reversals``
    The residual samples within -50 ms to +250 ms of every axis reversal,
    summed in 5 ms bins over all reversals of that axis with the same
    direction of motion after it (backlash, friction spikes, vibration).
``transients``
    The residual samples in the windows after each block's start ramp and
    after its end of motion (:mod:`imu_square.discrepancy.layout`: the ramps
    themselves are left out), summed in 2 ms bins over the blocks of a
    direction (a mode rung at block starts and stops).
``trend``
    Each cycle's offset and circle harmonic (three numbers per axis) of the
    cycles of one direction over every run, whitened with their covariance
    across cycles (:mod:`imu_square.discrepancy.window_noise`: a 1/f part
    correlates neighbouring cycles), and projected orthogonally to a
    constant: ``n - 1`` components per direction and number, so a drift
    across cycles or runs shows, a constant misfit does not.
``timing``
    The phase of x and of y at the circle frequency, cycle by cycle (from
    the recording's own phase of each cycle, whitened in each block): the
    arrival of each cycle against the program's clock (a period that
    drifts, a clock error, moves both).
``band``
    Harmonics above ``Kt`` up to ``K`` of each block's averaged traces, in
    octaves of harmonics; the view's gap is the largest octave's, and its
    null the maximum of independent scaled chi-square variables:
    ``P(gap <= g) = prod_j F_chi2(g^2 nu_j; nu_j)``.

The fit and the likelihood-ratio tests use the whitened *fit vector*: each
block's harmonics 2 to ``K``, each cycle's offset and circle harmonic
(whitened block by block with their covariance across cycles) and the
transient view's bins (samples outside the analysed cycles).
"""

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats
from scipy.linalg import block_diag, null_space

VIEWS = (
    "trace_x",
    "trace_y",
    "cw_vs_ccw",
    "harmonics",
    "reversals",
    "transients",
    "trend",
    "timing",
    "band",
)
# The pipeline's default low-pass: the trace views reach its harmonic.
TRACE_CUTOFF_HZ = 4.0


@dataclass(frozen=True)
class ViewGap:
    """One view's statistic.

    Attributes
    ----------
    name : str
        One of :data:`VIEWS`.
    gap : float
        ``sqrt(S / (nu - h))``; the band view's largest octave. 1.0 = noise floor.
    statistic : float
        ``S`` (for the band view, the largest ``S_j / (nu_j - h_j)``).
    dof : float
        ``nu - h`` (for the band view, summed over its octaves).
    p_value : float
        Probability of a gap at least this large if the model were right.
    """

    name: str
    gap: float
    statistic: float
    dof: float
    p_value: float

    def to_json_dict(self):
        """As JSON-ready numbers."""
        return {
            "gap": self.gap,
            "statistic": self.statistic,
            "dof": self.dof,
            "p_value": self.p_value,
        }


class FeatureSpace:
    """The noise model applied to features: the fit vector and the gap views.

    Parameters
    ----------
    layout : Layout
        The analysed samples.
    operator : FeatureOperator
        The features' operator.
    noise : NoiseModel
        The noise floor.
    reference : Features
        Features of the recording: its circle harmonic of each cycle is the
        phase reference of the timing view.
    """

    def __init__(self, layout, operator, noise, reference):
        self.layout = layout
        self.noise = noise
        k_max = operator.k_max
        n0 = operator.n0
        self.k_max = k_max
        self.k_trace = int(min(k_max, max(10, round(TRACE_CUTOFF_HZ / layout.frequency_hz))))
        per_block = np.bincount(layout.cycle_block, minlength=len(layout.blocks))
        k = np.arange(k_max + 1)
        # E|c_k|^2 of each block's mean coefficient
        self.block_var = np.stack(
            [
                np.stack([noise.coef_var(a, k, n0 * per_block[b], per_block[b]) for a in range(2)])
                for b in range(len(layout.blocks))
            ]
        )
        # per-cycle offset and circle harmonic: whitened block by block (1/f correlates cycles)
        self._cycles = [np.flatnonzero(layout.cycle_block == b) for b in range(len(layout.blocks))]
        self._white = {}
        self._cov1 = {}
        for b, idx in enumerate(self._cycles):
            pos = np.rint((layout.cycle_t0_s[idx] - layout.cycle_t0_s[idx[0]]) / layout.period_s)
            for a in range(2):
                for kk in (0, 1):
                    cov = noise.cycle_cov(a, kk, n0, pos.astype(int))
                    if kk == 1:
                        cov = cov / 2  # each of the real and imaginary parts
                        self._cov1[b, a] = cov
                    self._white[b, a, kk] = np.linalg.inv(np.linalg.cholesky(cov))
        self._directions = {
            d: [b for b, blk in enumerate(layout.blocks) if blk.direction == d]
            for d in ("ccw", "cw")
        }
        self._trend = {}
        for d, blocks in self._directions.items():
            n_d = sum(self._cycles[b].size for b in blocks)
            if n_d < 2:
                continue
            for a in range(2):
                for kk in (0, 1):
                    w = block_diag(*(self._white[b, a, kk] for b in blocks))
                    ones = w @ np.ones(n_d)
                    contrast = null_space(ones[None, :]).T  # orthonormal, orthogonal to a constant
                    self._trend[d, a, kk] = (
                        np.concatenate([self._cycles[b] for b in blocks]),
                        contrast @ w,
                    )
        self._rev_count = np.stack(
            [
                np.bincount(
                    layout.reversal_bin[a][layout.reversal_bin[a] >= 0],
                    minlength=4 * layout.n_bins,
                )
                for a in range(2)
            ]
        ).astype(float)
        self._rev_scale = [
            1.0 / np.sqrt(noise.sigma2[a] * self._rev_count[a][self._rev_count[a] > 0])
            for a in range(2)
        ]
        transient = layout.transient_bin[layout.transient_bin >= 0]
        count = np.bincount(transient, minlength=4 * layout.n_transient_bins).astype(float)
        self._transient_used = count > 0
        self._transient_scale = [
            1.0 / np.sqrt(noise.sigma2[a] * count[self._transient_used]) for a in range(2)
        ]
        ref = reference.cycle[:, :, 1]
        self._timing_ref = ref
        self._timing_white = []
        for b, idx in enumerate(self._cycles):
            # each axis's phase theta_a = Re(i dc / ref): its variance is (cov / 2) / |ref|^2
            mag2 = np.mean(np.abs(ref[idx]) ** 2, axis=0)
            self._timing_white.append(
                [np.linalg.inv(np.linalg.cholesky(self._cov1[b, a] / mag2[a])) for a in range(2)]
            )
        lo = self.k_trace + 1
        self._octaves = []
        while lo <= k_max:
            hi = min(2 * lo - 1, k_max)
            self._octaves.append((lo, hi))
            lo = hi + 1

    # -- the fit vector -------------------------------------------------------

    def fit_vector(self, f):
        """The whitened residual the fit minimises (independent unit-variance numbers).

        Parameters
        ----------
        f : Features
            Features of a residual (or of a model derivative).

        Returns
        -------
        ndarray
            Each block's harmonics 2..K (real and imaginary parts), each
            cycle's offset and circle harmonic, the transient bins and the
            prior on the blocks' time anchors.
        """
        sd = np.sqrt(self.block_var[:, :, 2:] / 2)
        blk = f.block[:, :, 2:] / sd
        parts = [blk.real.ravel(), blk.imag.ravel()]
        for b, idx in enumerate(self._cycles):
            for a in range(2):
                c = f.cycle[idx, a]
                parts += [
                    self._white[b, a, 0] @ c[:, 0].real,
                    self._white[b, a, 1] @ c[:, 1].real,
                    self._white[b, a, 1] @ c[:, 1].imag,
                ]
        parts.append(self._transients(f))
        parts.append(f.prior)
        return np.concatenate(parts)

    def _transients(self, f):
        """The transient bins of both axes, each over its white-noise standard deviation."""
        return np.concatenate(
            [f.transient[a][self._transient_used] * self._transient_scale[a] for a in range(2)]
        )

    # -- the views --------------------------------------------------------------

    def _harmonic_parts(self, coef, var, k0, k1):
        """Real components of harmonics k0..k1 of ``coef`` with E|c|^2 ``var``."""
        parts = []
        if k0 == 0:
            parts.append(coef[..., :1].real / np.sqrt(var[..., :1]))
            k0 = 1
        z = coef[..., k0 : k1 + 1] / np.sqrt(var[..., k0 : k1 + 1] / 2)
        parts += [z.real, z.imag]
        return np.concatenate([p.ravel() for p in parts])

    def components(self, f):
        """Every view's standard-normal components under the null.

        Parameters
        ----------
        f : Features
            Features of a residual.

        Returns
        -------
        dict of str to list of ndarray
            One array per view (the band view: one per octave).
        """
        kt = self.k_trace
        out = {}
        for a, name in ((0, "trace_x"), (1, "trace_y")):
            out[name] = [self._harmonic_parts(f.block[:, a], self.block_var[:, a], 0, kt)]
        ccw, cw = self._directions["ccw"], self._directions["cw"]
        if ccw and cw:
            diff = f.block[ccw].mean(axis=0) - f.block[cw].mean(axis=0)
            var = self.block_var[ccw].mean(axis=0) / len(ccw) + self.block_var[cw].mean(
                axis=0
            ) / len(cw)
            out["cw_vs_ccw"] = [self._harmonic_parts(diff, var, 0, kt)]
        else:
            out["cw_vs_ccw"] = [np.empty(0)]
        out["harmonics"] = [self._harmonic_parts(f.block, self.block_var, 2, min(10, self.k_max))]
        rev = [f.reversal[a][self._rev_count[a] > 0] * self._rev_scale[a] for a in range(2)]
        out["reversals"] = [np.concatenate(rev)]
        out["transients"] = [self._transients(f)]
        trend = []
        for (_, a, kk), (idx, m) in self._trend.items():
            c = f.cycle[idx, a, kk]
            trend += [m @ c.real] if kk == 0 else [m @ c.real, m @ c.imag]
        out["trend"] = [np.concatenate(trend) if trend else np.empty(0)]
        theta = (1j * f.cycle[:, :, 1] / self._timing_ref).real
        out["timing"] = [
            np.concatenate(
                [
                    w[a] @ theta[idx, a]
                    for w, idx in zip(self._timing_white, self._cycles, strict=True)
                    for a in range(2)
                ]
            )
        ]
        out["band"] = [
            self._harmonic_parts(f.block, self.block_var, lo, hi) for lo, hi in self._octaves
        ]
        return out

    def gaps(self, residual, hat=None):
        """The gap of every view.

        Parameters
        ----------
        residual : Features
            Features of recording minus model.
        hat : dict of str to list of float, optional
            Degrees of freedom the fit takes out of each view's parts
            (:meth:`hat_dof`); none if omitted.

        Returns
        -------
        dict of str to ViewGap
        """
        out = {}
        for name, parts in self.components(residual).items():
            h = hat[name] if hat else [0.0] * len(parts)
            stat = [float(np.sum(p**2)) for p in parts]
            dof = [max(p.size - hj, 1e-9) for p, hj in zip(parts, h, strict=True)]
            if parts[0].size == 0:
                out[name] = ViewGap(name, math.nan, math.nan, 0.0, math.nan)
            elif name == "band":
                ratio = [s / d for s, d in zip(stat, dof, strict=True)]
                worst = max(ratio)
                cdf = np.prod([stats.chi2.cdf(worst * d, d) for d in dof])
                out[name] = ViewGap(name, math.sqrt(worst), worst, float(sum(dof)), float(1 - cdf))
            else:
                s, d = stat[0], dof[0]
                out[name] = ViewGap(name, math.sqrt(s / d), s, d, float(stats.chi2.sf(s, d)))
        return out

    def hat_dof(self, columns):
        """Degrees of freedom fitted parameters take out of each view.

        Parameters
        ----------
        columns : list of Features
            Derivatives of the model's features by each fitted parameter.

        Returns
        -------
        dict of str to list of float
            ``trace(A (J'J)^-1 A')`` for each view part, ``A`` the view's
            components of the columns and ``J`` their fit vectors.
        """
        if not columns:
            return None
        jac = np.column_stack([self.fit_vector(c) for c in columns])
        gram_inv = np.linalg.pinv(jac.T @ jac)
        comps = [self.components(c) for c in columns]
        out = {}
        for name in comps[0]:
            out[name] = []
            for j in range(len(comps[0][name])):
                a = np.column_stack([c[name][j] for c in comps])
                out[name].append(float(np.einsum("ij,jk,ik->", a, gram_inv, a)))
        return out
