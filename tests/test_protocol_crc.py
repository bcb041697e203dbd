"""CRC variants and COBS against their catalogue definitions and the library calls."""

import binascii
import zlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from acquisition.cobs import cobs_decode, cobs_encode
from acquisition.crc import crc16, crc32

CHECK_INPUT = b"123456789"
# The catalogue's "check": the CRC of CHECK_INPUT.
CRC32_CHECK = 0xCBF43926
CRC16_CHECK = 0x29B1


def crc32_bitwise(data):
    """CRC-32/ISO-HDLC, bit by bit: the loop the firmware uses (reflected poly 0xEDB88320)."""
    crc = 0xFFFFFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ (0xEDB88320 if crc & 1 else 0)
    return crc ^ 0xFFFFFFFF


def crc16_bitwise(data):
    """CRC-16/CCITT-FALSE, bit by bit: poly 0x1021, init 0xFFFF, not reflected, no xorout."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021 if crc & 0x8000 else crc << 1) & 0xFFFF
    return crc


def test_check_values_match_the_catalogue():
    assert crc32(CHECK_INPUT) == CRC32_CHECK == 0xCBF43926
    assert crc16(CHECK_INPUT) == CRC16_CHECK == 0x29B1
    assert crc32_bitwise(CHECK_INPUT) == 0xCBF43926
    assert crc16_bitwise(CHECK_INPUT) == 0x29B1


def test_library_calls_are_the_named_variants():
    assert crc32(CHECK_INPUT) == zlib.crc32(CHECK_INPUT)
    assert crc16(CHECK_INPUT) == binascii.crc_hqx(CHECK_INPUT, 0xFFFF)
    # The variant an STM32 CRC unit computes by default is a different number.
    assert crc32(CHECK_INPUT) != 0x0376E6E7  # CRC-32/MPEG-2 check value


@given(st.binary(max_size=300))
def test_bitwise_ports_equal_library(data):
    assert crc32(data) == crc32_bitwise(data)
    assert crc16(data) == crc16_bitwise(data)


@given(st.binary(max_size=1200))
def test_cobs_round_trip_without_zeros(data):
    encoded = cobs_encode(data)
    assert 0 not in encoded
    assert len(data) + 1 <= len(encoded) <= len(data) + 1 + len(data) // 254
    assert cobs_decode(encoded) == data


@pytest.mark.parametrize(
    ("data", "encoded"),
    [  # examples from Cheshire & Baker / the Wikipedia COBS article
        (b"\x00", b"\x01\x01"),
        (b"\x00\x00", b"\x01\x01\x01"),
        (b"\x11\x22\x00\x33", b"\x03\x11\x22\x02\x33"),
        (b"\x11\x22\x33\x44", b"\x05\x11\x22\x33\x44"),
        (b"\x11\x00\x00\x00", b"\x02\x11\x01\x01\x01"),
        (bytes(range(1, 255)), b"\xff" + bytes(range(1, 255)) + b"\x01"),
        (bytes(range(1, 256)), b"\xff" + bytes(range(1, 255)) + b"\x02\xff"),
    ],
)
def test_cobs_reference_vectors(data, encoded):
    assert cobs_encode(data) == encoded
    assert cobs_decode(encoded) == data


def test_cobs_rejects_code_past_end():
    assert cobs_decode(b"\x05\x11\x22") is None
