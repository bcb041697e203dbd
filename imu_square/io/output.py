"""Where an output file may go: checked before any work, so no run is lost to a bad path.

A recording can start hours after the command, when a CNC's marker fires; a
path that cannot be written must be refused at once, not after the machine
has run. :func:`check_output_path` refuses a missing folder, a directory, a
folder where no file can be created, and (unless asked) an existing file.
:func:`check_free_space` refuses a disk too small for what is about to be
written.
"""

import os
import shutil
import tempfile
from pathlib import Path

from imu_square.errors import OutputError

MB = 1e6  # display unit of disk space [bytes]


def check_output_path(path, *, overwrite=False):
    """Refuse an output path that cannot be written, before any work is done.

    Parameters
    ----------
    path : str or Path
        The file to be written.
    overwrite : bool
        Accept an existing file (it is replaced when writing starts).

    Returns
    -------
    Path
        ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    OutputError
        Naming the path and what is wrong with it.
    """
    path = Path(path)
    folder = path.parent
    if path.is_dir():
        raise OutputError(f"{path}: is a directory; give a file name inside it")
    if not folder.exists():
        raise OutputError(f"{path}: the folder {str(folder)!r} does not exist")
    if not folder.is_dir():
        raise OutputError(f"{path}: {str(folder)!r} is not a folder")
    if path.exists() or path.is_symlink():
        if not overwrite:
            raise OutputError(f"{path}: already exists; refusing to replace it (--overwrite does)")
        if not os.access(path, os.W_OK):
            raise OutputError(f"{path}: exists and is not writable")
        return path
    refused = _creation_refused(folder)
    if refused:
        raise OutputError(f"{path}: cannot create a file in {str(folder)!r}: {refused}")
    return path


def _creation_refused(folder):
    """Why a file cannot be created in ``folder``, or "" if it can: the only sure test
    (permissions, read-only mounts) is to create one, which is removed at once."""
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".imu-square-probe-"):
            return ""
    except OSError as exc:
        return str(exc.strerror or exc)


def check_folder_path(folder, what):
    """Refuse a folder that cannot be made or written, without making it: before any work.

    The folder is created only when its files are written, so that a run
    that fails leaves no empty folder behind.

    Parameters
    ----------
    folder : str or Path
        The folder to be written into; it need not exist.
    what : str
        What goes there, for the message (e.g. ``"model"``).

    Returns
    -------
    Path
        ``folder`` as a :class:`~pathlib.Path`.

    Raises
    ------
    OutputError
        Naming the folder and what is wrong with it.
    """
    folder = Path(folder)
    existing = folder
    while not existing.exists() and existing != existing.parent:
        if existing.is_symlink():  # to nothing: making the folder would fail after the work
            raise OutputError(
                f"{folder}: cannot create the {what} folder: {str(existing)!r} is a symbolic "
                f"link to {os.readlink(existing)!r}, which does not exist"
            )
        existing = existing.parent
    if not existing.is_dir():
        raise OutputError(f"{folder}: cannot create the {what} folder: {str(existing)!r} is a file")
    refused = _creation_refused(existing)
    if refused:
        raise OutputError(
            f"{folder}: cannot create the {what} folder in {str(existing)!r}: {refused}"
        )
    return folder


def check_free_space(path, needed_bytes, what):
    """Refuse to start writing ``path`` when its disk cannot hold ``needed_bytes``.

    Parameters
    ----------
    path : str or Path
        The file about to be written (its folder must exist).
    needed_bytes : float
        Upper estimate of the file's size. [bytes]
    what : str
        What is being written, for the message (e.g. ``"215 s at 1000 Hz"``).

    Raises
    ------
    OutputError
        When the free space is below ``needed_bytes``.
    """
    free = shutil.disk_usage(Path(path).parent).free
    if free < needed_bytes:
        raise OutputError(
            f"{path}: the disk has {free / MB:.1f} MB free, and the recording ({what}) needs "
            f"up to {needed_bytes / MB:.1f} MB: free some space or write elsewhere"
        )


def check_plot_path(path):
    """Refuse a plot path that cannot be written or whose suffix names no image format.

    Checked before any work, so that a long analysis is not lost to a typo in
    the plot's name; an existing file is replaced.

    Parameters
    ----------
    path : str or Path
        The image to be written, e.g. ``gaps.png``.

    Returns
    -------
    Path
        ``path`` as a :class:`~pathlib.Path`.

    Raises
    ------
    OutputError
        Naming the path and what is wrong with it.
    """
    from matplotlib.backend_bases import FigureCanvasBase

    from imu_square.validation import check_option

    path = check_output_path(path, overwrite=True)
    formats = sorted(FigureCanvasBase.get_supported_filetypes())
    check_option(
        "plot format (suffix)", path.suffix.lstrip(".").lower(), formats, str(path), OutputError
    )
    return path
