"""halsampler's output, and where the program's blocks lie in it.

``halsampler -t`` writes one line per servo period: the sample number, then the
sampler's pins (here X and Y in µm and the marker count, see
``imu-square-sim.hal``). It writes ``overrun`` where the sampler's FIFO
overflowed and samples were lost; a line cut short when LinuxCNC stopped it is
dropped.
"""

import numpy as np

from imu_square.errors import ControllerError
from imu_square.units import UM


def parse_halsampler(text, where="halsampler"):
    """Positions and marker counts from halsampler's text.

    Parameters
    ----------
    text : str
        ``halsampler -t`` output with the pins X [µm], Y [µm], marker count.
    where : str
        Where it came from, for messages.

    Returns
    -------
    xy_m : ndarray, shape (n, 2)
        Commanded X and Y positions. [m]
    markers : ndarray of int64, shape (n,)
        Marker count at each sample.

    Raises
    ------
    ControllerError
        If samples were lost (an overrun or a gap in the sample numbers) or
        there are none.
    """
    rows = [line.split() for line in text.splitlines()]
    if any(row == ["overrun"] for row in rows):
        raise ControllerError(
            f"{where}: halsampler fell behind and the sampler's FIFO overflowed: samples lost"
        )
    rows = [row for row in rows if len(row) == 4]
    if not rows:
        raise ControllerError(f"{where}: no samples")
    data = np.array(rows, dtype=np.float64)
    number = data[:, 0].astype(np.int64)
    if np.any(np.diff(number) != 1):
        k = int(np.flatnonzero(np.diff(number) != 1)[0])
        raise ControllerError(
            f"{where}: sample {number[k + 1]} follows sample {number[k]}: samples lost"
        )
    return data[:, 1:3] * UM, data[:, 3].astype(np.int64)


def block_spans(markers, n_blocks):
    """Sample spans of the blocks between their start and end markers.

    Parameters
    ----------
    markers : ndarray of int, shape (n,)
        Marker count at each sample; each block raises it at its start and at
        its end.
    n_blocks : int
        Blocks in the program.

    Returns
    -------
    list of (int, int)
        Per block: the first sample after its start marker and the first after
        its end marker.

    Raises
    ------
    ControllerError
        If the markers do not count two per block, one at a time.
    """
    steps = np.diff(markers)
    raised = np.flatnonzero(steps) + 1
    if np.any(steps[raised - 1] != 1) or len(raised) != 2 * n_blocks or markers[0] != 0:
        raise ControllerError(
            f"the block markers ran {int(markers[-1] - markers[0])} times in "
            f"{len(raised)} steps, expected {2 * n_blocks} (one at the start and one at the "
            f"end of each of {n_blocks} blocks)"
        )
    return [(int(raised[2 * i]), int(raised[2 * i + 1])) for i in range(n_blocks)]
