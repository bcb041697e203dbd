"""The alert outbox: one JSON file per alert and sink that is not delivered yet.

Before a sink is tried, the alert is written here (a write-ahead outbox), so a
process killed mid-delivery leaves it to the next run instead of losing it.
A delivered entry is removed; one that failed for now stays, with its count of
attempts and its last error; one that a sink refused as a configuration error
moves to ``rejected/``, where it stays until it is re-queued. Each file is::

    {"schema": "imu-square.outbox/1", "sink": "webhook", "attempts": 3,
     "last_error": "HTTP 503 Service Unavailable", "updated_at": "...",
     "alert": {...the alert, as every sink sends it...}}

and is named ``CREATED-ALERTID-SINK.json`` (``20261003T021405.120000Z-3f0c...-email.json``),
so that a sorted listing is the order the alerts were made in. Every write is
atomic. An entry is locked (``flock``) while a process delivers it, so two
monitor jobs never send the same entry at once.
"""

import datetime as dt
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path

from imu_square.io.atomic import fsync_dir, write_atomic
from imu_square.json_values import from_json
from imu_square.monitor.alerts.alert import Alert
from imu_square.monitor.alerts.locking import try_lock

OUTBOX_SCHEMA = "imu-square.outbox/1"
REJECTED = "rejected"
_NAME = re.compile(r"(\d{8}T\d{6}\.\d{6}Z)-([0-9a-f]{32})-(.+)\.json")


@dataclass
class Entry:
    """One pending delivery, locked by this process until :func:`release`.

    Attributes
    ----------
    path : Path
        The entry's file.
    sink : str
        Name of the sink it is for.
    alert : Alert
        The alert.
    attempts : int
        Tries so far, over every round.
    last_error : str or None
        The last failure.
    fd : int or None
        Descriptor holding the lock.
    """

    path: Path
    sink: str
    alert: Alert
    attempts: int = 0
    last_error: str | None = None
    fd: int | None = None


def entry_name(alert, sink):
    """The file name of ``alert``'s entry for ``sink``."""
    created = alert.created.astimezone(dt.UTC).strftime("%Y%m%dT%H%M%S.%fZ")
    return f"{created}-{alert.alert_id}-{sink}.json"


def sink_of(path):
    """The sink an entry file is for, from its name; None if it is not an entry's name."""
    match = _NAME.fullmatch(Path(path).name)
    return match.group(3) if match else None


def pending_paths(outbox):
    """The pending entries' files, oldest alert first.

    Parameters
    ----------
    outbox : Path
        The outbox folder.

    Returns
    -------
    list of Path
    """
    if not outbox.is_dir():
        return []
    return sorted(p for p in outbox.iterdir() if p.is_file() and _NAME.fullmatch(p.name))


def _content(entry):
    doc = {
        "schema": OUTBOX_SCHEMA,
        "sink": entry.sink,
        "attempts": entry.attempts,
        "last_error": entry.last_error,
        "updated_at": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "alert": entry.alert.as_dict(),
    }
    return json.dumps(doc, ensure_ascii=False, allow_nan=False, indent=2).encode("utf-8") + b"\n"


def _write_locked(entry, path):
    """Write ``entry`` to ``path`` atomically, locked from its first moment; return its lock.

    The entry keeps its old file and lock: the caller swaps them once it is safe.
    """
    new_fd = []
    write_atomic(path, _content(entry), mode=0o600, before_replace=lambda fd: _lock_dup(fd, new_fd))
    return new_fd[0]


def _swap(entry, path, fd):
    release(entry)
    entry.path = path
    entry.fd = fd


def _lock_dup(fd, out):
    try_lock(fd)  # a brand-new temporary file: nobody else can hold it
    out.append(os.dup(fd))


def create(outbox, alert, sink):
    """Write a new entry for ``alert`` and ``sink``, locked by this process.

    Parameters
    ----------
    outbox : Path
        The outbox folder (created if missing).
    alert : Alert
        The alert.
    sink : str
        The sink's name.

    Returns
    -------
    Entry

    Raises
    ------
    OSError
        If the folder or the file cannot be written.
    """
    outbox.mkdir(parents=True, exist_ok=True)
    entry = Entry(path=outbox / entry_name(alert, sink), sink=sink, alert=alert)
    entry.fd = _write_locked(entry, entry.path)
    return entry


