"""Offline replay of recorded runs into a history: one folder or a fleet's archive.

One per-file function, :func:`replay_file`, does everything a recording needs
(read it, hash it, analyse it, build its history row) and returns a small
picklable :class:`FileOutcome`; the same function runs in local worker
processes (:func:`run_local`, ``concurrent.futures``) or on a Dask cluster
(:func:`run_dask`, ``distributed``, an optional extra imported only there).
Each worker reads its own file; results stream back as they finish and are
stored one by one (a transaction each), so an interrupted replay loses at
most the files in flight and the next call skips what is stored: a file is
skipped when its SHA-256 is in the history already under the same analysis
settings, with its diagnostics under the same diagnostic settings (a run
stored without them is read again for them: a replay rebuilds an archive's
diagnostics). Once every file is in, the verdicts are recomputed over the whole
history in recording-time order (:func:`~.night.judge_history`), so they do
not depend on the order the files finished in, nor on the number of workers.
"""

import contextlib
import glob
import hashlib
import os
import shutil
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

from imu_square.errors import ImuSquareError
from imu_square.monitor.config import AnalysisSettings
from imu_square.monitor.diagnostics.settings import DiagnosticSettings
from imu_square.monitor.history.encoding import first_line

STATUSES = ("analysed", "invalid", "skipped", "failed")

# glibc's malloc told to keep freed memory for reuse in the worker processes, which only
# analyse files: each file makes hundreds of temporary arrays of 0.1-5 MB, which glibc
# would map and unmap afresh (above its mmap threshold) and trim off the heap, paying
# the page faults again for the next array: a fifth of the per-file time
# (benchmarks/per_file.py --trick allocator). A worker then holds up to 128 MB of freed
# memory more. Read by glibc when a process starts; other C libraries ignore it.
ALLOCATOR_TUNABLES = "glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=134217728"


class ReplayError(ImuSquareError):
    """A replay cannot start: no recording found, a bad engine, a bad settings file."""


@dataclass(frozen=True)
class ReplayJob:
    """What every file of a replay is analysed with (picklable, sent to each worker).

    Attributes
    ----------
    machine_id : str
        The machine the recordings are of.
    analysis : AnalysisSettings
        The analysis settings.
    program : TestProgram or None
        The program the monitor expects; a recording of another is invalid.
    diagnostics : DiagnosticSettings
        The effects fitted to every valid run.
    """

    machine_id: str
    analysis: AnalysisSettings = field(default_factory=AnalysisSettings)
    program: object = None
    diagnostics: DiagnosticSettings = field(default_factory=DiagnosticSettings)


@dataclass(frozen=True)
class FileOutcome:
    """What replaying one file gave.

    Attributes
    ----------
    path : str
        The recording.
    status : str
        One of :data:`STATUSES`: ``failed`` means the file could not even be
        hashed (unreadable); an unanalysable recording is ``invalid``.
    sha256 : str
        The file's SHA-256, "" if unreadable.
    row : RunRow or None
        The history row, None when skipped or failed.
    diagnostics : DiagnosticFitRow or None
        The run's diagnostic fit, its run left for the store; None for an
        invalid run, without a diagnostic set, or when skipped or failed.
    reason : str
        The invalid run's or the failure's one-line reason.
    seconds : float
        Time spent on the file by its worker. [s]
    """

    path: str
    status: str
    sha256: str = ""
    row: object = None
    diagnostics: object = None
    reason: str = ""
    seconds: float = 0.0


def expand_paths(items):
    """The recordings named by files, folders (searched recursively) and globs.

    Parameters
    ----------
    items : sequence of str
        Paths, folders, glob patterns; ``scheme://`` URLs are kept as they are
        (read through fsspec by each worker).

    Returns
    -------
    list of str
        Distinct ``.mcap`` files, sorted.

    Raises
    ------
    ReplayError
        When an item matches nothing.
    """
    found = set()
    for item in items:
        if "://" in item:
            found.add(item)
            continue
        path = Path(item).expanduser().absolute()
        if path.is_dir():
            hits = [str(p) for p in path.rglob("*.mcap") if p.is_file()]
        elif path.is_file():
            hits = [str(path)]
        else:
            hits = [
                str(Path(h).absolute())
                for h in glob.glob(str(path), recursive=True)
                if Path(h).is_file()
            ]
        if not hits:
            raise ReplayError(f"{item}: no recording there (a file, a folder of .mcap or a glob)")
        found.update(hits)
    return sorted(found)


