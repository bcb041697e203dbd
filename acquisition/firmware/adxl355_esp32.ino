/*
 * adxl355_esp32.ino -- ADXL355 accelerometer on an ESP32, streaming the imu-square
 * wire protocol version 1 (binary mode). Specification: docs/protocol.md.
 *
 * !!! NOT COMPILED FOR THE ESP32 AND NEVER RUN ON HARDWARE by the imu-square project. !!!
 * It is an example for firmware authors, written against the Arduino-ESP32 core 2.x
 * API and the ADXL355 data sheet (Rev. D). The test suite only checks that it is valid
 * C++ against stub declarations of the Arduino API it uses. The protocol part lives in
 * imu_square_protocol.h, which IS compiled on the host by tests/test_protocol_firmware.py
 * and checked byte for byte against the Python encoder. Check a real board with the
 * snippet in docs/protocol.md section 9 before trusting it.
 *
 * Build: copy this file and imu_square_protocol.h into a folder named adxl355_esp32,
 * open it in the Arduino IDE (board: "ESP32 Dev Module"), upload.
 *
 * Wiring (VSPI):  ADXL355 SCLK -> GPIO18, MISO -> GPIO19, MOSI -> GPIO23, CS -> GPIO5,
 *                 VDDIO/VSUPPLY -> 3V3, GND -> GND.
 *                 Trigger input (CNC M-code relay, button to GND) -> GPIO4 (active low).
 *
 * What it does:
 *  - sets range and output data rate (ODR_CODE below), reads the sensor FIFO over SPI,
 *    20-bit counts, one temperature reading per frame;
 *  - counts every sample read in a 32-bit sequence counter, batches SAMPLES_PER_FRAME
 *    samples per frame, CRC-32, COBS, 0x00 before and after;
 *  - sends the header at start, on '?' from the host, and every second;
 *  - forwards a falling edge on the trigger pin as a marker frame;
 *  - never blocks on the UART: a frame that does not fit in the TX buffer is dropped
 *    (the counter still advances, so the host sees the exact gap; TX_DROPPED flag).
 *
 * CRC check value: isq_crc32("123456789") must be 0xCBF43926 (printed at boot with
 * CHECK_CRC_AT_BOOT set, as an "#crc,..." line the host parser rejects and counts).
 */
#include <SPI.h>
#include <math.h>

#include "imu_square_protocol.h"

/* ---- configuration ------------------------------------------------------------ */
static const uint32_t BAUD = 115200;      /* 1 kHz fits at 115200 (85 %), 4 kHz needs 460800 */
static const uint8_t ODR_CODE = 2;        /* ADXL355 Filter[3:0]: 0=4000 Hz, 1=2000, 2=1000, ... */
static const uint8_t RANGE_CODE = 1;      /* ADXL355 Range[1:0]: 1=+-2.048 g, 2=+-4.096 g, 3=+-8.192 g */
static const uint8_t SAMPLES_PER_FRAME = 25;
static const int PIN_CS = 5;
static const int PIN_TRIGGER = 4;
static const char *SERIAL_NUMBER = "ESP32-0001"; /* set per board */
static const char *FIRMWARE_VERSION = "1.0.0";
static const bool CHECK_CRC_AT_BOOT = true;

/* ---- ADXL355 registers (data sheet Rev. D, Table 15) -------------------------- */
enum {
    REG_DEVID_AD = 0x00,   /* 0xAD */
    REG_DEVID_MST = 0x01,  /* 0x1D */
    REG_PARTID = 0x02,     /* 0xED */
    REG_STATUS = 0x04,     /* bit 2: FIFO_OVR */
    REG_FIFO_ENTRIES = 0x05,
    REG_TEMP2 = 0x06,      /* bits 3:0 = TEMP[11:8] */
    REG_TEMP1 = 0x07,
    REG_FIFO_DATA = 0x11,  /* no address auto-increment: a burst pops FIFO bytes */
    REG_FILTER = 0x28,     /* bits 6:4 HPF (0 = off), bits 3:0 ODR */
    REG_RANGE = 0x2C,
    REG_POWER_CTL = 0x2D,  /* bit 0 standby; 0 = measure, temperature on */
    REG_RESET = 0x2F,      /* write 0x52 */
};
static const uint8_t STATUS_FIFO_OVR = 0x04;
static const double G = 9.80665;

static SPIClass spi(VSPI);
static const SPISettings SPI_SETTINGS(8000000, MSBFIRST, SPI_MODE0); /* ADXL355: <= 10 MHz */

