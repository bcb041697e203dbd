"""The two CRCs of the wire protocol, named by their exact catalogue variant.

Both are computed by the C code of the standard library (:mod:`zlib`,
:mod:`binascii`); the parameters are spelled out because microcontroller CRC
units often compute a different variant by default (STM32: CRC-32/MPEG-2).

========================  ==========  ==========  =====  ======  ==========  ==========
variant                   poly        init        refin  refout  xorout      check
========================  ==========  ==========  =====  ======  ==========  ==========
CRC-32/ISO-HDLC (frames)  0x04C11DB7  0xFFFFFFFF  true   true    0xFFFFFFFF  0xCBF43926
CRC-16/CCITT-FALSE (line) 0x1021      0xFFFF      false  false   0x0000      0x29B1
========================  ==========  ==========  =====  ======  ==========  ==========

"check" is the CRC of the nine ASCII bytes ``123456789``.
"""

import binascii
import zlib


def crc32(data):
    """CRC-32/ISO-HDLC (the zlib, Ethernet and PNG CRC) of ``data``.

    Parameters
    ----------
    data : bytes-like
        Bytes to protect.

    Returns
    -------
    int
        CRC in ``0 .. 2**32 - 1``; sent little-endian after a binary frame.
    """
    return zlib.crc32(data)


def crc16(data):
    """CRC-16/CCITT-FALSE of ``data`` (``binascii.crc_hqx`` started at 0xFFFF).

    Parameters
    ----------
    data : bytes-like
        Bytes to protect.

    Returns
    -------
    int
        CRC in ``0 .. 0xFFFF``; sent as four hex digits after ``*`` on a line.
    """
    return binascii.crc_hqx(data, 0xFFFF)
