"""The sensor's rotation ``eps_c`` about Z, from the phases with phi anchored.

A rotation of the sensor shifts ``theta_x`` and ``theta_y`` equally, so
``eps_c`` is the mean phase ``(theta_x + theta_y) / 2`` of the CCW and the
flipped CW fits, with each block's ``phi(t)`` anchored at the middle of its
motion (:mod:`imu_square.pipeline.segment`). A timing error of the anchor
shifts the two directions the opposite way and cancels in their mean
(``docs/model.md``). The paper's stage 2 cannot give it: it is degenerate for
a circle (:mod:`imu_square.pipeline.sine_fit`).

Seen through sensor axes turned by ``eps_c`` the machine's terms shrink by
``cos(2 eps_c)`` (``docs/model.md``, measurand); near 45 degrees they vanish,
so such a mounting is refused.
"""

import math

import numpy as np

from imu_square.errors import AnalysisError
from imu_square.pipeline.uncertainty import type_a

# Refuse a sensor turned within 15 deg of 45 deg to the axes (|cos 2 eps_c| < 0.5).
MIN_COS_2EPS = 0.5


def circular_mean(a_rad, b_rad):
    """Mean direction of two angles (a sensor turned ~180 deg averages to ~180, not 0).

    Parameters
    ----------
    a_rad, b_rad : float
        Angles. [rad]

    Returns
    -------
    float
        Their circular mean in (-pi, pi]. [rad]
    """
    return float(np.angle(np.exp(1j * a_rad) + np.exp(1j * b_rad)))


def estimate_eps_c(mean_fit):
    """Sensor rotation from the fits of the averaged traces; refuse one near 45 deg.

    Parameters
    ----------
    mean_fit : MeanFit
        Fits of the CCW and the flipped CW mean traces.

    Returns
    -------
    float
        ``eps_c``, circular mean of both directions' ``(theta_x + theta_y) / 2``. [rad]

    Raises
    ------
    AnalysisError
        If ``|cos(2 eps_c)| < MIN_COS_2EPS``.
    """
    phases = mean_fit.fit.mean_phase
    eps_c = circular_mean(phases[0], phases[1])
    cos2 = math.cos(2 * eps_c)
    if abs(cos2) < MIN_COS_2EPS:
        raise AnalysisError(
            f"the sensor is turned {math.degrees(eps_c):.1f} deg from the machine's axes: near "
            f"45 deg the machine's squareness is seen scaled by cos(2 eps_c) = {cos2:.2f} and "
            f"the sensor's own terms swamp it; mount the sensor within 30 deg of square to the "
            f"X and Y axes"
        )
    return eps_c


def eps_c_uncertainty(per_pair_eps_rad, segmentation):
    """Standard uncertainty of ``eps_c``: cycle scatter and the anchors' timing.

    Parameters
    ----------
    per_pair_eps_rad : ndarray, shape (n_pairs,)
        ``eps_c`` of each CCW/CW cycle pair. [rad]
    segmentation : Segmentation
        The blocks, whose motion midpoints anchor ``phi``.

    Returns
    -------
    float
        Type A scatter over the pairs combined with half the anchors' angle
        uncertainty of the two directions (the anchor error enters each
        direction's mean phase, and eps_c is their mean). [rad]
    """
    anchor = np.hypot(
        segmentation.anchor_uncertainty_rad("ccw"), segmentation.anchor_uncertainty_rad("cw")
    )
    return float(np.hypot(type_a(per_pair_eps_rad), 0.5 * anchor))
