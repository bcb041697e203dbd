"""glibc's thresholds raised in the replay's worker processes, and only there.

Each check runs in a fresh interpreter (``GLIBC_TUNABLES`` is read when a
process starts) and asks glibc itself, by ``mallinfo2``, whether a 16 MB block
is served by ``mmap`` (default thresholds: it is) or from the heap (tuned: 32 MB
threshold).
Python's and numpy's imports free no block that large, so glibc's own rising
threshold does not blur the difference (the first test holds that premise).
"""

import json
import os
import subprocess
import sys

import pytest

from imu_square.monitor import replay
from imu_square.monitor.replay import ALLOCATOR_TUNABLES

pytestmark = pytest.mark.skipif(
    not (hasattr(os, "confstr") and os.confstr("CS_GNU_LIBC_VERSION")),
    reason="GLIBC_TUNABLES is glibc's; this C library is another",
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
    full_env = {k: v for k, v in os.environ.items() if k != "GLIBC_TUNABLES"}
    full_env.update(env or {})
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


def test_the_tunables_serve_blocks_below_32_mb_from_the_heap():
    assert "glibc.malloc.mmap_threshold=33554432" in ALLOCATOR_TUNABLES
    probe = _probe("applied = True", {"GLIBC_TUNABLES": ALLOCATOR_TUNABLES})
    assert probe == {"applied": True, "mmap": False}


def test_replay_worker_processes_start_with_the_tunables(monkeypatch):
    monkeypatch.delenv("GLIBC_TUNABLES", raising=False)
    with replay._process_pool(1, frozenset()) as pool:
        with replay._tuned_allocator_for_children():
            seen = pool.submit(os.getenv, "GLIBC_TUNABLES")
        assert "GLIBC_TUNABLES" not in os.environ  # this process's environment given back
    assert seen.result() == ALLOCATOR_TUNABLES


def test_a_users_own_tunables_win(monkeypatch):
    monkeypatch.setenv("GLIBC_TUNABLES", "")
    with replay._process_pool(1, frozenset()) as pool:
        with replay._tuned_allocator_for_children():
            seen = pool.submit(os.getenv, "GLIBC_TUNABLES")
    assert seen.result() == ""


def test_importing_the_package_leaves_the_allocator_alone():
    call = "import imu_square.pipeline.squareness, imu_square.monitor.replay; applied = 0"
    assert _probe(call)["mmap"] is True


def test_a_local_dask_clusters_workers_start_with_the_tunables(monkeypatch):
    distributed = pytest.importorskip("distributed")
    monkeypatch.delenv("GLIBC_TUNABLES", raising=False)
    cluster = replay._local_cluster(1)
    try:
        with distributed.Client(cluster) as client:
            seen = list(client.run(os.getenv, "GLIBC_TUNABLES").values())
    finally:
        cluster.close()
    assert seen == [ALLOCATOR_TUNABLES]
    assert "GLIBC_TUNABLES" not in os.environ
