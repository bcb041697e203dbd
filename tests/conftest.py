"""Test-session set-up shared by every test module."""

import os

# As the CLI does (imu_square/cli.py): single-threaded BLAS for the many small solves.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
