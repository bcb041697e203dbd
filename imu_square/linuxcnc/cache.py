"""One controller run per program and configuration: the sampled motions, kept on disk.

LinuxCNC runs in real time (the paper's test takes almost four minutes), but
its motion depends only on the NC program, the configuration and LinuxCNC's
version: many nights with other noise seeds, machines or sensors reuse one run.
A sampled motion is kept as ``<key>.npz`` under the cache folder, the key the
SHA-256 of the program's NC text, the configuration's files and the version.

The folder is ``$IMU_SQUARE_CACHE_DIR/linuxcnc-motion`` if that is set, else
``$XDG_CACHE_HOME/imu-square/linuxcnc-motion`` (``~/.cache/...``). Delete it
to run LinuxCNC again.
"""

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from imu_square.simulate.sampled_motion import ServoSamples

# Raised when the stored layout changes: older entries are then not read.
FORMAT = 1


def cache_folder():
    """Where sampled motions are kept (see the module docstring)."""
    root = os.environ.get("IMU_SQUARE_CACHE_DIR")
    if root:
        return Path(root) / "linuxcnc-motion"
    xdg = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(xdg) / "imu-square" / "linuxcnc-motion"


def motion_key(nc_text, configuration_digest, version):
    """The cache key of a program's motion on a configuration and LinuxCNC version.

    Parameters
    ----------
    nc_text : str
        The NC program as run.
    configuration_digest : str
        :meth:`Configuration.digest`.
    version : str
        LinuxCNC's version.

    Returns
    -------
    str
        SHA-256, hex.
    """
    doc = {"format": FORMAT, "nc": nc_text, "configuration": configuration_digest}
    doc["linuxcnc"] = version
    return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()


def load_samples(key, folder=None):
    """The cached samples of a key, or None.

    Parameters
    ----------
    key : str
        :func:`motion_key`.
    folder : Path, optional
        The cache folder; :func:`cache_folder` by default.

    Returns
    -------
    ServoSamples or None
    """
    path = (folder or cache_folder()) / f"{key}.npz"
    if not path.is_file():
        return None
    with np.load(path) as data:
        return ServoSamples(
            float(data["period_s"]),
            data["xy_m"],
            data["markers"],
            json.loads(str(data["source"])),
        )


def store_samples(key, samples, folder=None):
    """Keep samples under a key (written whole, then renamed into place).

    Parameters
    ----------
    key : str
        :func:`motion_key`.
    samples : ServoSamples
        The samples.
    folder : Path, optional
        The cache folder; :func:`cache_folder` by default.

    Returns
    -------
    Path
        The file.
    """
    folder = folder or cache_folder()
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{key}.npz"
    part = folder / f"{key}.part.npz"
    np.savez_compressed(
        part,
        period_s=samples.period_s,
        xy_m=samples.xy_m,
        markers=samples.markers,
        source=json.dumps(samples.source),
    )
    os.replace(part, path)
    return path
