"""Cycle-averaged traces in the position-angle domain, as harmonics, and their noise.

The comparison between a recording and the model runs on cycle-averaged
traces, not on raw samples. Every analysed cycle's first ``n0`` samples
(``n0`` the fewest samples any cycle has, one period's worth) are projected
on the harmonics of the circle in the position angle,

    c[c, a, k] = (1 / n0) sum_i r_i exp(-i k phi_i),   k = 0 .. K,

by one real FFT per cycle and channel (the samples are uniform in ``phi``; a
cycle of ``P / dt`` samples puts harmonic ``k`` within ``0.5 k / n0`` of a
bin, which only matters at the top harmonics, and the same for data and
model). ``K`` reaches 0.45 of the sample rate. Their mean over a block's
cycles is the block's cycle-averaged trace; the offset and the circle
harmonic (``k = 0, 1``) are also kept per cycle, for the trend and the timing
across cycles. The samples within a window around each axis reversal are
summed in 5 ms bins (:mod:`imu_square.discrepancy.layout`) for the reversal
view, and the transient samples after each block's start ramp and end of
motion in 2 ms bins, over the blocks of a direction, for the transient view.

All of it is linear in the samples, so the features of ``data - model`` are
those of the data minus those of the model: both go through the same
operator, and what it does to the circle (leakage at a cycle's ends) cancels.

The noise of the features is modelled in :mod:`imu_square.discrepancy.window_noise`.
"""

from dataclasses import dataclass

import numpy as np
import scipy.fft

# Harmonics up to this fraction of the sample rate are compared.
NYQUIST_FRACTION = 0.45


@dataclass(frozen=True)
class Features:
    """Linear features of one set of samples (data, model or their difference).

    Attributes
    ----------
    block : ndarray of complex, shape (n_blocks, 2, K + 1)
        Harmonics of each block's cycle-averaged x and y trace. [m/s^2]
    cycle : ndarray of complex, shape (n_cycles, 2, 2)
        Offset (k = 0) and circle harmonic (k = 1) of each cycle. [m/s^2]
    reversal : ndarray, shape (2, n_groups * n_bins)
        Sums of x (row 0) and y (row 1) samples in each reversal bin. [m/s^2]
    transient : ndarray, shape (2, 4 * n_transient_bins)
        Sums of x and y samples in each transient bin. [m/s^2]
    prior : ndarray, shape (n_blocks,)
        Whitened prior on the blocks' time anchors (zero for the recording).
    """

    block: np.ndarray
    cycle: np.ndarray
    reversal: np.ndarray
    transient: np.ndarray
    prior: np.ndarray

    def __sub__(self, other):
        return Features(
            self.block - other.block,
            self.cycle - other.cycle,
            self.reversal - other.reversal,
            self.transient - other.transient,
            self.prior - other.prior,
        )

    def scaled(self, factor):
        """All features times ``factor``."""
        return Features(
            self.block * factor,
            self.cycle * factor,
            self.reversal * factor,
            self.transient * factor,
            self.prior * factor,
        )


class FeatureOperator:
    """The linear map from analysed samples to :class:`Features`.

    Parameters
    ----------
    layout : Layout
        The analysed samples.
    """

    def __init__(self, layout):
        self.layout = layout
        counts = np.diff(layout.cycle_edges)
        self.n0 = int(counts.min())
        self.k_max = min(
            self.n0 // 2 - 1,
            max(12, int(NYQUIST_FRACTION / (layout.dt_s * layout.frequency_hz))),
        )
        k = np.arange(self.k_max + 1)
        self._rows = layout.cycle_edges[:-1, None] + np.arange(self.n0)[None, :]
        signs = np.array([layout.blocks[b].sign for b in layout.cycle_block])
        self._cw = signs < 0
        first = layout.phi[layout.cycle_edges[:-1]]
        self._phase = np.exp(-1j * k[None, :] * first[:, None]) / self.n0
        self._block_of = layout.cycle_block
        self._n_blocks = len(layout.blocks)
        self._per_block = np.bincount(self._block_of, minlength=self._n_blocks).astype(float)
        self._block_starts = np.searchsorted(self._block_of, np.arange(self._n_blocks))
        self._bins = layout.reversal_bin
        self._n_rev = 4 * layout.n_bins
        self._transient = layout.transient_bin >= 0
        self._transient_bin = layout.transient_bin[self._transient]
        self._n_transient = 4 * layout.n_transient_bins
        u = (layout.t_s[self._rows] - layout.cycle_t0_s[:, None]) / layout.period_s
        self._hann = np.sin(np.pi * np.clip(u, 0.0, 1.0)) ** 2 * 2.0

    def _spectra(self, xy, window=None):
        rows = np.ascontiguousarray(xy.T)[:, self._rows].transpose(1, 0, 2)  # (n_cycles, 2, n0)
        if window is not None:
            rows = rows * window[:, None, :]
        spec = scipy.fft.rfft(rows, axis=-1)[..., : self.k_max + 1]
        np.conjugate(spec, out=spec, where=self._cw[:, None, None])
        spec *= self._phase[:, None, :]
        return spec

    def transform(self, xy):
        """Features of the analysed samples.

        Parameters
        ----------
        xy : ndarray, shape (m, 2)
            x and y at the layout's samples (analysed, then transient). [m/s^2]

        Returns
        -------
        Features
        """
        spec = self._spectra(xy)
        block = np.add.reduceat(spec, self._block_starts, axis=0)
        block /= self._per_block[:, None, None]
        reversal = np.empty((2, self._n_rev))
        for a in range(2):
            inside = self._bins[a] >= 0
            reversal[a] = np.bincount(
                self._bins[a][inside], weights=xy[inside, a], minlength=self._n_rev
            )
        transient = np.stack(
            [
                np.bincount(
                    self._transient_bin, weights=xy[self._transient, a], minlength=self._n_transient
                )
                for a in range(2)
            ]
        )
        return Features(block, spec[:, :, :2].copy(), reversal, transient, np.zeros(self._n_blocks))

    def cycle_spectra(self, xy):
        """Every harmonic of every cycle through a Hann window, for the noise estimate.

        Parameters
        ----------
        xy : ndarray, shape (m, 2)
            x and y at the analysed samples. [m/s^2]

        Returns
        -------
        ndarray of complex, shape (n_cycles, 2, K + 1)
            Windowed per-cycle harmonics (the window has mean 1; white noise
            gives them ``E|c_k|^2 = 1.5 sigma^2 / n0``). [m/s^2]
        """
        return self._spectra(xy, self._hann)
