"""The numpy CDR codec against mcap_ros2's encoder and decoder (the reference)."""

import numpy as np
import pytest
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic
from numpy.testing import assert_array_equal

from imu_square.errors import RecordingError
from imu_square.io.cdr import _FIXED_BYTES as FIXED_BYTES
from imu_square.io.cdr import (
    ACCEL_BATCH_SCHEMA,
    ACCEL_BATCH_SCHEMA_NAME,
    VECTOR3_STAMPED_SCHEMA,
    VECTOR3_STAMPED_SCHEMA_NAME,
    decode_accel_batches,
    encode_accel_batch,
    encode_vector3_stamped,
)

REF_ENCODE = serialize_dynamic(ACCEL_BATCH_SCHEMA_NAME, ACCEL_BATCH_SCHEMA)[ACCEL_BATCH_SCHEMA_NAME]
REF_DECODE = generate_dynamic(ACCEL_BATCH_SCHEMA_NAME, ACCEL_BATCH_SCHEMA)[ACCEL_BATCH_SCHEMA_NAME]

# (n, with temperature, with offsets, seq0, t0_ns): empty arrays, odd lengths, extremes.
CASES = [
    (0, False, False, 0, 0),
    (1, True, False, 2**32 - 1, -5),
    (7, False, True, 123, 1_700_000_000_123_456_789),
    (100, False, False, 2**31 + 3, 10**9),
    (401, True, True, 99, -(2**62)),
]


def accel_batch_size(n, has_temperature, has_offsets):
    """Bytes of an encoded AccelBatch.

    Parameters
    ----------
    n : int
        Samples in the batch.
    has_temperature, has_offsets : bool
        Whether the temperature and time-offset arrays are filled.

    Returns
    -------
    int
        Message size. [bytes]
    """
    return FIXED_BYTES + 4 * n * (3 + bool(has_temperature) + bool(has_offsets))


def _batch(n, temp, offs, seed):
    rng = np.random.default_rng(seed)
    accel = rng.normal(0, 3, (n, 3)).astype(np.float32)
    temperature = (20 + rng.normal(size=n)).astype(np.float32) if temp else None
    offsets = rng.integers(-(2**31), 2**31, n) if offs else None
    return accel, temperature, offsets


@pytest.mark.parametrize(("n", "temp", "offs", "seq0", "t0"), CASES)
def test_accel_batch_bytes_identical_to_mcap_ros2(n, temp, offs, seq0, t0):
    accel, temperature, offsets = _batch(n, temp, offs, n)
    ours = encode_accel_batch(seq0, 250_000, t0, accel, temperature, offsets)
    ref = REF_ENCODE(
        {
            "seq0": seq0,
            "dt_ns": 250_000,
            "t0_ns": t0,
            "x": accel[:, 0].tolist(),
            "y": accel[:, 1].tolist(),
            "z": accel[:, 2].tolist(),
            "temperature_c": [] if temperature is None else temperature.tolist(),
            "t_offset_ns": [] if offsets is None else offsets.tolist(),
        }
    )
    assert ours == ref
    assert len(ours) == accel_batch_size(n, temp, offs)


def test_decode_many_layouts_matches_mcap_ros2_decoder():
    messages, truth = [], []
    for i, (n, temp, offs, seq0, t0) in enumerate(CASES * 3):
        accel, temperature, offsets = _batch(n, temp, offs, 100 + i)
        messages.append(encode_accel_batch(seq0, 1000 + i, t0, accel, temperature, offsets))
        truth.append((accel, temperature, offsets))
    # 120 samples with time offsets take as many bytes as 160 samples without: equal-length
    # messages of different layouts must still be told apart.
    a = _batch(120, False, False, 7)[0]
    messages.append(encode_accel_batch(1, 2, 3, a, None, np.arange(120)))
    b = _batch(160, False, False, 8)[0]
    messages.append(encode_accel_batch(4, 5, 6, b, None, None))
    assert len(messages[-1]) == len(messages[-2])
    truth += [(a, None, np.arange(120)), (b, None, None)]

    got = decode_accel_batches(messages)
    start = 0
    for k, (msg, (accel, temperature, offsets)) in enumerate(zip(messages, truth, strict=True)):
        ref = REF_DECODE(msg)
        n = accel.shape[0]
        sl = slice(start, start + n)
        assert got.counts[k] == n
        assert got.seq0[k] == ref.seq0 and got.dt_ns[k] == ref.dt_ns and got.t0_ns[k] == ref.t0_ns
        assert_array_equal(got.accel[sl], np.column_stack([ref.x, ref.y, ref.z]).reshape(n, 3))
        assert got.has_temperature[k] == (temperature is not None)
        if temperature is not None:
            assert_array_equal(got.temperature_c[sl], np.asarray(ref.temperature_c, np.float32))
        expected_offsets = np.zeros(n) if offsets is None else np.asarray(ref.t_offset_ns)
        assert_array_equal(got.t_offset_ns[sl], expected_offsets)
        start += n
    assert got.accel.shape == (start, 3)