def _localise(path):
    """A local file for ``path``: itself, or a temporary copy of an fsspec URL."""
    if "://" not in path:
        return path, None
    try:
        import fsspec
    except ImportError:
        raise ReplayError(
            f"{path}: reading URLs needs fsspec (pip install 'imu-square[cluster]')"
        ) from None
    import tempfile

    fd, local = tempfile.mkstemp(suffix=".mcap", prefix="imu-square-replay-")
    with os.fdopen(fd, "wb") as out, fsspec.open(path, "rb") as src:
        shutil.copyfileobj(src, out)
    return local, local


def replay_file(path, job, known=frozenset()):
    """Read, hash, analyse one recording and build its history row: the replay's unit of work.

    Parameters
    ----------
    path : str
        The recording (a path, or an fsspec URL).
    job : ReplayJob
        The machine and the analysis settings.
    known : set of str
        SHA-256 of the recordings already stored under these settings, with
        their diagnostics: skipped.

    Returns
    -------
    FileOutcome
    """
    from imu_square.monitor.night import recording_row

    start = time.perf_counter()
    local, temporary = None, None
    try:
        local, temporary = _localise(path)
        with open(local, "rb") as f:
            sha = hashlib.file_digest(f, "sha256").hexdigest()
        if sha in known:
            return FileOutcome(path, "skipped", sha, seconds=time.perf_counter() - start)
        # a file that cannot be read is counted as failed, never stored as a run
        row, result, diagnostics = recording_row(
            job, local, job.program, sha, keep_unreadable=False
        )
        row = replace(row, recording_path=path)
        status = "analysed" if result is not None else "invalid"
        return FileOutcome(
            path,
            status,
            sha,
            row,
            diagnostics,
            row.invalid_reason or "",
            seconds=time.perf_counter() - start,
        )
    except (OSError, ImuSquareError) as exc:
        # the outcome names the file: its reason need not
        reason = first_line(exc).removeprefix(f"{local}: ").removeprefix(f"{path}: ")
        return FileOutcome(path, "failed", reason=reason, seconds=time.perf_counter() - start)
    finally:
        if temporary is not None:
            os.unlink(temporary)


_KNOWN = frozenset()


def _init_worker(known):
    global _KNOWN
    _KNOWN = known


def _replay_with_known(path, job):
    return replay_file(path, job, _KNOWN)


def run_local(paths, job, known=frozenset(), jobs=None):
    """Replay files over local processes; yield each outcome as it finishes.

    Parameters
    ----------
    paths : sequence of str
        The recordings.
    job : ReplayJob
        The analysis.
    known : set of str
        Hashes to skip.
    jobs : int, optional
        Worker processes; one per core if None. 1 runs in this process. The
        workers start with :data:`ALLOCATOR_TUNABLES` unless the environment
        sets ``GLIBC_TUNABLES`` itself.

    Yields
    ------
    FileOutcome
    """
    jobs = jobs or os.cpu_count() or 1
    if jobs == 1:
        for path in paths:
            yield replay_file(path, job, known)
        return
    from concurrent.futures import as_completed

    with _process_pool(jobs, known) as pool:
        with _tuned_allocator_for_children():  # the pool starts its workers as tasks come
            futures = [pool.submit(_replay_with_known, p, job) for p in paths]
        try:
            for future in as_completed(futures):
                yield future.result()
        except BaseException:
            for future in futures:
                future.cancel()
            raise


def _process_pool(jobs, known):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    context = multiprocessing.get_context("spawn")  # a fresh interpreter: reads the environment
    return ProcessPoolExecutor(
        max_workers=jobs, mp_context=context, initializer=_init_worker, initargs=(known,)
    )


