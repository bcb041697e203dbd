"""Reading the small text files users write (programs, machine and sensor TOML)."""

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
