/* protocol.c: framing, CRC, resynchronising byte-at-a-time receiver and the typed payloads of
 * the rccar link (docs/protocol.md). Plain C99: no Arduino headers, no heap, no clock, so the
 * same file runs on the ATmega328P and in the host tests and fuzzers. */
#include "protocol.h"

#include <string.h>

int rc_payload_len(uint8_t id) {
    switch (id) {
    case RC_HELLO: return 1;
    case RC_DRIVE: return 4;
    case RC_ARM: return 0;
    case RC_DISARM: return 0;
    case RC_PING: return 0;
    case RC_CONFIG_SET: return 1 + RC_CONFIG_WIRE_LEN;
    case RC_CONFIG_GET: return 0;
    case RC_HELLO_ACK: return 6;
    case RC_STATUS: return 3;
    case RC_TELEMETRY: return 26;
    case RC_CONFIG: return 1 + RC_CONFIG_WIRE_LEN;
    default: return -1;
    }
}

/* Bitwise MSB-first CRC-16/CCITT-FALSE: 8 shifts per byte, no table (saves 512 bytes of flash;
 * 38-byte frames at 115200 baud leave the AVR plenty of time). */
uint16_t rc_crc16_update(uint16_t crc, uint8_t byte) {
    crc ^= (uint16_t)byte << 8;
    for (uint8_t i = 0; i < 8; i++) crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
    return crc;
}

uint16_t rc_crc16(const uint8_t *data, size_t len) {
    uint16_t crc = RC_CRC_INIT;
    for (size_t i = 0; i < len; i++) crc = rc_crc16_update(crc, data[i]);
    return crc;
}

void rc_put_u16(uint8_t *p, uint16_t v) {
    p[0] = (uint8_t)v;
    p[1] = (uint8_t)(v >> 8);
}
void rc_put_u32(uint8_t *p, uint32_t v) {
    rc_put_u16(p, (uint16_t)v);
    rc_put_u16(p + 2, (uint16_t)(v >> 16));
}
uint16_t rc_get_u16(const uint8_t *p) { return (uint16_t)(p[0] | ((uint16_t)p[1] << 8)); }
uint32_t rc_get_u32(const uint8_t *p) { return rc_get_u16(p) | ((uint32_t)rc_get_u16(p + 2) << 16); }

/* ---- receiver ----------------------------------------------------------------------- */

void rc_parser_init(rc_parser *p) { memset(p, 0, sizeof *p); }

/* Drops the first k buffered bytes. */
static void shift(rc_parser *p, uint8_t k) {
    if (k >= p->n) {
        p->n = 0;
        return;
    }
    memmove(p->buf, p->buf + k, (size_t)(p->n - k));
    p->n = (uint8_t)(p->n - k);
}

/* Restores the invariant buf[0] == START by discarding leading bytes; a discarded run counts
 * one framing error unless we are already inside a counted bad stretch. */
static void skip_to_start(rc_parser *p) {
    uint8_t k = 0;
    while (k < p->n && p->buf[k] != RC_START) k++;
    if (k > 0 && !p->in_garbage) {
        p->in_garbage = 1;
        p->counters.framing_errors++;
    }
    shift(p, k);
}

/* Rejects the candidate frame at buf[0]: counts it, then rescans from the byte after its START
 * so that a START inside a damaged frame cannot hide the next valid frame. */
static void reject(rc_parser *p, int crc) {
    if (crc)
        p->counters.crc_errors++;
    else
        p->counters.framing_errors++;
    p->in_garbage = 1; /* bytes up to the next START belong to this error */
    shift(p, 1);
    skip_to_start(p);
}

int rc_parser_push(rc_parser *p, uint8_t byte) {
    if (p->n == 0) {
        if (byte != RC_START) {
            if (!p->in_garbage) {
                p->in_garbage = 1;
                p->counters.framing_errors++;
            }
            return 0;
        }
        p->buf[0] = byte;
        p->n = 1;
        return 0;
    }
    if (p->n >= RC_MAX_FRAME) {
        p->overflow = 1;
        p->counters.framing_errors++;
        return -1;
    }
    p->buf[p->n++] = byte;
    return 0;
}

