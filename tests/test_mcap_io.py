"""MCAP recordings: exact round trip, the decided layout, cut files, flush, recovery."""

import functools
import io
import json
import shutil
import struct
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.writer import Writer
from mcap_ros2.decoder import DecoderFactory
from numpy.testing import assert_allclose, assert_array_equal

import imu_square
from imu_square.errors import ImuSquareWarning, RecordingError
from imu_square.io.mcap import (
    ACCEL_TOPIC,
    EVENTS_TOPIC,
    PREVIEW_TOPIC,
    RecordingWriter,
    batch_layout,
    read_mcap,
    recover_mcap,
    scan_mcap,
    summarize,
    write_mcap,
)
from imu_square.io.recording import Event, Recording, SensorInfo
from imu_square.program import TestProgram

SENSOR = SensorInfo("ADXL355", "SN 42", 2.2e-4, 19.6133, float("nan"))


def make_recording(
    n=5000,
    dt_ns=1_000_000,
    t0=1_700_000_000_000_000_000,
    seq0=17,
    seed=0,
    temperature=True,
    gaps=None,
):
    """A recording with gaps, events, temperature and every header field filled."""
    rng = np.random.default_rng(seed)
    accel = rng.normal(0.0, 0.05, (n, 3)).astype(np.float32)
    accel[:, 2] += np.float32(9.80665)
    steps = np.ones(n - 1, np.int64)
    gaps = ((n * 6 // 25, 3), (n * 3 // 5, 1)) if gaps is None else gaps
    for index, lost in gaps:
        steps[index - 1] += lost
    seq = seq0 + np.concatenate([[0], np.cumsum(steps)])
    time_ns = t0 + (seq - seq0) * dt_ns
    events = [
        Event(int(time_ns[n // 50]), "block_start", "ccw", 0),
        Event(int(time_ns[n // 2]), "block_end", "ccw", 0, "marker M200"),
        Event(int(time_ns[n * 6 // 25]), "gap", detail="lost=3"),
    ]
    temp = (25 + 0.01 * np.arange(n)).astype(np.float32) if temperature else None
    return Recording(
        accel=accel,
        time_ns=time_ns,
        seq=seq,
        dt_ns=dt_ns,
        program=TestProgram(radius_m=0.05, feed_m_per_s=0.08, cycles_per_direction=4),
        sensor=SENSOR,
        machine_id="DMU-50 #3",
        events=events,
        temperature_c=temp,
        metadata={"operator": "kj", "note": "ünïcode"},
        processing=["simulate: test", "step two"],
    )


def assert_same_recording(a, b):
    assert_array_equal(a.accel, b.accel)
    assert a.accel.dtype == b.accel.dtype == np.float32
    assert_array_equal(a.time_ns, b.time_ns)
    assert_array_equal(a.seq, b.seq)
    assert a.dt_ns == b.dt_ns
    assert a.program == b.program
    assert repr(a.sensor) == repr(b.sensor)  # NaN fields compare unequal with ==
    assert a.machine_id == b.machine_id
    assert a.events == b.events
    if a.temperature_c is None:
        assert b.temperature_c is None
    else:
        assert_array_equal(a.temperature_c, b.temperature_c)
    assert a.metadata == b.metadata
    assert a.processing == b.processing


def test_round_trip_is_exact(tmp_path):
    rec = make_recording()
    write_mcap(rec, tmp_path / "run.mcap")
    assert_same_recording(rec, read_mcap(tmp_path / "run.mcap"))


def test_round_trip_without_program_or_temperature_through_a_stream():
    rec = make_recording(n=333, temperature=False, gaps=())
    rec.program = None
    buf = io.BytesIO()
    write_mcap(rec, buf)
    buf.seek(0)
    assert_same_recording(rec, read_mcap(buf))


def test_sequence_numbers_cross_2_to_the_32(tmp_path):
    rec = make_recording(n=3000, seq0=2**32 - 1234, gaps=((1200, 3), (2000, 1)))
    assert rec.seq[0] < 2**32 < rec.seq[-1]
    write_mcap(rec, tmp_path / "wrap.mcap")
    back = read_mcap(tmp_path / "wrap.mcap")
    assert_array_equal(back.seq, rec.seq)
    assert back.gaps() == rec.gaps()


def test_recording_starting_above_2_to_the_32_keeps_its_sequence(tmp_path):
    rec = make_recording(n=500, seq0=3 * 2**32 + 5, gaps=((10, 2**32 + 7),))
    write_mcap(rec, tmp_path / "high.mcap")
    back = read_mcap(tmp_path / "high.mcap")
    assert_array_equal(back.seq, rec.seq)


def test_irregular_times_and_a_long_pause_round_trip(tmp_path):
    rec = make_recording(n=2000, gaps=())
    jitter = np.random.default_rng(1).integers(-40_000, 40_000, rec.n_samples)
    time_ns = rec.time_ns + jitter
    time_ns[1500:] += 5_000_000_000  # a 5 s pause with no sample lost: beyond int32 offsets
    rec = Recording(rec.accel, time_ns, rec.seq, rec.dt_ns)
    write_mcap(rec, tmp_path / "jitter.mcap")
    back = read_mcap(tmp_path / "jitter.mcap")
    assert_array_equal(back.time_ns, rec.time_ns)
    assert_array_equal(back.seq, rec.seq)


def test_negative_times_round_trip(tmp_path):
    rec = make_recording(n=400, t0=-200_000_000, gaps=())
    write_mcap(rec, tmp_path / "neg.mcap")
    assert_same_recording(rec, read_mcap(tmp_path / "neg.mcap"))


@pytest.mark.parametrize(
    ("dt_ns", "per_preview", "per_batch"),
    [
        (1_000_000, 10, 100),
        (250_000, 40, 400),
        (625_000, 16, 160),
        (10_000_000, 1, 10),
        (744_048, 14, 140),
        (2_000_000_000, 1, 1),
    ],
)
def test_batch_layout(dt_ns, per_preview, per_batch):
    assert batch_layout(dt_ns) == (per_preview, per_batch)
    assert 1e9 / (per_preview * dt_ns) <= 100.0 or per_preview == 1
    assert per_batch * dt_ns <= 1e9 or per_batch == 1


def test_layout_as_mcap_and_mcap_ros2_read_it(tmp_path):
    rec = make_recording(n=2350, dt_ns=1_000_000, gaps=((1000, 5),), temperature=False)
    path = tmp_path / "layout.mcap"
    write_mcap(rec, path)
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        schemas = {s.id: s for s in summary.schemas.values()}
        channels = {c.topic: c for c in summary.channels.values()}
        assert channels[ACCEL_TOPIC].message_encoding == "cdr"
        accel_schema = schemas[channels[ACCEL_TOPIC].schema_id]
        assert (accel_schema.name, accel_schema.encoding) == (
            "imu_square/msg/AccelBatch",
            "ros2msg",
        )
        preview_schema = schemas[channels[PREVIEW_TOPIC].schema_id]
        assert preview_schema.name == "geometry_msgs/msg/Vector3Stamped"
        assert b"MSG: std_msgs/Header" in preview_schema.data
        assert b"MSG: builtin_interfaces/Time" in preview_schema.data
        events_schema = schemas[channels[EVENTS_TOPIC].schema_id]
        assert (events_schema.encoding, channels[EVENTS_TOPIC].message_encoding) == (
            "jsonschema",
            "json",
        )
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        assert max(c.uncompressed_size for c in summary.chunk_indexes) < 128 * 1024 + 8 * 1024
        counts = summary.statistics.channel_message_counts
        by_topic = {c.topic: counts[c.id] for c in summary.channels.values()}
        # 1000 samples before the gap, 1350 after: batches of 100 -> 10 + 14; previews of 10.
        assert by_topic == {ACCEL_TOPIC: 24, PREVIEW_TOPIC: 235, EVENTS_TOPIC: 3}

        batches, previews = [], []
        for _, channel, message, decoded in reader.iter_decoded_messages(
            topics=[ACCEL_TOPIC, PREVIEW_TOPIC], log_time_order=False
        ):
            if channel.topic == ACCEL_TOPIC:
                assert message.log_time == message.publish_time == decoded.t0_ns
                assert len(decoded.temperature_c) == len(decoded.t_offset_ns) == 0
                batches.append(decoded)
            else:
                previews.append(decoded)
    assert [len(b.x) for b in batches] == [100] * 10 + [100] * 13 + [50]
    assert_array_equal(np.concatenate([b.x for b in batches]), rec.accel[:, 0])
    assert_array_equal(np.array([b.seq0 for b in batches[:11]]), 17 + np.r_[0:1000:100, 1005])
    first = previews[0]
    assert first.header.frame_id == "imu"
    assert_allclose(first.vector.x, rec.accel[:10, 0].astype(np.float64).mean(), rtol=1e-12)
    stamp = first.header.stamp.sec * 10**9 + first.header.stamp.nanosec
    assert stamp == rec.time_ns[0] + 4_500_000  # mean time of samples 0..9

    with open(path, "rb") as f:
        reader = make_reader(f)
        attachments = {a.name: a for a in reader.iter_attachments()}
        assert attachments["program.toml"].media_type == "application/toml"
        assert attachments["program.toml"].data.decode() == rec.program.to_toml()
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert meta["software"] == {
        "name": "imu-square",
        "version": imu_square.__version__,
        "dt_ns": "1000000",
    }
    assert meta["machine"] == {"machine_id": "DMU-50 #3"}
    assert meta["sensor"]["model"] == "ADXL355" and meta["sensor"]["resolution_m_s2"] == "nan"
    assert json.loads(meta["recording"]["processing"]) == rec.processing


def test_reader_matches_mcap_ros2_decoding(tmp_path):
    rec = make_recording(n=1234, dt_ns=250_000, temperature=True)
    path = tmp_path / "ref.mcap"
    write_mcap(rec, path)
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        ref = [d for *_, d in reader.iter_decoded_messages(topics=[ACCEL_TOPIC])]
    ref_accel = np.concatenate([np.column_stack([d.x, d.y, d.z]) for d in ref]).astype(np.float32)
    ref_temp = np.concatenate([d.temperature_c for d in ref])
    ours = read_mcap(path)
    assert_array_equal(ours.accel, ref_accel)
    assert_array_equal(ours.temperature_c, ref_temp.astype(np.float32))


def _write_chunked(rec, path, chunk_size=4096):
    with RecordingWriter(
        path,
        dt_ns=rec.dt_ns,
        program=rec.program,
        sensor=rec.sensor,
        machine_id=rec.machine_id,
        metadata=rec.metadata,
        processing=rec.processing,
        chunk_size=chunk_size,
    ) as w:
        for a in range(0, rec.n_samples, 700):
            sl = slice(a, a + 700)
            w.write_samples(rec.seq[sl], rec.time_ns[sl], rec.accel[sl], rec.temperature_c[sl])
            for e in rec.events:
                if rec.time_ns[sl][0] <= e.time_ns <= rec.time_ns[sl][-1]:
                    w.write_event(e)


@functools.cache
def _chunked():
    rec = make_recording(n=3000, dt_ns=1_000_000, gaps=((1200, 3),))
    buf = io.BytesIO()
    _write_chunked(rec, buf)
    return rec, buf.getvalue()


@pytest.fixture
def chunked_file():
    """A 3000-sample recording in 4 KiB chunks, and its bytes."""
    return _chunked()


def _read_cut(data):
    """Read a cut copy of a file; (recording or None, warning messages, error message)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            back = read_mcap(io.BytesIO(data))
        except RecordingError as exc:
            return None, [str(w.message) for w in caught], str(exc)
    return back, [str(w.message) for w in caught], ""


@settings(max_examples=120, deadline=None)
@given(fraction=st.floats(0.0, 1.0, exclude_max=True))
def test_cut_file_gives_an_exact_prefix_or_a_clear_error(fraction):
    rec, data = _chunked()
    cut = int(fraction * len(data))
    back, messages, error = _read_cut(data[:cut])
    if back is None:
        assert error and "\n" not in error and not messages
        assert ("empty" in error) or ("no complete samples" in error)
        return
    n = back.n_samples
    assert len(messages) == 1
    assert f"read {n} samples" in messages[0] and "cut at byte" in messages[0]
    assert f"of {cut};" in messages[0]
    assert 0 < n <= rec.n_samples
    assert_array_equal(back.accel, rec.accel[:n])
    assert_array_equal(back.time_ns, rec.time_ns[:n])
    assert_array_equal(back.seq, rec.seq[:n])
    assert_array_equal(back.temperature_c, rec.temperature_c[:n])
    assert back.program == rec.program and back.machine_id == rec.machine_id
    assert back.events == rec.events[: len(back.events)]


def test_cut_every_257_bytes(chunked_file):
    rec, data = chunked_file
    counts = []
    for cut in range(0, len(data), 257):
        back, messages, _ = _read_cut(data[:cut])
        n = 0 if back is None else back.n_samples
        if back is not None:
            assert_array_equal(back.accel, rec.accel[:n])
            assert_array_equal(back.time_ns, rec.time_ns[:n])
            assert messages and f"read {n} samples" in messages[0]
        counts.append(n)
    assert counts == sorted(counts)  # a longer file never gives fewer samples
    assert counts[-1] == rec.n_samples and counts[0] == 0


def test_cut_at_every_byte_of_the_tail_keeps_every_chunk_before(tmp_path, chunked_file):
    rec, data = chunked_file
    # Between the data end and the footer, every sample is already on disk.
    path = tmp_path / "tail.mcap"
    for cut in range(len(data) - 400, len(data), 37):
        path.write_bytes(data[:cut])
        with pytest.warns(ImuSquareWarning, match=f"read {rec.n_samples} samples"):
            back = read_mcap(path)
        assert_array_equal(back.accel, rec.accel)


def test_damaged_chunk_stops_reading_there(tmp_path, chunked_file):
    rec, data = chunked_file
    broken = bytearray(data)
    middle = len(data) // 2
    broken[middle : middle + 8] = b"\xff" * 8
    path = tmp_path / "damaged.mcap"
    path.write_bytes(bytes(broken))
    with pytest.warns(ImuSquareWarning, match="damaged") as w:
        back = read_mcap(path)
    assert 0 < back.n_samples < rec.n_samples
    assert_array_equal(back.accel, rec.accel[: back.n_samples])
    assert "read " in str(w[0].message)


def test_flush_puts_every_sample_on_disk(tmp_path):
    rec = make_recording(n=2600, gaps=())
    path = tmp_path / "live.mcap"
    snapshot = tmp_path / "snapshot.mcap"
    writer = RecordingWriter(path, dt_ns=rec.dt_ns, sensor=rec.sensor, fsync=True)
    try:
        written = 0
        for k, step in enumerate((1, 149, 1000, 3, 700)):  # odd sizes: partial batches
            sl = slice(written, written + step)
            writer.write_samples(rec.seq[sl], rec.time_ns[sl], rec.accel[sl], rec.temperature_c[sl])
            writer.write_event(Event(int(rec.time_ns[written]), "marker", detail=str(step)))
            written += step
            writer.flush()
            shutil.copyfile(path, snapshot)  # what kill -9 would leave now
            with pytest.warns(ImuSquareWarning, match=f"read {written} samples"):
                back = read_mcap(snapshot)
            assert_array_equal(back.accel, rec.accel[:written])
            assert_array_equal(back.time_ns, rec.time_ns[:written])
            assert [e.detail for e in back.events] == ["1", "149", "1000", "3", "700"][: k + 1]
        assert writer.samples_written == written
    finally:
        writer.close()
    writer.close()  # idempotent
    back = read_mcap(path)
    assert back.n_samples == written


def test_writer_rejects_bad_input(tmp_path):
    with RecordingWriter(tmp_path / "w.mcap", dt_ns=1000) as w:
        w.write_samples([5, 6], [10, 20], np.zeros((2, 3)))
        with pytest.raises(RecordingError, match="increase strictly, also across calls"):
            w.write_samples([6, 7], [30, 40], np.zeros((2, 3)))
        with pytest.raises(RecordingError, match="same number of samples"):
            w.write_samples([7, 8], [30], np.zeros((2, 3)))
        with pytest.raises(RecordingError, match="in every call or in none"):
            w.write_samples([7], [30], np.zeros((1, 3)), [20.0])
    with pytest.raises(RecordingError, match="writer is closed"):
        w.write_samples([9], [50], np.zeros((1, 3)))
    with pytest.raises(RecordingError, match=r"dt_ns must be an integer in \[1, 2\*\*32\)"):
        RecordingWriter(io.BytesIO(), dt_ns=0)


def test_garbage_files_raise_one_line_errors(tmp_path):
    cases = {
        "missing.mcap": (None, "recording not found"),
        "empty.mcap": (b"", "the file is empty"),
        "text.mcap": (b"time_s,accel_x\n0,1\n", "not an MCAP file"),
        "magic_only.mcap": (b"\x89MCAP0\r\n", "no complete samples"),
    }
    for name, (content, message) in cases.items():
        path = tmp_path / name
        if content is not None:
            path.write_bytes(content)
        with pytest.raises(RecordingError, match=message) as exc:
            read_mcap(path)
        assert "\n" not in str(exc.value) and name in str(exc.value)


def test_mcap_without_samples_is_refused(tmp_path):
    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        ch = w.register_channel("/other", "json", 0)
        w.add_message(ch, 1, b"{}", 1)
        w.finish()
    with pytest.raises(RecordingError, match="no complete samples on /imu/accel"):
        read_mcap(path)


def test_recover_rewrites_a_cut_file_whole(tmp_path, chunked_file):
    rec, data = chunked_file
    src, dst = tmp_path / "cut.mcap", tmp_path / "fixed.mcap"
    src.write_bytes(data[: int(len(data) * 0.7)])
    report = recover_mcap(src, dst)
    assert not report.complete and report.file_bytes == int(len(data) * 0.7)
    assert 0 < report.samples < rec.n_samples
    assert report.cut_at_byte <= report.file_bytes
    assert report.last_time_ns == rec.time_ns[report.samples - 1]
    fixed = scan_mcap(dst)
    assert fixed.report.complete and fixed.problem == ""
    assert_array_equal(fixed.recording.accel, rec.accel[: report.samples])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_mcap(dst)  # a whole file reads without a warning


def test_summarize(tmp_path):
    rec = make_recording()
    s = summarize(rec)
    assert s["samples"] == 5000 and s["gaps"] == {"count": 2, "lost": 4}
    assert s["duration_s"] == pytest.approx(5003 * 1e-3, abs=1e-12)
    assert s["sample_rate_hz"] == 1000.0
    assert s["events"] == {"block_end": 1, "block_start": 1, "gap": 1}
    assert s["channels"][-1] == "temperature_c"
    assert s["program"]["radius_mm"] == pytest.approx(50.0)
    assert s["sensor"]["resolution_m_s2"] is None  # NaN is not JSON
    json.dumps(s, allow_nan=False)


def _with_bad_index(data, chunk_no, offset_of):
    """``data`` with the first offset of every message index after chunk ``chunk_no`` replaced.

    Returns the bytes and the offsets put in.
    """
    broken, pos, chunks, put = bytearray(data), 8, 0, []
    while pos + 9 <= len(data):
        opcode, length = struct.unpack_from("<BQ", data, pos)
        body = pos + 9
        if opcode == 0x06:
            chunks += 1
        elif opcode == 0x07 and chunks == chunk_no:
            entry = body + 6 + 8  # channel id, entries' length, first entry's timestamp
            new = offset_of(struct.unpack_from("<Q", data, entry)[0])
            struct.pack_into("<Q", broken, entry, new)
            put.append(new)
        elif opcode == 0x02:  # the footer
            break
        pos = body + length
    return bytes(broken), put


@pytest.mark.parametrize("bad", ["inside_a_record", "beyond_the_chunk"])
def test_message_index_pointing_astray_stops_reading_at_its_chunk(tmp_path, chunked_file, bad):
    rec, data = chunked_file
    shift = (lambda o: o + 1) if bad == "inside_a_record" else (lambda o: o + 2**40)
    broken, offsets = _with_bad_index(data, 3, shift)
    assert offsets
    path = tmp_path / "astray.mcap"
    path.write_bytes(broken)
    with pytest.warns(ImuSquareWarning, match="damaged at byte") as w:
        back = read_mcap(path)
    message = str(w[0].message)
    if bad == "inside_a_record":
        assert any(f"(message index points to a non-message at {o})" in message for o in offsets)
    else:
        assert any(f"unpacking 11 bytes at offset {o} " in message for o in offsets)
    assert "\n" not in message
    assert 0 < back.n_samples < rec.n_samples
    assert_array_equal(back.accel, rec.accel[: back.n_samples])