/* ---- state ---------------------------------------------------------------------- */
static isq_header_t header;
static uint32_t seq_next = 0;          /* sequence number of the next sample read */
static int32_t block[SAMPLES_PER_FRAME][3];
static uint8_t block_n = 0;
static uint32_t block_seq0 = 0;
static uint8_t pending_flags = 0;      /* flags for the next frame sent */
static uint32_t last_read_us = 0;      /* when the last FIFO read finished */
static uint32_t last_header_ms = 0;
static bool header_requested = true;   /* send one at start */
static volatile bool trigger_seen = false;
static volatile uint32_t trigger_us = 0;
static uint8_t body[ISQ_SAMPLES_BODY(ISQ_MAX_SAMPLES) + 4];
static uint8_t wire[ISQ_WIRE_SIZE(ISQ_SAMPLES_BODY(ISQ_MAX_SAMPLES))];

static void IRAM_ATTR on_trigger() {
    if (!trigger_seen) {
        trigger_us = micros();
        trigger_seen = true;
    }
}

/* ---- SPI ---------------------------------------------------------------------- */
static void reg_write(uint8_t reg, uint8_t value) {
    spi.beginTransaction(SPI_SETTINGS);
    digitalWrite(PIN_CS, LOW);
    spi.transfer((uint8_t)(reg << 1));        /* R/W bit 0 = write */
    spi.transfer(value);
    digitalWrite(PIN_CS, HIGH);
    spi.endTransaction();
}

static void reg_read(uint8_t reg, uint8_t *out, size_t n) {
    spi.beginTransaction(SPI_SETTINGS);
    digitalWrite(PIN_CS, LOW);
    spi.transfer((uint8_t)((reg << 1) | 1));  /* R/W bit 0 = read */
    for (size_t i = 0; i < n; i++) out[i] = spi.transfer(0x00);
    digitalWrite(PIN_CS, HIGH);
    spi.endTransaction();
}

static uint8_t reg_read1(uint8_t reg) {
    uint8_t v;
    reg_read(reg, &v, 1);
    return v;
}

/* ---- sending -------------------------------------------------------------------- */
static void send_frame(size_t body_len, bool may_drop) {
    size_t n = isq_frame(body, body_len, wire);
    if (may_drop && (size_t)Serial.availableForWrite() < n) {
        pending_flags |= ISQ_FLAG_TX_DROPPED; /* counter already advanced: exact gap */
        return;
    }
    Serial.write(wire, n); /* header and markers may wait for room: they are rare */
}

static int16_t read_temperature_centi() {
    uint8_t t[2];
    reg_read(REG_TEMP2, t, 2);
    int raw = ((t[0] & 0x0F) << 8) | t[1];
    /* Data sheet: 1885 LSB at 25 degC nominal, -9.05 LSB/degC. Uncalibrated, +-few degC. */
    double c = 25.0 + (raw - 1885) / -9.05;
    return (int16_t)lround(c * 100.0);
}

static void flush_block() {
    if (block_n == 0) return;
    size_t len = isq_samples_body(body, block_seq0, block_n, pending_flags,
                                  read_temperature_centi(), block);
    pending_flags = 0;
    send_frame(len, true);
    block_n = 0;
}

static void add_sample(int32_t x, int32_t y, int32_t z) {
    if (block_n == 0) block_seq0 = seq_next;
    block[block_n][0] = x;
    block[block_n][1] = y;
    block[block_n][2] = z;
    const int32_t fs = (1 << 19) - 1;
    if (x >= fs || x <= -fs || y >= fs || y <= -fs || z >= fs || z <= -fs)
        pending_flags |= ISQ_FLAG_SATURATED;
    seq_next++; /* wraps at 2^32 by unsigned arithmetic, as the protocol wants */
    if (++block_n == SAMPLES_PER_FRAME) flush_block();
}

static int32_t count20(const uint8_t *p) {
    /* FIFO entry: bits 23:4 data (two's complement), bit 1 empty, bit 0 x-axis marker. */
    int32_t v = ((int32_t)p[0] << 12) | ((int32_t)p[1] << 4) | (p[2] >> 4);
    if (v & 0x80000) v -= 0x100000;
    return v;
}

