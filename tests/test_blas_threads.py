"""The analysis and the alarm design run BLAS on one thread, and give the caller's setting back."""

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from imu_square.monitor.stats import alarms
from imu_square.pipeline import squareness
from imu_square.pipeline.squareness import AnalysisOptions, analyze
from imu_square.program import TestProgram
from imu_square.simulate import simulate_run, with_effects
from imu_square.units import URAD


def _blas_threads():
    return sorted({i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"})


@pytest.fixture(autouse=True)
def _has_blas():
    if not _blas_threads():
        pytest.skip("no BLAS library that threadpoolctl can see")


def _spy(monkeypatch, module, name):
    seen = []
    original = getattr(module, name)

    def spy(*args, **kwargs):
        seen.append(_blas_threads())
        return original(*args, **kwargs)

    monkeypatch.setattr(module, name, spy)
    return seen


def test_analyze_runs_blas_on_one_thread_and_restores_the_callers(monkeypatch):
    rec = simulate_run(TestProgram(cycles_per_direction=3, dwell_s=1.0), *with_effects([]))[0]
    seen = _spy(monkeypatch, squareness, "fit_mean_traces")
    with threadpool_limits(limits=2, user_api="blas"):
        analyze(rec, AnalysisOptions(cutoff_hz=4.0, bootstrap_n=0))
        after = _blas_threads()
    assert seen == [[1]]
    assert after == [2]


def test_the_alarm_design_runs_blas_on_one_thread(monkeypatch):
    seen = _spy(monkeypatch, alarms, "solve_limit")
    with threadpool_limits(limits=2, user_api="blas"):
        alarms.design_alarms(730, 8 * URAD, mc_nights=100_000)
        after = _blas_threads()
    assert seen and all(s == [1] for s in seen)
    assert after == [2]