def claim(path):
    """Lock and read a pending entry, unless another process holds it.

    Parameters
    ----------
    path : Path
        The entry's file.

    Returns
    -------
    Entry or None
        None if another process is delivering it or it was just removed.

    Raises
    ------
    ValueError
        If the file is not a readable entry (move it aside with :func:`reject_file`).
    """
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return None
    try:
        # Locked, and still the file at ``path`` (not one replaced or removed meanwhile).
        if not try_lock(fd) or os.stat(path).st_ino != os.fstat(fd).st_ino:
            os.close(fd)
            return None
        with os.fdopen(os.dup(fd), "rb") as f:
            doc = json.loads(f.read())
    except FileNotFoundError:
        os.close(fd)
        return None
    except (OSError, ValueError) as exc:
        os.close(fd)
        raise ValueError(f"{path}: not a readable outbox entry: {exc}") from None
    try:
        if doc.get("schema") != OUTBOX_SCHEMA:
            raise ValueError(f"schema is {doc.get('schema')!r}, not {OUTBOX_SCHEMA!r}")
        return Entry(
            path=Path(path),
            sink=str(doc["sink"]),
            alert=from_json(Alert, doc["alert"]),
            attempts=int(doc.get("attempts", 0)),
            last_error=doc.get("last_error"),
            fd=fd,
        )
    except (AttributeError, KeyError, TypeError, ValueError) as exc:
        os.close(fd)
        raise ValueError(f"{path}: not a readable outbox entry: {exc}") from None


def update(entry, attempts, last_error):
    """Record failed tries in the entry's file; it stays pending.

    Parameters
    ----------
    entry : Entry
        The entry (locked by this process).
    attempts : int
        Tries made in this round.
    last_error : str
        The last failure.
    """
    entry.attempts += attempts
    entry.last_error = last_error
    _swap(entry, entry.path, _write_locked(entry, entry.path))


def reject(entry, attempts, last_error):
    """Move the entry to ``rejected/``, with its error; it is not retried again.

    Parameters
    ----------
    entry : Entry
        The entry (locked by this process).
    attempts : int
        Tries made in this round.
    last_error : str
        Why it was rejected.

    Returns
    -------
    Path
        The entry's new file.
    """
    folder = entry.path.parent / REJECTED
    folder.mkdir(exist_ok=True)
    entry.attempts += attempts
    entry.last_error = last_error
    old = entry.path
    fd = _write_locked(entry, folder / old.name)
    # Remove the pending file while still holding its lock: nobody sends it meanwhile.
    # A crash in between leaves both files, a duplicate but never a loss.
    old.unlink(missing_ok=True)
    fsync_dir(old.parent)
    _swap(entry, folder / old.name, fd)
    return entry.path


def reject_file(path):
    """Move an unreadable entry file to ``rejected/`` as it is.

    Parameters
    ----------
    path : Path
        The file.

    Returns
    -------
    Path
        The file's new path.
    """
    folder = path.parent / REJECTED
    folder.mkdir(exist_ok=True)
    target = folder / path.name
    os.replace(path, target)
    fsync_dir(path.parent)
    return target


def remove(entry):
    """Delete a delivered entry."""
    entry.path.unlink(missing_ok=True)
    fsync_dir(entry.path.parent)
    release(entry)


def release(entry):
    """Let other processes take the entry."""
    if entry.fd is not None:
        os.close(entry.fd)
        entry.fd = None


def requeue_rejected(outbox):
    """Move every rejected entry back to the pending ones (after the configuration is fixed).

    Parameters
    ----------
    outbox : Path
        The outbox folder.

    Returns
    -------
    int
        Number of entries moved.
    """
    folder = outbox / REJECTED
    if not folder.is_dir():
        return 0
    moved = 0
    for path in sorted(folder.iterdir()):
        if _NAME.fullmatch(path.name):
            os.replace(path, outbox / path.name)
            moved += 1
    if moved:
        fsync_dir(outbox)
        fsync_dir(folder)
    return moved