@contextlib.contextmanager
def _tuned_allocator_for_children():
    """:data:`ALLOCATOR_TUNABLES` in the environment of the processes started meanwhile."""
    if "GLIBC_TUNABLES" in os.environ:  # the user's own setting (even empty) wins
        yield
        return
    os.environ["GLIBC_TUNABLES"] = ALLOCATOR_TUNABLES
    try:
        yield
    finally:
        del os.environ["GLIBC_TUNABLES"]


def _local_cluster(workers):
    """A ``distributed.LocalCluster`` whose workers start with :data:`ALLOCATOR_TUNABLES`."""
    from distributed import LocalCluster

    with _tuned_allocator_for_children():  # started before it returns
        return LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
        )


def run_dask(paths, job, known=frozenset(), scheduler=None, workers=2):
    """Replay files on a Dask cluster with the same per-file function; yield as they finish.

    Parameters
    ----------
    paths : sequence of str
        The recordings; each worker reads its own.
    job : ReplayJob
        The analysis.
    known : set of str
        Hashes to skip (scattered to the workers once).
    scheduler : str, optional
        ``tcp://HOST:PORT`` of a running scheduler, whose workers' environment
        is the cluster's own; None starts a ``distributed.LocalCluster`` of
        ``workers`` processes, with :data:`ALLOCATOR_TUNABLES`.
    workers : int
        Worker processes of the local cluster.

    Yields
    ------
    FileOutcome
    """
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise ReplayError(
            "a Dask replay needs dask and distributed: pip install 'imu-square[cluster]'"
        ) from None
    cluster = None
    if scheduler is None:
        cluster = _local_cluster(workers)
    try:
        with Client(scheduler or cluster) as client:
            # a list of one each: scatter sends a collection's items, not the collection
            known_future, job_future = client.scatter([known, job], broadcast=True)
            futures = client.map(
                replay_file,
                list(paths),
                job=job_future,
                known=known_future,
                pure=False,
                retries=2,
            )
            for future in as_completed(futures):
                yield future.result()
    except OSError as exc:
        raise ReplayError(f"the Dask scheduler {scheduler or 'LocalCluster'}: {exc}") from None
    finally:
        if cluster is not None:
            cluster.close()


@dataclass
class ReplaySummary:
    """How a replay went: counts, and what the verdicts say after it.

    Attributes
    ----------
    files : int
        Recordings named.
    counts : dict of str to int
        Files per :data:`STATUSES`.
    invalid : list of tuple (str, str)
        ``(path, reason)`` of each invalid run.
    failed : list of tuple (str, str)
        ``(path, reason)`` of each file that could not be read.
    seconds : float
        Wall time of the replay. [s]
    alarm_nights : list of str
        Recording times of the nights the alarms fired on, after the replay.
    state : str
        The latest night's state.
    """

    files: int
    counts: dict = field(default_factory=lambda: dict.fromkeys(STATUSES, 0))
    invalid: list = field(default_factory=list)
    failed: list = field(default_factory=list)
    seconds: float = 0.0
    alarm_nights: list = field(default_factory=list)
    state: str = ""

    def to_json_dict(self):
        """JSON-ready."""
        return asdict(self)


def stored_hashes(history, config):
    """The recordings a replay skips: stored under the monitor file's analysis settings, each
    valid one with its diagnostics under its diagnostic settings.

    Parameters
    ----------
    history : History
        The open history.
    config : MonitorConfig
        The monitor file (as the replay runs it).

    Returns
    -------
    frozenset of str
        SHA-256 of the recordings.
    """
    from imu_square.monitor.history.encoding import settings_hash
    from imu_square.monitor.night import analysis_settings

    analysis = settings_hash(analysis_settings(config))
    if not config.diagnostics.enabled:
        return frozenset(history.recording_hashes(config.machine_id, analysis))
    key = config.diagnostics.key()
    return frozenset(history.diagnosed_hashes(config.machine_id, analysis, key))


def store_outcome(history, outcome):
    """Store one file's run and diagnostics (one transaction): at most the files in flight
    are lost.

    Parameters
    ----------
    history : History
        The open history.
    outcome : FileOutcome
        A worker's outcome with a row.

    Returns
    -------
    tuple (int, bool)
        The run's id, and whether it (or its diagnostics) was inserted now.
    """
    from imu_square.monitor.night import store_run

    return store_run(history, outcome.row, outcome.diagnostics)