int rc_parser_pop(rc_parser *p, rc_frame *out) {
    for (;;) {
        /* 1. need START + LEN */
        if (p->n < 2) return 0;
        uint8_t len = p->buf[1];
        if (len > RC_MAX_PAYLOAD) {
            reject(p, 0);
            continue;
        }
        /* 2. the id must be one of the table's and fixes the length: reject early, before
         *    waiting for a payload that may swallow the next frame */
        if (p->n < 3) return 0;
        int expected = rc_payload_len(p->buf[2]);
        if (expected != (int)len) {
            reject(p, 0);
            continue;
        }
        /* 3. whole frame buffered: check the CRC over LEN, ID, SEQ, PAYLOAD */
        uint8_t total = (uint8_t)(RC_HEADER_LEN + len + RC_CRC_LEN);
        if (p->n < total) return 0;
        uint16_t crc = rc_crc16(p->buf + 1, (size_t)(RC_HEADER_LEN - 1 + len));
        if (crc != rc_get_u16(p->buf + RC_HEADER_LEN + len)) {
            reject(p, 1);
            continue;
        }
        /* 4. accept, keep whatever followed it */
        out->id = p->buf[2];
        out->seq = p->buf[3];
        out->len = len;
        memcpy(out->payload, p->buf + RC_HEADER_LEN, len);
        p->counters.frames_ok++;
        p->in_garbage = 0;
        shift(p, total);
        skip_to_start(p);
        return 1;
    }
}

size_t rc_encode(uint8_t id, uint8_t seq, const uint8_t *payload, uint8_t len, uint8_t *out, size_t cap) {
    size_t total = (size_t)RC_HEADER_LEN + len + RC_CRC_LEN;
    if (len > RC_MAX_PAYLOAD || cap < total) return 0;
    out[0] = RC_START;
    out[1] = len;
    out[2] = id;
    out[3] = seq;
    if (len) memcpy(out + RC_HEADER_LEN, payload, len);
    rc_put_u16(out + RC_HEADER_LEN + len, rc_crc16(out + 1, (size_t)(RC_HEADER_LEN - 1 + len)));
    return total;
}

/* ---- typed payloads ------------------------------------------------------------------- */

uint8_t rc_pack_hello(uint8_t *out, uint8_t protocol_version) {
    out[0] = protocol_version;
    return 1;
}

uint8_t rc_pack_drive(uint8_t *out, const rc_drive *d) {
    rc_put_u16(out, (uint16_t)d->steer);
    rc_put_u16(out + 2, (uint16_t)d->throttle);
    return 4;
}

static void put_config(uint8_t *out, const rc_config *c) {
    rc_put_u16(out + 0, c->servo_min_us);
    rc_put_u16(out + 2, c->servo_center_us);
    rc_put_u16(out + 4, c->servo_max_us);
    rc_put_u16(out + 6, c->esc_min_us);
    rc_put_u16(out + 8, c->esc_neutral_us);
    rc_put_u16(out + 10, c->esc_max_us);
    rc_put_u16(out + 12, c->failsafe_ms);
}

static void get_config(const uint8_t *in, rc_config *c) {
    c->servo_min_us = rc_get_u16(in + 0);
    c->servo_center_us = rc_get_u16(in + 2);
    c->servo_max_us = rc_get_u16(in + 4);
    c->esc_min_us = rc_get_u16(in + 6);
    c->esc_neutral_us = rc_get_u16(in + 8);
    c->esc_max_us = rc_get_u16(in + 10);
    c->failsafe_ms = rc_get_u16(in + 12);
}

uint8_t rc_pack_config(uint8_t *out, uint8_t flags, const rc_config *c) {
    out[0] = flags;
    put_config(out + 1, c);
    return 1 + RC_CONFIG_WIRE_LEN;
}

uint8_t rc_pack_hello_ack(uint8_t *out, const rc_hello_ack *a) {
    out[0] = a->re_seq;
    out[1] = a->status;
    out[2] = a->protocol_version;
    out[3] = a->fw_major;
    out[4] = a->fw_minor;
    out[5] = a->fw_patch;
    return 6;
}

uint8_t rc_pack_status(uint8_t *out, const rc_status_msg *s) {
    out[0] = s->re_id;
    out[1] = s->re_seq;
    out[2] = s->status;
    return 3;
}

uint8_t rc_pack_telemetry(uint8_t *out, const rc_telemetry *t) {
    out[0] = t->state;
    out[1] = t->flags;
    out[2] = t->last_rx_seq;
    out[3] = t->drive_seq;
    rc_put_u16(out + 4, t->servo_us);
    rc_put_u16(out + 6, t->esc_us);
    rc_put_u16(out + 8, t->crc_errors);
    rc_put_u16(out + 10, t->framing_errors);
    rc_put_u16(out + 12, t->overruns);
    rc_put_u16(out + 14, t->failsafe_trips);
    rc_put_u16(out + 16, t->lost_frames);
    rc_put_u32(out + 18, t->rx_frames);
    rc_put_u32(out + 22, t->uptime_ms);
    return 26;
}

static int fits(const rc_frame *f, uint8_t id) { return f->id == id && (int)f->len == rc_payload_len(id); }

int rc_unpack_hello(const rc_frame *f, uint8_t *protocol_version) {
    if (!fits(f, RC_HELLO)) return -1;
    *protocol_version = f->payload[0];
    return 0;
}

