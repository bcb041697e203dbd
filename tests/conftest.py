"""Test-session set-up shared by every test module."""

import os

# Single-threaded BLAS for the tests' many small solves, in every process they start
# (the library limits its own analysis and alarm design: imu_square/blas.py).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