/* Read every complete x, y, z triple from the FIFO (96 entries = 32 samples). */
static void read_fifo() {
    uint8_t status = reg_read1(REG_STATUS);
    uint8_t entries = reg_read1(REG_FIFO_ENTRIES) & 0x7F;
    uint32_t now = micros();
    if (status & STATUS_FIFO_OVR) {
        /* Samples were lost; estimate how many from the time since the last read. */
        uint32_t expected = (uint32_t)((now - last_read_us) * header.sample_rate_hz / 1e6);
        uint32_t held = entries / 3;
        flush_block(); /* samples in a block must be consecutive */
        if (expected > held) seq_next += expected - held;
        pending_flags |= ISQ_FLAG_FIFO_OVERRUN;
    }
    uint8_t buf[96 * 3];
    size_t n = entries - entries % 3;
    if (n == 0) return;
    reg_read(REG_FIFO_DATA, buf, n * 3);
    last_read_us = micros();
    bool misaligned = false;
    size_t i = 0;
    while (i + 3 <= n) {
        const uint8_t *e = buf + 3 * i;
        if (!(e[2] & 0x01) || (e[2] & 0x02)) { /* not an x entry, or empty: step one entry */
            misaligned = true;
            i++;
            continue;
        }
        if (misaligned) { /* a partial sample was skipped: count it as lost, flag the gap */
            flush_block();
            seq_next++;
            pending_flags |= ISQ_FLAG_FIFO_OVERRUN;
            misaligned = false;
        }
        add_sample(count20(e), count20(e + 3), count20(e + 6));
        i += 3;
    }
}

/* Headers and markers go between frames; the block being filled is not sent yet. */
static void send_header() {
    send_frame(isq_header_body(body, &header), false);
    last_header_ms = millis();
    header_requested = false;
}

static void send_marker() {
    uint32_t t = trigger_us;
    if ((int32_t)(last_read_us - t) < 0) return; /* wait for a FIFO read after the edge */
    /* The newest sample read (seq_next - 1) was taken at about last_read_us. */
    double back = (last_read_us - t) * header.sample_rate_hz / 1e6;
    uint32_t seq = seq_next - 1 - (uint32_t)lround(back);
    send_frame(isq_marker_body(body, seq, "trigger GPIO4"), false);
    trigger_seen = false;
}

static void fail_forever(const char *why) {
    for (;;) { /* visible in a terminal; the host parser counts it as a bad chunk */
        Serial.print("#error,");
        Serial.println(why);
        delay(1000);
    }
}

void setup() {
    Serial.setTxBufferSize(4096); /* before begin(): about 0.35 s of 1 kHz frames */
    Serial.begin(BAUD);
    pinMode(PIN_CS, OUTPUT);
    digitalWrite(PIN_CS, HIGH);
    pinMode(PIN_TRIGGER, INPUT_PULLUP);
    spi.begin(18, 19, 23, PIN_CS);

    if (CHECK_CRC_AT_BOOT) {
        Serial.printf("#crc,%08lx\n", (unsigned long)isq_crc32((const uint8_t *)"123456789", 9));
    }
    reg_write(REG_RESET, 0x52);
    delay(10);
    uint8_t id[3];
    reg_read(REG_DEVID_AD, id, 3);
    if (id[0] != 0xAD || id[1] != 0x1D || id[2] != 0xED) fail_forever("ADXL355 not found");

    reg_write(REG_RANGE, RANGE_CODE);           /* INT_POL 0, I2C_HS 0 */
    reg_write(REG_FILTER, ODR_CODE & 0x0F);     /* high-pass off */
    reg_write(REG_POWER_CTL, 0x00);             /* measure, temperature on, DRDY on */

    double rate = 4000.0 / (double)(1u << ODR_CODE);
    double lsb_per_g = 256000.0 / (double)(1u << (RANGE_CODE - 1));
    header.sample_rate_hz = rate;
    header.dt_ns = (uint64_t)llround(1e9 / rate); /* 4 kHz / 2^k: exact in ns */
    header.scale_m_s2_per_count = G / lsb_per_g;
    header.range_m_s2 = 524287.0 / lsb_per_g * G;
    /* Data sheet typical 22.5 ug/rtHz at +-2 g; other ranges: unknown here, send NaN. */
    header.noise_density_m_s2_rthz = RANGE_CODE == 1 ? 22.5e-6 * G : NAN;
    header.has_temperature = 1;
    header.model = "ADXL355";
    header.serial = SERIAL_NUMBER;
    header.firmware = FIRMWARE_VERSION;

    last_read_us = micros();
    attachInterrupt(digitalPinToInterrupt(PIN_TRIGGER), on_trigger, FALLING);
}

void loop() {
    while (Serial.available() > 0) {
        if (Serial.read() == '?') header_requested = true; /* every other byte is ignored */
    }
    read_fifo();
    if (header_requested || millis() - last_header_ms >= 1000) send_header();
    if (trigger_seen) send_marker();
    delayMicroseconds(500); /* poll well inside the 8 ms the FIFO holds at 4 kHz */
}