int rc_unpack_drive(const rc_frame *f, rc_drive *d) {
    if (!fits(f, RC_DRIVE)) return -1;
    d->steer = (int16_t)rc_get_u16(f->payload);
    d->throttle = (int16_t)rc_get_u16(f->payload + 2);
    return 0;
}

int rc_unpack_config(const rc_frame *f, uint8_t *flags, rc_config *c) {
    if (!fits(f, RC_CONFIG_SET) && !fits(f, RC_CONFIG)) return -1;
    *flags = f->payload[0];
    get_config(f->payload + 1, c);
    return 0;
}

int rc_unpack_hello_ack(const rc_frame *f, rc_hello_ack *a) {
    if (!fits(f, RC_HELLO_ACK)) return -1;
    a->re_seq = f->payload[0];
    a->status = f->payload[1];
    a->protocol_version = f->payload[2];
    a->fw_major = f->payload[3];
    a->fw_minor = f->payload[4];
    a->fw_patch = f->payload[5];
    return 0;
}

int rc_unpack_status(const rc_frame *f, rc_status_msg *s) {
    if (!fits(f, RC_STATUS)) return -1;
    s->re_id = f->payload[0];
    s->re_seq = f->payload[1];
    s->status = f->payload[2];
    return 0;
}

int rc_unpack_telemetry(const rc_frame *f, rc_telemetry *t) {
    if (!fits(f, RC_TELEMETRY)) return -1;
    const uint8_t *b = f->payload;
    t->state = b[0];
    t->flags = b[1];
    t->last_rx_seq = b[2];
    t->drive_seq = b[3];
    t->servo_us = rc_get_u16(b + 4);
    t->esc_us = rc_get_u16(b + 6);
    t->crc_errors = rc_get_u16(b + 8);
    t->framing_errors = rc_get_u16(b + 10);
    t->overruns = rc_get_u16(b + 12);
    t->failsafe_trips = rc_get_u16(b + 14);
    t->lost_frames = rc_get_u16(b + 16);
    t->rx_frames = rc_get_u32(b + 18);
    t->uptime_ms = rc_get_u32(b + 22);
    return 0;
}

/* ---- configuration -------------------------------------------------------------------- */

static int ordered(uint16_t lo, uint16_t mid, uint16_t hi) { return 500 <= lo && lo < mid && mid < hi && hi <= 2500; }

int rc_config_valid(const rc_config *c) {
    return ordered(c->servo_min_us, c->servo_center_us, c->servo_max_us) &&
           ordered(c->esc_min_us, c->esc_neutral_us, c->esc_max_us) && c->failsafe_ms >= 20 && c->failsafe_ms <= 5000;
}

void rc_config_defaults(rc_config *c) {
    c->servo_min_us = 1000;
    c->servo_center_us = 1500;
    c->servo_max_us = 2000;
    c->esc_min_us = 1000;
    c->esc_neutral_us = 1500;
    c->esc_max_us = 2000;
    c->failsafe_ms = 250;
}

void rc_eeprom_encode(const rc_config *c, uint8_t out[RC_EEPROM_LEN]) {
    rc_put_u16(out, RC_EEPROM_MAGIC);
    out[2] = RC_EEPROM_VERSION;
    put_config(out + 3, c);
    rc_put_u16(out + 3 + RC_CONFIG_WIRE_LEN, rc_crc16(out, 3 + RC_CONFIG_WIRE_LEN));
}

int rc_eeprom_decode(const uint8_t in[RC_EEPROM_LEN], rc_config *c) {
    rc_config tmp;
    if (rc_get_u16(in) != RC_EEPROM_MAGIC || in[2] != RC_EEPROM_VERSION ||
        rc_get_u16(in + 3 + RC_CONFIG_WIRE_LEN) != rc_crc16(in, 3 + RC_CONFIG_WIRE_LEN)) {
        rc_config_defaults(c);
        return 0;
    }
    get_config(in + 3, &tmp);
    if (!rc_config_valid(&tmp)) {
        rc_config_defaults(c);
        return 0;
    }
    *c = tmp;
    return 1;
}

uint16_t rc_permille_to_us(int16_t permille, uint16_t min_us, uint16_t center_us, uint16_t max_us) {
    int32_t v = permille;
    if (v > 1000) v = 1000;
    if (v < -1000) v = -1000;
    /* rounded to the nearest microsecond, symmetric about the centre */
    int32_t span = v >= 0 ? (int32_t)max_us - center_us : (int32_t)center_us - min_us;
    int32_t mag = v >= 0 ? v : -v;
    int32_t off = (mag * span + 500) / 1000;
    int32_t us = v >= 0 ? (int32_t)center_us + off : (int32_t)center_us - off;
    if (us < min_us) us = min_us;
    if (us > max_us) us = max_us;
    return (uint16_t)us;
}
