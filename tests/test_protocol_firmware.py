"""The firmware's C protocol code builds exactly the frames the Python encoder builds.

``acquisition/firmware/imu_square_protocol.h`` is compiled with the host C compiler.
The board sketch needs the Arduino-ESP32 toolchain, which is not installed here: it is
only syntax-checked with the host C++ compiler against stub Arduino declarations.
"""

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from acquisition.protocol import (
    DeviceHeader,
    Marker,
    SampleBlock,
    encode_block,
    encode_header,
    encode_marker,
)
from imu_square.units import G

FIRMWARE = Path(__file__).resolve().parents[1] / "acquisition" / "firmware"
CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
CXX = shutil.which("c++") or shutil.which("g++") or shutil.which("clang++")

HEADER = DeviceHeader(
    model="ADXL355",
    serial="SN-0042",
    firmware="1.0.0",
    sample_rate_hz=4000.0,
    dt_ns=250_000,
    scale_m_s2_per_count=G / 256000,
    range_m_s2=2.048 * G,
    noise_density_m_s2_rthz=22.5e-6 * G,
    has_temperature=True,
)


def _blocks():
    rng = np.random.default_rng(3)
    yield SampleBlock(2**32 - 7, rng.integers(-(2**19), 2**19, (25, 3), dtype=np.int32), 24.37, 0)
    # zeros everywhere and a 255-sample frame exercise the COBS 254-byte blocks
    yield SampleBlock(0, np.zeros((255, 3), np.int32), float("nan"), 0x05)
    yield SampleBlock(1, np.full((30, 3), -1, np.int32), -12.5, 0x02)


HARNESS = r"""
#include <math.h>
#include <stdio.h>
#include "imu_square_protocol.h"

static void dump(const uint8_t *p, size_t n) {
    for (size_t i = 0; i < n; i++) printf("%02x", p[i]);
    printf("\n");
}

int main(void) {
    static uint8_t body[4096], out[4200];
    printf("%08x %04x\n", (unsigned)isq_crc32((const uint8_t *)"123456789", 9),
           (unsigned)isq_crc16((const uint8_t *)"123456789", 9));
    isq_header_t h = {250000u, 4000.0, 9.80665 / 256000, 2.048 * 9.80665,
                      22.5e-6 * 9.80665, 1, "ADXL355", "SN-0042", "1.0.0"};
    dump(out, isq_frame(body, isq_header_body(body, &h), out));
    dump(out, isq_frame(body, isq_marker_body(body, 305419896u, "M100 ccw start"), out));
    %BLOCKS%
    return 0;
}
"""


def _c_block(i, block):
    rows = ",".join(f"{{{x},{y},{z}}}" for x, y, z in block.counts.tolist())
    t = block.temperature_c
    temp = "ISQ_TEMPERATURE_ABSENT" if np.isnan(t) else str(round(t * 100))
    n = block.n_samples
    return (
        f"static const int32_t xyz{i}[{n}][3] = {{{rows}}};\n"
        f"    dump(out, isq_frame(body, isq_samples_body(body, {block.seq0}u, {n}, "
        f"{block.flags}, {temp}, xyz{i}), out));"
    )


@pytest.mark.skipif(CC is None, reason="no C compiler on this machine")
def test_c_encoder_matches_python(tmp_path):
    blocks = list(_blocks())
    source = HARNESS.replace(
        "%BLOCKS%", "\n    ".join(_c_block(i, b) for i, b in enumerate(blocks))
    )
    (tmp_path / "harness.c").write_text(source)
    exe = tmp_path / "harness"
    subprocess.run(
        [CC, "-std=c99", "-Wall", "-Wextra", "-Werror", "-O2", f"-I{FIRMWARE}",
         str(tmp_path / "harness.c"), "-o", str(exe)],
        check=True,
    )  # fmt: skip
    lines = subprocess.run([exe], check=True, capture_output=True, text=True).stdout.split()
    assert lines[0] == "cbf43926"
    assert lines[1] == "29b1"
    assert lines[2] == encode_header(HEADER).hex()
    assert lines[3] == encode_marker(Marker(305419896, "M100 ccw start")).hex()
    assert lines[4:] == [encode_block(b).hex() for b in blocks]


ARDUINO_STUB = r"""
#include <stddef.h>
#include <stdint.h>
#define IRAM_ATTR
#define VSPI 3
#define MSBFIRST 1
#define SPI_MODE0 0
#define LOW 0
#define HIGH 1
#define OUTPUT 1
#define INPUT_PULLUP 2
#define FALLING 2
struct SPISettings {
    SPISettings(uint32_t, int, int) {}
};
struct SPIClass {
    SPIClass(int) {}
    void begin(int, int, int, int) {}
    void beginTransaction(SPISettings) {}
    void endTransaction() {}
    uint8_t transfer(uint8_t v) { return v; }
};
struct HWSerial {
    void setTxBufferSize(size_t) {}
    void begin(uint32_t) {}
    int available() { return 0; }
    int read() { return -1; }
    int availableForWrite() { return 4096; }
    size_t write(const uint8_t *, size_t n) { return n; }
    void print(const char *) {}
    void println(const char *) {}
    int printf(const char *, ...) { return 0; }
};
extern HWSerial Serial;
void digitalWrite(int, int);
void pinMode(int, int);
uint32_t micros();
uint32_t millis();
void delay(uint32_t);
void delayMicroseconds(uint32_t);
void attachInterrupt(int, void (*)(), int);
int digitalPinToInterrupt(int);
"""


@pytest.mark.skipif(CXX is None, reason="no C++ compiler on this machine")
def test_sketch_is_valid_cpp_against_stub_arduino_api(tmp_path):
    (tmp_path / "SPI.h").write_text(ARDUINO_STUB)
    sketch = tmp_path / "sketch.cpp"
    sketch.write_text((FIRMWARE / "adxl355_esp32.ino").read_text())
    subprocess.run(
        [CXX, "-std=c++17", "-fsyntax-only", "-Wall", "-Wextra", "-Werror",
         f"-I{tmp_path}", f"-I{FIRMWARE}", str(sketch)],
        check=True,
    )  # fmt: skip
