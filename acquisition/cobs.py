"""Consistent Overhead Byte Stuffing (Cheshire & Baker, IEEE/ACM ToN 1999).

COBS rewrites a frame so that it contains no 0x00 byte; 0x00 then delimits
frames on the wire. The overhead is one byte per started 254 bytes of frame,
so a frame of at most 254 bytes grows by exactly one byte.
"""

MAX_BLOCK = 254


def cobs_encode(data):
    """Encode ``data`` so that the result contains no zero byte.

    Parameters
    ----------
    data : bytes-like
        Frame to encode (may contain zeros).

    Returns
    -------
    bytes
        Encoded frame, ``len(data) + 1 + len(data) // 254`` bytes at most, no 0x00,
        without delimiters.
    """
    out = bytearray()
    for part in bytes(data).split(b"\x00"):
        while len(part) >= MAX_BLOCK:
            out.append(0xFF)
            out += part[:MAX_BLOCK]
            part = part[MAX_BLOCK:]
        out.append(len(part) + 1)
        out += part
    return bytes(out)


def cobs_decode(chunk):
    """Decode one COBS-encoded frame (delimiters removed).

    Parameters
    ----------
    chunk : bytes-like
        Encoded frame; must not contain 0x00.

    Returns
    -------
    bytes or None
        The decoded frame, or None when a code byte points past the end of
        ``chunk`` (a truncated or corrupted frame).
    """
    out = bytearray()
    i = 0
    n = len(chunk)
    while i < n:
        code = chunk[i]
        end = i + code
        if code == 0 or end > n:
            return None
        out += chunk[i + 1 : end]
        i = end
        if code != 0xFF and i < n:
            out.append(0)
    return bytes(out)
