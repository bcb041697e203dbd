"""The example program, machine and sensor files that ship with the package."""

from importlib.resources import files
from pathlib import Path

from imu_square.errors import ConfigError


def data_names():
    """Names of the shipped example files.

    Returns
    -------
    list of str
    """
    folder = files("imu_square").joinpath("data")
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".toml"))


def data_path(name):
    """Path of a shipped example file, e.g. ``data_path("machine_typical.toml")``.

    Parameters
    ----------
    name : str
        File name (with or without ``.toml``).

    Returns
    -------
    pathlib.Path

    Raises
    ------
    ConfigError
        If there is no such file.
    """
    if not name.endswith(".toml"):
        name += ".toml"
    path = files("imu_square").joinpath("data", name)
    if not path.is_file():
        raise ConfigError(f"data file {name!r} is not shipped; available: {data_names()}")
    return Path(str(path))
