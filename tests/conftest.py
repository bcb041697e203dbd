"""Test-session set-up shared by every test module."""

import os

import pytest

# Single-threaded BLAS for the tests' many small solves, in every process they start
# (the library limits its own analysis and alarm design: imu_square/blas.py).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


@pytest.fixture(scope="session")
def linuxcnc_motions(tmp_path_factory):
    """LinuxCNC, installed, with a motion cache shared by the session: each program runs once.

    Skips where LinuxCNC is not installed; ``.ci/run`` installs it. A cache
    folder already named by ``IMU_SQUARE_CACHE_DIR`` is used as it is (runs kept
    from an earlier session); otherwise a fresh one.
    """
    import shutil

    if shutil.which("linuxcnc") is None or shutil.which("halsampler") is None:
        pytest.skip("LinuxCNC is not installed: apt-get install linuxcnc-uspace (Debian 12)")
    if not os.environ.get("IMU_SQUARE_CACHE_DIR"):
        # the CLI's runs in the tests read it too
        os.environ["IMU_SQUARE_CACHE_DIR"] = str(tmp_path_factory.mktemp("linuxcnc-cache"))
    return os.environ["IMU_SQUARE_CACHE_DIR"]
