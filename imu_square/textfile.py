"""Reading the small text files users write (programs, machine, sensor and monitor TOML)."""

import tomllib
from pathlib import Path


def read_text(path, error, what="file"):
    """Read a UTF-8 text file, turning every failure into one ``error`` naming it.

    Parameters
    ----------
    path : str or Path
        The file.
    error : type
        The :class:`~imu_square.errors.ImuSquareError` subclass to raise.
    what : str
        What the file is, for the message (e.g. ``"program file"``).

    Returns
    -------
    str
        The file's text.
    """
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{path}: {what} not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise error(f"{path}: cannot read the {what}: {exc}") from None


def parse_toml(text, source, error):
    """Parse TOML text, turning a syntax error into one ``error`` naming its source.

    Parameters
    ----------
    text : str
        The TOML.
    source : str
        Where it came from, for the message.
    error : type
        The :class:`~imu_square.errors.ImuSquareError` subclass to raise.

    Returns
    -------
    dict
    """
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{source}: not valid TOML: {exc}") from None


def read_toml(path, error, what="file"):
    """Read and parse a TOML file (:func:`read_text`, then :func:`parse_toml`).

    Parameters
    ----------
    path : str or Path
        The file.
    error : type
        The :class:`~imu_square.errors.ImuSquareError` subclass to raise.
    what : str
        What the file is, for the message.

    Returns
    -------
    dict
    """
    return parse_toml(read_text(path, error, what), path, error)