def test_decode_runs_of_one_layout_among_others_matches_mcap_ros2_decoder():
    # Consecutive messages of one layout are copied as one slice, scattered ones sample by
    # sample: both, in one call, against the reference decoder.
    layouts = [(100, False, False)] * 5 + [(7, True, True)] * 2 + [(100, False, False)] * 4
    layouts += [(50, False, True), (100, False, False), (50, False, True)]
    messages, truth = [], []
    for i, (n, temp, offs) in enumerate(layouts):
        accel, temperature, offsets = _batch(n, temp, offs, 300 + i)
        messages.append(encode_accel_batch(i, 1000, 10 * i, accel, temperature, offsets))
        truth.append(accel)
    got = decode_accel_batches(messages)
    start = 0
    for k, (msg, accel) in enumerate(zip(messages, truth, strict=True)):
        ref = REF_DECODE(msg)
        n = accel.shape[0]
        assert got.counts[k] == n and got.seq0[k] == ref.seq0
        expected = np.column_stack([ref.x, ref.y, ref.z]).reshape(n, 3)
        assert_array_equal(got.accel[start : start + n], expected)
        if ref.t_offset_ns:
            assert_array_equal(got.t_offset_ns[start : start + n], ref.t_offset_ns)
        start += n
    assert got.accel.shape == (start, 3)


def test_decode_regular_batches_has_no_offsets_or_temperature():
    got = decode_accel_batches([encode_accel_batch(0, 1, 0, np.zeros((5, 3)))] * 3)
    assert got.t_offset_ns is None and got.temperature_c is None
    assert got.accel.shape == (15, 3)


@pytest.mark.parametrize("frame_id", ["imu", "a", "frame_of_eleven"])
def test_vector3_stamped_bytes_identical_to_mcap_ros2(frame_id):
    encode = serialize_dynamic(VECTOR3_STAMPED_SCHEMA_NAME, VECTOR3_STAMPED_SCHEMA)[
        VECTOR3_STAMPED_SCHEMA_NAME
    ]
    decode = generate_dynamic(VECTOR3_STAMPED_SCHEMA_NAME, VECTOR3_STAMPED_SCHEMA)[
        VECTOR3_STAMPED_SCHEMA_NAME
    ]
    times = np.array([0, 1_500_000_001, 1_700_000_000_999_999_999, -1])
    vectors = np.random.default_rng(3).normal(size=(4, 3))
    ours = encode_vector3_stamped(times, vectors, frame_id)
    for t, v, msg in zip(times, vectors, ours, strict=True):
        sec, nanosec = divmod(int(t), 10**9)
        ref = encode(
            {
                "header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id},
                "vector": {"x": v[0], "y": v[1], "z": v[2]},
            }
        )
        assert msg == ref
        back = decode(msg)
        assert back.header.frame_id == frame_id
        assert back.header.stamp.sec * 10**9 + back.header.stamp.nanosec == t


def test_malformed_batches_raise():
    good = encode_accel_batch(0, 1, 0, np.zeros((4, 3)))
    with pytest.raises(RecordingError, match="shorter than the 40"):
        decode_accel_batches([good[:30]], "f.mcap")
    with pytest.raises(RecordingError, match="does not match its array lengths"):
        decode_accel_batches([good + b"\0\0\0\0"], "f.mcap")
    bad_y = bytearray(good)
    bad_y[24 + 16] = 3  # y claims 3 samples
    with pytest.raises(RecordingError, match="unequal length"):
        decode_accel_batches([bytes(bad_y)], "f.mcap")
    with pytest.raises(RecordingError, match="not little-endian CDR"):
        decode_accel_batches([b"\0\0\0\0" + good[4:]], "f.mcap")
