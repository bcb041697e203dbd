"""Reference squareness methods a ballbar or laser owner compares against.

Each method simulates a standard test on a geometric error map, given as a
plain callable ``deviation(x, y) -> (dx, dy)`` (commanded ``(x, y)`` reaches
``(x + dx, y + dy)``, arrays in metres; three coordinates for body diagonals),
and analyses it the way the standard or the instrument's software does:

- :func:`ballbar_squareness`: ISO 230-4 circular test, ``sin(2 phi)`` term;
- :func:`diagonal_squareness`, :func:`diagonal_test`,
  :func:`body_diagonal_squareness`: ISO 230-6 diagonal displacement tests;
- :func:`biaxial_squareness`: ISO 230-1 bi-axial straightness, L, T and +,
  with least-squares, end-point or minimum-zone reference lines
  (:func:`reference_line`);
- :func:`step_diagonal_test`: the step-diagonal ("vector") test on a face and
  its plane mirror's misalignment.

:mod:`imu_square.reference.compare` runs all of them and the IMU circle test
(simulator and pipeline) side by side on a simulated machine; it is not
imported here, as it pulls in the pipeline.

Every result calls the machine's squareness alone ``machine_squareness_rad``.

Sign convention (Renishaw/Chapman, as everywhere in the project): positive when
the angle between +X and +Y exceeds 90 deg; a pure squareness ``alpha`` is
``dx = -alpha y``.
"""

from imu_square.reference.ballbar import BallbarResult, ballbar_squareness
from imu_square.reference.biaxial import (
    ORIENTATIONS_DEG,
    SHAPES,
    BiaxialResult,
    biaxial_squareness,
)
from imu_square.reference.diagonal import (
    DiagonalResult,
    DiagonalTest,
    body_diagonal_squareness,
    body_diagonals,
    diagonal_lengths,
    diagonal_squareness,
    diagonal_test,
    face_diagonals,
    squareness_from_diagonals,
)
from imu_square.reference.reference_line import REFERENCE_LINES, ReferenceLine, reference_line
from imu_square.reference.step_diagonal import StepDiagonalResult, step_diagonal_test

__all__ = [
    "ORIENTATIONS_DEG",
    "REFERENCE_LINES",
    "SHAPES",
    "BallbarResult",
    "BiaxialResult",
    "DiagonalResult",
    "DiagonalTest",
    "ReferenceLine",
    "StepDiagonalResult",
    "ballbar_squareness",
    "biaxial_squareness",
    "body_diagonal_squareness",
    "body_diagonals",
    "diagonal_lengths",
    "diagonal_squareness",
    "diagonal_test",
    "face_diagonals",
    "reference_line",
    "squareness_from_diagonals",
    "step_diagonal_test",
]
