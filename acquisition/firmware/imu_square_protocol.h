/*
 * imu_square_protocol.h -- the imu-square wire protocol, version 1, in portable C99.
 *
 * Specification: docs/protocol.md. Reference implementation: acquisition/protocol.py.
 * No Arduino or SDK dependency: the test suite (tests/test_protocol_firmware.py) compiles
 * this file with the host C compiler and checks every frame it builds byte for byte against
 * the Python encoder. The board sketches (adxl355_esp32.ino) are NOT compiled by the test
 * suite; only this header is.
 *
 * All multi-byte fields are little-endian. Frames are COBS-encoded and written as
 *     0x00, COBS(body || CRC-32(body)), 0x00
 * CRC: CRC-32/ISO-HDLC (the zlib/Ethernet CRC): poly 0x04C11DB7 (reflected 0xEDB88320),
 * init 0xFFFFFFFF, refin=true, refout=true, xorout 0xFFFFFFFF, check("123456789")=0xCBF43926.
 * A hardware CRC unit must be configured for exactly this variant (STM32 defaults to
 * CRC-32/MPEG-2, check 0x0376E6E7, which is NOT it); the bitwise loop below is always right.
 */
#ifndef IMU_SQUARE_PROTOCOL_H
#define IMU_SQUARE_PROTOCOL_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

#define ISQ_VERSION 1u
#define ISQ_TYPE_HEADER 0x01u
#define ISQ_TYPE_SAMPLES 0x02u
#define ISQ_TYPE_MARKER 0x03u

#define ISQ_FLAG_FIFO_OVERRUN 0x01u /* sensor FIFO overflowed: samples lost, seq gap estimated */
#define ISQ_FLAG_SATURATED 0x02u    /* a sample in this block reached full scale */
#define ISQ_FLAG_TX_DROPPED 0x04u   /* frames were dropped before this one (UART full) */

#define ISQ_TEMPERATURE_ABSENT ((int16_t)-32768)
#define ISQ_MAX_SAMPLES 255u
#define ISQ_MAX_NAME 32u
#define ISQ_MAX_TEXT 120u
/* Body sizes (before CRC). */
#define ISQ_SAMPLES_BODY(n) (10u + 9u * (n))
#define ISQ_HEADER_BODY_MAX (46u + 3u * ISQ_MAX_NAME)
#define ISQ_MARKER_BODY_MAX (7u + ISQ_MAX_TEXT)
/* Wire size for a body of b bytes: CRC 4, COBS 1 per started 254, two delimiters. */
#define ISQ_WIRE_SIZE(b) ((b) + 4u + 1u + ((b) + 4u) / 254u + 2u)

/* Sensor description sent in the header frame (type 0x01). */
typedef struct {
    uint64_t dt_ns;                 /* exact nominal sample spacing, round(1e9/rate) [ns] */
    double sample_rate_hz;          /* nominal output data rate [Hz] */
    double scale_m_s2_per_count;    /* one count [m/s^2] */
    double range_m_s2;              /* full scale [m/s^2] */
    double noise_density_m_s2_rthz; /* per axis [m/s^2/sqrt(Hz)], NAN if unknown */
    uint8_t has_temperature;        /* 1 if sample frames carry a temperature */
    const char *model;              /* 1..32 printable ASCII, no ',' '=' '*' */
    const char *serial;             /* 0..32 */
    const char *firmware;           /* 0..32 */
} isq_header_t;

static inline void isq_put_u16(uint8_t *p, uint16_t v) {
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}

static inline void isq_put_u32(uint8_t *p, uint32_t v) {
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static inline void isq_put_u64(uint8_t *p, uint64_t v) {
    for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}

static inline void isq_put_f64(uint8_t *p, double v) {
    uint64_t bits;
    memcpy(&bits, &v, sizeof bits); /* IEEE 754 binary64, as on ESP32 and RP2040 */
    isq_put_u64(p, bits);
}

/* CRC-32/ISO-HDLC, bit by bit (no table: 8 shifts per byte, ample at 4 kHz x 9 B). */
static inline uint32_t isq_crc32(const uint8_t *data, size_t n) {
    uint32_t crc = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) {
        crc ^= data[i];
        for (int k = 0; k < 8; k++) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
    }
    return crc ^ 0xFFFFFFFFu;
}

/* CRC-16/CCITT-FALSE for the optional "*hhhh" line checksum: poly 0x1021, init 0xFFFF,
 * refin=false, refout=false, xorout 0, check("123456789")=0x29B1. */
