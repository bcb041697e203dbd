"""An independent reader opens the recorder's files: TypeScript @mcap/core under Node.

``tests/node/check_mcap.mjs`` reads the file through its summary and indexes
and again record by record with chunk CRCs checked; both passes must agree
with each other and with what the Python reader finds.
"""

import collections
import json
import shutil
import subprocess
from pathlib import Path

import pytest
from acq_board import running_board, write_inputs

from imu_square.cli import main
from imu_square.io.mcap import (
    ACCEL_TOPIC,
    EVENTS_TOPIC,
    PREVIEW_TOPIC,
    read_mcap,
    scan_mcap,
)

NODE_DIR = Path(__file__).parent / "node"


@pytest.fixture(scope="module")
def node():
    exe, npm = shutil.which("node"), shutil.which("npm")
    if exe is None or npm is None:
        pytest.skip("node and npm are not installed: the @mcap/core cross-check needs them")
    if not (NODE_DIR / "node_modules" / "@mcap" / "core").is_dir():
        subprocess.run(
            [npm, "ci", "--no-audit", "--no-fund"], cwd=NODE_DIR, check=True, timeout=600
        )
    return exe


def check_with_node(node, path):
    proc = subprocess.run(
        [node, str(NODE_DIR / "check_mcap.mjs"), str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(proc.stdout)


@pytest.mark.slow
def test_node_reads_a_recorded_file_like_python_does(node, tmp_path, capsys):
    program, _ = write_inputs(tmp_path)
    out = tmp_path / "run.mcap"
    argv = ["record", "--port", str(tmp_path / "board"), "--program", str(program)]
    with running_board(tmp_path, faults="corrupt=0.0002,disconnect=5:1"):
        code = main([*argv, "-o", str(out), "--until-done"])
    assert code == 3
    rec = read_mcap(out)
    contents = scan_mcap(out)
    report = check_with_node(node, out)

    assert report["profile"] == "ros2"
    assert report["passes_agree"] and report["stream"]["complete"]
    schemas = {s["id"]: s for s in report["schemas"]}
    channels = {c["topic"]: c for c in report["channels"]}
    assert set(channels) == {ACCEL_TOPIC, PREVIEW_TOPIC, EVENTS_TOPIC}
    assert schemas[channels[ACCEL_TOPIC]["schema_id"]]["name"] == "imu_square/msg/AccelBatch"
    assert schemas[channels[ACCEL_TOPIC]["schema_id"]]["encoding"] == "ros2msg"
    assert channels[ACCEL_TOPIC]["message_encoding"] == "cdr"
    assert schemas[channels[EVENTS_TOPIC]["schema_id"]]["encoding"] == "jsonschema"
    assert channels[EVENTS_TOPIC]["message_encoding"] == "json"
    assert report["chunk_compression"] == ["zstd"]

    counts = {topic: m["count"] for topic, m in report["messages"].items()}
    assert counts == contents.channel_counts
    stats = report["statistics"]
    assert int(stats["message_count"]) == sum(counts.values())
    assert stats["chunk_count"] >= 1
    assert report["samples"] == rec.n_samples
    kinds = collections.Counter(e.kind for e in rec.events)
    assert report["event_kinds"] == dict(kinds)
    assert kinds["gap"] >= 1 and kinds["reconnect"] == 1 and kinds["crc_error"] >= 1
    assert int(report["messages"][ACCEL_TOPIC]["first_log_time"]) == rec.time_ns[0]
    assert {m["name"] for m in report["metadata"]} >= {"sensor", "machine", "recording"}
    assert report["attachments"] == ["program.toml"]
