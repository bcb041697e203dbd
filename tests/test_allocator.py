"""glibc's thresholds raised in the processes that analyse files, and only there.

Each check runs in a fresh interpreter (the setting is for the whole process)
and asks glibc itself, by ``mallinfo2``, whether a 16 MB block is served by
``mmap`` (default thresholds: it is) or from the heap (tuned: 32 MB threshold).
Python's and numpy's imports free no block that large, so glibc's own rising
threshold does not blur the difference (the first test holds that premise).
"""

import json
import os
import subprocess
import sys

import pytest

from imu_square.allocator import MMAP_THRESHOLD_BYTES

pytestmark = pytest.mark.skipif(
    not (hasattr(os, "confstr") and os.confstr("CS_GNU_LIBC_VERSION")),
    reason="mallopt thresholds are glibc's; this C library is another",
)

PROBE = r"""
import ctypes, json, sys

class MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd",
        "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]

libc = ctypes.CDLL(None)
libc.mallinfo2.restype = MallInfo2
libc.malloc.restype = ctypes.c_void_p
libc.malloc.argtypes = (ctypes.c_size_t,)
libc.free.argtypes = (ctypes.c_void_p,)

def mapped_by_mmap(size):
    before = libc.mallinfo2().hblkhd
    p = libc.malloc(size)
    grew = libc.mallinfo2().hblkhd - before
    libc.free(p)
    return grew >= size

exec(sys.argv[1])  # the call under test
# once only: freeing an mmap-ed block raises glibc's threshold to its size
print(json.dumps({"applied": applied, "mmap": mapped_by_mmap(16 * 1024 * 1024)}))
"""


def _probe(call, env=None):
    full_env = dict(os.environ, **(env or {}))
    out = subprocess.run(
        [sys.executable, "-c", PROBE, call],
        capture_output=True,
        text=True,
        check=True,
        env=full_env,
        timeout=60,
    )
    return json.loads(out.stdout)


def test_glibcs_defaults_serve_16_mb_by_mmap():
    # the probes' premise (and mallinfo2 there: glibc >= 2.33; Debian 12 has 2.36)
    assert _probe("applied = None")["mmap"] is True


def test_tune_allocator_serves_blocks_below_32_mb_from_the_heap():
    assert MMAP_THRESHOLD_BYTES == 32 * 1024 * 1024
    probe = _probe("from imu_square.allocator import tune_allocator; applied = tune_allocator()")
    assert probe == {"applied": True, "mmap": False}


def test_the_environment_can_keep_glibcs_defaults():
    call = "from imu_square.allocator import tune_allocator; applied = tune_allocator()"
    probe = _probe(call, {"IMU_SQUARE_MALLOC_TUNING": "0"})
    assert probe == {"applied": False, "mmap": True}


@pytest.mark.parametrize("value", ["off", "False", " no "])
def test_the_environment_says_off_in_words_too(value):
    # "off" and "false" tuned the allocator: only "0" was read as off
    call = "from imu_square.allocator import tune_allocator; applied = tune_allocator()"
    assert _probe(call, {"IMU_SQUARE_MALLOC_TUNING": value}) == {"applied": False, "mmap": True}


def test_an_unreadable_setting_keeps_glibcs_defaults_and_says_so(tmp_path):
    call = "from imu_square.allocator import tune_allocator; applied = tune_allocator()"
    assert _probe(call, {"IMU_SQUARE_MALLOC_TUNING": "maybe"}) == {"applied": False, "mmap": True}
    # the analyze command, which tunes, says why it did not
    run = "import sys; from imu_square.cli import main; sys.exit(main(sys.argv[1:]))"
    out = subprocess.run(
        [sys.executable, "-c", run, "analyze", str(tmp_path / "none.mcap")],
        capture_output=True,
        text=True,
        env=dict(os.environ, IMU_SQUARE_MALLOC_TUNING="maybe"),
        timeout=60,
    )
    assert out.returncode == 2
    assert "IMU_SQUARE_MALLOC_TUNING must be 0 or 1, got 'maybe'" in out.stderr


def test_replay_worker_processes_are_tuned_on_start():
    call = "from imu_square.monitor import replay; replay._init_worker(frozenset()); applied = 1"
    assert _probe(call)["mmap"] is False


def test_dask_tasks_are_tuned_before_the_file(tmp_path):
    # the task replays a missing file (a failed outcome): the allocator is tuned all the same
    call = (
        "from imu_square.monitor import replay\n"
        f"out = replay._replay_on_dask_worker({str(tmp_path / 'none.mcap')!r}, "
        "replay.ReplayJob('m1'), frozenset())\n"
        "assert out.status == 'failed', out\n"
        "applied = 1"
    )
    assert _probe(call)["mmap"] is False


def test_importing_the_package_leaves_the_allocator_alone():
    call = "import imu_square.pipeline.squareness, imu_square.monitor.replay; applied = 0"
    assert _probe(call)["mmap"] is True