static inline uint16_t isq_crc16(const uint8_t *data, size_t n) {
    uint16_t crc = 0xFFFFu;
    for (size_t i = 0; i < n; i++) {
        crc ^= (uint16_t)data[i] << 8;
        for (int k = 0; k < 8; k++)
            crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
    }
    return crc;
}

/* Close a frame: append the CRC to body (which must have 4 spare bytes), then write
 * 0x00, COBS(body || crc), 0x00 to out (ISQ_WIRE_SIZE(body_len) bytes). Returns bytes written. */
static inline size_t isq_frame(uint8_t *body, size_t body_len, uint8_t *out) {
    isq_put_u32(body + body_len, isq_crc32(body, body_len));
    size_t n = body_len + 4;
    size_t w = 0;
    out[w++] = 0x00;
    size_t code_at = w++;
    uint8_t code = 1;
    for (size_t i = 0; i < n; i++) {
        if (body[i] == 0) {
            out[code_at] = code;
            code_at = w++;
            code = 1;
        } else {
            out[w++] = body[i];
            if (++code == 0xFF) {
                out[code_at] = code;
                code_at = w++;
                code = 1;
            }
        }
    }
    out[code_at] = code;
    out[w++] = 0x00;
    return w;
}

/* Sample frame body (type 0x02). xyz: n samples of x, y, z counts within int24.
 * temperature_centi_c: sensor temperature in 0.01 degC, or ISQ_TEMPERATURE_ABSENT.
 * body needs ISQ_SAMPLES_BODY(n) + 4 bytes. Returns the body length. */
static inline size_t isq_samples_body(uint8_t *body, uint32_t seq0, uint8_t n, uint8_t flags,
                                      int16_t temperature_centi_c, const int32_t (*xyz)[3]) {
    body[0] = ISQ_VERSION;
    body[1] = ISQ_TYPE_SAMPLES;
    isq_put_u32(body + 2, seq0);
    body[6] = n;
    body[7] = flags;
    isq_put_u16(body + 8, (uint16_t)temperature_centi_c);
    uint8_t *p = body + 10;
    for (unsigned i = 0; i < n; i++) {
        for (int a = 0; a < 3; a++) {
            uint32_t v = (uint32_t)xyz[i][a];
            *p++ = (uint8_t)v;
            *p++ = (uint8_t)(v >> 8);
            *p++ = (uint8_t)(v >> 16);
        }
    }
    return (size_t)(p - body);
}

static inline uint8_t *isq_put_name(uint8_t *p, const char *s, size_t max) {
    size_t n = strlen(s);
    if (n > max) n = max;
    *p++ = (uint8_t)n;
    memcpy(p, s, n);
    return p + n;
}

/* Header frame body (type 0x01); body needs ISQ_HEADER_BODY_MAX + 4 bytes. */
static inline size_t isq_header_body(uint8_t *body, const isq_header_t *h) {
    body[0] = ISQ_VERSION;
    body[1] = ISQ_TYPE_HEADER;
    isq_put_u64(body + 2, h->dt_ns);
    isq_put_f64(body + 10, h->sample_rate_hz);
    isq_put_f64(body + 18, h->scale_m_s2_per_count);
    isq_put_f64(body + 26, h->range_m_s2);
    isq_put_f64(body + 34, h->noise_density_m_s2_rthz);
    body[42] = h->has_temperature ? 1u : 0u;
    uint8_t *p = body + 43;
    p = isq_put_name(p, h->model, ISQ_MAX_NAME);
    p = isq_put_name(p, h->serial, ISQ_MAX_NAME);
    p = isq_put_name(p, h->firmware, ISQ_MAX_NAME);
    return (size_t)(p - body);
}

/* Marker frame body (type 0x03); text: printable ASCII without '*', up to 120 chars.
 * body needs ISQ_MARKER_BODY_MAX + 4 bytes. */
static inline size_t isq_marker_body(uint8_t *body, uint32_t seq, const char *text) {
    body[0] = ISQ_VERSION;
    body[1] = ISQ_TYPE_MARKER;
    isq_put_u32(body + 2, seq);
    uint8_t *p = isq_put_name(body + 6, text, ISQ_MAX_TEXT);
    return (size_t)(p - body);
}

#endif /* IMU_SQUARE_PROTOCOL_H */
